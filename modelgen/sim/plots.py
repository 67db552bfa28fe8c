"""Figures of a :class:`~modelgen.sim.result.Result`: states, outputs, energy.

Built on ``matplotlib.figure.Figure`` directly, so plotting never selects a
backend or touches pyplot's global state (``plt.show()`` and notebooks keep
working in the caller's session).
"""
from __future__ import annotations

import numpy as np


#: outputs with more columns than this (orientations, poses) are not drawn
MAX_COLUMNS = 6
#: values beyond this magnitude are not drawn: matplotlib's tick formatter overflows
#: on ranges near the largest double (a run that blew up)
MAX_DRAWN = 1e150
#: characters of a failed run's reason in the figure's title (the message can list a state)
MAX_REASON = 90


def _line(ax, t, values, **style):
    """``ax.plot`` of the values that can be drawn (finite, below :data:`MAX_DRAWN`)."""
    values = np.asarray(values, dtype=float)
    with np.errstate(invalid="ignore"):
        drawn = np.where(np.abs(values) <= MAX_DRAWN, values, np.nan)
    ax.plot(t, drawn, **style)


def result_figure(res, *, title: str = "", conservative=None):
    """The figure :meth:`Result.plot` returns.

    Panels: the coordinates; one per recorded output; the energy when it was
    recorded.  With the work of non-conservative effects (``res.work``, from a
    scene with damping, friction or actions) the energy panel also draws each
    effect's work W_k(t) and E(0) + sum W_k, and a panel below draws the balance
    error E(t) - E(0) - sum W_k(t) [J], which only the integration (and the
    work's quadrature) makes nonzero.  A ``conservative`` run without work gets
    the relative change of the total energy instead (its drift is the
    integration error).
    """
    from matplotlib.figure import Figure

    n_states = len(res.state_names)
    nq = n_states // 2 if res.n_coordinates is None else res.n_coordinates
    coords = res.state_names[:nq] if n_states else ()
    plotted = [name for name, v in res.outputs.items() if np.shape(v)[-1] <= MAX_COLUMNS]
    skipped = [name for name in res.outputs if name not in plotted]
    panels = ["coordinates"] + [("output", name) for name in plotted]
    if res.energy is not None:
        panels.append("energy")
        if res.work:
            panels.append("energy_balance")
        elif conservative:
            panels.append("energy_error")
    fig = Figure(figsize=(8, 1.7 * len(panels) + 0.9), layout="constrained")
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    t = res.t
    # each column's unit, when the run recorded them (the command line does)
    names = res.columns()
    units = dict(zip(names, res.info["units"])) \
        if len(res.info.get("units", ())) == len(names) else {}
    for ax, panel in zip(axes, panels):
        if panel == "coordinates":
            for i, name in enumerate(coords):
                _line(ax, t, res.y[i], label=name)
            ax.set_ylabel("coordinates\n[rad or m]")
        elif panel == "energy":
            total = res.energy.sum(axis=1)
            _line(ax, t, res.energy[:, 0], label="kinetic")
            _line(ax, t, res.energy[:, 1], label="potential")
            _line(ax, t, total, label="total E", color="k")
            for name, w in res.work.items():
                _line(ax, t, w, label=f"work of {name}", ls="--")
            if res.work:
                supplied = total[0] + sum(res.work.values())
                _line(ax, t, supplied, label="E(0) + sum of work", color="0.5", ls=":", lw=2)
            ax.set_ylabel("energy, work [J]")
        elif panel == "energy_balance":
            balance = res.energy.sum(axis=1) - res.energy.sum(axis=1)[0] - sum(res.work.values())
            _line(ax, t, balance, color="k", label="E - E(0) - sum of work")
            ax.set_ylabel("energy balance\nerror [J]")
        elif panel == "energy_error":
            total = res.energy.sum(axis=1)
            scale = res.energy_change().scale   # the largest |T| + |V|: E(0) may be 0
            change = np.abs(total[1:] - total[0]) / (scale if scale > 0 else 1.0)
            _line(ax, t[1:], np.maximum(change, 1e-17))
            ax.set_yscale("log")
            ax.set_ylabel("|E - E(0)| / E scale" if scale > 0 else "|E - E(0)| [J]")
        else:
            name = panel[1]
            values = np.asarray(res.outputs[name]).reshape(len(t), -1)
            columns = res.output_columns.get(name) or [f"{name}[{j}]" for j in
                                                        range(values.shape[1])]
            for j, column in enumerate(columns):
                _line(ax, t, values[:, j], label=column)
            unit = {units.get(column, "") for column in columns}
            ax.set_ylabel(f"{name} [{unit.pop()}]" if len(unit) == 1 and "" not in unit
                          else name)
        if ax.get_legend_handles_labels()[0]:
            entries = len(ax.get_legend_handles_labels()[0])
            ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0),
                      fontsize="small" if entries <= 8 else "x-small",
                      ncol=1 if entries <= 8 else 2)
        if not res.success and len(t):
            ax.axvline(t[-1], color="r", ls="--")
    axes[-1].set_xlabel("t [s]")
    if skipped:
        axes[-1].set_xlabel(f"t [s]        (not drawn: {', '.join(skipped)}, more than "
                            f"{MAX_COLUMNS} columns; they are in the CSV and NPZ)")
    fig.suptitle(_title(res, title))
    return fig


def _title(res, title: str) -> str:
    """The figure's title: ``title`` (else the run's message), and for a run that did
    not reach its end, where and why it stopped, so the PNG alone says it is partial."""
    if res.success or not title:
        return title or res.message
    reason = res.message.split("; ")[0].split(". ")[0]
    reason = reason if len(reason) <= MAX_REASON else reason[:MAX_REASON - 3] + "..."
    where = f" at t = {res.t_fail:g} s" if res.t_fail is not None else ""
    return f"{title}\nstopped{where} (status {res.status}): {reason}"
