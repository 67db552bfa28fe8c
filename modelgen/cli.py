"""Command-line interface: a thin shell over the library.

``modelgen generate MODEL.yaml [-o DIR]``  writes the C, header and compiled
module and prints n, the operation counts and the time of each stage.

``modelgen sweep SCENE.yaml --param m2=0.5:2:64 --init q1=0.1:3:32 [--scheduler local]``
runs a grid of runs (in-process or on Dask) into a netCDF dataset.

``modelgen simulate SCENE.yaml [-o OUT]``  builds (or reuses) the scene's
reduced model, integrates it in C and writes CSV, NPZ and PNG; given a model
file instead of a scene, integrates it with RK4 from ``--init`` values.

Exit status (:data:`EXIT`): 0 success; 2 bad input (a model, scene or
command-line mistake); 3 a build error (compiler missing or failing); 4 a
simulation that failed (its partial results are still written); 1 an
unexpected internal error; 130 interrupted.  Errors print one line,
``modelgen: error: ...``, with the fix; ``--debug`` shows the traceback.
"""
from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
import threading
import time
import warnings
from pathlib import Path

from modelgen.codegen.capi import STATUS_BY_NAME
from modelgen.codegen.options import BuildOptions
from modelgen.errors import (BuildError, ModelgenError, SimulationError, TemplateError)
from modelgen.version import __version__


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


def _bound(text: str) -> float:
    """A finite number >= 0 (for --min-mass and --min-inertia)."""
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number >= 0")
    return value


def _add_reading_options(parser) -> None:
    parser.add_argument("--inertia", choices=("physical", "as-is", "balance"),
                        default="physical",
                        help="(a URDF) bodies whose inertia no rigid body has: refuse them "
                             "(physical, default), keep the file's values as Pinocchio "
                             "does (as-is, with a warning per body), or set the principal "
                             "moments to their mean as MuJoCo's balanceinertia does "
                             "(balance)")
    parser.add_argument("--min-mass", type=_bound, default=0.0, metavar="KG",
                        help="(a URDF) lower bound on each moving body's mass, as MuJoCo's "
                             "boundmass (for massless moving links)")
    parser.add_argument("--min-inertia", type=_bound, default=0.0, metavar="KG_M2",
                        help="(a URDF) lower bound on each body's principal moments of "
                             "inertia, as MuJoCo's boundinertia")
    parser.add_argument("--mimic", choices=("strict", "ignore"), default="strict",
                        help="(a URDF) follow the <mimic> tags (strict, default) or ignore "
                             "them, each joint a coordinate of its own, as Pinocchio's "
                             "mimic=False (ignore)")


def _generate(args) -> int:
    from modelgen.model import as_spec, is_scene_file
    from modelgen.sim.load import generate_model
    t0 = time.perf_counter()
    if is_scene_file(args.model):
        raise ModelgenError(f"{args.model} is a scene file, not a model; fix: run it with "
                            f"`modelgen simulate {args.model}` (which builds its reduced model), "
                            f"or generate the model file it names")
    # --floating-base and the inertia options act as the file is read; the rest says
    # what to build
    options = BuildOptions(jacobian=args.jacobian, formulation=args.formulation)
    spec = as_spec(args.model, floating_base=args.floating_base, **_reading(args))
    t_load = time.perf_counter() - t0
    with _generation_progress(args, spec.name) as stages:
        g = generate_model(spec, args.output, force=args.force, options=options,
                           progress=stages)
    b = g.build
    print(f"model      {spec.name}  ({args.model})")
    sizes = f"{spec.n} coordinates" if spec.nq == spec.n else \
        f"{spec.nq} coordinates, {spec.n} speeds ({len(spec.joints)} quaternion joints)"
    print(f"n          {sizes}, {len(spec.parameters)} parameters, "
          f"{len(spec.inputs)} inputs, {len(spec.bodies)} bodies")
    print(f"output     {b.directory}/{spec.name}.c, {spec.name}.h, {b.module_path.name}")
    print(f"rhs        formulation {g.manifest['formulation']}")
    if b.cached:
        print("build      unchanged model: reused the cached build")
    print("\nroutine              statements   ops before CSE   ops after CSE")
    for name, o in g.ops.items():
        print(f"{name:<20} {o['statements']:>10} {o['before_cse']:>16} {o['after_cse']:>15}")
    if not b.cached:
        s = g.seconds
        print("\nstage      seconds")
        print(f"load       {t_load:8.3f}")
        for stage in ("derive", "cse", "emit", "compile"):
            print(f"{stage:<10} {s[stage]:8.3f}")
        print(f"total      {time.perf_counter() - t0:8.3f}")
    return 0


def _import(args) -> int:
    if Path(args.urdf).suffix.lower() == ".xml":
        return _import_mjcf(args)
    from modelgen.model.urdf import import_urdf, urdf_to_yaml
    imported = import_urdf(args.urdf, fix_floating_root=args.fix_floating_root,
                           inertial_parameters=args.inertial_parameters,
                           floating_base=args.floating_base, **_reading(args))
    spec = imported.model.spec()
    out = Path(args.output) if args.output else Path(args.urdf).with_suffix(".yaml")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(urdf_to_yaml(imported))
    print(f"model      {spec.name}  ({args.urdf})")
    sizes = f"{spec.n} coordinates" if spec.nq == spec.n else \
        f"{spec.nq} coordinates, {spec.n} speeds"
    print(f"n          {sizes}, {len(spec.bodies)} bodies, "
          f"{len(spec.inputs)} inputs, {len(spec.effects)} joint effects")
    for note in imported.notes:
        print(f"note       {note}")
    print(f"wrote      {out}")
    return 0


def _import_mjcf(args) -> int:
    """``modelgen import robot.xml``: an MJCF file compiled by MuJoCo (docs/mjcf.md)."""
    from modelgen.model.mjcf import import_mjcf, mjcf_to_yaml
    if args.fix_floating_root or args.floating_base or args.inertial_parameters:
        print("error: --fix-floating-root, --floating-base and --inertial-parameters apply "
              "to a URDF file; an MJCF model declares its free joints itself", file=sys.stderr)
        return 2
    imported = import_mjcf(args.urdf)
    spec = imported.model.spec()
    out = Path(args.output) if args.output else Path(args.urdf).with_suffix(".yaml")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(mjcf_to_yaml(imported))
    print(f"model      {spec.name}  ({args.urdf})")
    sizes = f"{spec.n} coordinates" if spec.nq == spec.n else \
        f"{spec.nq} coordinates, {spec.n} speeds"
    print(f"n          {sizes}, {len(spec.bodies)} bodies, {len(spec.effects)} joint effects")
    for note in imported.notes:
        print(f"note       {note}")
    print(f"wrote      {out}")
    return 0


def _parse_assignments(items, what):
    out = {}
    for item in items or ():
        name, sep, value = item.partition("=")
        if not sep:
            raise ModelgenError(f"--{what} takes NAME=VALUE, got {item!r}")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            raise ModelgenError(f"--{what} {item!r}: {value!r} is not a number") from None
    return out


def _state_overrides(names, items) -> dict:
    init = _parse_assignments(items, "init")
    for key in init:
        if key not in names:
            raise ModelgenError(f"--init {key}: unknown state; the state is {', '.join(names)}")
    return init


def _parameter_overrides(parameters, items) -> dict:
    values = _parse_assignments(items, "set")
    for key in values:
        if key not in parameters:
            raise ModelgenError(f"--set {key}: unknown parameter; parameters are "
                                f"{', '.join(parameters) or 'none'}")
    return values


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


def _report(result, out: Path, name: str, args, title: str, conservative,
            animation=None) -> int:
    """Write CSV, NPZ and PNG of a result (and with ``--animate`` the animation and the
    HTML viewer, from ``animation`` = (model spec, compiled model, p)); print the
    energy balance; the exit status."""
    import numpy as np
    out.mkdir(parents=True, exist_ok=True)
    print(f"wrote {result.to_csv(out / f'{name}.csv')}")
    print(f"wrote {result.to_npz(out / f'{name}.npz')}")
    if not args.no_plot:
        png = out / f"{name}.png"
        result.plot(png, title=title, conservative=conservative)
        print(f"wrote {png}")
    if args.animate and animation is not None:
        from modelgen.sim.animate import animate_files
        spec, compiled, p = animation
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


def _simulate_scene(args) -> int:
    from dataclasses import replace

    from modelgen.model.scene import load_scene
    from modelgen.sim.scene import Scene

    def progress(message):
        if not args.quiet:
            print(message, file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    spec = load_scene(args.model)
    # every override is checked before anything is built
    states = list(spec.model.coordinates) + list(spec.model.speeds)
    init = _state_overrides(states, args.init)
    p = _parameter_overrides([name for name, _ in spec.model.parameters], args.set) or None
    changes = {k: v for k, v in (("t_end", args.t_end), ("step", args.dt),
                                 ("sample_dt", args.sample)) if v is not None}
    if args.method is not None:
        method = _method(args.method)
        changes["method"] = method.name
        if not method.adaptive and args.dt is None and spec.step is None:
            raise ModelgenError(f"--method {method.name} has a fixed step; fix: give --dt")
    if changes.get("t_end", spec.t_end) <= spec.t_start:
        raise ModelgenError(f"--t-end must be after the scene's start {spec.t_start:g} s")
    spec = replace(spec, **changes)
    with _generation_progress(args, spec.name) as stages:
        # the run settings changed above do not change the build: the files still say it
        scene = Scene(spec, args.build_dir, progress=progress, stages=stages,
                      files=(spec.source, spec.full_model.source))
    x0 = scene.initial_state(init)
    print(scene.summary())
    progress(f"{spec.name}: integrating ({time.perf_counter() - t0:.2f} s so far)")
    with _simulation_progress(args, spec.name, spec.t_start, spec.t_end) as advance:
        result = _quietly(scene.run, p=p, x0=x0, max_steps=args.max_steps, progress=advance)
    return _report(result, Path(args.output), spec.name, args, f"scene {spec.name}",
                   scene.conservative, animation=(spec.model, scene.model, p))


def _check_output_dir(path) -> None:
    """Refuse an output directory that cannot be one before anything is built or run."""
    for parent in (Path(path), *Path(path).parents):
        if parent.exists():
            if not parent.is_dir():
                raise ModelgenError(f"-o {path}: {parent} is a file, not a directory; fix: "
                                    f"give a directory (it is created if missing)")
            break


def _simulate(args) -> int:
    import numpy as np
    from modelgen.model import as_spec, is_scene_file
    from modelgen.sim.load import load
    _check_times(args)
    _check_output_dir(args.output)
    if is_scene_file(args.model):
        return _simulate_scene(args)
    model = as_spec(args.model, floating_base=args.floating_base, **_reading(args))
    with _generation_progress(args, model.name) as stages:
        cm = load(model, args.build_dir, progress=stages)
    x0 = cm.neutral_state()
    for key, value in _state_overrides(cm.state_names, args.init).items():
        x0[cm.state_names.index(key)] = value
    p = _parameter_overrides(cm.parameters, args.set) or None
    method = _method(args.method or "rk4")
    t_end, dt = args.t_end or 10.0, args.dt or 1e-3
    sample = args.sample or dt
    times = np.linspace(0.0, t_end, int(round(t_end / sample)) + 1)
    with _simulation_progress(args, cm.name, 0.0, t_end) as advance:
        result = _quietly(cm.simulate, x0, (0.0, t_end), t_eval=times, method=method.name,
                          step=None if method.adaptive else dt, p=p,
                          max_steps=args.max_steps, progress=advance)
    result.energy = cm.energies(result, p)
    how = f"step {dt:g} s" if not method.adaptive else "rtol 1e-8"
    print(f"{cm.name}: {method.name}, {how}, t = 0..{t_end:g} s, {len(result.t)} samples")
    return _report(result, Path(args.output), cm.name, args, f"{cm.name}: {method.name}, {how}",
                   conservative=None, animation=(model, cm, p))


def _linearize(args) -> int:
    """Linearize a model or scene at --at (over the scene's initial state, or zero) and
    --u (over the scene's inputs at --t, or zero); print A, B, the modes; write -o."""
    import numpy as np
    from modelgen.model import as_spec, is_scene_file
    from modelgen.model.scene import load_scene
    from modelgen.sim.load import load
    from modelgen.sim.scene import Scene
    out = Path(args.output) if args.output else None
    if out is not None and out.suffix.lower() not in (".npz", ".mat"):
        raise ModelgenError(f"-o {out}: the file must end in .npz or .mat")
    if is_scene_file(args.model):
        spec = load_scene(args.model)
        model, x0 = spec.model, np.array(spec.initial, dtype=float)
        t = spec.t_start if args.t is None else args.t
    else:
        spec, model = None, as_spec(args.model)
        x0, t = np.zeros(model.nq + model.n), args.t or 0.0
    # every value is checked before anything is built
    states = list(model.coordinates) + list(model.speeds)
    at = _parse_assignments(args.at, "at")
    for key, value in at.items():
        if key not in states:
            raise ModelgenError(f"--at {key}: unknown state; the state is {', '.join(states)}")
        x0[states.index(key)] = value
    u = _parse_assignments(args.u, "u")
    for key in u:
        if key not in model.inputs:
            raise ModelgenError(f"--u {key}: unknown input; inputs are "
                                f"{', '.join(model.inputs) or 'none'}")
    p = _parameter_overrides([name for name, _ in model.parameters], args.set) or None
    if spec is not None:
        scene = Scene(spec, args.build_dir, options=BuildOptions(linearize=True))
        cm, u = scene.model, dict(scene.inputs_at(t), **u)
    else:
        cm = load(model, args.build_dir, options=BuildOptions(linearize=True))
    if args.equilibrium:
        q = cm.equilibrium(x0[:cm.n], u=u, p=p, t=t)
        print("equilibrium " + ", ".join(f"{c}={v:.12g}" for c, v in zip(cm.coordinates, q)))
        x0 = np.concatenate([q, np.zeros(cm.n)])
    lin = cm.linearize(x0, u=u, t=t, p=p)
    print(lin)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        print(f"wrote {lin.to_npz(out) if out.suffix.lower() == '.npz' else lin.to_mat(out)}")
    return 0


def _bench(args) -> int:
    import modelgen.bench as wp
    from modelgen.model import is_scene_file

    def progress(message):
        print(f"... {message}", file=sys.stderr, flush=True)
    if not Path(args.scene).is_file():
        raise ModelgenError(f"{args.scene}: no such file; fix: give a scene file, e.g. "
                            f"models/scenes/dp_free.yaml")
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


def _hard_cases(args) -> int:
    import modelgen.bench.hard_cases as hc

    def progress(name):
        print(f"... {name}", file=sys.stderr, flush=True)
    results = hc.run_cases(args.cases, quick=args.quick, build_root=args.build_dir,
                           progress=progress)
    table = hc.markdown(results)
    print(table)
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    (out / "hard_cases.md").write_text(table)
    hc.figure(results).savefig(out / "hard_cases.png", dpi=80)
    print(f"wrote {out / 'hard_cases.md'} and {out / 'hard_cases.png'}")
    failed = [r.name for r in results if r.passed is False]
    if failed:
        print(f"modelgen: error: hard cases failed: {', '.join(failed)}", file=sys.stderr)
        return EXIT["simulation"]
    return 0


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors end with the fix: the help of the command at fault."""

    def error(self, message):
        self.print_usage(sys.stderr)
        self.exit(EXIT["input"], f"{self.prog}: error: {message}; fix: see "
                                 f"`{self.prog} --help` for the options\n")


def _fmu(args) -> int:
    from modelgen.codegen.fmu import build_fmu
    if not Path(args.model).is_file():
        raise ModelgenError(f"{args.model}: no such file; fix: give a model or scene file, "
                            f"e.g. models/cart_pole.yaml")
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


def _fmu_parser(sub) -> None:
    f = sub.add_parser("fmu", help="export a model or scene as an FMI 2.0 FMU (Model Exchange "
                                   "and Co-Simulation)",
                       description="Write an FMI 2.0 FMU for Model Exchange and Co-Simulation "
                                   "in one archive: modelDescription.xml (states q.., q.._dot "
                                   "and their derivatives, tunable parameters, inputs, a "
                                   "scene's outputs), the C sources and the binary for this "
                                   "platform. Co-Simulation steps with modelgen's own "
                                   "integrator, chosen here.")
    f.add_argument("model", help="model or scene YAML file")
    f.add_argument("-o", "--output", default="out",
                   help="the .fmu file, or a directory for <name>.fmu (default: out)")
    f.add_argument("--method", default=None,
                   help="Co-Simulation integrator: rk4, dopri5, dop853, rodas, midpoint, gauss4 "
                        "(default: the scene's, or dop853)")
    f.add_argument("--rtol", type=float, default=None,
                   help="relative tolerance of an adaptive method (default: the scene's, "
                        "or 1e-8)")
    f.add_argument("--atol", type=float, default=None,
                   help="absolute tolerance (default: the scene's, or 1e-10)")
    f.add_argument("--step", type=float, default=None,
                   help="step of a fixed-step method [s] (default: the scene's)")
    f.add_argument("--build-dir", default=None,
                   help="where the model is built (default: the per-user cache)")
    f.set_defaults(func=_fmu)


def _sweep(args) -> int:
    """``modelgen sweep``: a grid of parameters and initial values, in-process or on Dask."""
    import numpy as np
    from modelgen.model import is_scene_file
    from modelgen.model.scene import load_scene
    from modelgen.sim import sweep as sw

    def axis(item, flag):
        name, sep, text = item.partition("=")
        parts = text.split(":")
        try:
            values = [float(v) for v in parts]
            if not sep or len(parts) not in (1, 3) or (len(parts) == 3 and values[2] < 1):
                raise ValueError
        except ValueError:
            raise ModelgenError(f"{flag} takes NAME=VALUE or NAME=START:STOP:COUNT, "
                                f"got {item!r}") from None
        return name.strip(), (values if len(parts) == 1
                              else np.linspace(values[0], values[1], int(values[2])))
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
    t_eval = None
    scene = is_scene_file(args.scene)
    if not scene or args.t_end is not None or args.sample is not None:
        spec = load_scene(args.scene) if scene else None
        t0 = spec.t_start if scene else 0.0
        t1 = args.t_end or (spec.t_end if scene else 10.0)
        if t1 <= t0:
            raise ModelgenError(f"--t-end must be after the scene's start {t0:g} s")
        dt = args.sample or (spec.sample_dt if scene else 0.01)
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
    ds.to_netcdf(out)
    print(sw.summary(ds))
    print(f"wrote {out}")
    if args.plot:
        png = out.with_suffix(".png")
        sw.plot_scalar(ds, how, variable, png)
        print(f"wrote {png}")
    return EXIT["simulation"] if ds.attrs["failed"] and args.strict else 0


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="modelgen",
        description="Generate fast C code for the equations of motion of multibody models.")
    parser.add_argument("--version", action="version", version=f"modelgen {__version__}")
    parser.add_argument("--debug", action="store_true",
                        help="show the Python traceback of an error")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    g = sub.add_parser("generate", help="derive the equations, write C and compile the module",
                       description="Derive A, h and tau, eliminate common subexpressions, "
                                   "write <name>.c/<name>.h and compile them into a shared "
                                   "library. An "
                                   "unchanged model reuses the cached build.")
    g.add_argument("model", help="model YAML file")
    g.add_argument("-o", "--output", default=None,
                   help="output directory (default: the per-user cache, see modelgen.codegen.pipeline.default_output)")
    g.add_argument("--force", action="store_true", help="rebuild even if cached")
    g.add_argument("-q", "--quiet", action="store_true",
                   help="no progress bar (one is drawn on a terminal when the build takes "
                        "more than 2 s)")
    g.add_argument("--jacobian", action="store_true",
                   help="also generate <name>_jacobian, the symbolic d(xdot)/dx")
    g.add_argument("--formulation", choices=("auto", "aba", "crba"), default="auto",
                   help="how <name>_rhs computes q_ddot: aba (articulated-body algorithm, "
                        "O(n), joint trees only), crba (mass matrix and Cholesky solve), or "
                        "auto (aba for joint trees from a measured size on; default)")
    g.add_argument("--floating-base", action="store_true",
                   help="(a URDF) make the root link a free body: a free joint root_joint "
                        "with a position, a unit quaternion and 6 speeds")
    _add_reading_options(g)
    g.set_defaults(func=_generate)

    s = sub.add_parser("simulate", help="run a scene (or a model) and write CSV, NPZ and PNG",
                       description="Run a scene file: build (or reuse) its reduced model with "
                                   "only the effects and outputs it selects, integrate it in C "
                                   "and write OUT/<scene>.csv, .npz and .png. Given a model "
                                   "file instead, integrate it with RK4 from --init values.")
    s.add_argument("model", help="scene YAML file (or model YAML file)")
    s.add_argument("-o", "--output", default="out", help="output directory (default: out)")
    s.add_argument("--build-dir", default=None,
                   help="where the model is built (default: the per-user cache)")
    s.add_argument("--t-end", type=float, default=None,
                   help="final time [s] (default: the scene's, or 10 for a model)")
    s.add_argument("--dt", type=float, default=None,
                   help="step of a fixed-step method [s] (default: the scene's, or 1e-3)")
    s.add_argument("--sample", type=float, default=None,
                   help="sampling interval of the output [s] (default: the scene's, or "
                        "the step)")
    s.add_argument("--method", default=None,
                   help="integration method: rk4, dopri5, dop853, rodas, midpoint, gauss4, "
                        "or solve_ivp's RK45, DOP853, Radau, BDF, LSODA (mapped to dopri5, "
                        "dop853, rodas) (default: the scene's, or rk4 for a model)")
    s.add_argument("--max-steps", type=int, default=None, metavar="N",
                   help="most steps of the integrator (default 100000); a run that needs "
                        "more stops with a warning saying so")
    s.add_argument("--init", action="append", metavar="NAME=VALUE",
                   help="initial coordinate or speed, e.g. q1=1.2 or q1_dot=0 (repeatable; "
                        "default 0)")
    s.add_argument("--set", action="append", metavar="NAME=VALUE",
                   help="override a parameter (repeatable)")
    s.add_argument("--no-plot", action="store_true", help="do not write the PNG")
    s.add_argument("-q", "--quiet", action="store_true",
                   help="no progress bars or messages on stderr (bars are drawn on a "
                        "terminal for a build or a run taking more than 2 s)")
    s.add_argument("--animate", action="store_true",
                   help="also write OUT/<name>.gif (the bodies' frames, the points as a "
                        "stick figure, traces) and OUT/<name>.html (a 3D viewer that plays "
                        "offline)")
    s.add_argument("--animate-format", choices=("gif", "mp4"), default="gif",
                   help="format of the animation (mp4 needs ffmpeg; default gif)")
    s.add_argument("--trace", action="append", metavar="POINT",
                   help="trace this point in the animation (repeatable; default: the ends "
                        "of the longest branches)")
    s.add_argument("--floating-base", action="store_true",
                   help="(a URDF) make the root link a free body (a free joint root_joint)")
    _add_reading_options(s)
    s.set_defaults(func=_simulate)

    i = sub.add_parser("import", help="import a URDF robot as a model file",
                       description="Read a URDF file and write a model file in modelgen's "
                                   "YAML: bases, points, bodies, gravity, one input "
                                   "tau_<joint> per joint and the joints' damping and "
                                   "friction as effects. Meshes are not read.")
    i.add_argument("urdf", help="URDF file, or an MJCF file (.xml, compiled by MuJoCo)")
    i.add_argument("-o", "--output", default=None,
                   help="model file to write (default: the URDF path with .yaml)")
    i.add_argument("--fix-floating-root", action="store_true",
                   help="weld a floating joint at the root to the ground instead of making "
                        "it a free joint")
    i.add_argument("--floating-base", action="store_true",
                   help="make the root link a free body (a free joint root_joint, as "
                        "Pinocchio's free-flyer)")
    i.add_argument("--inertial-parameters", action="store_true",
                   help="make masses and inertias parameters instead of numbers")
    _add_reading_options(i)
    i.set_defaults(func=_import)

    b = sub.add_parser("bench", help="work-precision diagram of a scene: the C integrators "
                                     "against scipy's solve_ivp",
                       description="Integrate a scene with every C integrator (the adaptive "
                                   "ones over tolerances, the fixed-step ones over steps) and with "
                                   "solve_ivp (RK45, DOP853, Radau) on the same compiled rhs; "
                                   "measure the final-time and dense L2 errors of the positions "
                                   "against a reference by two high-order methods at 1e-14, the "
                                   "minimum wall time and the rhs evaluations. Writes "
                                   "OUT/<scene>_work_precision.png, .md and .csv.")
    b.add_argument("scene", help="scene YAML file")
    b.add_argument("-o", "--output", default="out", help="output directory (default: out)")
    b.add_argument("--quick", action="store_true",
                   help="whole-decade tolerances, half-decade steps, 2 repeats")
    b.add_argument("--build-dir", default=None,
                   help="where the model is built (default: the per-user cache)")
    b.add_argument("-v", "--verbose", action="store_true", help="report every run on stderr")
    b.set_defaults(func=_bench)

    lz = sub.add_parser("linearize", help="linearize a model or scene at an operating point: "
                                          "A, B, C, D and the modes",
                        description="Build (or reuse) the model with its symbolic "
                                    "linearization, evaluate A = d xdot/dx and B = d xdot/du "
                                    "(and, for a scene's outputs, C and D) at --at and --u, "
                                    "and print them with the eigenvalues, their natural "
                                    "frequencies and damping ratios.")
    lz.add_argument("model", help="model or scene YAML file")
    lz.add_argument("--at", action="append", metavar="NAME=VALUE",
                    help="coordinate or speed of the operating point, e.g. q1=3.14159 "
                         "(repeatable; default: the scene's initial state, or 0)")
    lz.add_argument("--u", action="append", metavar="NAME=VALUE",
                    help="input at the operating point (repeatable; default: the scene's "
                         "input at --t, or 0)")
    lz.add_argument("--set", action="append", metavar="NAME=VALUE",
                    help="override a parameter (repeatable)")
    lz.add_argument("--t", type=float, default=None,
                    help="time of the operating point [s] (default: the scene's start, or 0)")
    lz.add_argument("--equilibrium", action="store_true",
                    help="first find the rest point (q_ddot = 0 at zero speeds) by Newton "
                         "from the --at coordinates, and linearize there")
    lz.add_argument("-o", "--output", default=None, metavar="FILE.npz|FILE.mat",
                    help="write A, B, C, D, the operating point and the names")
    lz.add_argument("--build-dir", default=None,
                    help="where the model is built (default: the per-user cache)")
    lz.set_defaults(func=_linearize)
    w = sub.add_parser("sweep", help="run a scene over a grid of parameters and initial "
                                     "values, in-process or on a Dask cluster",
                       description="Run a scene (or a model) over the product of --param and "
                                   "--init ranges (one simulate_batch call per chunk, on Dask "
                                   "workers with --scheduler) and write an xarray dataset "
                                   "(netCDF): a variable per state and output, dims run and "
                                   "time, per-run status. Needs the sweep extra "
                                   "(pip install 'modelgen[sweep]').")
    w.add_argument("scene", help="scene YAML file (or model YAML file)")
    w.add_argument("--param", action="append", metavar="NAME=START:STOP:COUNT",
                   help="sweep a parameter over COUNT values (or one NAME=VALUE); repeatable")
    w.add_argument("--init", action="append", metavar="NAME=START:STOP:COUNT",
                   help="sweep an initial value (q1, q1_dot, ...); repeatable")
    w.add_argument("--scheduler", default=None, metavar="local|tcp://HOST:8786",
                   help="run on Dask: 'local' starts a LocalCluster with one worker per "
                        "core; an address joins a running scheduler (default: in-process)")
    w.add_argument("--chunk", type=int, default=None,
                   help="runs per simulate_batch call (default: 4 chunks per worker)")
    w.add_argument("--method", default=None, help="integration method (default: the scene's)")
    w.add_argument("--rtol", type=float, default=None, help="relative tolerance")
    w.add_argument("--dt", type=float, default=None, help="fixed step [s]")
    w.add_argument("--max-steps", type=int, default=None, metavar="N",
                   help="most steps of each run (default 100000); a run that needs more "
                        "stops with status -1, keeping what it computed")
    w.add_argument("--t-end", type=float, default=None,
                   help="final time [s] (default: the scene's, or 10 for a model)")
    w.add_argument("--sample", type=float, default=None,
                   help="sampling interval [s] (default: the scene's, or 0.01 for a model)")
    w.add_argument("-o", "--output", default="out/sweep.nc",
                   help="netCDF file to write (default: out/sweep.nc)")
    w.add_argument("--plot", default=None, metavar="HOW:VARIABLE",
                   help="also write OUTPUT.png: final|max|min|mean|period of a state or "
                        "scalar output against the swept values, e.g. final:q2, period:q1")
    w.add_argument("--build-dir", default=None,
                   help="where the model is built (default: the per-user cache)")
    w.add_argument("--quiet", action="store_true", help="no progress bar")
    w.add_argument("--strict", action="store_true",
                   help="exit with status 4 when a run failed (default: 0, failures are data)")
    w.set_defaults(func=_sweep)

    h = sub.add_parser("hard-cases", help="run the hard-case suite: each case against an "
                                          "independent reference, a table and a figure",
                       description="Run the named hard cases (pendulum near the top, Lagrange "
                                   "top, stiff springs, mass ratios, singular mass matrices, "
                                   "long-run energy, friction, chains against MuJoCo, tennis "
                                   "racket, ...) and write OUT/hard_cases.md and .png. Exit "
                                   "status 4 when a case fails.")
    h.add_argument("-o", "--output", default="out", help="output directory (default: out)")
    h.add_argument("--quick", action="store_true", help="the short version of each case")
    h.add_argument("--cases", nargs="+", metavar="NAME", default=None,
                   help="run only these cases")
    h.add_argument("--build-dir", default=None,
                   help="where the models are built (default: the per-user build cache)")
    h.set_defaults(func=_hard_cases)
    _fmu_parser(sub)
    for command in sub.choices.values():
        command.set_defaults(command_parser=command)
    return parser


#: the C integrators' status for a run stopped by Ctrl-C
INTERRUPTED = STATUS_BY_NAME["INTERRUPTED"].code
#: exit status of each outcome (documented in the module docstring and the README)
EXIT = {"ok": 0, "internal": 1, "input": 2, "build": 3, "simulation": 4, "interrupted": 130}


def exit_status(exc: BaseException) -> int:
    """The exit status for an error that ends a command."""
    if isinstance(exc, (BuildError, TemplateError)):
        return EXIT["build"]
    if isinstance(exc, SimulationError):
        return EXIT["simulation"]
    if isinstance(exc, (ModelgenError, OSError)):
        return EXIT["input"]
    return EXIT["internal"]


def main(argv=None) -> int:
    """Entry point; returns the exit status (see :data:`EXIT`)."""
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:     # the subcommand's own usage, not the top-level one
        args.command_parser.error(f"unrecognized arguments: {' '.join(extra)}")
    try:
        return args.func(args)
    except KeyboardInterrupt:
        print("modelgen: interrupted", file=sys.stderr)
        return EXIT["interrupted"]
    except (ModelgenError, OSError) as exc:
        if args.debug:
            raise
        text = str(exc) if isinstance(exc, ModelgenError) else \
            f"{exc.strerror or exc}: {exc.filename!r}; fix: check the path and its permissions"
        print(f"modelgen: error: {text}", file=sys.stderr)
        return exit_status(exc)
    except Exception as exc:            # a bug: say so, briefly, unless --debug
        if args.debug:
            raise
        print(f"modelgen: internal error: {type(exc).__name__}: {exc} (please report it; "
              f"--debug shows the traceback)", file=sys.stderr)
        return EXIT["internal"]


if __name__ == "__main__":   # pragma: no cover
    sys.exit(main())
