"""What a study is, with no server: its protocol, its steps and their answers, its database. The lowest room of
`langpref.study`: it imports nothing of `session`, `server` or `analysis` (tests/test_layout.py holds it).

config.py    StudyConfig: the protocol, stored in the database when it is created
kinds.py     the feedback kinds a study runs, as data (each kind's page, answer field and table are its own)
surveys.py   Appendix B questionnaires and the task descriptions, as data
flow.py      the participant's path as a state machine: (step, answer) -> next step, over a `flow.Robot`
queries.py   which trajectories each Study-2 query shows (random, or an active strategy; `--query-selection`)
schema.py    the database's tables, one SQL script per schema version, and what migrations fill in
db.py        opening (creating, migrating) a database, its transactions, the writes and reads rooms share
"""
