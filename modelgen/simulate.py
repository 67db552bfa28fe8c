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

from .errors import ModelgenError, SimulationError


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


def _inputs_at(u, t, cm):
    """Input vector at time t for sampled inputs ``(times, values, interpolation)``."""
    if u is None:
        return None
    times, values, interpolation = u
    if interpolation == "hold":
        k = int(np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 1))
        return values[k]
    return np.array([np.interp(t, times, values[:, j]) for j in range(values.shape[1])])


#: effect kinds whose forces derive from a potential (energy is then conserved)
CONSERVATIVE_KINDS = ("gravity", "spring", "torsion_spring")


class Scene:
    """A scene ready to run: its reduced model built with exactly its outputs.

    >>> scene = modelgen.load_scene("models/scenes/dp_damped.yaml")   # doctest: +SKIP
    >>> res = scene.run()                                             # doctest: +SKIP
    >>> res.t, res.x, res["tip"]                                      # doctest: +SKIP
    """

    def __init__(self, spec, out_dir=None, *, force: bool = False, progress=None):
        from .pipeline import generate
        from .runtime import CompiledModel, check_mass_matrix
        self.spec = spec
        if progress:
            progress(f"{spec.name}: generating (or reusing) the model")
        # stiff scenes get the symbolic Jacobian, for implicit integrators
        generated = generate(spec.model, out_dir, force=force, outputs=spec.outputs,
                             jacobian=bool(spec.stiff_effects) and spec.model.n <= 12)
        self.generated = generated
        self.model = CompiledModel(generated.manifest, generated.build.module_path)
        if not generated.build.cached:
            check_mass_matrix(self.model)

    @property
    def conservative(self) -> bool:
        """True when every selected effect derives from a potential."""
        kinds = {e.name: e.kind for e in self.spec.full_model.effects}
        kinds.update({a.name: "action" for a in self.spec.full_model.actions})
        kinds["gravity"] = "gravity"
        return all(kinds.get(name) in CONSERVATIVE_KINDS for name in self.spec.effects)

    def summary(self) -> str:
        """What the scene simulates: effects, stiff ones flagged, outputs, ops."""
        s = self.spec
        lines = [f"scene {s.name}: model {s.full_model.name}, n = {s.model.n}",
                 f"effects on: {', '.join(s.effects) or 'none'}"]
        off = [name for name in _effect_names(s.full_model) if name not in s.effects]
        lines.append(f"effects off (not generated): {', '.join(off) or 'none'}")
        if s.stiff_effects:
            lines.append(f"STIFF or non-smooth: {', '.join(s.stiff_effects)} -- a small step "
                         f"or a stiff integrator (method: rodas) is needed")
        lines.append(f"outputs: {', '.join(o.name for o in s.outputs) or 'none'}")
        ops = self.generated.manifest["ops"]["rhs"]
        lines.append(f"rhs: {ops['after_cse']} operations after CSE")
        how = (f"{s.method} step {s.step:g} s" if s.method in ("rk4", "midpoint", "gauss4")
               else f"{s.method} rtol {s.rtol:g} atol {s.atol:g}")
        lines.append(f"time {s.t_start:g} .. {s.t_end:g} s, {how}, "
                     f"sampled every {s.sample_dt:g} s")
        return "\n".join(lines)

    def _inputs(self):
        s = self.spec
        signals = {sig.name: sig for sig in s.inputs}
        names = self.model.inputs
        if not signals:
            return None
        if all(sig.constant is not None for sig in signals.values()):
            return {name: sig.constant for name, sig in signals.items()}
        grid = sorted({t for sig in signals.values() for t in sig.times})
        values = np.zeros((len(grid), len(names)))
        holds = {sig.interpolation for sig in signals.values() if sig.constant is None}
        if len(holds) > 1:
            raise SimulationError(f"scene {s.name}: all sampled inputs must use the same "
                                  f"interpolation, got {sorted(holds)}")
        hold = holds.pop() == "hold"
        for j, name in enumerate(names):
            sig = signals.get(name)
            if sig is None:
                continue
            if sig.constant is not None:
                values[:, j] = sig.constant
            elif hold:
                idx = np.searchsorted(sig.times, grid, side="right") - 1
                values[:, j] = np.asarray(sig.values)[np.clip(idx, 0, len(sig.times) - 1)]
            else:
                values[:, j] = np.interp(grid, sig.times, sig.values)
        return (np.array(grid), values, "hold" if hold else "linear")

    def _run_integrator(self, x0, u, p) -> SimulationResult:
        """Adaptive or implicit C integrators, sampled at the scene's times."""
        s, cm = self.spec, self.model
        if callable(u):
            raise SimulationError(f"scene {s.name}: a feedback u(t, x) needs method rk4")
        fixed = s.method in ("midpoint", "gauss4")
        times = _scene_times(s.t_start, s.t_end, s.sample_dt)
        res = cm.simulate(x0, (s.t_start, s.t_end), t_eval=times, method=s.method,
                          rtol=s.rtol, atol=s.atol, u=u, p=p,
                          step=s.step if fixed else None)
        t, x = np.asarray(res.t), np.asarray(res.y).T
        outputs = {}
        if cm.output_columns:
            u_vec = None if u is None or isinstance(u, tuple) else u
            y = np.array([cm.output_values(ti, xi, u_vec if u_vec is not None
                                           else _inputs_at(u, ti, cm), p)
                          for ti, xi in zip(t, x)]).reshape(len(t), -1)
            outputs = {name: y[:, [cm.output_columns.index(c) for c in cols]]
                       for name, cols in cm.outputs.items()}
        return SimulationResult(t, x, cm.coordinates, status=0 if res.success else 1,
                                message=res.message, outputs=outputs,
                                output_columns=dict(cm.outputs))

    def run(self, p=None, x0=None, u=None) -> SimulationResult:
        """Integrate the scene in C; energies are recorded for the plot.

        ``p`` overrides parameters, ``x0`` the initial state, and ``u`` the
        scene's inputs (anything :meth:`CompiledModel.simulate_rk4` accepts,
        including a feedback callable ``u(t, x)``).
        """
        s = self.spec
        x0 = np.array(s.initial if x0 is None else x0, dtype=float)
        u = self._inputs() if u is None else u
        if s.method == "rk4":
            every = max(1, int(round(s.sample_dt / s.step)))
            if abs(every * s.step - s.sample_dt) > 1e-9 * s.sample_dt:
                raise SimulationError(f"scene {s.name}: the sampling interval "
                                      f"{s.sample_dt:g} s must be a multiple of the step "
                                      f"{s.step:g} s")
            res = self.model.simulate_rk4(x0, (s.t_start, s.t_end), s.step, every=every,
                                          u=u, p=p)
        else:
            res = self._run_integrator(x0, u, p)
        n = self.model.n
        res.energy = np.array([self.model.energy(row[:n], row[n:], p) for row in res.x])
        return res


def _scene_times(t0, t1, dt):
    count = int(np.floor((t1 - t0) / dt * (1 + 1e-12))) + 1
    times = t0 + dt * np.arange(count)
    return times if times[-1] >= t1 - 1e-12 * abs(t1) else np.append(times, t1)


def _effect_names(spec) -> list:
    names = ["gravity"] if spec.gravity is not None else []
    return names + [a.name for a in spec.actions] + [e.name for e in spec.effects]
