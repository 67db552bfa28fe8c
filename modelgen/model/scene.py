"""The scene loader: a scene file and its model -> a validated :class:`SceneSpec`.

Input: scene YAML (a path for :func:`load_scene`, text for :func:`parse_scene`)
naming a model file relative to itself.  Output: a frozen
:class:`~modelgen.model.spec.SceneSpec`: the reduced model (only the switched-on
effects and the parameters they use, overrides as defaults, named after the
scene), the full model, the initial state, time span, integrator, input
signals and resolved outputs; or a :class:`~modelgen.errors.ModelError` naming
the scene file, line, key and a fix.

The format (every key, rule and output kind, with examples) is documented in
``docs/model-format.md``, section "Scenes".  Selected effects whose class is
flagged ``stiff`` (:data:`~modelgen.model.spec.STIFF_KINDS`) are listed in
``SceneSpec.stiff_effects``; the test is by kind only, it does not estimate
frequencies.
"""
from __future__ import annotations

import os
from dataclasses import replace

from modelgen.errors import ModelError
from modelgen.model import is_scene_text
from modelgen.model.builder import ModelBuilder, replay
from modelgen.model.expr import ExpressionParseError, parse_expression
from modelgen.model.messages import article, closest, describe, listing
from modelgen.model.names import NAME_RE, check_name
from modelgen.model.reader import compose, read_text
from modelgen.model.schema import NUMERIC_STRING
from modelgen.model.scene_timing import timing_problem
from modelgen.model.sections import (builder_from_text, check_top_level, load_effects,
                                     load_parameters)
from modelgen.model.spec import (CANONICAL_BASE, CANONICAL_POINT, EFFECT_KINDS, OUTPUT_KINDS,
                                 InputSignal, ModelSpec, OutputSpec, SceneSpec, symbol)
from modelgen.model.writer import yaml_float

__all__ = ["METHODS", "METHOD_ALIASES", "TOP_LEVEL_KEYS", "INTERPOLATIONS", "ENERGIES", "OUTPUT_DEFAULTS",
           "GRAVITY", "load_scene", "parse_scene"]

#: Integration methods a scene may ask for (see modelgen.sim.integrate); rk4 runs
#: the scene's own C loop, the others the adaptive/implicit C integrators.
METHODS = ("rk4", "dopri5", "dop853", "rodas", "midpoint", "gauss4")
#: Other accepted spellings (matched case-insensitively) -> method; equal to
#: modelgen.codegen.capi.ALIASES (a test keeps them so): solve_ivp's "RK45",
#: "Radau", "BDF", "LSODA" run modelgen's dopri5 and rodas.
METHOD_ALIASES = {"rk45": "dopri5", "rodas4": "rodas", "radau": "rodas", "bdf": "rodas",
                  "lsoda": "rodas", "implicit_midpoint": "midpoint",
                  "gauss_legendre4": "gauss4"}
#: Methods that take a fixed step (the others adapt theirs to rtol/atol).
FIXED_STEP_METHODS = ("rk4", "midpoint", "gauss4")
#: Default integrator settings.
DEFAULT_METHOD, DEFAULT_STEP = "rk4", 1e-3
DEFAULT_RTOL, DEFAULT_ATOL = 1e-8, 1e-10
#: Top-level keys of a scene file, in processing order.
TOP_LEVEL_KEYS = ("scene", "description", "model", "add_parameters", "add_effects", "effects",
                  "parameters", "initial", "time", "integrator", "inputs", "outputs",
                  "kinematics")
#: Keys of a scene's ``kinematics:`` (the fields of the build's KinematicsOptions).
KINEMATICS_KEYS = ("frames", "reference", "bias_acceleration", "com", "centroidal")
#: Values of ``kinematics.reference``; equal to modelgen.codegen.options.REFERENCES
#: (a test keeps them so: this stage does not import the code generator).
KINEMATICS_REFERENCES = ("local", "world", "local_world_aligned")
TIME_KEYS = ("start", "end", "sample")
INTEGRATOR_KEYS = ("method", "step", "rtol", "atol")
SIGNAL_KEYS = ("times", "values", "interpolation")
INTERPOLATIONS = ("linear", "hold")
ENERGIES = ("kinetic", "potential", "total")
#: Options of each output kind that may be omitted, with their defaults.
OUTPUT_DEFAULTS = {
    "position": {"from": CANONICAL_POINT, "base": CANONICAL_BASE},
    "velocity": {"base": CANONICAL_BASE},
    "orientation": {"relative_to": CANONICAL_BASE},
    "angular_velocity": {"relative_to": CANONICAL_BASE, "components": CANONICAL_BASE},
}
#: What each output argument names.
_ARG_ROLE = {"point": "point", "from": "point", "base": "base", "relative_to": "base",
             "components": "base", "body": "body", "which": "energy", "effect": "effect",
             "constraint": "constraint"}
#: Name of the top-level gravity as an effect.
GRAVITY = "gravity"


def load_scene(path) -> SceneSpec:
    """Load and validate a scene file and the model it names.

    >>> scene = load_scene("models/scenes/dp_damped.yaml")     # doctest: +SKIP
    >>> scene.effects, scene.model.parameter_names              # doctest: +SKIP
    (('gravity', 'hinge_damping'), ('m1', 'm2', 'l1', 'l2', 'g', 'c'))
    """
    file, text = read_text(path, "scene")
    return parse_scene(text, source=file, base_dir=os.path.dirname(file))


def parse_scene(text: str, source: str = "<string>", base_dir=None) -> SceneSpec:
    """Parse and validate scene YAML text; ``source`` names it in errors.

    The model path is relative to ``base_dir`` (default: the current
    directory).

    >>> scene = parse_scene('''
    ... scene: swing
    ... model: models/simple_pendulum.yaml
    ... effects: [gravity]
    ... initial: {q: 0.5, q_dot: 0.0}
    ... time: {end: 2.0, sample: 0.01}
    ... outputs: {bob: {position: P}}
    ... ''')                                                      # doctest: +SKIP
    >>> scene.outputs[0].args                                    # doctest: +SKIP
    (('point', 'P'), ('from', 'O'), ('base', 'E'))
    """
    if not isinstance(text, str):
        raise ModelError(f"expected YAML text but got {describe(text)}", file=source,
                         fix="pass the file's text, or use load_scene(path)")
    data, lines = compose(text, source)
    base_dir = os.getcwd() if base_dir is None else os.fspath(base_dir)
    return _SceneReader(data, lines, source, base_dir).read()


class _SceneReader:
    """Reads one scene; errors name the scene file (``self.ctx`` holds its lines)."""

    def __init__(self, data, lines: dict, file: str, base_dir: str):
        self.data = data
        self.lines = lines
        self.file = file
        self.base_dir = base_dir
        self.ctx = ModelBuilder(file, lines)     # errors, numbers and lines of the scene file

    def error(self, problem: str, key, fix) -> ModelError:
        return self.ctx.error(problem, key, fix)

    def number(self, value, key: str, what: str) -> float:
        return self.ctx.number(value, key, what)

    def constant(self, value, key: str, what: str) -> float:
        """A number, or an expression of numbers (``pi - 0.1``, ``2*pi/3``: the upright
        pendulum is where a user types pi), as a double: evaluated exactly, rounded
        once (the grammar refuses what is not a finite real number)."""
        if not isinstance(value, str) or NUMERIC_STRING.match(value):
            return self.number(value, key, what)
        try:
            return float(parse_expression(value, {}))
        except ExpressionParseError as exc:
            reason = (f"it names '{exc.name}'" if exc.name is not None
                      else f"invalid expression: {exc.reason}")
            raise self.error(f"{what} must be a number or an expression of numbers; {reason}",
                             key, "write a number such as 1.0 or an expression of numbers "
                             "such as pi/2") from None

    def mapping(self, key: str, example: str) -> dict:
        """The mapping at top-level ``key`` ({} if absent or null)."""
        value = self.data.get(key)
        if value is None:
            return {}
        if not isinstance(value, dict):
            raise self.error(f"expected a mapping but got {describe(value)}", key,
                             f"write {key}: {example}")
        return value

    def missing(self, key: str, example: str) -> ModelError:
        return ModelError(f"missing required key '{key}'", file=self.file, line=1,
                          fix=f"add '{key}: {example}' at the top level")

    def check_keys(self, entry: dict, valid: tuple, key: str, what: str) -> None:
        for field in entry:
            if field not in valid:
                close = closest(field, valid)
                fix = f"did you mean '{close}'? " if close else ""
                raise self.error(f"unknown key '{field}' in {what}", f"{key}.{field}",
                                 fix + "valid keys: " + ", ".join(valid))

    # -- the whole scene ---------------------------------------------------------
    def read(self) -> SceneSpec:
        data = self.data
        if data is None:
            raise ModelError("the scene file is empty", file=self.file, line=1,
                             fix="start with 'scene: <scene name>' and 'model: <model file>'")
        check_top_level(data, self.ctx, "scene", TOP_LEVEL_KEYS,
                        "start with 'scene: <scene name>'")
        if "scene" not in data:
            raise self.missing("scene", "<scene name>")
        name = check_name(data["scene"], file=self.file, line=self.ctx.line_of("scene"),
                          key="scene", what="scene name", modelgen_reserved=False)
        description = data.get("description")
        if description is not None and not isinstance(description, str):
            raise self.error(f"expected a string but got {describe(description)}",
                             "description", "write the description as text (quote it if "
                             "needed)")
        model_ctx = self.model_context()
        full_ctx = model_ctx.clone()
        for section in ("add_parameters", "add_effects"):
            full_ctx.add_source(section, self.file, self.lines)
        load_parameters(full_ctx, data.get("add_parameters"), "add_parameters")
        load_effects(full_ctx, data.get("add_effects"), "add_effects")
        full = full_ctx.build()
        self.full, self.full_ctx = full, full_ctx
        if name == full.name:
            stem = os.path.splitext(os.path.basename(self.file))[0]
            other = stem if stem != name and NAME_RE.match(stem) else f"{name}_scene"
            raise self.error(f"the scene has its model's name '{name}', so its generated "
                             "files would replace the model's own", "scene",
                             f"name the scene after what it runs, e.g. scene: {other}")

        kinds = _effect_kinds(full)
        selected = self.selected_effects(kinds)
        reduced = self.reduced_model(name, description, selected)
        initial = self.initial_state(full)
        t_start, t_end, sample = self.time_span()
        method, step, rtol, atol = self.integrator(t_start, t_end, sample)
        inputs = self.inputs(reduced, selected)
        outputs = self.outputs(reduced, selected, kinds)
        kinematics = self.kinematics(reduced)
        return SceneSpec(
            name=name, model=reduced, full_model=full, effects=selected, initial=initial,
            t_start=t_start, t_end=t_end, sample_dt=sample, method=method, step=step,
            rtol=rtol, atol=atol,
            inputs=inputs, outputs=outputs, kinematics=kinematics,
            stiff_effects=tuple(e for e in selected if EFFECT_KINDS[kinds[e]].stiff),
            source=self.file, lines=tuple(self.lines.items()))

    # -- the model ----------------------------------------------------------------
    def model_context(self) -> ModelBuilder:
        value = self.data.get("model")
        if value is None:
            raise self.missing("model", "<model file, relative to the scene file>")
        if not isinstance(value, str) or not value.strip():
            raise self.error(f"expected the path of a model file but got {describe(value)}",
                             "model", "write the model file's path relative to the scene "
                             "file, e.g. model: ../double_pendulum.yaml")
        path = os.path.normpath(os.path.join(self.base_dir, value))
        if os.path.exists(path) and not os.path.isfile(path):
            raise self.error(f"'{path}' is not a model file but a "
                             f"{'folder' if os.path.isdir(path) else 'special file'}",
                             "model", "give the path of a model file relative to the scene "
                             "file, e.g. model: ../double_pendulum.yaml")
        if not os.path.isfile(path):
            folder = os.path.dirname(path)
            known = sorted(f for f in os.listdir(folder) if f.endswith((".yaml", ".yml"))) \
                if os.path.isdir(folder) else []
            close = closest(os.path.basename(path), known)
            if close:
                fix = f"did you mean '{os.path.join(os.path.dirname(value), close)}'?"
            else:
                fix = f"give the model's path relative to the scene file's folder " \
                      f"{self.base_dir or '.'}"
            raise self.error(f"model file '{path}' does not exist", "model", fix)
        try:
            file, text = read_text(path)
            if is_scene_text(text):
                raise self.error(f"'{path}' is a scene file, not a model", "model",
                                 "name the model file the scene runs (a file that starts "
                                 "with 'name: <model name>')")
            ctx = builder_from_text(text, file)
            ctx.build()                        # the model alone must be valid
        except ModelError as exc:
            if exc.file == self.file:
                raise
            where = ":".join(str(part) for part in (exc.file, exc.line) if part is not None)
            where += f": {exc.key}" if exc.key else ""
            raise self.error(f"the model file is not valid: {where}: {exc.problem}", "model",
                             "name another model file, or correct that one"
                             + (f": {exc.fix}" if exc.fix else "")) from None
        return ctx

    def selected_effects(self, kinds: dict) -> tuple:
        known = f"effects of model '{self.full.name}': {listing(kinds, 20)}"
        if "effects" not in self.data:
            raise self.missing("effects", "[" + ", ".join(kinds) + "]")
        value = self.data["effects"]
        if not isinstance(value, list):
            raise self.error(f"expected a list of effect names but got {describe(value)}",
                             "effects", "list the effects to switch on, e.g. effects: ["
                             + ", ".join(kinds) + "], or write effects: [] for none")
        chosen = []
        for i, item in enumerate(value):
            key = f"effects[{i}]"
            if not isinstance(item, str):
                raise self.error(f"expected an effect name but got {describe(item)}", key,
                                 known)
            if item not in kinds:
                close = closest(item, kinds)
                fix = (f"did you mean '{close}'? " if close else "") + known
                if not close:
                    fix += " (define new ones under 'add_effects')"
                raise self.error(f"unknown effect '{item}'", key, fix)
            if item in chosen:
                raise self.error(f"effect '{item}' is listed twice", key,
                                 "list each effect once")
            chosen.append(item)
        return tuple(name for name in kinds if name in chosen)

    def reduced_model(self, name: str, description, selected: tuple) -> ModelSpec:
        full = self.full
        on = set(selected)
        kept = replace(full, gravity=full.gravity if GRAVITY in on else None,
                       actions=tuple(a for a in full.actions if a.name in on),
                       effects=tuple(e for e in full.effects if e.name in on))
        used = _free_symbols(kept)
        parameters = [(p, v) for p, v in full.parameters if symbol(p) in used]
        used_names = {p for p, _ in parameters}
        overrides = self.mapping("parameters", "{m2: 2.0}")
        values = dict(parameters)
        for p, value in overrides.items():
            key = f"parameters.{p}"
            if p not in full.parameter_names:
                close = closest(str(p), full.parameter_names)
                fix = f"did you mean '{close}'? " if close else ""
                raise self.error(f"unknown parameter '{p}'", key, fix + "parameters of "
                                 f"model '{full.name}': {listing(full.parameter_names, 20)}")
            if p not in used_names:
                users = [n for n in _effect_kinds(full) if n not in on
                         and symbol(p) in _free_symbols(_only(full, n))]
                fix = "remove the override" + (
                    f", or switch on an effect that uses it: {listing(users)}" if users
                    else f" (no expression of model '{full.name}' uses it)")
                raise self.error(f"parameter '{p}' is not used by the switched-on effects",
                                 key, fix)
            values[p] = self.number(value, key, f"the override of parameter '{p}'")
        parameters = [(p, values[p]) for p, _ in parameters]

        ctx = ModelBuilder(full.source, dict(full.lines))
        ctx.set_name(name, "scene")
        ctx.set_description(full.description if description is None else description)
        ctx.set_physical_inertia(full.physical_inertia)
        try:
            replay(ctx, kept, parameters)
            return ctx.build()
        except ModelError as exc:
            if not overrides:      # pragma: no cover - the full model was checked already
                raise
            where = f"{exc.file}:{exc.line}: {exc.key}" if exc.line else f"{exc.file}: {exc.key}"
            raise self.error(f"with these overrides, {exc.problem} ({where})", "parameters",
                             f"change the overrides ({exc.fix})") from None

    # -- state, time and integrator ------------------------------------------------
    def initial_state(self, full: ModelSpec) -> tuple:
        state = full.coordinates + full.speeds
        value = self.data.get("initial")
        given: dict = {}
        unit_w = {j.quaternion[0] for j in full.joints}

        def template() -> str:
            return "initial: {" + ", ".join(
                f"{s}: {yaml_float(given.get(s, 1.0 if s in unit_w else 0.0))}"
                for s in state) + "}"

        if "initial" not in self.data:
            raise ModelError("missing required key 'initial'", file=self.file, line=1,
                             fix=f"give every coordinate and speed a value, e.g. "
                             f"{template()}")
        if not isinstance(value, dict):
            raise self.error(f"expected a mapping of coordinates and speeds to values but "
                             f"got {describe(value)}", "initial", f"write {template()}")
        for s, v in value.items():
            key = f"initial.{s}"
            if s not in state:
                close = closest(str(s), state)
                fix = f"did you mean '{close}'? " if close else ""
                raise self.error(f"unknown coordinate or speed '{s}'", key,
                                 fix + f"the state of model '{full.name}' is "
                                 + ", ".join(state))
            given[s] = self.constant(v, key, f"the initial value of '{s}'")
        missing = [s for s in state if s not in given]
        if missing:
            names = " and ".join(", ".join(f"'{m}'" for m in missing).rsplit(", ", 1))
            plural = "s" if len(missing) > 1 else ""
            raise self.error(f"missing initial value{plural} for {names}", "initial",
                             f"every coordinate and speed needs one; write {template()}")
        for j in full.joints:
            if all(given[c] == 0 for c in j.quaternion):
                raise self.error(f"the quaternion of joint '{j.name}' is zero", "initial",
                                 f"give a unit quaternion, e.g. {j.quaternion[0]}: 1.0 and "
                                 "the others 0 for no rotation (it is normalised)")
        return tuple(given[s] for s in state)

    def time_span(self) -> tuple:
        if "time" not in self.data:
            raise self.missing("time", "{start: 0.0, end: 10.0, sample: 0.01}")
        time = self.mapping("time", "{start: 0.0, end: 10.0, sample: 0.01}")
        self.check_keys(time, TIME_KEYS, "time", "time")
        for field in ("end", "sample"):
            if field not in time:
                raise self.error(f"missing required key '{field}'", "time",
                                 "write time: {start: 0.0, end: 10.0, sample: 0.01} "
                                 "(start defaults to 0)")
        start = self.number(time.get("start", 0.0), "time.start", "the start time")
        end = self.number(time["end"], "time.end", "the end time")
        sample = self.number(time["sample"], "time.sample", "the sample interval")
        if not end > start:
            raise self.error(f"the end time {end!r} is not after the start time {start!r}",
                             "time.end", "make end greater than start")
        if not sample > 0:
            raise self.error(f"the sample interval must be positive but is {sample!r}",
                             "time.sample", "give the time between recorded samples, "
                             "e.g. sample: 0.01")
        return start, end, sample

    def integrator(self, t_start: float, t_end: float, sample: float) -> tuple:
        """(method, step, rtol, atol), checked with the time span by the rules of
        :func:`~modelgen.model.scene_timing.timing_problem` (a fixed step samples at
        whole steps, is no longer than the span and takes a bounded number of steps)."""
        settings = self.mapping("integrator", "{method: rk4, step: 0.001}")
        self.check_keys(settings, INTEGRATOR_KEYS, "integrator", "integrator")
        given = settings.get("method", DEFAULT_METHOD)
        method = METHOD_ALIASES.get(given.lower(), given.lower()) if isinstance(given, str) \
            else given
        if not isinstance(method, str) or method not in METHODS:
            shown = f"'{given}'" if isinstance(given, str) else describe(given)
            close = closest(method, METHODS) if isinstance(method, str) else None
            fix = f"did you mean '{close}'? " if close else ""
            raise self.error(f"unknown integration method {shown}", "integrator.method",
                             fix + "methods: " + ", ".join(METHODS) + " (or solve_ivp's "
                             "RK45, DOP853, Radau, BDF, LSODA)")
        step = self.number(settings.get("step", DEFAULT_STEP), "integrator.step", "the step")
        if not step > 0:
            raise self.error(f"the step must be positive but is {step!r}", "integrator.step",
                             "give the integration step in seconds, e.g. step: 0.001")
        tolerances = []
        for key, default in (("rtol", DEFAULT_RTOL), ("atol", DEFAULT_ATOL)):
            value = self.number(settings.get(key, default), f"integrator.{key}", f"the {key}")
            if not value > 0:
                raise self.error(f"{key} must be positive but is {value!r}", f"integrator.{key}",
                                 f"give a relative/absolute tolerance, e.g. {key}: {default!r}")
            tolerances.append(value)
        problem = timing_problem(t_start, t_end, sample, method in FIXED_STEP_METHODS, step)
        if problem is not None:
            # a default step (no integrator key) is blamed on the time span it must fit
            key = problem.key if self.ctx.line_of(problem.key) is not None else "time"
            raise self.error(problem.problem, key, problem.fix)
        return (method, step, *tolerances)

    # -- inputs ------------------------------------------------------------------------
    def inputs(self, reduced: ModelSpec, selected: tuple) -> tuple:
        full = self.full
        signals = {}
        used = _free_symbols(reduced)
        for name, value in self.mapping("inputs", "{T1: 0.5}").items():
            key = f"inputs.{name}"
            if name not in full.inputs:
                close = closest(str(name), full.inputs)
                fix = f"did you mean '{close}'? " if close else ""
                raise self.error(f"unknown input '{name}'", key,
                                 fix + f"inputs of model '{full.name}': "
                                 f"{listing(full.inputs, 20)}")
            if symbol(name) not in used:
                users = [n for n in _effect_kinds(full) if n not in selected
                         and symbol(name) in _free_symbols(_only(full, n))]
                fix = "remove it" + (f", or switch on an effect that uses it: "
                                     f"{listing(users)}" if users else "")
                raise self.error(f"input '{name}' is not used by the switched-on effects",
                                 key, fix)
            signals[name] = self.signal(name, value, key)
        return tuple(signals.get(name, InputSignal(name, constant=0.0))
                     for name in reduced.inputs)

    def signal(self, name: str, value, key: str) -> InputSignal:
        example = "{times: [0.0, 1.0], values: [0.0, 2.0], interpolation: linear}"
        if not isinstance(value, dict):
            if isinstance(value, (list, tuple)) or value is None:
                raise self.error(f"expected a number or a mapping of samples but got "
                                 f"{describe(value)}", key,
                                 f"write a constant such as {name}: 0.5, or {name}: {example}")
            return InputSignal(name, constant=self.number(value, key, f"input '{name}'"))
        self.check_keys(value, SIGNAL_KEYS, key, "a sampled input")
        for field in ("times", "values"):
            if field not in value:
                raise self.error(f"missing required key '{field}'", key, f"write {example}")
        lists = {}
        for field in ("times", "values"):
            items = value[field]
            if not isinstance(items, list) or not items:
                raise self.error(f"expected a list of one or more numbers but got "
                                 f"{describe(items)}", f"{key}.{field}", f"write {example}")
            lists[field] = tuple(self.number(v, f"{key}.{field}[{i}]",
                                             f"{field[:-1]} {i} of input '{name}'")
                                 for i, v in enumerate(items))
        times, values = lists["times"], lists["values"]
        for i in range(1, len(times)):
            if not times[i] > times[i - 1]:
                raise self.error(f"sample times must increase, but times[{i}] = {times[i]!r} "
                                 f"follows {times[i - 1]!r}", f"{key}.times[{i}]",
                                 "list the times in increasing order, each once")
        if len(values) != len(times):
            raise self.error(f"{len(values)} values for {len(times)} times", f"{key}.values",
                             "give one value per sample time")
        interpolation = value.get("interpolation", "linear")
        if interpolation not in INTERPOLATIONS:
            shown = f"'{interpolation}'" if isinstance(interpolation, str) \
                else describe(interpolation)
            close = closest(interpolation, INTERPOLATIONS) \
                if isinstance(interpolation, str) else None
            fix = f"did you mean '{close}'? " if close else ""
            raise self.error(f"unknown interpolation {shown}", f"{key}.interpolation",
                             fix + "use linear or hold (zero-order hold)")
        return InputSignal(name, times=times, values=values, interpolation=interpolation)

    # -- outputs -----------------------------------------------------------------------
    def outputs(self, reduced: ModelSpec, selected: tuple, kinds: dict) -> tuple:
        result = []
        example = "tip: {position: P1, from: O, base: E}"
        for name, entry in self.mapping("outputs", "{" + example + "}").items():
            key = f"outputs.{name}"
            check_name(name, file=self.file, line=self.ctx.line_of(key), key=key,
                       what="output name", modelgen_reserved=False)
            if not isinstance(entry, dict):
                raise self.error(f"expected a mapping but got {describe(entry)}", key,
                                 f"write it like '{example}'")
            self.check_output_name(name, key, entry, reduced)
            found = [k for k in entry if k in OUTPUT_KINDS]
            kinds_text = "output kinds: " + ", ".join(OUTPUT_KINDS)
            if not found:
                options = {o for args in OUTPUT_KINDS.values() for o in args[1:]}
                strange = [k for k in entry if k not in options]
                if not strange:
                    raise self.error(f"output '{name}' has no kind", key,
                                     f"add one of the {kinds_text}")
                close = closest(strange[0], OUTPUT_KINDS)
                fix = f"did you mean '{close}'? " if close else ""
                raise self.error(f"unknown output kind '{strange[0]}'",
                                 f"{key}.{strange[0]}", fix + kinds_text)
            if len(found) > 1:
                raise self.error(f"output '{name}' has two kinds, '{found[0]}' and "
                                 f"'{found[1]}'", f"{key}.{found[1]}",
                                 "give each output one kind (make two outputs)")
            kind = found[0]
            first, *options = OUTPUT_KINDS[kind]
            for field in entry:
                if field != kind and field not in options:
                    close = closest(field, options + list(OUTPUT_KINDS))
                    fix = f"did you mean '{close}'? " if close else ""
                    takes = "only '" + kind + "'" if not options else \
                        f"{kind}, " + ", ".join(options)
                    raise self.error(f"unknown key '{field}' for {article(kind)} output",
                                     f"{key}.{field}",
                                     fix + f"{article(kind)} output takes {takes}")
            args = {first: (entry[kind], f"{key}.{kind}")}
            for option in options:
                default = OUTPUT_DEFAULTS.get(kind, {}).get(option)
                args[option] = (entry[option], f"{key}.{option}") if option in entry \
                    else (default, None)
            values = tuple((arg, self.output_arg(arg, value, where, reduced, selected,
                                                 kinds))
                           for arg, (value, where) in args.items())
            if kind == "energy" and dict(values)["which"] != "kinetic":
                self.check_potential(name, f"{key}.{kind}", reduced)
            result.append(OutputSpec(name, kind, values))
        return tuple(result)

    def check_output_name(self, name: str, key: str, entry: dict, reduced: ModelSpec) -> None:
        """An output name is none of the result's other names: the time, a state, an
        energy column (the table's columns and ``res[name]`` would be ambiguous)."""
        state = reduced.coordinates + reduced.speeds
        taken = ("the time" if name == "t" else
                 "a state of the model" if name in state else
                 "a column of the recorded energies" if name in ENERGIES else None)
        if taken is None:
            return
        kind = next((k for k in entry if k in OUTPUT_KINDS), "out")
        other = f"{name}_{kind}" if kind != name else f"{name}_out"
        raise self.error(f"output name '{name}' is also {taken}: the results' columns "
                         f"and res['{name}'] would be ambiguous", key,
                         f"rename the output, e.g. '{other}' (t, the states "
                         f"{listing(state)} and {', '.join(ENERGIES)} are taken)")

    def kinematics(self, reduced: ModelSpec) -> tuple:
        """``kinematics: {frames: [tool0], reference: local, com: true, ...}`` as
        ((key, value), ...) in :data:`KINEMATICS_KEYS` order."""
        if self.data.get("kinematics") is None:
            return ()
        example = "{frames: [tool0], reference: local_world_aligned, com: true}"
        entry = self.mapping("kinematics", example)
        self.check_keys(entry, KINEMATICS_KEYS, "kinematics", "kinematics")
        out = []
        names = [f.name for f in reduced.frames]
        for field in KINEMATICS_KEYS:
            if field not in entry:
                continue
            value, key = entry[field], f"kinematics.{field}"
            if field == "frames":
                if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
                    raise self.error(f"expected a list of frame names but got "
                                     f"{describe(value)}", key, f"write it like '{example}'")
                for frame in value:
                    if frame not in names:
                        close = closest(frame, names)
                        raise self.error(f"no frame named '{frame}' in the model", key,
                                         (f"did you mean '{close}'? " if close else "")
                                         + "frames: " + (", ".join(names) or "none"))
                value = tuple(value)
            elif field == "reference":
                if not isinstance(value, str):
                    raise self.error(f"expected a name but got {describe(value)}", key,
                                     "write local, world or local_world_aligned")
                if value not in KINEMATICS_REFERENCES:
                    close = closest(value, KINEMATICS_REFERENCES)
                    raise self.error(f"unknown reference '{value}'", key,
                                     (f"did you mean '{close}'? " if close else "")
                                     + "write local, world or local_world_aligned")
            elif not isinstance(value, bool):
                raise self.error(f"expected true or false but got {describe(value)}", key,
                                 f"write '{field}: true'")
            out.append((field, value))
        return tuple(out)

    def output_arg(self, arg: str, value, key, model: ModelSpec, selected: tuple,
                   kinds: dict):
        if key is None:                  # a default
            return value
        role = _ARG_ROLE[arg]
        if role == "energy":
            if value not in ENERGIES:
                shown = f"'{value}'" if isinstance(value, str) else describe(value)
                close = closest(value, ENERGIES) if isinstance(value, str) else None
                fix = f"did you mean '{close}'? " if close else ""
                raise self.error(f"unknown energy {shown}", key,
                                 fix + "write kinetic, potential or total")
            return value
        if not isinstance(value, str):
            raise self.error(f"expected {article(role)} name but got {describe(value)}", key,
                             f"write the name of {article(role)}")
        if role == "effect":
            if value in selected:
                return value
            if value in kinds:
                raise self.error(f"effect '{value}' is not switched on", key,
                                 f"add it to 'effects', or record a switched-on effect: "
                                 f"{listing(selected)}")
            close = closest(value, selected)
            fix = f"did you mean '{close}'? " if close else ""
            raise self.error(f"unknown effect '{value}'", key,
                             fix + f"switched-on effects: {listing(selected)}")
        known = {"point": [CANONICAL_POINT] + [p.name for p in model.points],
                 "base": [CANONICAL_BASE] + [b.name for b in model.bases],
                 "body": [b.name for b in model.bodies],
                 "constraint": [c.name for c in model.constraints]}[role]
        if value in known:
            return value
        if role == "constraint" and not known:
            raise self.error(f"model '{self.full.name}' has no constraints, so no constraint "
                             "forces", key, "record a constraint force of a model with a "
                             "'constraints:' section")
        plural = {"point": "points", "base": "bases", "body": "bodies",
                  "constraint": "constraints"}[role]
        names = f"{plural} of model '{self.full.name}': {listing(known, 20)}"
        other = self.full_ctx.kind_of(value)
        if other is not None:
            raise self.error(f"'{value}' is {article(other)}, not {article(role)}", key,
                             f"name {article(role)} here ({names})")
        close = closest(value, known)
        fix = f"did you mean '{close}'? " if close else ""
        raise self.error(f"unknown {role} '{value}'", key, fix + names)

    def check_potential(self, name: str, key: str, model: ModelSpec) -> None:
        for e in model.effects:
            if e.kind == "gravity" and e.base != CANONICAL_BASE:
                raise self.error(f"the potential energy leaves out gravity effect '{e.name}' "
                                 f"(its base is '{e.base}', not E)", key,
                                 "give that gravity vector in base E, or record "
                                 "energy: kinetic")


# -- helpers -------------------------------------------------------------------------------

def _effect_kinds(spec: ModelSpec) -> dict:
    """Every effect a scene can switch on, in model order: name -> kind."""
    kinds = {GRAVITY: "gravity"} if spec.gravity is not None else {}
    kinds.update((a.name, "action") for a in spec.actions)
    kinds.update((e.name, e.kind) for e in spec.effects)
    return kinds


def _only(spec: ModelSpec, effect: str) -> ModelSpec:
    """``spec`` with nothing but the effect ``effect`` (for finding who uses a symbol)."""
    return ModelSpec(name=spec.name, gravity=spec.gravity if effect == GRAVITY else None,
                     actions=tuple(a for a in spec.actions if a.name == effect),
                     effects=tuple(e for e in spec.effects if e.name == effect))


def _free_symbols(spec: ModelSpec) -> set:
    return spec.free_symbols()
