"""The web app for the paper's user studies (Sec. 5.2): `langpref study serve` and `langpref study export`.

config.py    StudyConfig (the protocol, stored in the database), VideoConfig, ServeConfig
surveys.py   Appendix B questionnaires and the task descriptions, as data
flow.py      the participant's path as a state machine: (step, answer) -> next step
engine.py    embedding feedback, improvement (Eq. 4), a reward learner per participant (Eq. 5-9 / Bradley-Terry)
queries.py   which trajectories each Study-2 query shows (random, or an active strategy; `--query-selection`)
generated.py Study 1's new trajectories made in the simulator, in the background (`--improve-candidates generated`)
db.py        SQLite schema (WAL, versioned) and transactions
videos.py    render cache with background pre-rendering
app.py       the HTTP contract (DESIGN.md) and the pages
serve.py     starting a server (CLI, tests)
export.py    CSVs, analyses, figures, report
simulate.py  simulated participants over HTTP (load test, benchmark, demo data)
bench.py     20 simulated participants: answer latency (`python -m langpref.study.bench`)
faultbench.py  unrendered-video flood, SIGTERM and SIGKILL figures (`python -m langpref.study.faultbench`)
deploy/      a TLS reverse proxy in front of the server (nginx site, tested by tests/study/test_proxy.py)
"""
