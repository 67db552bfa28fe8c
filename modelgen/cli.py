"""Command-line interface: a thin shell over the library.

``modelgen generate MODEL.yaml [-o DIR]``  writes the C, header and compiled
module and prints n, the operation counts and the time of each stage.

``modelgen simulate SCENE.yaml [-o OUT]``  builds (or reuses) the scene's
reduced model, integrates it in C and writes CSV, NPZ and PNG; given a model
file instead of a scene, integrates it with RK4 from ``--init`` values.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from modelgen.errors import ModelgenError
from modelgen.version import __version__


def _generate(args) -> int:
    from modelgen.model import as_spec
    from modelgen.codegen.pipeline import generate
    t0 = time.perf_counter()
    spec = as_spec(args.model)
    t_load = time.perf_counter() - t0
    g = generate(spec, args.output, force=args.force, jacobian=args.jacobian)
    b = g.build
    print(f"model      {spec.name}  ({args.model})")
    print(f"n          {spec.n} coordinates, {len(spec.parameters)} parameters, "
          f"{len(spec.inputs)} inputs, {len(spec.bodies)} bodies")
    print(f"output     {b.directory}/{spec.name}.c, {spec.name}.h, {b.module_path.name}")
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


def _simulate_scene(args) -> int:
    from modelgen.sim.load import load_scene

    def progress(message):
        print(message, file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    scene = load_scene(args.model, args.build_dir, progress=progress)
    print(scene.summary())
    progress(f"{scene.spec.name}: integrating ({time.perf_counter() - t0:.2f} s so far)")
    result = scene.run()
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    name = scene.spec.name
    print(f"wrote {result.to_csv(out / f'{name}.csv')}")
    print(f"wrote {result.to_npz(out / f'{name}.npz')}")
    if not args.no_plot:
        png = result.plot(out / f"{name}.png", title=f"scene {name}",
                          energy_error=scene.conservative)
        print(f"wrote {png}")
    total = result.energy.sum(axis=1)
    change = (total[-1] - total[0]) / max(abs(result.energy).max(), 1e-300)
    label = "relative energy error" if scene.conservative else "relative energy change"
    print(f"{label} {change:.3e}; {len(result.t)} samples to t = {result.t[-1]:g} s "
          f"in {time.perf_counter() - t0:.2f} s")
    if not result.success:
        print(f"simulation stopped: {result.message}", file=sys.stderr)
        return 1
    return 0


def _simulate(args) -> int:
    import numpy as np

    from modelgen.model import is_scene_file
    from modelgen.sim.load import load
    from modelgen.sim.simulate import rk4
    if is_scene_file(args.model):
        return _simulate_scene(args)
    cm = load(args.model, args.build_dir)
    init = _parse_assignments(args.init, "init")
    names = list(cm.coordinates) + [c + "_dot" for c in cm.coordinates]
    x0 = np.zeros(2 * cm.n)
    for key, value in init.items():
        if key not in names:
            raise ModelgenError(f"--init {key}: unknown state; the state is {', '.join(names)}")
        x0[names.index(key)] = value
    p = _parse_assignments(args.set, "set")
    result = rk4(cm, x0, (0.0, args.t_end), args.dt, p=p or None)
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    csv_path = result.to_csv(out / f"{cm.name}.csv")
    print(f"{cm.name}: RK4, dt={args.dt}, t=0..{result.t[-1]:g} s, {len(result.t)} samples")
    print(f"wrote {csv_path}")
    if not args.no_plot:
        png = result.plot(out / f"{cm.name}.png", title=f"{cm.name}: RK4, dt = {args.dt} s")
        print(f"wrote {png}")
    if result.energy is not None:
        total = result.energy.sum(axis=1)
        drift = abs(total[-1] - total[0]) / max(abs(result.energy).max(), 1e-300)
        print(f"relative energy change {drift:.3e}")
    if not result.success:
        print(f"simulation stopped: {result.message}", file=sys.stderr)
        return 1
    return 0


def _bench(args) -> int:
    import modelgen.bench as wp

    def progress(message):
        print(f"... {message}", file=sys.stderr, flush=True)
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


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="modelgen",
        description="Generate fast C code for the equations of motion of multibody models.")
    parser.add_argument("--version", action="version", version=f"modelgen {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    g = sub.add_parser("generate", help="derive the equations, write C and compile the module",
                       description="Derive A, h and tau, eliminate common subexpressions, "
                                   "write <name>.c/<name>.h and compile a cffi module. An "
                                   "unchanged model reuses the cached build.")
    g.add_argument("model", help="model YAML file")
    g.add_argument("-o", "--output", default=None,
                   help="output directory (default: generated/<name>)")
    g.add_argument("--force", action="store_true", help="rebuild even if cached")
    g.add_argument("--jacobian", action="store_true",
                   help="also generate <name>_jacobian, the symbolic d(xdot)/dx")
    g.set_defaults(func=_generate)

    s = sub.add_parser("simulate", help="run a scene (or a model) and write CSV, NPZ and PNG",
                       description="Run a scene file: build (or reuse) its reduced model with "
                                   "only the effects and outputs it selects, integrate it in C "
                                   "and write OUT/<scene>.csv, .npz and .png. Given a model "
                                   "file instead, integrate it with RK4 from --init values.")
    s.add_argument("model", help="scene YAML file (or model YAML file)")
    s.add_argument("-o", "--output", default="out", help="output directory (default: out)")
    s.add_argument("--build-dir", default=None,
                   help="where the model is built (default: generated/<name>)")
    s.add_argument("--t-end", type=float, default=10.0, help="final time [s] (default 10)")
    s.add_argument("--dt", type=float, default=1e-3, help="RK4 step [s] (default 1e-3)")
    s.add_argument("--init", action="append", metavar="NAME=VALUE",
                   help="initial coordinate or speed, e.g. q1=1.2 or q1_dot=0 (repeatable; "
                        "default 0)")
    s.add_argument("--set", action="append", metavar="NAME=VALUE",
                   help="override a parameter (repeatable)")
    s.add_argument("--no-plot", action="store_true", help="do not write the PNG")
    s.set_defaults(func=_simulate)

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
                   help="where the model is built (default: generated/workprecision/<scene>)")
    b.add_argument("-v", "--verbose", action="store_true", help="report every run on stderr")
    b.set_defaults(func=_bench)
    return parser


def main(argv=None) -> int:
    """Entry point; returns the exit status (0 ok, 1 simulation failed, 2 error)."""
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except ModelgenError as exc:
        print(f"modelgen: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":   # pragma: no cover
    sys.exit(main())
