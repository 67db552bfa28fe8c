"""Figures of a :class:`~modelgen.sim.result.Result`: states, outputs, energy.

Built on ``matplotlib.figure.Figure`` directly, so plotting never selects a
backend or touches pyplot's global state (``plt.show()`` and notebooks keep
working in the caller's session).
"""
from __future__ import annotations

import numpy as np


#: outputs with more columns than this (orientations, poses) are not drawn
MAX_COLUMNS = 6


def result_figure(res, *, title: str = "", conservative=None):
    """The figure :meth:`Result.plot` returns.

    Panels: the coordinates; one per recorded output; the energy when it was
    recorded, with the relative change of the total energy when the run is
    ``conservative`` (a conserved quantity: its drift is the integration
    error) and the energy itself otherwise.
    """
    from matplotlib.figure import Figure

    n_states = len(res.state_names)
    coords = res.state_names[: n_states // 2] if n_states else ()
    plotted = [name for name, v in res.outputs.items() if np.shape(v)[-1] <= MAX_COLUMNS]
    skipped = [name for name in res.outputs if name not in plotted]
    panels = ["coordinates"] + [("output", name) for name in plotted]
    if res.energy is not None:
        panels.append("energy")
        if conservative:
            panels.append("energy_error")
    fig = Figure(figsize=(8, 1.7 * len(panels) + 0.9), layout="constrained")
    axes = fig.subplots(len(panels), 1, sharex=True, squeeze=False)[:, 0]
    t = res.t
    for ax, panel in zip(axes, panels):
        if panel == "coordinates":
            for i, name in enumerate(coords):
                ax.plot(t, res.y[i], label=name)
            ax.set_ylabel("coordinates\n[rad or m]")
        elif panel == "energy":
            total = res.energy.sum(axis=1)
            ax.plot(t, res.energy[:, 0], label="kinetic")
            ax.plot(t, res.energy[:, 1], label="potential")
            ax.plot(t, total, label="total", color="k")
            ax.set_ylabel("energy [J]")
        elif panel == "energy_error":
            total = res.energy.sum(axis=1)
            scale = max(np.max(np.abs(res.energy[0])), 1e-300)
            change = np.abs(total[1:] - total[0]) / scale
            ax.semilogy(t[1:], np.maximum(change, 1e-17))
            ax.set_ylabel("|E - E(0)| / E scale")
        else:
            name = panel[1]
            values = np.asarray(res.outputs[name]).reshape(len(t), -1)
            columns = res.output_columns.get(name) or [f"{name}[{j}]" for j in
                                                        range(values.shape[1])]
            for j, column in enumerate(columns):
                ax.plot(t, values[:, j], label=column)
            ax.set_ylabel(name)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize="small")
        if not res.success and len(t):
            ax.axvline(t[-1], color="r", ls="--")
    axes[-1].set_xlabel("t [s]")
    if skipped:
        axes[-1].set_xlabel(f"t [s]        (not drawn: {', '.join(skipped)}, more than "
                            f"{MAX_COLUMNS} columns; they are in the CSV and NPZ)")
    fig.suptitle(title or res.message)
    return fig
