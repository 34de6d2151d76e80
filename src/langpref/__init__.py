"""langpref: teach robots with comparative language feedback.

A latent space shared by robot trajectories and comparative feedback ("move faster"), used to improve trajectories
and to learn reward functions from language (Yang et al., CoRL 2024).
"""

__version__ = "0.1.0"
