"""The study's summary (`stats.analyse`) as one HTML page, report.html: a section per part of the study, each its own
function, each figure (`figures.figures`, a PNG beside the page) in its section, linked and captioned, and the free-text
answers at the end."""

from __future__ import annotations

import html
import json
from typing import Any

from langpref.study.analysis.figures import CAPTIONS
from langpref.study.analysis.learned import confirmations_html

Summary = dict[str, Any]

STYLE = """body{font-family:sans-serif;max-width:1000px;margin:2em auto;padding:0 1em}table{border-collapse:collapse;
margin:1em 0}td,th{border:1px solid #ccc;padding:4px 8px;text-align:left}figure{display:inline-block;margin:.5em}
img{max-width:460px}figcaption{max-width:460px;font-size:.85em;color:#444}"""

ASPECT_LABELS = (("Time efficiency", "Time efficient"), ("Convenience", "Convenient"), ("Adaptability", "Adaptable"))


def report_html(
    summary: Summary,
    figs: dict[str, str],
    texts: list[tuple[str, str, str]],
    rewards: list[dict[str, Any]] | None = None,
) -> str:
    """The whole page: `figs` name -> PNG file beside it, each shown (and linked, full size) in its section with its
    caption; `texts` (participant, question, answer) of free text; `rewards` (method, participant, wants) of each
    participant's learned reward, in words beside its figure."""

    def fig(*names: str) -> str:
        return "".join(_figure(n, figs[n]) for n in names if n in figs)

    return (
        _head(summary)
        + _study1(summary)
        + fig("study1_attributes", "study1_iterations")
        + _study2_survey(summary)
        + fig("study2_attributes")
        + _time_per_query(summary)
        + fig("study2_time")
        + confirmations_html(summary["study2_confirmations"], _fmt)
        + "\n"
        + _ratings(summary)
        + fig("study2_ratings")
        + _wants(rewards or [])
        + fig("study2_rewards")
        + _figures_and_texts({k: v for k, v in figs.items() if k not in CAPTIONS}, texts)
    )


def _figure(name: str, file: str) -> str:
    """One figure: the PNG beside the report, linked to itself at full size, with what it shows as its caption."""
    src = html.escape(file)
    return (
        f'<figure><a href="{src}"><img src="{src}" alt="{html.escape(name)}"></a>'
        f'<figcaption>{html.escape(CAPTIONS.get(name, name))} <a href="{src}">{src}</a></figcaption></figure>\n'
    )


def _wants(rewards: list[dict[str, Any]]) -> str:
    """What each participant's learned reward wants, in words (`langpref.reward.wants.describe`), per method."""
    if not rewards:
        return ""
    from langpref.reward.wants import describe

    rows = "".join(
        f"<tr><td>{html.escape(r['participant'])}</td><td>{html.escape(r['method'])}</td>"
        f"<td>{html.escape(describe(r['wants']))}</td></tr>"
        for r in rewards
    )
    return f"""<h3>What each learned reward wants</h3>
<table><tr><th>participant</th><th>method</th><th>the reward (rewards/METHOD/reward-P.json)</th></tr>{rows}</table>
"""


def _fmt(x: Any, digits: int = 2) -> str:
    """A number with `digits` decimals, "-" for None, anything else as escaped text."""
    if x is None:
        return "-"
    if isinstance(x, float):
        return f"{x:.{digits}f}"
    return html.escape(str(x))


def _ms(s: dict[str, Any]) -> str:
    """`mean +- std (n=N)` of a `stats.describe` result, "-" when it has no values."""
    return "-" if s.get("mean") is None else f"{s['mean']:.2f} &plusmn; {s['std']:.2f} (n={s['n']})"


def _head(s: Summary) -> str:
    """The document head and who took part."""
    excluded = html.escape(" (#" + ", #".join(str(e["number"]) for e in s["excluded"]) + ")") if s["excluded"] else ""
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>langpref study report</title>
<style>{STYLE}</style></head><body>
<h1>Study report</h1>
<p>{s["participants"]} participants ({s["finished"]} finished), env {_fmt(s.get("env"))}; excluded from the
analyses: {len(s["excluded"])}{excluded};
Study-2 orders: {html.escape(json.dumps(s["method_order"]))}.</p>
"""


def _study1(s: Summary) -> str:
    """Study 1: attribute scores and iterations to satisfaction."""
    a1 = s["study1_attributes"]
    it = s["study1_iterations_to_satisfaction"]
    rows = "".join(f"<tr><td>{html.escape(v['text'])}</td><td>{_ms(v)}</td></tr>" for v in a1.values())
    return f"""<h2>Study 1: trajectory improvement</h2>
<table><tr><th>attribute</th><th>score</th></tr>
{rows}
</table>
<p>Iterations to satisfaction: mean {_fmt(it.get("mean"))} (n={it.get("n", 0)}), not satisfied within the rounds:
{it["not_satisfied"]}. Effective: {html.escape(json.dumps(s["study1_effective"]))}.</p>
"""


def _study2_survey(s: Summary) -> str:
    """Study 2's questionnaire: attribute scores, their average, the aspects table and the overall preference."""
    rows = "".join(
        f"<tr><td>{html.escape(v['text'])}</td><td>{_ms(v['language'])}</td><td>{_ms(v['comparison'])}</td></tr>"
        for v in s["study2_attributes"].values()
    )
    asp = s["study2_aspects"]
    n = asp["respondents"]
    aspect_rows = "".join(
        f"<tr><td>{html.escape(label)}</td><td>{asp['language'][a]} / {n}</td>"
        f"<td>{asp['comparison'][a]} / {n}</td></tr>"
        for a, label in ASPECT_LABELS
    )
    avg = s["study2_attribute_average"]
    return f"""<h2>Study 2: preference learning</h2>
<h3>Attribute scores (1-5)</h3>
<table><tr><th>question</th><th>language</th><th>comparison</th></tr>{rows}</table>
<p>Average over attributes: language {_fmt(avg["language"])}, comparison
{_fmt(avg["comparison"])} (language higher by
{_fmt(avg["language_vs_comparison_percent"], 1)}%).</p>
<h3>Satisfactory aspects (not exclusive between methods)</h3>
<table><tr><th></th><th>language</th><th>comparison</th></tr>{aspect_rows}</table>
<p>Overall preference: {html.escape(json.dumps(s["study2_preference"]))}</p>
"""


def _time_per_query(s: Summary) -> str:
    """Study 2's time per query and which clock it was read from."""
    t = s["study2_time_per_query_s"]
    src = t["source"]
    return f"""<h3>Time per query (s)</h3>
<p>Language {_ms(t["language"])}; comparison {_ms(t["comparison"])}; language takes
{_fmt(t["language_less_time_percent"], 1)}% less time. Timing used: the page's clock for
{src["language"]["client_ms"] + src["comparison"]["client_ms"]} answers, the server's for
{src["language"]["server_ms"] + src["comparison"]["server_ms"]} (where the page's was inconsistent
with it or missing).</p>
"""


def _ratings(s: Summary) -> str:
    """Study 2's ratings per rating point and the paired test of the areas under the rating curves."""
    r = s["study2_ratings"]
    test = r["auc_paired_test"]
    rows = "".join(
        f"<tr><td>{q}</td><td>{_ms(r['language']['per_point'][str(q)])}</td>"
        f"<td>{_ms(r['comparison']['per_point'][str(q)])}</td></tr>"
        for q in r["points"]
    )
    return f"""<h3>Ratings of the best trajectory under the learned reward</h3>
<table><tr><th>queries</th><th>language</th><th>comparison</th></tr>{rows}</table>
<p>Area under the rating curve: language {_ms(r["language"]["auc"])}, comparison {_ms(r["comparison"]["auc"])};
paired t-test p = {_fmt(test["t_p_value"], 4)}, Wilcoxon p = {_fmt(test["wilcoxon_p_value"], 4)}
(n = {test["n"]}).</p>
"""


def _figures_and_texts(figs: dict[str, str], texts: list[tuple[str, str, str]]) -> str:
    """The figures, the free-text answers (participants by the first 8 characters of their id) and the page's end."""
    img = "".join(_figure(k, f) for k, f in figs.items())
    rows = "".join(
        f"<tr><td>{html.escape(p[:8])}</td><td>{html.escape(q)}</td><td>{html.escape(v)}</td></tr>" for p, q, v in texts
    )
    return f"""{"<h2>Other figures</h2>" + img if img else ""}
<h2>Free-text answers</h2>
<table><tr><th>participant</th><th>question</th><th>answer</th></tr>{rows}</table>
</body></html>
"""
