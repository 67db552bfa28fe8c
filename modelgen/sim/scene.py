"""Scenes: a scene's reduced model built with exactly its effects and outputs, and run.

Input: a :class:`~modelgen.model.spec.SceneSpec`, or the :class:`SceneCard`
made from one.  Output: a compiled model (through
:func:`modelgen.codegen.pipeline.generate`) and its trajectories.

A scene run from the command line or :func:`modelgen.load_scene` a second time
reads neither its model nor sympy: its card (what the run needs, as plain
values) is kept in the build cache under a key of the scene file's bytes, with
the model file's SHA-256 checked on every use (:func:`read_card`), and the
build is then found through the cache's fast index.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from modelgen.codegen import index
from modelgen.codegen.build import Generated, cache_dir
from modelgen.codegen.options import BuildOptions
from modelgen.errors import ArgumentValueError
from modelgen.model.records import InputSignal, OutputSpec
from modelgen.model.scene_timing import Spelling, timing_problem
from modelgen.sim.integrate import method_of
from modelgen.sim.result import Result, output_bytes
from modelgen.sim.runtime import STABILITY_LIMIT, CompiledModel, check_mass_matrix
from modelgen.sim.mechanical_work import PER, energy_balance, quadrature_times


#: a run needing more steps than this for stability alone is called stiff
STIFF_STEPS = 1e4
#: Changes when a card's fields change meaning (old cards are then misses).
CARD_FORMAT = "modelgen-scene-card-1"
#: the largest results :meth:`Scene.run` makes without ``max_output_mb=`` [MB]: its
#: samples x columns doubles; the command line's default --max-output-mb (which
#: counts the CSV text too, and passes its own limit)
MAX_OUTPUT_MB = 1000.0
#: the Python names of the settings :func:`with_settings` changes, for its messages
PYTHON_SPELLING = Spelling({"time.end": "t_end", "time.sample": "sample_dt",
                            "integrator.step": "step", "integrator.method": "method"},
                           "{name}={value}")
#: what a run of a scene writes beside its tables, by name: the plot and animations
PRODUCTS = (".png", ".gif", ".mp4", ".html")


@dataclass(frozen=True)
class SceneCard:
    """What running a scene needs, as plain values: the scene's settings (the fields
    of :class:`~modelgen.model.spec.SceneSpec` of the same names) and the few facts
    of its model that the run, its summary and the command line use."""
    name: str
    effects: tuple                  # names switched on, in model order
    initial: tuple                  # full state in [q, q_dot] order
    t_start: float
    t_end: float
    sample_dt: float
    method: str
    step: float
    rtol: float
    atol: float
    inputs: tuple                   # InputSignal, in model input order
    outputs: tuple                  # OutputSpec
    stiff_effects: tuple
    kinematics: tuple               # ((key, value), ...)
    source: str | None              # the scene file
    model_source: str | None        # its model file
    model_name: str                 # the full model's name
    coordinates: tuple              # of the scene's reduced model
    speeds: tuple
    parameters: tuple               # names of the reduced model's parameters
    nq: int
    n: int
    effects_off: tuple              # the full model's effects left out (not generated)
    powers: tuple                   # (effect, OutputSpec): work of effects outside the energy

    @classmethod
    def of(cls, spec) -> SceneCard:
        """The card of a :class:`~modelgen.model.spec.SceneSpec`."""
        on = set(spec.effects)
        return cls(
            name=spec.name, effects=tuple(spec.effects),
            initial=tuple(float(v) for v in spec.initial), t_start=float(spec.t_start),
            t_end=float(spec.t_end), sample_dt=float(spec.sample_dt), method=spec.method,
            step=float(spec.step), rtol=float(spec.rtol), atol=float(spec.atol),
            inputs=tuple(spec.inputs), outputs=tuple(spec.outputs),
            stiff_effects=tuple(spec.stiff_effects), kinematics=tuple(spec.kinematics),
            source=spec.source, model_source=spec.full_model.source,
            model_name=spec.full_model.name, coordinates=tuple(spec.model.coordinates),
            speeds=tuple(spec.model.speeds),
            parameters=tuple(name for name, _ in spec.model.parameters),
            nq=spec.model.nq, n=spec.model.n,
            effects_off=tuple(e for e in _effect_names(spec.full_model) if e not in on),
            powers=tuple(_power_outputs(spec).items()))

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, data: dict) -> SceneCard:
        """The card :meth:`to_json` wrote (lists back to tuples, the records rebuilt)."""
        d = {k: _tuples(v) for k, v in data.items()}
        d["inputs"] = tuple(InputSignal(**dict(_pairs(sig))) for sig in data["inputs"])
        d["outputs"] = tuple(_output(o) for o in data["outputs"])
        d["powers"] = tuple((effect, _output(o)) for effect, o in data["powers"])
        return cls(**d)


def _tuples(value):
    """JSON's lists back to the tuples a spec holds."""
    return tuple(_tuples(v) for v in value) if isinstance(value, list) else value


def _pairs(record: dict) -> list:
    return [(k, _tuples(v)) for k, v in record.items()]


def _output(data: dict) -> OutputSpec:
    return OutputSpec(data["name"], data["kind"], _tuples(data["args"]))


def _card_key(path: Path, out_dir) -> str:
    h = hashlib.sha256(f"{CARD_FORMAT}\0{index.environment_text()}\0".encode())
    h.update(str(path.resolve()).encode() + b"\0" + path.read_bytes())
    h.update(b"\0" + (str(Path(out_dir).resolve()) if out_dir is not None else "").encode())
    return h.hexdigest()


def _card_path(key: str) -> Path:
    return cache_dir() / "index" / f"scene-{key[:32]}.json"


def _file_digest(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def read_card(path, out_dir=None, *, force: bool = False) -> tuple:
    """(card, spec) of the scene file ``path``: the card kept in the cache, spec None
    (nothing symbolic imported), when the scene file and its model file are
    unchanged since it was made; else the file read (the model reader, sympy),
    its card made and kept (best effort), and its :class:`SceneSpec`."""
    path = Path(path)
    try:
        key = _card_key(path, out_dir)
    except OSError:
        key = None      # the reader says what is wrong with the file
    if key is not None and not force:
        try:
            entry = json.loads(_card_path(key).read_text())
            if entry["key"] == key and all(_file_digest(f) == digest
                                           for f, digest in entry["files"]):
                return SceneCard.from_json(entry["card"]), None
        except (OSError, ValueError, KeyError, TypeError):
            pass
    from modelgen.model.scene import load_scene     # imported here: it needs sympy
    spec = load_scene(path)
    card = SceneCard.of(spec)
    if key is not None:
        try:
            files = [[str(f), _file_digest(f)] for f in (spec.full_model.source,)
                     if f is not None]
            index.write_best_effort(_card_path(key), json.dumps(
                {"key": key, "files": files, "card": card.to_json()}))
        except OSError:
            pass
    return card, spec


class Scene:
    """A scene ready to run: its reduced model built with exactly its outputs.

    >>> scene = modelgen.load_scene("models/scenes/dp_damped.yaml")   # doctest: +SKIP
    >>> res = scene.run()                                             # doctest: +SKIP
    >>> res.t, res.y, res["q1"], res["elbow"]                         # doctest: +SKIP
    """

    def __init__(self, spec, out_dir=None, *, force: bool = False, progress=None,
                 stages=None, linearize: bool | None = None,
                 options: BuildOptions | None = None, files=(),
                 max_operations: int | None = None, scene_spec=None):
        """``spec``: a :class:`~modelgen.model.spec.SceneSpec`, or a :class:`SceneCard`
        (then ``scene_spec``, the SceneSpec it was made from, if at hand, saves
        reading the file again when the model must be built).
        ``progress(message)`` hears what is being done; ``stages(stage)`` is
        called as each stage of a build starts (see :func:`generate`).
        ``options`` (:class:`~modelgen.codegen.options.BuildOptions`; ``linearize``
        is shorthand) get the scene's outputs and, for stiff effects, the Jacobian.
        ``files``: the files ``spec`` was read from, unchanged (the scene's, then
        its model's), which let the build cache's fast index find a build
        without the symbolic pipeline (:mod:`modelgen.codegen.index`).
        ``max_operations``: the build budget (:mod:`modelgen.codegen.budget`)."""
        if isinstance(spec, SceneCard):
            self.card, self._spec = spec, scene_spec
        else:
            self.card, self._spec = SceneCard.of(spec), spec
        card = self.card
        if progress:
            progress(f"{card.name}: generating (or reusing) the model")
        # the power of every effect outside the energy, for the energy balance
        self.powers = dict(card.powers)
        extra = tuple(out for out in self.powers.values() if out not in card.outputs)
        options = BuildOptions.of(options, linearize=linearize)
        # stiff scenes get the symbolic Jacobian, for implicit integrators
        options = replace(options, outputs=card.outputs + extra, jacobian=options.jacobian or (
            bool(card.stiff_effects) and card.n <= 12))
        if card.kinematics:
            options = replace(options, kinematics=dict(card.kinematics))
        key = index.fast_key(files, options, out_dir) if files else None
        hit = None if force else index.lookup(key)
        if hit is not None:
            generated, runtime = Generated(hit.build, hit.build.manifest), hit.runtime
        else:
            # imported here, not at the top: the symbolic pipeline (about a second
            # of imports) is needed only when the fast index has no build
            from modelgen.codegen.pipeline import generate, runtime as runtime_location
            generated = generate(self.spec.model, out_dir, force=force, options=options,
                                 progress=stages, max_operations=max_operations)
            runtime = runtime_location()
            index.record(key, generated.build, runtime)
        self.generated = generated
        self.model = CompiledModel(generated.manifest, generated.build.module_path, runtime)
        check_mass_matrix(self.model)          # on every load: the cache hides nothing

    @property
    def spec(self):
        """The scene's :class:`~modelgen.model.spec.SceneSpec`; for a scene run from its
        cached card, read from the scene file on first use (so with the file's
        settings, whatever the card's were changed to)."""
        if self._spec is None:
            from modelgen.model.scene import load_scene     # imported here: it needs sympy
            self._spec = load_scene(self.card.source)
        return self._spec

    @property
    def conservative(self) -> bool:
        """True when every selected effect derives from a potential (and the energy
        counts it: gravity in a base other than E does not)."""
        return not self.powers

    def summary(self) -> str:
        """What the scene simulates: effects, stiff ones flagged, outputs, ops."""
        s = self.card
        lines = [f"scene {s.name}: model {s.model_name}, n = {s.n}",
                 f"effects on: {', '.join(s.effects) or 'none'}",
                 f"effects off (not generated): {', '.join(s.effects_off) or 'none'}"]
        if s.stiff_effects:
            lines.append(self._stiffness_line())
        lines.append(f"outputs: {', '.join(o.name for o in s.outputs) or 'none'}")
        ops = self.generated.manifest["ops"]["rhs"]
        lines.append(f"rhs: {ops['after_cse']} operations after CSE")
        how = (f"{s.method} step {s.step:g} s" if not method_of(s.method).adaptive
               else f"{s.method} rtol {s.rtol:g} atol {s.atol:g}")
        lines.append(f"time {s.t_start:g} .. {s.t_end:g} s, {how}, "
                     f"sampled every {s.sample_dt:g} s")
        return "\n".join(lines)

    def stiffness(self, x0=None, p=None) -> float:
        """The largest ``|eigenvalue|`` of d xdot / d x at the scene's initial state, and at
        the same configuration at rest (where smoothed friction is steepest) [1/s].

        Explicit methods need steps below about ``3/|lambda|max`` (their stability
        limit); a run whose span holds many such steps is stiff.
        """
        s, cm = self.card, self.model
        # at the state the run starts from: simulate normalises the quaternions
        x = cm.checked_state(self.initial_state(x0), "x0")
        rest = np.concatenate([x[:cm.nq], np.zeros(cm.n)])
        u = self._constant_inputs()
        return max(float(np.max(np.abs(np.linalg.eigvals(cm.jac(s.t_start, state, u, p)))))
                   for state in (x, rest))

    def _constant_inputs(self):
        u = self._inputs()
        return u if isinstance(u, dict) else None

    def _stiffness_line(self) -> str:
        """The summary's verdict on the stiff-prone effects, from |lambda|max."""
        s = self.card
        method = method_of(s.method)
        lam = self.stiffness()
        span = s.t_end - s.t_start
        # implicit methods have no limit: a nominal 3 (about the explicit ones') says how
        # many steps an explicit method would need
        limit = STABILITY_LIMIT.get(method.name, 3.0)
        stability_steps = lam * span / limit
        head = (f"stiff-prone effects: {', '.join(s.stiff_effects)}; |lambda|max = "
                f"{lam:.3g} 1/s at the start (moving and at rest)")
        if method.implicit:
            stiff = "STIFF, " if stability_steps > STIFF_STEPS else ""
            return f"{head} ({stiff}handled by {method.name}, which is implicit)"
        if not method.adaptive and s.step * lam > limit:
            return (f"{head}: WARNING the step {s.step:g} s is beyond {method.name}'s "
                    f"stability limit ({limit:g}/|lambda|max = {limit / lam:.3g} s): the result "
                    f"will be wrong; use a smaller step or method: rodas")
        if stability_steps > STIFF_STEPS:
            return (f"{head}: STIFF, {method.name} needs about {stability_steps:.2g} steps for "
                    f"stability alone; use method: rodas")
        return f"{head}: not stiff for {method.name} over {span:g} s"

    def _inputs(self):
        s = self.card
        signals = {sig.name: sig for sig in s.inputs}
        if not signals:
            return None
        if all(sig.constant is not None for sig in signals.values()):
            return {name: sig.constant for name, sig in signals.items()}
        return _input_samples(signals, self.model.inputs)

    def inputs_at(self, t: float) -> dict:
        """The scene's inputs at time ``t`` by name (a sampled input interpolated as the
        integrators do, its end values held outside the samples; missing inputs 0)."""
        t = self.model._time(t)         # a real, finite number, as rhs takes it
        out = dict.fromkeys(self.model.inputs, 0.0)
        for sig in self.card.inputs:
            if sig.constant is not None:
                out[sig.name] = float(sig.constant)
            elif sig.interpolation == "hold":
                k = int(np.searchsorted(sig.times, t, side="right")) - 1
                out[sig.name] = float(sig.values[min(max(k, 0), len(sig.times) - 1)])
            else:
                out[sig.name] = float(np.interp(t, sig.times, sig.values))
        return out

    def input_signal(self):
        """The scene's inputs in a form :meth:`CompiledModel.simulate` takes: None, a
        dict of constants, or samples ``(times, values, "linear" | "hold")``."""
        return self._inputs()

    def times(self) -> np.ndarray:
        """The scene's sample times, start to end every ``sample`` seconds (the end included)."""
        s = self.card
        return _scene_times(s.t_start, s.t_end, s.sample_dt)

    def run(self, p=None, x0=None, u=None, max_steps=None, progress=None, *,
            max_output_mb: float | None = None) -> Result:
        """Integrate the scene with its method, sampled at its times; energies recorded.

        ``p`` overrides parameters, ``x0`` the initial state (an array, or a
        mapping of coordinate and speed names to values, missing ones taken
        from the scene), and ``u`` the scene's inputs (anything
        :meth:`CompiledModel.simulate` accepts, including a feedback callable
        ``u(t, x)``).  ``max_steps`` overrides the step budget of
        :meth:`CompiledModel.simulate`; ``progress(t)`` hears the time reached while
        the C runs (see :func:`modelgen.sim.integrate.simulate`).  A run whose samples
        would take more than ``max_output_mb`` (default :data:`MAX_OUTPUT_MB`) is
        refused before it starts.  Returns a :class:`~modelgen.sim.result.Result`.
        """
        s, cm = self.card, self.model
        x0 = self.initial_state(x0)
        u = self._inputs() if u is None else u
        fixed = not method_of(s.method).adaptive
        columns = 1 + cm.nx + len(cm.output_columns) + 3      # t, x, outputs, energies
        times = _scene_times(s.t_start, s.t_end, s.sample_dt, columns,
                             MAX_OUTPUT_MB if max_output_mb is None else max_output_mb)
        # with work to integrate, the run also samples the quadrature nodes between
        grid = quadrature_times(times) if self.powers else times
        res = cm.simulate(x0, (s.t_start, s.t_end), t_eval=grid, method=s.method,
                          rtol=s.rtol, atol=s.atol, u=u, p=p, step=s.step if fixed else None,
                          max_steps=max_steps, **({} if progress is None else
                                                  {"progress": progress}))
        powers = {}
        if self.powers:
            reached = res.t
            powers = {effect: res.outputs[out.name][:, 0] for effect, out in self.powers.items()}
            _keep_samples(res, slice(0, None, PER))
        res.energy = cm.energies(res, p)
        res.info.update(scene=s.name, conservative=self.conservative)
        if powers:
            balance = energy_balance(reached, res.energy.sum(axis=1), powers)
            res.work = balance.work
            res.info.update(energy_balance=balance.error,
                            work_quadrature_check=balance.quadrature_check,
                            work_unresolved=balance.unresolved)
        for out in self.powers.values():        # recorded for the balance only
            if out not in s.outputs:
                res.outputs.pop(out.name, None)
                res.output_columns.pop(out.name, None)
        return res

    def animate(self, res: Result, path, **options):
        """Write the animation of a run of this scene to ``path`` (``.gif``, ``.mp4`` or
        ``.html``); ``options`` as :func:`modelgen.sim.animate.motion` (pass the run's
        ``p`` if it overrode parameters).

        >>> scene.animate(scene.run(), "out/dp_free.html")       # doctest: +SKIP
        """
        from modelgen.sim.animate import animate    # its drawing needs the kinematics
        return animate(res, self.spec.model, path, compiled=self.model, **options)

    def linearize(self, x0=None, u=None, t=None, p=None, outputs=None):
        """The state space model of :meth:`CompiledModel.linearize` about the scene's
        initial state (or ``x0``), its inputs at ``t`` (default its start; ``u``
        overrides them by name) and with y the scene's own outputs (``outputs``
        selects among them): not the ``power`` outputs a scene records for its
        energy balance.  Build the scene with ``linearize=True``."""
        t = self.card.t_start if t is None else t
        inputs = dict(self.inputs_at(t), **(u or {}))
        asked = [out.name for out in self.card.outputs] if outputs is None else outputs
        return self.model.linearize(self.initial_state(x0), u=inputs, t=t, p=p, outputs=asked)

    def initial_state(self, x0=None) -> np.ndarray:
        """The scene's initial state, or ``x0`` (an array, or names -> values over it)."""
        s, cm = self.card, self.model
        if x0 is None:
            return np.array(s.initial, dtype=float)
        return cm.state_vector(x0, "x0", base=s.initial)


def with_settings(card: SceneCard, spell: Spelling = PYTHON_SPELLING, **changes) -> SceneCard:
    """``card`` with some run settings changed (``t_end``, ``step``, ``sample_dt``,
    ``method``), checked by the scene file's rules (an ArgumentValueError naming
    the changes, in ``spell``'s words, and the scene file): the end after the
    start, and :func:`~modelgen.model.scene_timing.timing_problem`'s span and step."""
    keys = {"t_end": "time.end", "step": "integrator.step", "sample_dt": "time.sample",
            "method": "integrator.method"}
    unknown = [name for name in changes if name not in keys]
    if unknown:
        raise ArgumentValueError(f"unknown scene setting {unknown[0]!r}; fix: change one of "
                                 + ", ".join(keys))
    new = replace(card, **changes)
    given = ", ".join(spell.write(keys[name], value) for name, value in changes.items())
    where = f"scene {card.name}" + (f" ({card.source})" if card.source else "")
    if "step" in changes and method_of(new.method).adaptive:
        raise ArgumentValueError(
            f"{where} with {given}: method {new.method} adapts its steps to rtol and atol, "
            f"so a step would be ignored; fix: leave out {spell.name('integrator.step')}, "
            f"or choose a fixed-step method, e.g. {spell.write('integrator.method', 'rk4')}")
    if not new.t_end > new.t_start:
        raise ArgumentValueError(f"{where} with {given}: the end time {new.t_end!r} is not "
                                 f"after the scene's start {new.t_start!r}; fix: give "
                                 f"{spell.name('time.end')} after {new.t_start!r}")
    problem = timing_problem(new.t_start, new.t_end, new.sample_dt,
                             not method_of(new.method).adaptive, new.step, spell)
    if problem is not None:
        raise ArgumentValueError(f"{where} with {given}: {problem.problem}; fix: "
                                 f"{problem.fix}")
    return new


def remove_stale_products(folder, name: str, written) -> list:
    """Remove ``<name>.png``, ``.gif``, ``.mp4`` and ``.html`` in ``folder`` that a run
    left there and this one does not write (``written``: the suffixes it writes), so
    no plot or animation of an earlier run sits beside this run's tables; returns
    the paths removed."""
    removed = []
    for suffix in PRODUCTS:
        path = Path(folder) / f"{name}{suffix}"
        if suffix not in written and path.is_file():
            path.unlink()
            removed.append(path)
    return removed


def _keep_samples(res: Result, rows: slice) -> None:
    """Keep only ``rows`` of a result's times, states and outputs (in place)."""
    res.t = res.t[rows]
    res.y = res.y[:, rows]
    res.outputs = {name: values[rows] for name, values in res.outputs.items()}


def _power_outputs(spec) -> dict:
    """effect -> the ``power`` output recording it, for every switched-on effect whose
    energy the total energy leaves out (non-conservative ones, gravity in a base
    other than E or varying in time); a ``power`` output the scene already asks for
    is reused."""
    from modelgen.model.scene import ENERGIES                      # a spec is read
    from modelgen.model.spec import CONSERVATIVE_KINDS, time_free
    kinds = {e.name: e for e in spec.model.effects}
    kinds.update({a.name: a for a in spec.model.actions})
    # the names of the result's other columns are taken too (the reader refuses them)
    taken = {out.name for out in spec.outputs} | {"t", *ENERGIES}
    taken.update(spec.model.coordinates + spec.model.speeds)
    powers = {}
    for name in spec.effects:
        effect = kinds.get(name)
        if effect is None:            # the top-level gravity, in E: counted unless it varies
            if time_free(spec.model.gravity or ()):
                continue
        elif effect.kind in CONSERVATIVE_KINDS and getattr(effect, "in_energy", True):
            continue
        asked = [out for out in spec.outputs if out.kind == "power"
                 and out.arg("effect") == name]
        label = f"power_{name}"
        while label in taken:
            label += "_"
        powers[name] = asked[0] if asked else OutputSpec(label, "power", (("effect", name),))
        taken.add(powers[name].name)
    return powers


def _input_samples(signals: dict, names) -> tuple:
    """``(times, values, "linear" | "hold")`` for the C integrators, which interpolate
    every input alike: each signal keeps its own interpolation all the same.  With
    mixed ones, the samples are linear and a held signal's step at each of its
    times t_k gets a sample one double below t_k with the value before it; the C
    looks for ts[lo] <= t < ts[lo + 1], so no double t sees a value between the
    two and the step is exact."""
    sampled = [sig for sig in signals.values() if sig.constant is None]
    holds = {sig.interpolation for sig in sampled}
    grid = {t for sig in sampled for t in sig.times}
    if len(holds) > 1:
        grid.update(np.nextafter(t, -np.inf) for sig in sampled
                    if sig.interpolation == "hold" for t in sig.times[1:])
    grid = np.array(sorted(grid))
    values = np.zeros((len(grid), len(names)))
    for j, name in enumerate(names):
        sig = signals.get(name)
        if sig is None:
            continue
        if sig.constant is not None:
            values[:, j] = sig.constant
        elif sig.interpolation == "hold":
            idx = np.searchsorted(sig.times, grid, side="right") - 1
            values[:, j] = np.asarray(sig.values)[np.clip(idx, 0, len(sig.times) - 1)]
        else:
            values[:, j] = np.interp(grid, sig.times, sig.values)
    return grid, values, "hold" if holds == {"hold"} else "linear"


def _scene_times(t0, t1, dt, columns: int = 1, max_mb: float = MAX_OUTPUT_MB):
    """Every ``dt`` from ``t0`` to ``t1``, the end included; refused (an
    ArgumentValueError) when their ``columns`` would take more than ``max_mb``."""
    samples = (t1 - t0) / dt + 1
    size = output_bytes(samples, columns)
    if not size <= max_mb * 1e6:
        raise ArgumentValueError(
            f"the samples every {dt!r} s from {t0!r} to {t1!r} s would take {size / 1e6:.4g} "
            f"MB ({samples:.4g} samples x {columns} columns), more than max_output_mb="
            f"{max_mb:g}; fix: a longer sample interval or a shorter span (or a larger "
            f"max_output_mb)")
    count = int(np.floor((t1 - t0) / dt * (1 + 1e-12))) + 1
    times = t0 + dt * np.arange(count)
    return times if times[-1] >= t1 - 1e-12 * abs(t1) else np.append(times, t1)


def _effect_names(spec) -> list:
    names = ["gravity"] if spec.gravity is not None else []
    return names + [a.name for a in spec.actions] + [e.name for e in spec.effects]
