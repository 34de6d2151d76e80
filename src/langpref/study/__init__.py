"""The web app for the paper's user studies (Sec. 5.2): `langpref study serve`, `simulate` and `export`.

Four rooms, whose imports run one way (server -> session -> protocol, server -> analysis -> protocol; nothing
imports back up: tests/test_layout.py holds it):

protocol/   what a study is, with no server: StudyConfig, the feedback kinds it runs, surveys, the participant's
            flow, query selection, the database's schema and transactions
session/    what a running study computes for its participants: the model, the reward learners, Study 1's
            generated trajectories
server/     the running web app: the HTTP contract (docs/design.md), its guards, videos, the robot hook, starting a
            server, and simulated participants over HTTP
analysis/   `langpref study export`: tables, the paper's analyses, figures, the HTML report, learned rewards
templates/, static/   the pages and their scripts (served by `server.pages`)
deploy/     a TLS reverse proxy in front of the server (nginx site, tested by tests/study/server/test_proxy.py)
The server's load and fault benchmarks are not part of the package: `benchmarks/` at the repository root.
"""
