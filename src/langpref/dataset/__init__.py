"""Trajectory datasets: generation in the simulator, storage on disk, splits."""
