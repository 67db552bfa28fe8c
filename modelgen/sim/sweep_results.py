"""What a sweep's dataset gives: one number per run (:func:`scalar`: the final,
extreme or mean value of a trajectory, or its period), its figure
(:func:`plot_scalar`) and the table the CLI prints (:func:`summary`).  Imported
by :mod:`modelgen.sim.sweep`, which exports them; needs only numpy (and
matplotlib for the figure), not xarray: each reads what it needs of the dataset.
"""
from __future__ import annotations

import numpy as np

from modelgen.errors import SimulationError
from modelgen.sim.integrate import STATUS

__all__ = ["REDUCTIONS", "crossings", "scalar", "plot_scalar", "summary"]


# -- what the CLI shows ----------------------------------------------------------------

def summary(ds) -> str:
    """A text table of a sweep: runs, failures by status, wall time and runs per second."""
    status = np.asarray(ds["status"])
    seconds = float(ds.attrs.get("seconds", float("nan")))
    lines = [f"{'runs':<24}{status.size:>12}",
             f"{'succeeded':<24}{int(np.count_nonzero(status >= 0)):>12}"]
    for code in sorted(set(status[status < 0].tolist())):
        name = STATUS[code].name if code in STATUS else "unknown"
        lines.append(f"{f'failed: {code} {name}':<24}{int(np.count_nonzero(status == code)):>12}")
    lines += [f"{'wall time [s]':<24}{seconds:>12.3f}",
              f"{'runs per second':<24}{status.size / seconds if seconds > 0 else 0.0:>12.1f}",
              f"{'workers':<24}{ds.attrs.get('workers', 1):>12}",
              f"{'chunks x runs':<24}{ds.attrs.get('chunks', 1):>6} x {ds.attrs.get('chunk', 0):<5}",
              f"{'scheduler':<24}{ds.attrs.get('scheduler', ''):>12}"]
    return "\n".join(lines)


#: how a trajectory becomes one number per run, for :func:`scalar`
REDUCTIONS = ("final", "max", "min", "mean", "period")


def crossings(t, y, dy=None) -> np.ndarray:
    """Times at which samples ``y(t)`` cross zero upwards.  With the derivative
    ``dy`` (a coordinate's speed, from the same samples) each crossing is the root
    of the cubic Hermite interpolant on its interval (error O(h^4), found by
    safeguarded Newton steps), else of the linear one.

    >>> t = np.linspace(0, 20, 201)
    >>> f"{float(np.diff(crossings(t, np.sin(t), np.cos(t))).mean()) - 2 * np.pi:.0e}"
    '1e-09'
    """
    t, y = np.asarray(t, dtype=float), np.asarray(y, dtype=float)
    k = np.flatnonzero((y[:-1] < 0) & (y[1:] >= 0))
    out = []
    for i in k:
        h, y0, y1 = t[i + 1] - t[i], y[i], y[i + 1]
        s = y0 / (y0 - y1)                   # the linear root, a start and a fallback
        if dy is not None and np.isfinite(dy[i]) and np.isfinite(dy[i + 1]):
            d0, d1 = dy[i] * h, dy[i + 1] * h
            lo, hi = 0.0, 1.0
            for _ in range(30):
                h00, h10 = 2 * s**3 - 3 * s**2 + 1, s**3 - 2 * s**2 + s
                h01, h11 = -2 * s**3 + 3 * s**2, s**3 - s**2
                f = h00 * y0 + h10 * d0 + h01 * y1 + h11 * d1
                df = ((6 * s**2 - 6 * s) * y0 + (3 * s**2 - 4 * s + 1) * d0
                      + (-6 * s**2 + 6 * s) * y1 + (3 * s**2 - 2 * s) * d1)
                if f < 0:
                    lo = s
                else:
                    hi = s
                step = s - f / df if df > 0 else 0.5 * (lo + hi)
                s_new = step if lo < step < hi else 0.5 * (lo + hi)
                if abs(s_new - s) < 1e-15:
                    s = s_new
                    break
                s = s_new
        out.append(t[i] + s * h)
    return np.array(out)


def scalar(ds, how: str, variable: str) -> np.ndarray:
    """One number per run: the ``final`` (last finite sample), ``max``, ``min`` or
    ``mean`` of ``variable`` (a state or a single-column output) over time, or its
    ``period``: the mean interval between its upward zero crossings (located on
    the cubic Hermite interpolant when ``variable`` is a coordinate, whose speed
    is sampled too; NaN with fewer than two).  NaN for a run that failed."""
    if how not in REDUCTIONS:
        raise SimulationError(f"unknown reduction {how!r}; use one of {', '.join(REDUCTIONS)}")
    if variable not in ds or ds[variable].dims != ("run", "time"):
        names = [k for k, v in ds.data_vars.items() if v.dims == ("run", "time")]
        raise SimulationError(f"{variable!r} is not a state or single-column output of the "
                              f"sweep; choose one of {', '.join(names)}")
    a = np.asarray(ds[variable])
    ok = np.asarray(ds["status"]) >= 0
    if how == "period":
        t = np.asarray(ds["time"], dtype=float)
        speed = f"{variable}_dot"
        d = np.asarray(ds[speed]) if speed in ds and ds[speed].dims == ("run", "time") else None
        value = np.full(a.shape[0], np.nan)
        for r in range(a.shape[0]):
            times = crossings(t, a[r], None if d is None else d[r])
            if len(times) >= 2:
                value[r] = (times[-1] - times[0]) / (len(times) - 1)
        return np.where(ok, value, np.nan)
    with np.errstate(all="ignore"):
        value = {"final": a[:, -1] if a.shape[1] else np.full(a.shape[0], np.nan),
                 "max": np.max(a, axis=1), "min": np.min(a, axis=1),
                 "mean": np.mean(a, axis=1)}[how]
    return np.where(ok, value, np.nan)


def plot_scalar(ds, how: str, variable: str, path=None):
    """A figure of :func:`scalar` against the swept values: a curve for one swept
    name, a colour map for a product of two (from :func:`grid`), else points against
    the first; failed runs are marked.  Saved to ``path`` when given."""
    from matplotlib.figure import Figure
    values = scalar(ds, how, variable)
    swept = str(ds.attrs.get("swept", "")).split()
    fig = Figure(figsize=(6.4, 4.4), layout="constrained")
    ax = fig.add_subplot()
    unit = "s" if how == "period" else ds[variable].attrs.get("units")
    label = f"{how} {variable}" + (f" [{unit}]" if unit else "")
    failed = np.asarray(ds["status"]) < 0
    if len(swept) == 2:
        a, b = (np.asarray(ds[name]) for name in swept)
        ua, ub = np.unique(a), np.unique(b)
        if ua.size * ub.size == a.size and ua.size > 1 and ub.size > 1:
            Z = np.full((ub.size, ua.size), np.nan)
            Z[np.searchsorted(ub, b), np.searchsorted(ua, a)] = values
            mesh = ax.pcolormesh(ua, ub, Z, shading="nearest")
            fig.colorbar(mesh, ax=ax, label=label)
            ax.set_xlabel(_label(ds, swept[0]))
            ax.set_ylabel(_label(ds, swept[1]))
            if failed.any():
                ax.plot(a[failed], b[failed], "rx", label="failed")
                ax.legend()
            swept = []
    if swept:
        x = np.asarray(ds[swept[0]])
        order = np.argsort(x, kind="stable")
        style = "-" if len(swept) == 1 else "."
        ax.plot(x[order], values[order], style, label=label)
        if failed.any():
            ax.plot(x[failed], np.zeros(failed.sum()), "rx", label="failed")
        ax.set_xlabel(_label(ds, swept[0]))
        ax.set_ylabel(label)
        ax.legend()
    elif not ax.collections:
        ax.plot(values, ".")
        ax.set_xlabel("run")
        ax.set_ylabel(label)
    ax.set_title(f"{ds.attrs.get('scene') or ds.attrs.get('model')}: {how} {variable} over "
                 f"{ds.attrs.get('runs')} runs")
    if path is not None:
        fig.savefig(path, dpi=100)
    return fig


def _label(ds, name: str) -> str:
    """An axis label: the variable's name and its unit, if the model gives one."""
    unit = ds[name].attrs.get("units")
    return f"{name} [{unit}]" if unit else name
