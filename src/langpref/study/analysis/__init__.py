"""A study's analysis, one job per module (`langpref study export` and `GET /api/admin/export` use them):

tables.py    the database's tables as rows (credentials left out), exclusions, survey answers, CSV files
stats.py     the paper's analyses of those rows (Sec. 5.2, Table 1): `analyse` -> the summary (summary.json)
figures.py   the summary's PNG figures (Fig. 7-9 and Appendix E's time per query)
report.py    the summary as one HTML page (report.html)

`langpref.study.export` writes them all into one folder.
"""
