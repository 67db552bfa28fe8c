"""The argument parser of the command line: one function per subcommand."""
from __future__ import annotations

import argparse
import math
import sys

from modelgen.version import __version__
from modelgen.cli.commands import (EXIT, MAX_OUTPUT_MB, bench_command, fmu_command,
                                   generate_command, hard_cases_command, import_command,
                                   linearize_command, simulate_command, sweep_command)
from modelgen.cli.kinematics_options import add_kinematics_options


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


#: the exit statuses, as ``modelgen --help`` lists them (the values of EXIT)
EXIT_STATUS_HELP = (
    f"exit status: {EXIT['ok']} success; {EXIT['input']} bad input (a model, scene or "
    f"command-line mistake, an -o that cannot be written); {EXIT['build']} a build error; "
    f"{EXIT['simulation']} a simulation that failed (its partial results are written); "
    f"{EXIT['interrupted']} interrupted (Ctrl-C), {EXIT['terminated']} terminated (SIGTERM); "
    f"{EXIT['internal']} an internal error")


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors end with the fix: the help of the command at fault."""

    def error(self, message):
        self.print_usage(sys.stderr)
        self.exit(EXIT["input"], f"{self.prog}: error: {message}; fix: see "
                                 f"`{self.prog} --help` for the options\n")


def _fmu_parser(sub) -> None:
    f = sub.add_parser("fmu", help="export a model or scene as an FMI 2.0 FMU (Model Exchange "
                                   "and Co-Simulation)",
                       description="Write an FMI 2.0 FMU for Model Exchange and Co-Simulation "
                                   "in one archive: modelDescription.xml (states q.., q.._dot "
                                   "and their derivatives, tunable parameters, inputs, a "
                                   "scene's outputs), the C sources and the binary for this "
                                   "platform. Co-Simulation steps with modelgen's own "
                                   "integrator, chosen here.")
    f.add_argument("model", help="model YAML, URDF or scene YAML file")
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
    f.set_defaults(func=fmu_command)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="modelgen",
        description="Generate fast C code for the equations of motion of multibody models.",
        epilog=EXIT_STATUS_HELP)
    parser.add_argument("--version", action="version", version=f"modelgen {__version__}")
    parser.add_argument("--debug", action="store_true",
                        help="show the Python traceback of an error")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    _generate_parser(sub)
    _simulate_parser(sub)
    _import_parser(sub)
    _bench_parser(sub)
    _linearize_parser(sub)
    _sweep_parser(sub)
    _hard_cases_parser(sub)
    _fmu_parser(sub)
    for command in sub.choices.values():
        command.set_defaults(command_parser=command)
    return parser


def _generate_parser(sub) -> None:
    g = sub.add_parser("generate", help="derive the equations, write C and compile the module",
                       description="Derive A, h and tau, eliminate common subexpressions, "
                                   "write <name>.c/<name>.h and compile them into a shared "
                                   "library. An "
                                   "unchanged model reuses the cached build.")
    g.add_argument("model", help="model YAML or URDF file")
    g.add_argument("-o", "--output", "--build-dir", dest="output", default=None,
                   help="output directory of the C, header and library: the build directory "
                        "(-o and --build-dir are the same here; default: the per-user cache, "
                        "see modelgen.codegen.build.default_output)")
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
    g.add_argument("--max-operations", type=int, default=None, metavar="N",
                   help="build budget: refuse a model whose C would cost more than N "
                        "operations after CSE (sin, cos count 40), before compiling "
                        "(default: $MODELGEN_MAX_OPERATIONS, else 320000)")
    add_kinematics_options(g)
    g.set_defaults(func=generate_command)


def _simulate_parser(sub) -> None:
    s = sub.add_parser("simulate", help="run a scene (or a model) and write CSV, NPZ and PNG",
                       description="Run a scene file: build (or reuse) its reduced model with "
                                   "only the effects and outputs it selects, integrate it in C "
                                   "and write OUT/<scene>.csv, .npz and .png. Given a model "
                                   "file instead, integrate it with RK4 from --init values.")
    s.add_argument("model", help="scene YAML file (or model YAML or URDF file)")
    s.add_argument("-o", "--output", default="out", help="output directory (default: out)")
    s.add_argument("--build-dir", default=None,
                   help="where the model is built (default: the per-user cache)")
    s.add_argument("--max-operations", type=int, default=None, metavar="N",
                   help="build budget: refuse a model whose C would cost more than N "
                        "operations after CSE (sin, cos count 40), before compiling "
                        "(default: $MODELGEN_MAX_OPERATIONS, else 320000)")
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
                   help="most steps of the integrator (default: 100000, or the steps a "
                        "fixed-step method needs for the span); a run that needs more stops "
                        "with a warning saying so (exit status 4)")
    s.add_argument("--init", action="append", metavar="NAME=VALUE",
                   help="initial coordinate or speed, e.g. q1=1.2, q1=pi/2 or q1_dot=0 "
                        "(a number or an expression of numbers; repeatable; default 0)")
    s.add_argument("--set", action="append", metavar="NAME=VALUE",
                   help="override a parameter (repeatable)")
    s.add_argument("--no-plot", action="store_true", help="do not write the PNG")
    s.add_argument("-q", "--quiet", action="store_true",
                   help="no progress bars or progress messages on stderr (bars are drawn "
                        "on a terminal for a build or a run taking more than 2 s); errors, "
                        "warnings and a failed run's reason are still printed")
    s.add_argument("--max-output-mb", type=float, default=None, metavar="MB",
                   help=f"refuse, before anything runs, results larger than MB megabytes "
                        f"(samples x columns doubles plus the CSV text; default {MAX_OUTPUT_MB:g})")
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
    s.set_defaults(func=simulate_command)


def _import_parser(sub) -> None:
    i = sub.add_parser("import", help="import a robot description (URDF, or MJCF where "
                                      "supported) as a model file",
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
    i.set_defaults(func=import_command)


def _bench_parser(sub) -> None:
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
    b.set_defaults(func=bench_command)


def _linearize_parser(sub) -> None:
    lz = sub.add_parser("linearize", help="linearize a model or scene at an operating point: "
                                          "A, B, C, D and the modes",
                        description="Build (or reuse) the model with its symbolic "
                                    "linearization, evaluate A = d xdot/dx and B = d xdot/du "
                                    "(and, for a scene's outputs, C and D) at --at and --u, "
                                    "and print them with the eigenvalues, their natural "
                                    "frequencies and damping ratios.")
    lz.add_argument("model", help="model YAML, URDF or scene YAML file")
    lz.add_argument("--at", action="append", metavar="NAME=VALUE",
                    help="coordinate or speed of the operating point, e.g. q1=pi "
                         "(a number or an expression of numbers; repeatable; default: the "
                         "scene's initial state, or 0)")
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
    lz.set_defaults(func=linearize_command)


def _sweep_parser(sub) -> None:
    w = sub.add_parser("sweep", help="run a scene over a grid of parameters and initial "
                                     "values, in-process or on a Dask cluster",
                       description="Run a scene (or a model) over the product of --param and "
                                   "--init ranges (one simulate_batch call per chunk, on Dask "
                                   "workers with --scheduler) and write an xarray dataset "
                                   "(netCDF): a variable per state and output, dims run and "
                                   "time, per-run status. Needs the sweep extra "
                                   "(pip install 'modelgen[sweep]').")
    w.add_argument("scene", help="scene YAML file (or model YAML or URDF file)")
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
    w.add_argument("--max-output-mb", type=float, default=None, metavar="MB",
                   help=f"refuse, before anything runs, results larger than MB megabytes "
                        f"(runs x samples x columns doubles; default {MAX_OUTPUT_MB:g})")
    w.add_argument("--quiet", action="store_true", help="no progress bar")
    w.add_argument("--strict", action="store_true",
                   help="exit with status 4 when a run failed (default: 0, failures are data)")
    w.set_defaults(func=sweep_command)


def _hard_cases_parser(sub) -> None:
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
    h.set_defaults(func=hard_cases_command)
