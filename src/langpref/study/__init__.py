"""The web app for the paper's user studies (Sec. 5.2): `langpref study serve` and `langpref study export`.

config.py    StudyConfig (the protocol, stored in the database), VideoConfig, ServeConfig
surveys.py   Appendix B questionnaires and the task descriptions, as data
flow.py      the participant's path as a state machine: (step, answer) -> next step
engine.py    embedding feedback, improvement (Eq. 4), a reward learner per participant (Eq. 5-9 / Bradley-Terry)
queries.py   which trajectories each Study-2 query shows (random, or an active strategy; `--query-selection`)
generated.py Study 1's new trajectories made in the simulator, in the background (`--improve-candidates generated`)
db.py        SQLite schema (WAL, versioned) and transactions
videos.py    render cache with background pre-rendering
serving, the HTTP contract (docs/design.md):
  state.py         StudyApp: what every request shares (database, engine, videos, locks, rate limits)
  participants.py  the participants' router: join, resume, step, answer, videos
  admin.py         the lab's router: dashboard data, exclusions, export, status (admin token)
  pages.py         the pages, static files, /healthz and /api/info
  app.py           create_app: the routers behind the Host/cross-site checks, security headers, errors
  serve.py         starting a server (CLI, tests)
analysis, `langpref study export`:
  analysis/        tables (rows, exclusions, CSV), stats (the paper's analyses), figures, report (HTML)
  learned.py       the learned rewards, the confirmed meanings and the bank additions
  export.py        writes all of it into one folder
simulate.py  simulated participants over HTTP (load test, benchmark, demo data)
deploy/      a TLS reverse proxy in front of the server (nginx site, tested by tests/study/test_proxy.py)
The server's load and fault benchmarks are not part of the package: `benchmarks/` at the repository root.
"""
