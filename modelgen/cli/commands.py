"""The commands of the command line: one function each (``generate_command``,
``simulate_command``, ...), taking the parsed arguments and returning the exit
status; the progress bars, the overrides of --set/--init, the output budget and
the reports they share.  :mod:`modelgen.cli.parsers` builds the parser that
calls them, :mod:`modelgen.cli` runs it.
"""
from __future__ import annotations

import contextlib
import math
import os
import shutil
import sys
import threading
import time
import warnings
from pathlib import Path

from modelgen.cli.assignments import parameter_overrides, parse_assignments, state_overrides
from modelgen.cli.kinematics_options import kinematics_line, kinematics_of
from modelgen.cli.output_paths import check_output_dir, check_output_file, describe_run
from modelgen.codegen.capi import STATUS_BY_NAME
from modelgen.codegen.options import BuildOptions
from modelgen.errors import (ModelgenError,
                             SimulationError)


#: exit status of each outcome (documented in the module docstring and the README):
#: 128 + the signal's number for SIGINT and SIGTERM, as a shell reports them
EXIT = {"ok": 0, "internal": 1, "input": 2, "build": 3, "simulation": 4, "interrupted": 130,
        "terminated": 143}


#: the C integrators' status for a run stopped by Ctrl-C
INTERRUPTED = STATUS_BY_NAME["INTERRUPTED"].code


#: the largest output a run or sweep may write without --max-output-mb [MB]: its
#: samples x columns x runs doubles, plus a run's CSV text
MAX_OUTPUT_MB = 1000.0


#: the columns an output of each kind adds to a result (n: one per speed)
_OUTPUT_COLUMNS = {"position": 3, "velocity": 3, "orientation": 9, "angular_velocity": 3,
                   "energy": 1, "generalized_force": "n", "power": 1, "pose": 16,
                   "constraint_force": 3}


#: a progress bar appears only once its task has run this long [s]
#: (``MODELGEN_PROGRESS_DELAY`` overrides it)
PROGRESS_DELAY = 2.0


@contextlib.contextmanager
def _progress_bar(args, total, desc, **options):
    """A tqdm bar on stderr, or None when stderr is not a terminal or with --quiet.

    It is drawn only after PROGRESS_DELAY seconds (short tasks show nothing) and
    redrawn by a ticker, so a long stage without updates still shows it."""
    if getattr(args, "quiet", False) or not sys.stderr.isatty():
        yield None
        return
    from tqdm import tqdm
    delay = float(os.environ.get("MODELGEN_PROGRESS_DELAY", PROGRESS_DELAY))
    bar = tqdm(total=total, desc=desc, delay=delay, file=sys.stderr, leave=False,
               dynamic_ncols=True, **options)
    stop = threading.Event()

    def tick():
        while not stop.wait(0.25):
            bar.update(0)
    ticker = threading.Thread(target=tick, daemon=True)
    ticker.start()
    try:
        yield bar
    finally:
        stop.set()
        ticker.join()
        bar.close()


@contextlib.contextmanager
def _generation_progress(args, name):
    """``stages(stage)`` for :func:`modelgen.codegen.pipeline.generate`, drawing the
    stages of a build on a progress bar (see :func:`_progress_bar`)."""
    from modelgen.codegen.build import STAGES
    with _progress_bar(args, len(STAGES), f"{name}: generating",
                       bar_format="{desc} {n_fmt}/{total_fmt} stages |{bar}| "
                                  "[{elapsed}]") as bar:
        def stages(stage):
            if bar is not None:
                bar.set_description(f"{name}: {stage}")     # drawn now: a stage may be short
                bar.update(STAGES.index(stage) - bar.n)
        yield stages


@contextlib.contextmanager
def _simulation_progress(args, name, t0, t1):
    """``progress(t)`` for ``simulate``: the simulated time on a progress bar."""
    span = float(t1 - t0)
    with _progress_bar(args, span, f"{name}: integrating",
                       bar_format="{desc} |{bar}| {percentage:3.0f}% of "
                                  f"{t0:g}..{t1:g} s [{{elapsed}}<{{remaining}}]") as bar:
        def progress(t):
            if bar is not None:
                bar.update(min(max(t - t0, 0.0), span) - bar.n)
        yield progress


def _reading(args) -> dict:
    """The URDF reading options of --inertia, --min-mass and --min-inertia, as keywords
    (only those given, so a model file without them is read as before)."""
    out = {}
    if args.inertia != "physical":
        out["inertia"] = args.inertia.replace("-", "_")
    for key in ("min_mass", "min_inertia"):
        if getattr(args, key):
            out[key] = getattr(args, key)
    if args.mimic != "strict":
        out["mimic"] = args.mimic
    return out


#: what ``generate`` says of the manifest's ``jacobian_method``
_JACOBIAN_WORDS = {"forward": "forward mode over the rhs program (fewer operations here)",
                   "derivatives": "from the analytical derivatives (<name>_derivatives)"}


def generate_command(args) -> int:
    from modelgen.model import as_spec, is_scene_file
    from modelgen.sim.load import generate_model
    t0 = time.perf_counter()
    if is_scene_file(args.model):
        raise ModelgenError(f"{args.model} is a scene file, not a model; fix: run it with "
                            f"`modelgen simulate {args.model}` (which builds its reduced model), "
                            f"or generate the model file it names")
    _check_floating_base(args)
    _check_max_operations(args)
    # --floating-base and the inertia options act as the file is read; the rest says
    # what to build
    options = BuildOptions(jacobian=args.jacobian, formulation=args.formulation,
                           kinematics=kinematics_of(args))
    spec = as_spec(args.model, floating_base=args.floating_base, **_reading(args))
    t_load = time.perf_counter() - t0
    with _generation_progress(args, spec.name) as stages:
        g = generate_model(spec, args.output, force=args.force, options=options,
                           progress=stages, max_operations=args.max_operations)
    b = g.build
    print(f"model      {spec.name}  ({args.model})")
    sizes = f"{spec.n} coordinates" if spec.nq == spec.n else \
        f"{spec.nq} coordinates, {spec.n} speeds ({len(spec.joints)} quaternion joints)"
    print(f"n          {sizes}, {len(spec.parameters)} parameters, "
          f"{len(spec.inputs)} inputs, {len(spec.bodies)} bodies")
    print(f"output     {b.directory}/{spec.name}.c, {spec.name}.h, {b.module_path.name}")
    print(f"rhs        formulation {g.manifest['formulation']}")
    if g.manifest.get("jacobian_method"):
        print(f"jacobian   {_JACOBIAN_WORDS[g.manifest['jacobian_method']]}")
    if g.manifest.get("kinematics"):
        print(f"kinematics {kinematics_line(g.manifest['kinematics'])}")
    if g.manifest.get("constraints"):
        for line in _constraint_lines(spec, g.manifest["constraints"]):
            print(line)
    if b.cached:
        print("build      unchanged model: reused the cached build")
    w = max([20, *map(len, g.ops)])
    print(f"\n{'routine':<{w}} statements   ops before CSE   ops after CSE")
    for name, o in g.ops.items():
        print(f"{name:<{w}} {o['statements']:>10} {o['before_cse']:>16} {o['after_cse']:>15}")
    if not b.cached:
        s = g.seconds
        print("\nstage      seconds")
        print(f"load       {t_load:8.3f}")
        for stage, seconds in s.items():
            print(f"{stage:<10} {seconds:8.3f}")
        total = time.perf_counter() - t0
        # importing the symbolic pipeline, and loading the library to check its A
        print(f"other      {total - t_load - sum(s.values()):8.3f}")
        print(f"total      {total:8.3f}")
    return 0


def _constraint_lines(spec, c: dict) -> list:
    """What ``generate`` says of a constrained model: its equations, and the dependent
    coordinates and speeds, declared in the model or chosen by modelgen."""
    def names(kind, indices):
        return ", ".join(kind[k] for k in indices) or "none"
    how = ("chosen by modelgen (largest pivots of the constraint Jacobian; declare them "
           "with 'dependent:' to fix them)" if c["chosen"] else "declared in the model")
    return [f"constraints {c['m']} equations ({c['holonomic']} on positions), dependent "
            f"coordinates and speeds {how}",
            f"dependent  coordinates {names(spec.coordinates, c['dependent_coordinates'])}; "
            f"speeds {names(spec.speeds, c['dependent_speeds'])}",
            f"independent speeds {names(spec.speeds, c['independent_speeds'])}"]


def _import_path(args) -> Path:
    """The model file an import writes: -o, else the source's path with .yaml."""
    return Path(args.output) if args.output else Path(args.urdf).with_suffix(".yaml")


def import_command(args) -> int:
    check_output_file(_import_path(args), "model.yaml")
    if Path(args.urdf).suffix.lower() == ".xml":
        return _import_mjcf(args)
    from modelgen.model.urdf import import_urdf, urdf_to_yaml
    imported = import_urdf(args.urdf, fix_floating_root=args.fix_floating_root,
                           inertial_parameters=args.inertial_parameters,
                           floating_base=args.floating_base, **_reading(args))
    return _write_import(args, imported, urdf_to_yaml(imported), inputs=True)


def _import_mjcf(args) -> int:
    """``modelgen import robot.xml``: an MJCF file compiled by MuJoCo (docs/mjcf.md)."""
    from modelgen.model.mjcf import import_mjcf, mjcf_to_yaml
    if args.fix_floating_root or args.floating_base or args.inertial_parameters:
        print("error: --fix-floating-root, --floating-base and --inertial-parameters apply "
              "to a URDF file; an MJCF model declares its free joints itself", file=sys.stderr)
        return 2
    imported = import_mjcf(args.urdf)
    return _write_import(args, imported, mjcf_to_yaml(imported), inputs=False)


def _write_import(args, imported, text: str, *, inputs: bool) -> int:
    """Write an imported model's YAML ``text`` (to -o, else beside the source) and
    report it; ``inputs``: the import made one input per joint (URDF)."""
    from modelgen.sim.result import replacing
    spec = imported.model.spec()
    out = _import_path(args)
    out.parent.mkdir(parents=True, exist_ok=True)
    with replacing(out) as part:        # no cut model file under the final name
        part.write_text(text)
    print(f"model      {spec.name}  ({args.urdf})")
    sizes = f"{spec.n} coordinates" if spec.nq == spec.n else \
        f"{spec.nq} coordinates, {spec.n} speeds"
    counts = f"{len(spec.inputs)} inputs, " if inputs else ""
    print(f"n          {sizes}, {len(spec.bodies)} bodies, {counts}"
          f"{len(spec.effects)} joint effects")
    for note in imported.notes:
        print(f"note       {note}")
    print(f"wrote      {out}")
    return 0


def _quietly(run, *args, **kwargs):
    """``run(*args, **kwargs)`` without the max_steps RuntimeWarning: the CLI prints
    the result's message (which says the same) itself."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=".*max_steps", category=RuntimeWarning)
        return run(*args, **kwargs)


def _check_times(args) -> None:
    if args.max_steps is not None and args.max_steps < 1:
        raise ModelgenError(f"--max-steps must be a positive count, got {args.max_steps}")
    for flag, value in (("--t-end", args.t_end), ("--dt", args.dt), ("--sample", args.sample)):
        if value is not None and not (value > 0 and value < float("inf")):
            raise ModelgenError(f"{flag} must be a positive number of seconds, got {value!r}")
    if args.max_output_mb is not None and not (0 < args.max_output_mb < float("inf")):
        raise ModelgenError(f"--max-output-mb must be a positive number, got "
                            f"{args.max_output_mb!r}")


def _check_max_operations(args) -> None:
    """--max-operations is checked here, before the model is read: the build that checks
    it again knows neither the flag's name nor the file."""
    if args.max_operations is not None and args.max_operations < 1:
        raise ModelgenError(f"--max-operations must be a positive number of operations, got "
                            f"{args.max_operations}; fix: give e.g. --max-operations 320000, "
                            f"or leave it out for the default")


def _check_trace(args, spec) -> None:
    """The --trace points of an --animate run are points of ``spec`` (the model drawn):
    checked before the run, as the animation is drawn only after it."""
    if not (args.animate and args.trace):
        return
    from modelgen.model.spec import CANONICAL_POINT
    names = (CANONICAL_POINT, *(pt.name for pt in spec.points))
    for name in args.trace:
        if name not in names:
            raise ModelgenError(f"--trace {name}: unknown point of model {spec.name} "
                                f"({args.model}); fix: trace one of {', '.join(names)}")


def _check_floating_base(args) -> None:
    """--floating-base acts on a robot description as it is read, never on a model or
    scene file (whose free joints are declared in the file)."""
    if getattr(args, "floating_base", False) and Path(args.model).suffix.lower() != ".urdf":
        raise ModelgenError(f"--floating-base applies to a URDF file, not {args.model}; fix: "
                            f"in a model file, declare a free joint under 'joints:' (a scene "
                            f"runs the model it names as that file declares it)")


def _columns_of(model, outputs=()) -> int:
    """Columns of a run's table: t, the state, the energies and the outputs' columns."""
    n = 1 + model.nq + model.n + 3
    for out in outputs:
        width = _OUTPUT_COLUMNS.get(out.kind, 1)
        n += model.n if width == "n" else width
    return n


def _check_output_size(args, samples: float, columns: int, runs: float = 1,
                       csv: bool = True) -> None:
    """Refuse, before anything is built or run, a run or sweep whose results (samples x
    columns x runs doubles, plus a run's CSV text) exceed --max-output-mb."""
    from modelgen.sim.result import output_bytes
    limit = MAX_OUTPUT_MB if args.max_output_mb is None else args.max_output_mb
    size = output_bytes(samples, columns, runs, csv=csv)
    if not size <= limit * 1e6:
        what = f"{samples:.4g} samples x {columns} columns" + \
            (f" x {runs:.4g} runs" if runs != 1 else "")
        raise ModelgenError(f"the results would take {size / 1e6:.4g} MB ({what}), more than "
                            f"--max-output-mb {limit:g}; fix: fewer samples (a larger "
                            f"--sample, a shorter --t-end{', fewer runs' if runs != 1 else ''}), "
                            f"or raise --max-output-mb")


def _samples(t0: float, t1: float, dt: float) -> float:
    """How many samples every dt from t0 to t1 (the end included): a float, never huge."""
    return (t1 - t0) / dt + 1


def _report(result, out: Path, name: str, args, title: str, conservative,
            animation=None) -> int:
    """Write CSV, NPZ and PNG of a result (and with ``--animate`` the animation and the
    HTML viewer, from ``animation`` = (model spec or a function giving it, compiled
    model, p)); print the energy balance; the exit status."""
    import numpy as np
    out.mkdir(parents=True, exist_ok=True)
    partial = "" if result.success else \
        f" (partial: {len(result.t)} samples to t = {result.t[-1] if len(result.t) else 0:g} s)"
    if not args.quiet:
        print(f"{name}: writing {len(result.t)} samples{partial} (Ctrl-C again stops "
              f"at once)", file=sys.stderr, flush=True)
    # the NPZ first: it takes a fraction of a second where the CSV's exact text of
    # every float takes seconds, so a second Ctrl-C during the CSV still leaves it
    print(f"wrote {result.to_npz(out / f'{name}.npz')}{partial}")
    print(f"wrote {result.to_csv(out / f'{name}.csv')}{partial}")
    if not args.no_plot:
        png = out / f"{name}.png"
        result.plot(png, title=title, conservative=conservative)
        print(f"wrote {png}")
    if args.animate and animation is not None:
        from modelgen.sim.animate import animate_files
        spec, compiled, p = animation
        spec = spec() if callable(spec) else spec   # a scene's model is read only now
        for path in animate_files(result, spec, out / name, compiled=compiled, p=p,
                                  trace=args.trace, movie=args.animate_format):
            print(f"wrote {path}")
    if result.energy is not None and len(result.t):
        energy = result.energy_change()
        print(f"{energy.describe(bool(conservative))}; {len(result.t)} samples "
              f"to t = {result.t[-1]:g} s")
        if result.work:
            balance = float(np.max(np.abs(result.info["energy_balance"])))
            work = ", ".join(f"{name} {w[-1]:.6g} J" for name, w in result.work.items())
            relative = f" (relative {balance / energy.scale:.3e})" if energy.scale > 0 else ""
            print(f"work done: {work}; energy balance E - E(0) - sum of work: max "
                  f"{balance:.3e} J{relative}")
            from modelgen.sim.mechanical_work import UNRESOLVED
            if result.info.get("work_unresolved", 0.0) > UNRESOLVED:
                print(f"modelgen: note: a power changes faster than the samples resolve "
                      f"(a fast transient, or an input that jumps between two samples), so "
                      f"the work's quadrature may be off by up to "
                      f"{result.info['work_quadrature_check']:.3e} J an interval; a finer "
                      f"--sample separates it from the integration error", file=sys.stderr)
    if result.info.get("stability_warning"):
        print(f"modelgen: warning: {result.info['stability_warning']}", file=sys.stderr)
    if not result.success:
        print(f"modelgen: simulation stopped: {result.message}", file=sys.stderr)
        return EXIT["interrupted" if result.status == INTERRUPTED else "simulation"]
    return 0


def _method(name):
    """The integration method named on the command line (an input error if unknown)."""
    from modelgen.sim.integrate import method_of
    try:
        return method_of(name)
    except SimulationError as exc:
        raise ModelgenError(f"--method: {exc}") from None


#: the command line's names of a scene's run settings, for the messages of its overrides
_SCENE_FLAGS = {"time.end": "--t-end", "time.sample": "--sample", "integrator.step": "--dt",
                "integrator.method": "--method"}


def _simulate_scene(args) -> int:
    from modelgen.model.scene_timing import Spelling
    from modelgen.sim.scene import Scene, read_card, with_settings

    def progress(message):
        if not args.quiet:
            print(message, file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    # a scene run before: its card from the cache, nothing symbolic imported
    card, spec = read_card(args.model, args.build_dir)
    if args.animate and args.trace and spec is None:
        # a cached card names no points: the scene is read now, as the animation would
        from modelgen.model.scene import load_scene
        spec = load_scene(args.model)
    if spec is not None:
        _check_trace(args, spec.model)
    # every override is checked before anything is built
    init = state_overrides(list(card.coordinates) + list(card.speeds), args.init)
    p = parameter_overrides(list(card.parameters), args.set) or None
    changes = {k: v for k, v in (("t_end", args.t_end), ("step", args.dt),
                                 ("sample_dt", args.sample)) if v is not None}
    if args.method is not None:
        changes["method"] = _method(args.method).name
    _check_output_size(args, _samples(card.t_start, changes.get("t_end", card.t_end),
                                      changes.get("sample_dt", card.sample_dt)),
                       _columns_of(card, card.outputs))
    # by the scene file's rules: a fixed step divides the sample interval, and more
    card = with_settings(card, Spelling(_SCENE_FLAGS, "{name} {value}"), **changes)
    with _generation_progress(args, card.name) as stages:
        # the run settings changed above do not change the build: the files still say it
        scene = Scene(card, args.build_dir, progress=progress, stages=stages,
                      files=(card.source, card.model_source),
                      max_operations=args.max_operations, scene_spec=spec)
    x0 = scene.initial_state(init)
    print(scene.summary())
    progress(f"{card.name}: integrating (after {time.perf_counter() - t0:.2f} s of "
             f"set-up)")
    with _simulation_progress(args, card.name, card.t_start, card.t_end) as advance:
        result = _quietly(scene.run, p=p, x0=x0, max_steps=args.max_steps, progress=advance,
                          max_output_mb=args.max_output_mb or MAX_OUTPUT_MB)
    _remove_stale_products(args, card.name)
    describe_run(result, model=card.model_name, scene=card.name, outputs=card.outputs,
                 units=scene.model.units)
    return _report(result, Path(args.output), card.name, args, f"scene {card.name}",
                   scene.conservative, animation=(lambda: scene.spec.model, scene.model, p))


def _remove_stale_products(args, name: str) -> None:
    """Remove the plot or animation of an earlier run of ``name`` that this one does not
    write: every file of it in -o is then of this run."""
    from modelgen.sim.scene import remove_stale_products
    written = ((".png",) if not args.no_plot else ()) + (
        (f".{args.animate_format}", ".html") if args.animate else ())
    remove_stale_products(args.output, name, written)


def simulate_command(args) -> int:
    import numpy as np
    from modelgen.model import as_spec, is_scene_file
    from modelgen.sim.load import load
    _check_times(args)
    check_output_dir(args.output)
    _check_floating_base(args)
    _check_max_operations(args)
    if args.trace and not args.animate:
        raise ModelgenError("--trace draws a point's path in the animation; fix: add "
                            "--animate, or leave out --trace")
    if args.animate and args.animate_format == "mp4" and shutil.which("ffmpeg") is None:
        raise ModelgenError("--animate-format mp4 needs ffmpeg on PATH; fix: install ffmpeg, "
                            "or use --animate-format gif")
    if is_scene_file(args.model):
        return _simulate_scene(args)
    model = as_spec(args.model, floating_base=args.floating_base, **_reading(args))
    _check_trace(args, model)
    method = _method(args.method or "rk4")
    if args.dt is not None and method.adaptive:     # as a scene's run refuses it
        raise ModelgenError(f"--dt {args.dt:g}: method {method.name} adapts its steps to rtol "
                            f"and atol, so a step would be ignored; fix: leave out --dt (the "
                            f"samples are every --sample), or choose a fixed-step method, "
                            f"e.g. --method rk4")
    t_end, dt = args.t_end or 10.0, args.dt or 1e-3
    sample = args.sample or dt
    _check_output_size(args, _samples(0.0, t_end, sample), _columns_of(model))
    with _generation_progress(args, model.name) as stages:
        cm = load(model, args.build_dir, progress=stages, max_operations=args.max_operations)
    x0 = cm.neutral_state()
    for key, value in state_overrides(cm.state_names, args.init).items():
        x0[cm.state_names.index(key)] = value
    p = parameter_overrides(cm.parameters, args.set) or None
    times = np.linspace(0.0, t_end, int(round(t_end / sample)) + 1)
    with _simulation_progress(args, cm.name, 0.0, t_end) as advance:
        result = _quietly(cm.simulate, x0, (0.0, t_end), t_eval=times, method=method.name,
                          step=None if method.adaptive else dt, p=p,
                          max_steps=args.max_steps, progress=advance)
    result.energy = cm.energies(result, p)
    how = f"step {dt:g} s" if not method.adaptive else "rtol 1e-8"
    print(f"{cm.name}: {method.name}, {how}, t = 0..{t_end:g} s, {len(result.t)} samples")
    _remove_stale_products(args, cm.name)
    describe_run(result, model=cm.name, units=cm.units)
    return _report(result, Path(args.output), cm.name, args, f"{cm.name}: {method.name}, {how}",
                   conservative=None, animation=(model, cm, p))


def linearize_command(args) -> int:
    """Linearize a model or scene at --at (over the scene's initial state, or zero) and
    --u (over the scene's inputs at --t, or zero); print A, B, the modes; write -o."""
    import numpy as np
    from modelgen.cli.operating_point import at_rest, check_equilibrium
    from modelgen.model import as_spec, is_scene_file
    from modelgen.model.scene import load_scene
    from modelgen.sim.load import load
    from modelgen.sim.scene import Scene
    out = Path(args.output) if args.output else None
    if out is not None:
        if out.suffix.lower() not in (".npz", ".mat"):
            raise ModelgenError(f"-o {out}: the file must end in .npz or .mat")
        check_output_file(out, "linear.npz")
    if args.t is not None and not math.isfinite(args.t):
        raise ModelgenError(f"--t must be a finite time [s], got {args.t!r}")
    if is_scene_file(args.model):
        spec = load_scene(args.model)
        model, x0 = spec.model, np.array(spec.initial, dtype=float)
        t = spec.t_start if args.t is None else args.t
    else:
        spec, model = None, as_spec(args.model)
        x0, t = np.zeros(model.nq + model.n), args.t or 0.0
    # every value is checked before anything is built
    states = list(model.coordinates) + list(model.speeds)
    at = parse_assignments(args.at, "at")
    for key, value in at.items():
        if key not in states:
            raise ModelgenError(f"--at {key}: unknown state; the state is {', '.join(states)}")
        x0[states.index(key)] = value
    u = parse_assignments(args.u, "u")
    for key in u:
        if key not in model.inputs:
            raise ModelgenError(f"--u {key}: unknown input; inputs are "
                                f"{', '.join(model.inputs) or 'none'}")
    p = parameter_overrides([name for name, _ in model.parameters], args.set) or None
    if args.equilibrium:
        check_equilibrium(model)
    if spec is not None:
        scene = Scene(spec, args.build_dir, options=BuildOptions(linearize=True))
        cm, u = scene.model, dict(scene.inputs_at(t), **u)
    else:
        cm = load(model, args.build_dir, options=BuildOptions(linearize=True))
    if args.equilibrium:
        x0 = at_rest(cm, x0, u, p, t)
    # a scene's y: its own outputs, not the power ones recorded for its energy balance
    lin = cm.linearize(x0, u=u, t=t, p=p,
                       outputs=None if spec is None else [o.name for o in spec.outputs])
    print(lin)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        # written under a temporary name and renamed: exactly -o's name, even .NPZ
        lin.to_npz(out) if out.suffix.lower() == ".npz" else lin.to_mat(out)
        print(f"wrote {out}")
    return 0


def bench_command(args) -> int:
    import modelgen.bench as wp
    from modelgen.model import is_scene_file

    def progress(message):
        print(f"... {message}", file=sys.stderr, flush=True)
    if Path(args.scene).is_dir():
        raise ModelgenError(f"{args.scene} is a directory, not a scene file; fix: give a "
                            f"scene file, e.g. models/scenes/dp_free.yaml")
    if not Path(args.scene).is_file():
        raise ModelgenError(f"{args.scene}: no such file; fix: give a scene file, e.g. "
                            f"models/scenes/dp_free.yaml")
    check_output_dir(args.output)
    if not is_scene_file(args.scene):
        raise ModelgenError(f"{args.scene} is a model file, not a scene; fix: `modelgen bench` "
                            f"takes a scene (it names the initial state, time span and "
                            f"effects), e.g. models/scenes/dp_free.yaml")
    t0 = time.perf_counter()
    progress(f"{args.scene}: building the model and the reference (two methods at 1e-14)")
    problem = wp.scene_problem(args.scene, args.build_dir, quick=args.quick)
    points = wp.run_sweep(problem, wp.default_methods(),
                          repeats=2 if args.quick else 5, time_budget=0.3 if args.quick else 1.0,
                          budget=wp.Budget(max_nfev=1_000_000, max_seconds=20.0),
                          progress=progress if args.verbose else None)
    out = Path(args.output)
    stem = out / f"{problem.name}_work_precision"
    md, csv_path = wp.write_tables(points, stem, problem)
    png = wp.plot_work_precision(points, problem, stem.with_suffix(".png"))
    print(wp.describe(problem))
    print()
    print(wp.markdown_table(points))
    print()
    for path in (png, md, csv_path):
        print(f"wrote {path}")
    failed = sum(p.failed for p in points)
    print(f"{len(points)} points, {failed} failed, in {time.perf_counter() - t0:.1f} s")
    return 0


def hard_cases_command(args) -> int:
    import modelgen.bench.hard_cases as hc
    check_output_dir(args.output)

    def progress(name):
        print(f"... {name}", file=sys.stderr, flush=True)
    results = hc.run_cases(args.cases, quick=args.quick, build_root=args.build_dir,
                           progress=progress)
    table = hc.markdown(results)
    print(table)
    from modelgen.sim.result import replacing
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    with replacing(out / "hard_cases.md") as part:     # whole files or none, as every result
        part.write_text(table)
    with replacing(out / "hard_cases.png") as part:
        hc.figure(results).savefig(part, dpi=80)
    print(f"wrote {out / 'hard_cases.md'} and {out / 'hard_cases.png'}")
    failed = [r.name for r in results if r.passed is False]
    if failed:
        print(f"modelgen: error: hard cases failed: {', '.join(failed)}", file=sys.stderr)
        return EXIT["simulation"]
    return 0


def fmu_command(args) -> int:
    from modelgen.codegen.fmu import build_fmu
    if not Path(args.model).is_file():
        what = " is a directory, not a file" if Path(args.model).is_dir() else ": no such file"
        raise ModelgenError(f"{args.model}{what}; fix: give a model or scene file, e.g. "
                            f"models/cart_pole.yaml")
    # -o is the .fmu file, or the directory it is written into
    if Path(args.output).suffix.lower() == ".fmu":
        check_output_file(args.output, "model.fmu")
    else:
        check_output_dir(args.output)
    fmu = build_fmu(args.model, args.output, method=args.method, rtol=args.rtol,
                    atol=args.atol, step=args.step, out_dir=args.build_dir)
    count = {kind: len(fmu.names(kind)) for kind in ("parameter", "input", "output")}
    print(f"fmu        {fmu.path}  ({args.model})")
    print(f"interfaces Model Exchange and Co-Simulation (FMI 2.0), binary {fmu.platform}")
    print(f"variables  {sum(v.derivative_of is not None for v in fmu.variables)} states, "
          f"{count['parameter']} parameters, {count['input']} inputs, "
          f"{count['output']} outputs")
    print(f"co-sim     {fmu.settings.describe()} (fixed at export)")
    print(f"seconds    {fmu.seconds:.2f}")
    return 0


def _check_sweep(args, sw) -> None:
    """The flags of a sweep, checked before the model is read or built: the library
    finds a bad chunk, tolerance or method only once the model is loaded."""
    check_output_file(args.output, "sweep.nc")
    if args.chunk is not None and args.chunk < 1:
        raise ModelgenError(f"--chunk must be a positive number of runs per call, got "
                            f"{args.chunk}; fix: give e.g. --chunk 64, or leave it out (about "
                            f"{sw.CHUNKS_PER_WORKER} chunks per worker)")
    if args.rtol is not None and not (math.isfinite(args.rtol) and args.rtol > 0):
        raise ModelgenError(f"--rtol must be a positive number, got {args.rtol!r}; fix: give "
                            f"a relative tolerance, e.g. --rtol 1e-8")
    if args.method is not None:
        _method(args.method)
    if args.scheduler is not None:
        sw.check_client(args.scheduler, name="--scheduler")


def _check_sweep_model(args, axes, inits, model, scene_method) -> None:
    """The swept names and the step, checked against the model read (before it is built):
    a fixed-step --method needs --dt, unless the scene's own method (``scene_method``)
    has a step too."""
    parameters = [name for name, _ in model.parameters]
    states = list(model.coordinates) + list(model.speeds)
    for flag, names, known, what in (("--param", axes, parameters, "parameter"),
                                     ("--init", inits, states, "state")):
        for name in names:
            if name not in known:
                raise ModelgenError(f"{flag}: unknown {what} {name!r}; {what}s are "
                                    f"{', '.join(known) or 'none'}")
    if args.method is None or args.dt is not None or _method(args.method).adaptive:
        return
    if scene_method is None or _method(scene_method).adaptive:
        raise ModelgenError(f"--method {_method(args.method).name} has a fixed step; fix: "
                            f"give --dt")


def sweep_command(args) -> int:
    """``modelgen sweep``: a grid of parameters and initial values, in-process or on Dask."""
    import numpy as np
    from modelgen.model import as_spec, is_scene_file
    from modelgen.model.scene import load_scene
    from modelgen.sim import sweep as sw
    from modelgen.sim.result import replacing

    def axis(item, flag):
        name, sep, text = item.partition("=")
        parts = text.split(":")
        try:
            values = [float(v) for v in parts]
            if not sep or len(parts) not in (1, 3) or (len(parts) == 3 and values[2] < 1) \
                    or not all(map(math.isfinite, values)):
                raise ValueError
        except ValueError:
            raise ModelgenError(f"{flag} takes NAME=VALUE or NAME=START:STOP:COUNT of finite "
                                f"numbers, got {item!r}") from None
        return name.strip(), values
    # the values are made only once the sweep's size is known to fit
    axes = dict(axis(i, "--param") for i in args.param or ())
    inits = dict(axis(i, "--init") for i in args.init or ())
    if set(axes) & set(inits):
        raise ModelgenError(f"{sorted(set(axes) & set(inits))} given to both --param and --init")
    how, _, variable = (args.plot or "final:").partition(":")
    if args.plot and (how not in sw.REDUCTIONS or not variable):
        raise ModelgenError(f"--plot takes HOW:VARIABLE with HOW one of "
                            f"{', '.join(sw.REDUCTIONS)}, got {args.plot!r}")
    sw.require("xarray", *(["distributed"] if args.scheduler else []))
    _check_times(args)
    _check_sweep(args, sw)
    t_eval = None
    scene = is_scene_file(args.scene)
    spec = load_scene(args.scene) if scene else as_spec(args.scene)
    model = spec.model if scene else spec
    _check_sweep_model(args, axes, inits, model, spec.method if scene else None)
    t0 = spec.t_start if scene else 0.0
    t1 = args.t_end or (spec.t_end if scene else 10.0)
    dt = args.sample or (spec.sample_dt if scene else 0.01)
    if t1 <= t0:
        raise ModelgenError(f"--t-end must be after the scene's start {t0:g} s")
    if scene:     # the scene file's time rules, as simulate applies them to overrides
        from modelgen.model.scene_timing import Spelling, timing_problem
        problem = timing_problem(t0, t1, dt, not _method(args.method or spec.method).adaptive,
                                 spec.step if args.dt is None else args.dt,
                                 Spelling(_SCENE_FLAGS, "{name} {value}"))
        if problem is not None:
            raise ModelgenError(f"scene {spec.name}: {problem.problem}; fix: {problem.fix}")
    runs = math.prod(1 if len(v) == 1 else int(v[2]) for v in (*axes.values(), *inits.values()))
    _check_output_size(args, max(_samples(t0, t1, dt), 2), _columns_of(
        model, spec.outputs if scene else ()) - 3, runs, csv=False)
    axes, inits = ({k: v if len(v) == 1 else np.linspace(v[0], v[1], int(v[2]))
                    for k, v in d.items()} for d in (axes, inits))
    if not scene or args.t_end is not None or args.sample is not None:
        t_eval = np.linspace(t0, t1, max(int(round((t1 - t0) / dt)), 1) + 1)
    g = sw.grid(**axes, **inits)
    bar = None
    if not args.quiet and sys.stderr.isatty():
        from tqdm import tqdm
        bar = tqdm(total=len(next(iter(g.values()))) if g else 1, unit="run", file=sys.stderr)

    def progress(done, total):
        if bar is not None:
            bar.update(done - bar.n)
    try:
        ds = sw.sweep(args.scene, {k: g[k] for k in axes}, {k: g[k] for k in inits},
                      t_eval=t_eval, method=args.method, rtol=args.rtol, step=args.dt,
                      client=args.scheduler, chunk=args.chunk,
                      **({} if args.max_steps is None else {"max_steps": args.max_steps}),
                      progress=progress if bar is not None else None,
                      build_dir=args.build_dir)
    finally:
        if bar is not None:
            bar.close()
    out = Path(args.output)
    out.parent.mkdir(parents=True, exist_ok=True)
    with replacing(out) as part:
        ds.to_netcdf(part)
    print(sw.summary(ds))
    print(f"wrote {out}")
    if args.plot:
        png = out.with_suffix(".png")
        with replacing(png) as part:
            sw.plot_scalar(ds, how, variable, part)
        print(f"wrote {png}")
    return EXIT["simulation"] if ds.attrs["failed"] and args.strict else 0
