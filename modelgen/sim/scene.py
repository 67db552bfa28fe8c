"""Scenes: a scene's reduced model built with exactly its effects and outputs, and run.

Input: a :class:`~modelgen.model.spec.SceneSpec`.  Output: a compiled model
(through :func:`modelgen.codegen.pipeline.generate`) and its trajectories.
"""
from __future__ import annotations

import numpy as np

from modelgen.codegen.pipeline import generate
from modelgen.errors import SimulationError
from modelgen.model.spec import CONSERVATIVE_KINDS
from modelgen.sim.runtime import CompiledModel, check_mass_matrix
from modelgen.sim.simulate import SimulationResult


def _inputs_at(u, t, cm):
    """Input vector at time t for sampled inputs ``(times, values, interpolation)``."""
    if u is None:
        return None
    times, values, interpolation = u
    if interpolation == "hold":
        k = int(np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 1))
        return values[k]
    return np.array([np.interp(t, times, values[:, j]) for j in range(values.shape[1])])



class Scene:
    """A scene ready to run: its reduced model built with exactly its outputs.

    >>> scene = modelgen.load_scene("models/scenes/dp_damped.yaml")   # doctest: +SKIP
    >>> res = scene.run()                                             # doctest: +SKIP
    >>> res.t, res.x, res["tip"]                                      # doctest: +SKIP
    """

    def __init__(self, spec, out_dir=None, *, force: bool = False, progress=None):
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
