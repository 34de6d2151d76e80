"""A study's analysis, one job per module (`langpref study export` and `GET /api/admin/export` use them). Imports
`protocol` only: it reads a study's database, never a running server (tests/test_layout.py holds it).

settings.py  ExportConfig: the options of `langpref study export`
tables.py    the database's tables as rows (credentials left out), exclusions, survey answers, CSV files
stats.py     the paper's analyses of those rows (Sec. 5.2, Table 1): `analyse` -> the summary (summary.json)
learned.py   the learned rewards, the confirmed meanings and the bank additions
rewards.py   each participant's answers and rewards as the library's files (answers.jsonl, rewards/)
figures.py   the summary's PNG figures (Fig. 7-9 and Appendix E's time per query)
report.py    the summary as one HTML page (report.html)
export.py    writes all of it into one folder
"""
