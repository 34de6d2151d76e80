"""langpref's benchmarks: speed and fault figures, not tests and not part of the package (the wheel holds none).

Run from a checkout, with the package installed (`make install`): `make bench` runs `pipeline` and `study_load`;
each is also `python -m benchmarks.NAME --help` from the repository root. Tables go into this checkout's
docs/results.md, between `<!-- bench:NAME -->` markers (`common.write_section`), whatever the working directory.

pipeline.py      `make bench`: every library table below, skippable one by one
throughput.py    simulators, generator, Ray overhead, `langpref import`, default datasets
latency.py       reward update and improvement step, feedback gate, generation step, sweeps, training times
selection.py     choosing the next active query (and the answer-model learner's update) at study sizes
study_load.py    20 simulated participants against `langpref study serve`: answer latency, and the export
study_faults.py  the study server under video floods, large uploads, SIGTERM and SIGKILL (prints JSON)
common.py        the repository root, writing a results section, reading /proc
"""
