"""Work-precision diagrams: modelgen's C integrators against scipy's solve_ivp.

Run from the repository root::

    .venv/bin/python bench/work_precision.py                 # the standard set, full sweep
    .venv/bin/python bench/work_precision.py --quick         # whole decades, 2 repeats
    .venv/bin/python bench/work_precision.py --problems double_pendulum stiff_chain

Problems (``modelgen.bench.STANDARD``; scenes in ``modelgen/bench/problems/``)
    * ``pendulum``: simple pendulum released from horizontal (L = 1, g = 9.81)
      over 4 periods of 2.367841947576237 s; closed-form reference (Jacobi sn
      in mpmath; after whole periods the state is the initial one).
    * ``double_pendulum``: scene dp_free over 10 s.  Chaotic (the outer rod
      turns over), so the reference is made in long double by DOP853 and GBS
      extrapolation on the closed-form equations, and their disagreement is
      shown.
    * ``arm7``: scene arm7_damped (7 joints, gravity, joint damping) over 5 s;
      reference C dop853 at 1e-14 checked against C rodas at 1e-14.
    * ``stiff_chain``: scene spring_chain_stiff, three masses with a stiff
      spring and a stiff damper between the first two, |lambda| from 1 to
      2e7 1/s, 2 s; the system is linear, so the reference is its matrix
      exponential (mpmath).

Method
    Every method integrates the same compiled model from the same state,
    returning the state on the same 201-point grid (the C methods and
    solve_ivp through their dense output; fixed steps divide the grid
    spacing).  x: the final-time error of the positions (max over
    coordinates) and the RMS error of the positions over the grid; y: the
    minimum wall time over up to 5 repeats (1 s per setting at most), and the
    rhs evaluations.  Adaptive methods run at atol = rtol over half decades
    (``--quick``: whole decades); fixed-step methods (C rk4, midpoint, gauss4) over
    step sizes in quarter decades (``--quick``: half).  solve_ivp (RK45,
    DOP853, Radau with the generated symbolic Jacobian) calls
    ``cm.rhs_function()``, the low-overhead path into the same compiled rhs.
    Failures are plotted as x; a run over its budget (1e6 rhs evaluations or
    20 s for solve_ivp, 1e7 steps for the adaptive C methods, 3e7 for the
    fixed-step ones) fails, and the tighter settings of that method are listed
    as not run.  Errors below 100x the reference's own
    spread are marked * and drawn hollow.

Output: ``OUT/<problem>.png``, ``.md`` and ``.csv`` per problem, and
``OUT/summary.md`` with the targets.
"""
from __future__ import annotations

import argparse
import platform
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

import modelgen.bench as wp  # noqa: E402

#: target 1: C dop853 against solve_ivp DOP853 at equal final error on the double pendulum
DP_ERROR, DP_SPEEDUP = 1e-8, 30.0
#: target 2: the stiff method against dopri5 at rtol 1e-6 on the stiff chain
STIFF_RTOL, STIFF_NFEV_RATIO, MUCH_SLOWER = 1e-6, 100.0, 10.0
#: Hairer's default step limit (nmax), used to show what dopri5 reports by default
HAIRER_NMAX = 100_000


def _verdict(ok) -> str:
    return "met" if ok else "NOT met"


def dp_target(points) -> list:
    """Time and rhs evaluations of C dop853 and solve_ivp DOP853 at final error 1e-8."""
    c = wp.cost_at_error(points, "C dop853", DP_ERROR)
    s = wp.cost_at_error(points, "solve_ivp DOP853", DP_ERROR)
    cn = wp.cost_at_error(points, "C dop853", DP_ERROR, cost="nfev")
    sn = wp.cost_at_error(points, "solve_ivp DOP853", DP_ERROR, cost="nfev")
    if c is None or s is None:
        return [f"double pendulum, final error {DP_ERROR:g}: not measurable (C dop853 "
                f"{'reached' if c else 'did not reach'} it, solve_ivp DOP853 "
                f"{'reached' if s else 'did not reach'} it) — NOT met"]
    ratio = s / c
    return [f"double pendulum over 10 s at final error {DP_ERROR:g} (log-log interpolation): "
            f"C dop853 {c * 1e3:.3g} ms ({cn:.0f} rhs evaluations), solve_ivp DOP853 on the "
            f"same compiled rhs {s * 1e3:.3g} ms ({sn:.0f}): C is {ratio:.0f}x faster "
            f"(target >= {DP_SPEEDUP:g}x): {_verdict(ratio >= DP_SPEEDUP)}"]


def stiff_target(points, problem, budget) -> list:
    """The stiff method against dopri5 at rtol 1e-6; plus dopri5 with Hairer's nmax."""
    lines = []
    stiff = wp.point_at(points, "C rodas", STIFF_RTOL)
    explicit = wp.point_at(points, "C dopri5", STIFF_RTOL)
    if stiff is None or explicit is None:
        return [f"stiff chain: C rodas / C dopri5 at rtol {STIFF_RTOL:g} not in the sweep — "
                "NOT met"]
    if not stiff.ok:
        return [f"stiff chain: C rodas failed at rtol {STIFF_RTOL:g}: {stiff.message} — NOT met"]
    if not explicit.ran:        # skipped in the sweep after a looser setting hit the budget
        explicit = wp.run_sweep(problem, [wp.c_method("dopri5")], tolerances=[STIFF_RTOL],
                                repeats=1, warmup=False, budget=budget)[0]
    nfev_ratio = explicit.nfev / stiff.nfev
    time_ratio = explicit.seconds / stiff.seconds
    if explicit.ok:
        how = (f"C dopri5 finished with {explicit.nfev} evaluations in "
               f"{explicit.seconds * 1e3:.4g} ms: rodas needs {nfev_ratio:.0f}x fewer")
    else:
        how = (f"C dopri5 gave up after {explicit.nfev} evaluations and "
               f"{explicit.seconds * 1e3:.4g} ms ({explicit.message}): rodas needs more than "
               f"{nfev_ratio:.0f}x fewer")
    lines.append(f"stiff chain at rtol = atol = {STIFF_RTOL:g}: C rodas {stiff.nfev} rhs "
                 f"evaluations ({stiff.njev} Jacobians) in {stiff.seconds * 1e3:.3g} ms, final "
                 f"error {stiff.final_error:.1e}; {how} (target >= {STIFF_NFEV_RATIO:g}x): "
                 f"{_verdict(nfev_ratio >= STIFF_NFEV_RATIO)}")
    slower = (not explicit.ok) or time_ratio >= MUCH_SLOWER
    lines.append(f"  dopri5 {'fails' if not explicit.ok else f'is {time_ratio:.0f}x slower'} "
                 f"where rodas finishes (target: fails/reports, or >= {MUCH_SLOWER:g}x slower): "
                 f"{_verdict(slower and stiff.ok)}")
    res = problem.model.simulate(problem.x0, problem.t_span, problem.t_eval, method="dopri5",
                                 rtol=STIFF_RTOL, atol=STIFF_RTOL, max_steps=HAIRER_NMAX)
    lines.append(f"  with Hairer's default nmax = {HAIRER_NMAX}, C dopri5 reports: status "
                 f"{res.status}, {res.message} ({res.nfev} evaluations)")
    for label in ("solve_ivp Radau", "solve_ivp RK45"):
        p = wp.point_at(points, label, STIFF_RTOL)
        if p is not None:
            lines.append(f"  {label} at {STIFF_RTOL:g}: "
                         + (f"{p.nfev} evaluations, {p.seconds * 1e3:.4g} ms" if p.ok else
                            (p.message if not p.ran else f"FAILED: {p.message}")))
    return lines


def summary_lines(points, problem) -> list:
    """Per method: the settings run, how many failed, the error range reached."""
    lines = []
    for label in dict.fromkeys(p.method for p in points):
        mine = [p for p in points if p.method == label]
        good = [p for p in mine if p.ok]
        failed = sum(p.failed for p in mine)
        skipped = sum(not p.ran for p in mine)
        span = (f"final error {min(p.final_error for p in good):.1e} … "
                f"{max(p.final_error for p in good):.1e}, "
                f"{min(p.seconds for p in good) * 1e3:.3g} … "
                f"{max(p.seconds for p in good) * 1e3:.4g} ms" if good else "no success")
        lines.append(f"- {label}: {len(mine)} settings, {failed} failed, {skipped} not run; "
                     f"{span}")
    return lines


def build_parser():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true",
                        help="whole-decade tolerances, half-decade steps, 2 repeats")
    parser.add_argument("--out", default=str(REPO / "out" / "work_precision"),
                        help="output directory (default out/work_precision in the "
                             "repository, whatever the current directory)")
    parser.add_argument("--problems", nargs="+", choices=list(wp.STANDARD),
                        default=list(wp.STANDARD), metavar="NAME",
                        help=f"problems to run (default all: {' '.join(wp.STANDARD)})")
    parser.add_argument("--build-dir", default=None,
                        help="where the models are built (default: the per-user cache)")
    parser.add_argument("--repeats", type=int, default=None,
                        help="repeats per setting (default 5, --quick 2)")
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    repeats = args.repeats or (2 if args.quick else 5)
    time_budget = 0.3 if args.quick else 1.0
    budget = wp.Budget(max_nfev=1_000_000, max_seconds=20.0, max_steps=10_000_000,
                       max_fixed_steps=30_000_000)

    def progress(message):
        print(f"... {message}", file=sys.stderr, flush=True)

    report = [f"# Work-precision diagrams ({'quick' if args.quick else 'full'} sweep)", "",
              f"{platform.processor() or platform.machine()}, Python {platform.python_version()}, "
              f"numpy {np.__version__}; {time.strftime('%Y-%m-%d %H:%M')}", ""]
    targets = []
    for name in args.problems:
        t0 = time.perf_counter()
        progress(f"{name}: building the model and the reference")
        problem = wp.STANDARD[name](args.build_dir, quick=args.quick)
        t_ref = time.perf_counter() - t0
        methods = wp.default_methods()
        points = wp.run_sweep(problem, methods, repeats=repeats, time_budget=time_budget,
                              budget=budget, progress=progress)
        md, csv_path = wp.write_tables(points, out / name, problem)
        png = wp.plot_work_precision(points, problem, out / f"{name}.png")
        section = [f"## {problem.title}", "", wp.describe(problem), "",
                   f"Model and reference: {t_ref:.1f} s; sweep: "
                   f"{time.perf_counter() - t0 - t_ref:.1f} s. Files: {png}, {md}, {csv_path}.",
                   "", *summary_lines(points, problem), "", wp.markdown_table(points), ""]
        print("\n".join(section), flush=True)
        report += section
        if name == "double_pendulum":
            targets += dp_target(points)
        if name == "stiff_chain":
            targets += stiff_target(points, problem, budget)
    if targets:
        block = ["## Targets", "", *[f"- {line}" if not line.startswith("  ") else
                                     f"  - {line.strip()}" for line in targets], ""]
        print("\n".join(block))
        report += block
    (out / "summary.md").write_text("\n".join(report))
    print(f"wrote {out / 'summary.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
