"""What a running study computes for its participants, with no HTTP: the robot of `protocol.flow` over the model,
its reward learners and Study 1's generated trajectories. Imports `protocol` only (tests/test_layout.py holds it).

A room of its own rather than part of `server` because it is the study's learning side, not its web side: it runs
without a web app (tests/study/session/test_robot_blindness.py drives the robot alone; test_rebuild.py rebuilds a
learner from the database), and it keeps the heavy work (torch, the simulator's worker process) apart from the request
handling above it. The server's video cache shares its worker-process helpers (`workers.py`) from here, below both.

engine.py     StudyEngine (the model, the study set, embedding feedback, Eq. 4) and StudyRobot (a learner per
              participant and method, replayed from the database after a restart)
learners.py   Study 2's reward learners as the study reads them (meanings, the learned reward stored per answer)
generated.py  Study 1's new trajectories made in the simulator, in the background (`--improve-candidates generated`)
workers.py    a background worker process that yields to the server and dies with it (videos and generation)
"""
