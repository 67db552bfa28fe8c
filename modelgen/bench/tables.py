"""A sweep as text: a markdown table, a CSV file and a paragraph on the problem;
and the plain markdown table and number format the benchmark scripts print with.

>>> md, csv_path = write_tables(points, "out/pendulum", problem)     # doctest: +SKIP
>>> print(markdown(["model", "µs"], [["arm7", fmt(0.2468)], ["chain", fmt(None)]]))
| model | µs |
|:---|---:|
| arm7 | 0.247 |
| chain | – |
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from modelgen.bench.problem import Problem
from modelgen.bench.precision_sweep import Point

CSV_COLUMNS = ("problem", "method", "family", "kind", "setting", "final_error", "l2_error",
               "seconds", "repeats", "nfev", "njev", "status", "resolved", "message")


def _csv_row(p: Point) -> list:
    return [p.problem, p.method, p.family, "step" if p.fixed_step else "rtol",
            repr(p.setting), repr(p.final_error), repr(p.l2_error), repr(p.seconds), p.repeats,
            p.nfev, p.njev, p.status, int(p.ok and p.resolved("final") and p.resolved("l2")),
            p.message]


def fmt(value, spec=".3g", missing="–") -> str:
    """``value`` formatted with ``spec``, or ``missing`` for None."""
    return missing if value is None else format(value, spec)


def markdown(headers, rows, left=1) -> str:
    """A markdown table; the first ``left`` columns are left-aligned, the rest right."""
    lines = ["| " + " | ".join(headers) + " |",
             "|" + "|".join(":---" if i < left else "---:" for i in range(len(headers))) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _fmt(value, spec=".2e"):
    return "–" if value is None or not np.isfinite(value) else format(value, spec)


def markdown_table(points) -> str:
    """One row per point: method, setting, both errors, time, repeats, nfev, njev, status.

    Errors below the reference's floor are marked with an asterisk.
    """
    lines = ["| method | setting | final error | L2 error | time [ms] | repeats | nfev | njev "
             "| status |",
             "|---|---|---:|---:|---:|---:|---:|---:|---|"]
    for p in points:
        if not p.ran:
            status = p.message
        elif p.ok:
            status = "ok"
        else:
            status = f"**FAILED** ({p.status}): {p.message}"
        star = {m: "" if not p.ok or p.resolved(m) else "*" for m in ("final", "l2")}
        lines.append(f"| {p.method} | {p.setting_text} | {_fmt(p.final_error)}{star['final']} | "
                     f"{_fmt(p.l2_error)}{star['l2']} | {_fmt(p.seconds * 1e3, '.4g')} | "
                     f"{p.repeats} | {p.nfev if p.ran else '–'} | "
                     f"{p.njev if p.ran else '–'} | {status.replace('|', '/')} |")
    return "\n".join(lines)


def describe(problem: Problem) -> str:
    """A markdown paragraph: the problem, its reference and the resolvable floors."""
    ref = problem.reference
    lines = [f"**{problem.title}** — t = {problem.t_span[0]:g} … {problem.t_span[1]:.10g} s, "
             f"n = {problem.n}, dense grid of {len(problem.t_eval)} points.",
             f"Reference: {ref.how}; its spread is {ref.spread_final:.1e} (final) and "
             f"{ref.spread_l2:.1e} (L2), so errors below {ref.floor('final'):.1e} / "
             f"{ref.floor('l2'):.1e} (marked *) are not resolved."]
    lines += list(problem.notes)
    return "\n\n".join(lines)


def write_tables(points, stem, problem: Problem | None = None) -> tuple:
    """Write ``<stem>.md`` (markdown) and ``<stem>.csv``; returns the two paths."""
    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    md, csv_path = stem.with_suffix(".md"), stem.with_suffix(".csv")
    head = (f"# Work-precision: {problem.title}\n\n{describe(problem)}\n\n"
            if problem is not None else "")
    md.write_text(head + markdown_table(points) + "\n")
    with csv_path.open("w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(CSV_COLUMNS)
        for p in points:
            writer.writerow(_csv_row(p))
    return md, csv_path


