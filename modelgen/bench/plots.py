"""Work-precision figures: error against cost, one line per method.

Built on :class:`matplotlib.figure.Figure` directly (no pyplot state, no
backend switch), so plotting never changes the caller's matplotlib set-up.

>>> plot_work_precision(points, problem, "out/pendulum.png")       # doctest: +SKIP
"""
from __future__ import annotations

import math
import textwrap
from pathlib import Path

import numpy as np
from matplotlib import colormaps
from matplotlib.figure import Figure
from matplotlib.lines import Line2D

from modelgen.bench.problem import Problem

MEASURES = (("final", "final-time error of q (max over coordinates)"),
            ("l2", "dense L2 error of q (RMS over the grid)"))
COSTS = (("seconds", "wall time [s] (minimum over repeats)"),
         ("nfev", "rhs evaluations"))


#: a C method and its scipy counterpart share a colour (C solid, scipy dashed)
COLOR_SLOTS = {"dopri5": 0, "rk45": 0, "dop853": 1, "rodas": 2, "radau": 2, "rk4": 3,
               "gauss4": 4, "midpoint": 5, "bdf": 6, "lsoda": 7}


def _colors(labels, palette) -> dict:
    free = iter([i for i in range(len(palette)) if i not in COLOR_SLOTS.values()] * 4)
    out = {}
    for label in labels:
        slot = COLOR_SLOTS.get(label.split()[-1].lower())
        out[label] = palette[(slot if slot is not None else next(free, 9)) % len(palette)]
    return out


def plot_work_precision(points, problem: Problem, path, title: str | None = None) -> Path:
    """Four log-log panels: (final, dense L2 error) x (wall time, rhs evaluations).

    One line per method (C solid and filled, scipy dashed and hollow; squares
    for fixed-step methods; a C method and its scipy counterpart share a
    colour).  Points below the reference's floor (grey band, "unresolved")
    are drawn faint and off their line; failures are ``x`` in the red
    "failed" band at the right, at the time / evaluations they used.
    """
    labels = list(dict.fromkeys(p.method for p in points))
    colors = _colors(labels, colormaps["tab10"].colors)
    finite = [p.error(m) for p in points if p.ok for m in ("final", "l2") if p.error(m) > 0]
    if finite:
        lo, hi = min(finite), max(finite)
    else:
        lo, hi = 1e-12, 1.0
    ref = problem.reference
    lo = min(lo / 3, ref.floor("l2") / 100, ref.floor("final") / 100)
    fail_x = 10 ** (math.ceil(math.log10(hi)) + 1)
    fig = Figure(figsize=(13, 10))
    axes = fig.subplots(2, 2, sharex="row", squeeze=False)
    for r, (measure, xlabel) in enumerate(MEASURES):
        for c, (cost, ylabel) in enumerate(COSTS):
            ax = axes[r, c]
            floor = ref.floor(measure)
            ax.axvspan(lo, floor, color="0.88", zorder=0)
            ax.text(lo * 1.3, 0.985, "unresolved", transform=ax.get_xaxis_transform(),
                    ha="left", va="top", fontsize=7, color="0.3")
            ax.axvspan(fail_x / 4, fail_x * 4, color="#fde0dc", zorder=0)
            ax.text(fail_x, 0.98, "failed", transform=ax.get_xaxis_transform(), ha="center",
                    va="top", fontsize=8, color="#b2182b")
            for i, label in enumerate(labels):
                mine = [p for p in points if p.method == label and p.ran]
                if not mine:
                    continue
                color = colors[label]
                scipy_like = mine[0].family == "scipy"
                marker = "s" if mine[0].fixed_step else "o"
                good = sorted((p for p in mine if p.ok and p.error(measure) > 0),
                              key=lambda p: -p.setting)
                resolved = [p for p in good if p.resolved(measure)]
                value = (lambda p: p.seconds) if cost == "seconds" else (lambda p: p.nfev)
                ax.plot([p.error(measure) for p in resolved], [value(p) for p in resolved],
                        ls="--" if scipy_like else "-", marker=marker, color=color, ms=5,
                        mfc="white" if scipy_like else color, label=label, lw=1.4)
                under = [p for p in good if not p.resolved(measure)]
                ax.plot([p.error(measure) for p in under], [value(p) for p in under],
                        ls="none", marker=marker, color=color, ms=5, mfc="none", alpha=0.6)
                bad = [p for p in mine if p.failed]
                jitter = np.exp(0.25 * (i - len(labels) / 2) / len(labels))
                ax.plot([fail_x * jitter] * len(bad), [max(value(p), 1e-9) for p in bad],
                        ls="none", marker="x", color=color, ms=8, mew=2)
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlim(lo, fail_x * 4)
            ax.grid(True, which="major", alpha=0.4)
            ax.grid(True, which="minor", alpha=0.1)
            ax.set_xlabel(xlabel)
            ax.set_ylabel(ylabel)
    handles, names = axes[0, 0].get_legend_handles_labels()
    handles.append(Line2D([], [], ls="none", marker="x", color="k", mew=2))
    names.append("failed (time / evaluations used)")
    fig.legend(handles, names, loc="lower center", ncol=5, fontsize=9, frameon=False)
    heading = title or (f"Work-precision: {problem.title}\n"
                        + textwrap.fill(f"reference: {ref.how}", 150))
    fig.suptitle(heading, fontsize=11)
    fig.tight_layout(rect=(0, 0.06, 1, 0.96 - 0.015 * heading.count("\n")))
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    return path


