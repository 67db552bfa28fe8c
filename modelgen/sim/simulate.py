"""Fixed-step simulation of a compiled model, with CSV and PNG output.

This is the small integrator the CLI's ``simulate`` uses: classic RK4 on the
compiled right-hand side.  A failing step (mass matrix not positive
definite, a non-finite state) never loses the trajectory: the result holds
everything computed up to the failure, its time and the reason.
"""
from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from modelgen.errors import ModelgenError, SimulationError


@dataclass
class SimulationResult:
    """Trajectory ``x[i]`` at times ``t[i]``; ``status`` 0 on success.

    ``energy[i] = [kinetic, potential]`` when recorded.
    """
    t: np.ndarray
    x: np.ndarray
    coordinates: tuple
    status: int = 0
    message: str = "success"
    energy: np.ndarray | None = None
    outputs: dict = field(default_factory=dict)          # name -> (samples, columns)
    output_columns: dict = field(default_factory=dict)   # name -> column names

    @property
    def success(self) -> bool:
        return self.status == 0

    def __getitem__(self, name):
        """A recorded output by name, shape (samples, columns)."""
        return self.outputs[name]

    def columns(self) -> list:
        speeds = [c + "_dot" for c in self.coordinates]
        names = ["t", *self.coordinates, *speeds]
        for name in self.outputs:
            names += list(self.output_columns[name])
        if self.energy is not None:
            names += ["kinetic", "potential", "total"]
        return names

    def table(self) -> np.ndarray:
        parts = [self.t[:, None], self.x, *self.outputs.values()]
        if self.energy is not None:
            parts += [self.energy, self.energy.sum(axis=1, keepdims=True)]
        return np.hstack(parts)

    def to_npz(self, path) -> Path:
        """t, x, the energies and every output as arrays in one .npz file."""
        path = Path(path)
        arrays = {"t": self.t, "x": self.x, **{f"output:{k}": v for k, v in self.outputs.items()}}
        if self.energy is not None:
            arrays["energy"] = self.energy
        np.savez(path, status=self.status, message=self.message,
                 coordinates=np.array(self.coordinates), **arrays)
        return path

    def to_csv(self, path) -> Path:
        path = Path(path)
        with path.open("w", newline="") as fh:
            writer = csv.writer(fh)
            writer.writerow(self.columns())
            for row in self.table():
                writer.writerow([repr(float(v)) for v in row])
        return path

    def plot(self, path, title: str = "", energy_error: bool = True) -> Path:
        """Coordinates against time, and the energy with its relative error.

        ``energy_error=False`` leaves out the error panel (for scenes with
        dissipation or driving forces, whose energy is not conserved).
        """
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        rows = 1 if self.energy is None else (3 if energy_error else 2)
        fig, axes = plt.subplots(rows, 1, figsize=(8, 2.6 * rows + 0.6), sharex=True,
                                 squeeze=False)
        axes = axes[:, 0]
        n = len(self.coordinates)
        for i, name in enumerate(self.coordinates):
            axes[0].plot(self.t, self.x[:, i], label=name)
        axes[0].set_ylabel("coordinates")
        axes[0].legend(loc="upper right", fontsize="small")
        if self.energy is not None:
            total = self.energy.sum(axis=1)
            axes[1].plot(self.t, self.energy[:, 0], label="kinetic")
            axes[1].plot(self.t, self.energy[:, 1], label="potential")
            axes[1].plot(self.t, total, label="total", color="k")
            axes[1].set_ylabel("energy [J]")
            axes[1].legend(loc="upper right", fontsize="small")
        if self.energy is not None and energy_error:
            scale = max(np.max(np.abs(self.energy)), 1e-300)
            axes[2].semilogy(self.t[1:], np.maximum(np.abs(total[1:] - total[0]) / scale, 1e-17))
            axes[2].set_ylabel("relative energy error")
        axes[-1].set_xlabel("t [s]")
        if not self.success:
            for ax in axes:
                ax.axvline(self.t[-1], color="r", ls="--")
        fig.suptitle(title or f"{n} coordinates, {self.message}")
        fig.tight_layout()
        fig.savefig(path, dpi=110)
        plt.close(fig)
        return Path(path)


def rk4(cm, x0, t_span, dt, *, u=None, p=None, record_energy=True) -> SimulationResult:
    """Integrate ``cm`` with classic fixed-step RK4 from ``x0`` over ``t_span``.

    The loop runs in Python on the compiled rhs; ``u`` may be a constant
    vector or dict, or a callable ``u(t, x)`` (feedback), which is why this
    loop exists beside the C one (:meth:`CompiledModel.simulate_rk4`).

    >>> res = rk4(cm, [1.0, 0.0, 0.0, 0.0], (0.0, 10.0), 1e-3)   # doctest: +SKIP
    >>> res.t[-1], res.status                                      # doctest: +SKIP
    (10.0, 0)
    """
    t0, t1 = map(float, t_span)
    if not dt > 0 or not np.isfinite(dt):
        raise SimulationError(f"step dt must be a positive number, got {dt!r}")
    if not t1 > t0:
        raise SimulationError(f"t_span must be increasing, got {t_span!r}")
    x = np.array(x0, dtype=float)
    if x.shape != (2 * cm.n,):
        raise SimulationError(f"x0 must have {2 * cm.n} entries [q, qd], got {x.shape}")
    if not np.all(np.isfinite(x)):
        raise SimulationError("x0 must be finite")
    steps = int(np.ceil((t1 - t0) / dt - 1e-9))
    ts = t0 + dt * np.arange(steps + 1)
    ts[-1] = t1
    xs = np.empty((steps + 1, x.size))
    xs[0] = x
    if callable(u):        # feedback: u(t, x) evaluated at every stage
        p_vec = cm.params(p)

        def f(t, x):
            return cm.rhs(t, x, u=u(t, x), p=p_vec)
    else:
        f = cm.rhs_function(u=u, p=p)
    status, message, last = 0, "success", steps
    for i in range(steps):
        t, h = ts[i], ts[i + 1] - ts[i]
        try:
            k1 = f(t, x)
            k2 = f(t + h / 2, x + h / 2 * k1)
            k3 = f(t + h / 2, x + h / 2 * k2)
            k4 = f(t + h, x + h * k3)
        except ModelgenError as exc:
            status, message, last = 1, f"step failed at t={t!r}: {exc}", i
            break
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        if not np.all(np.isfinite(x)):
            status, message, last = 2, f"non-finite state at t={ts[i + 1]!r}", i
            break
        xs[i + 1] = x
    ts, xs = ts[:last + 1], xs[:last + 1]
    energy = None
    if record_energy:
        n = cm.n
        energy = np.array([cm.energy(row[:n], row[n:], p) for row in xs])
    return SimulationResult(ts, xs, cm.coordinates, status, message, energy)
