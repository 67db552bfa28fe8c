"""ABA against CRBA: operation counts, generation cost and rhs time in C, with MuJoCo.

Run from the repository root::

    .venv/bin/python bench/aba_scaling.py                 # n = 2 7 20 50 100 and the arm
    .venv/bin/python bench/aba_scaling.py --n 2 3 4 5 7   # the crossover region
    .venv/bin/python bench/aba_scaling.py --n 100 --agreement-only

Models
    ``modelgen.model.chains.spatial_chain(n)`` (hinges alternating z, y) and
    ``models/arm7.yaml`` (row ``arm7``; its seven motor torques are actions).

Method
    * Each (model, formulation) is generated in a fresh subprocess with
      ``generate(spec, dir, force=True, options=BuildOptions(formulation=...))``;
      *derive*, *cse*, *emit*, *compile* are modelgen's stage timers, *RSS* the child's peak
      resident set (Python side, its own VmHWM) after generating.
    * ops: modelgen's operation counts of the ``rhs`` routine
      (:func:`modelgen.codegen.cse.count_ops`: C operators as printed) before
      and after CSE, per coordinate; after CSE without the parameter-only
      statements (``<name>_prepare``, run once per parameter set).  For crba
      they do not include the Cholesky solve run in C on A (about n^3/6
      multiply-adds).
    * rhs in C: modelgen/bench/harness/model_bench.c (``<name>_prepare`` once,
      ``<name>_rhs_prepared`` in a loop,
      each call perturbed by the previous output, min over 5 repeats of
      >= 0.2 s, the rhs part of ``<name>.c`` compiled with the build's own
      command); MuJoCo's ``mj_forward`` on the identical chain with its
      harness (the arm rebuilt in MJCF from its joint tree by
      ``modelgen.bench.peers.tree_mjcf``), alternated ``--rounds`` times, minimum
      kept; *mj rel*: MuJoCo's ``qacc`` after ``mj_forward`` against the ABA's q_ddot
      at the timed state, max |qacc - qdd| / max |qdd|, in the same run.  Without
      mujoco (or its headers) the MuJoCo columns are empty and a note says why.
    * plans: the ABA rhs derived in-process with each ``velocity_products``
      (inward, outward, auto), operations per coordinate before and after
      CSE, and auto's per-joint plan.
    * agreement: q_ddot of aba against crba at 5 seeded random states, as
      max |qdd_aba - qdd_crba| / max |qdd_crba|, and the backward error of
      the ABA answer in the CRBA equations,
      ||A qdd_aba - b|| / (||A|| ||qdd_aba|| + ||b||) (infinity norms), which
      does not grow with cond(A).  With ``--reference`` both are also
      compared with q_ddot from the CRBA program evaluated in 40-digit
      mpmath arithmetic (A and b, then an mpmath LU solve): this shows which
      side of a disagreement carries the rounding error.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import numpy as np  # noqa: E402

DEFAULT_NS = (2, 7, 20, 50, 100)
MARK = "@@aba_scaling@@ "
FORMULATIONS = ("crba", "aba")


def model_spec(kind: str):
    from modelgen.model.api import load_model
    from modelgen.model.chains import spatial_chain
    if kind == "arm7":
        return load_model(str(REPO / "models" / "arm7.yaml"))
    return spatial_chain(int(kind)).spec()


def peak_rss_mb() -> float:
    """This process's own peak RSS in MB (VmHWM).  Not ru_maxrss: exec carries the
    parent's peak into it, and the parent has imported modelgen.bench."""
    status = Path("/proc/self/status")
    if status.is_file():
        return next(int(line.split()[1]) for line in status.read_text().splitlines()
                    if line.startswith("VmHWM:")) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def child(kind: str, formulation: str, out_dir: str) -> None:
    """Generate one model with one formulation; print the figures as JSON."""
    from modelgen.codegen.options import BuildOptions
    from modelgen.codegen.pipeline import generate
    spec = model_spec(kind)
    t0 = time.perf_counter()
    g = generate(spec, out_dir, force=True, options=BuildOptions(formulation=formulation))
    wall = time.perf_counter() - t0
    rss = peak_rss_mb()
    print(MARK + json.dumps({"seconds": g.seconds, "wall": wall, "rss_mb": rss,
                             "ops": g.ops["rhs"], "n": spec.n}))


def generate_in_child(kind: str, formulation: str, out_dir: Path) -> dict:
    proc = subprocess.run([sys.executable, __file__, "--child", kind, formulation,
                           str(out_dir)], capture_output=True, text=True, cwd=REPO)
    if proc.returncode:
        raise RuntimeError(proc.stdout + proc.stderr)
    line = next(x for x in proc.stdout.splitlines() if x.startswith(MARK))
    return json.loads(line[len(MARK):])


def compiled(kind: str, formulation: str, out_dir: Path):
    """The CompiledModel of an existing build (the cache answers)."""
    from modelgen.codegen.options import BuildOptions
    from modelgen.codegen.pipeline import generate
    from modelgen.sim.runtime import CompiledModel
    g = generate(model_spec(kind), out_dir, options=BuildOptions(formulation=formulation))
    return CompiledModel(g.manifest, g.build.module_path)


def plan_row(kind: str) -> list:
    """The ABA rhs operations per coordinate with each place of the
    velocity-product accelerations (derive_aba's ``velocity_products``): before
    CSE and after (the rhs eliminated alone, as a build does, without the
    parameter-only ``prepare``), and auto's plan (o: c outwards, .: inwards)."""
    from modelgen.codegen.cse import hoist_parameters, make_routines
    from modelgen.codegen.pipeline import routines_for
    from modelgen.derive.aba import derive_aba
    from modelgen.derive.dynamics import derive_equations
    from modelgen.derive.joint_tree import extract_joint_tree
    from modelgen.derive.kinematics import derive_kinematics
    spec = model_spec(kind)
    eqs = derive_equations(derive_kinematics(spec))
    tree = extract_joint_tree(spec)
    row, plan = [kind], ""
    for vp in ("inward", "outward", "auto"):
        fd = derive_aba(eqs, tree, spec, velocity_products=vp)
        (rhs,) = make_routines(fd.graph, [r for r in routines_for(eqs, (), None, fd)
                                          if r[0] == "rhs"])
        rest = hoist_parameters(rhs)[1]
        row.append(f"{fd.graph.operations(fd.qdd + fd.D) / spec.n:.1f} / "
                   f"{rest.ops_after / spec.n:.1f}")
        plan = "".join("o" if x else "." for x in fd.outward)
    return row + [plan if len(plan) <= 12 else f"{plan[:6]}...{plan[-3:]} ({plan.count('o')} o)"]


def agreement(cm_crba, cm_aba, n: int, seed: int = 0) -> tuple:
    rng = np.random.default_rng(seed)
    forward, backward = 0.0, 0.0
    for _ in range(5):
        x = rng.uniform(-1, 1, 2 * n)
        q1 = cm_crba.rhs(0.0, x)[n:]
        q2 = cm_aba.rhs(0.0, x)[n:]
        forward = max(forward, float(np.max(np.abs(q1 - q2)) / np.max(np.abs(q1))))
        A = cm_crba.mass_matrix(x[:n])
        b = cm_crba.generalized_forces(0.0, x[:n], x[n:]) - cm_crba.velocity_terms(x[:n], x[n:])
        r = A @ q2 - b
        scale = np.max(np.sum(np.abs(A), axis=1)) * np.max(np.abs(q2)) + np.max(np.abs(b))
        backward = max(backward, float(np.max(np.abs(r)) / scale))
    return forward, backward


def mp_reference(spec, states, digits: int = 40) -> list:
    """q_ddot at ``states`` from the CRBA program in ``digits``-digit arithmetic."""
    import mpmath
    import sympy
    from sympy.printing.pycode import MpmathPrinter
    from modelgen.derive.dynamics import derive_equations
    from modelgen.derive.kinematics import derive_kinematics
    eqs = derive_equations(derive_kinematics(spec))
    n = len(eqs.q)
    outputs = [eqs.A[i][j] for i in range(n) for j in range(n)] + \
              [eqs.tau[k] - eqs.h[k] for k in range(n)]
    printer = MpmathPrinter({"fully_qualified_modules": True})
    inputs = (eqs.t,) + eqs.q + eqs.qd + eqs.u + eqs.p
    lines = ["def f(" + ", ".join(str(x) for x in inputs) + "):"]
    lines += [f"    {sym} = {printer.doprint(e)}" for sym, e in eqs.graph.closure(outputs)]
    lines.append("    return [" + ", ".join(printer.doprint(sympy.sympify(e)) for e in outputs)
                 + "]")
    namespace = {"mpmath": mpmath}
    exec("\n".join(lines), namespace)     # noqa: S102 - our own program
    out = []
    with mpmath.workdps(digits):
        for x in states:
            values = ([mpmath.mpf(0)] + [mpmath.mpf(float(v)) for v in x]
                      + [mpmath.mpf(0)] * len(eqs.u)
                      + [mpmath.mpf(v) for v in spec.parameter_defaults])
            r = namespace["f"](*values)
            A = mpmath.matrix(n, n)
            for i in range(n):
                for j in range(n):
                    A[i, j] = r[i * n + j]
            b = mpmath.matrix(r[n * n:])
            out.append(np.array([float(v) for v in mpmath.lu_solve(A, b)]))
    return out


def reference_errors(spec, cms, seed: int = 0) -> dict:
    """max |qdd - qdd_mp| / max |qdd_mp| over 2 seeded states, per formulation."""
    n = spec.n
    rng = np.random.default_rng(seed)
    states = [rng.uniform(-1, 1, 2 * n) for _ in range(2)]
    refs = mp_reference(spec, states)
    return {f: max(float(np.max(np.abs(cms[f].rhs(0.0, x)[n:] - ref)) / np.max(np.abs(ref)))
                   for x, ref in zip(states, refs)) for f in FORMULATIONS}


def fmt(v, spec=".3g"):
    return "–" if v is None else format(v, spec)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--child", nargs=3, metavar=("KIND", "FORMULATION", "DIR"),
                    help=argparse.SUPPRESS)
    ap.add_argument("--n", type=int, nargs="+", default=list(DEFAULT_NS))
    ap.add_argument("--no-arm", action="store_true", help="skip models/arm7.yaml")
    ap.add_argument("--rounds", type=int, default=3,
                    help="alternating timing rounds, minimum kept (default 3)")
    ap.add_argument("--agreement-only", action="store_true",
                    help="no timing: generation figures and agreement only")
    ap.add_argument("--reference", action="store_true",
                    help="also compare both with a 40-digit mpmath solution")
    args = ap.parse_args(argv)
    if args.child:
        child(*args.child)
        return 0

    # here, not at the top: the children (--child) measure their memory without them
    from modelgen.bench import harnesses, peers
    from modelgen.bench.tables import markdown
    kinds = ([] if args.no_arm else ["arm7"]) + [str(n) for n in args.n]
    print(f"load average {os.getloadavg()[0]:.2f} (2 cores shared: > 0.5 means noisy times)\n")
    gen_rows, run_rows, plan_rows = [], [], []
    with tempfile.TemporaryDirectory(prefix="aba_scaling_") as tmp:
        tmp = Path(tmp)
        mj_harness = None
        if args.agreement_only:
            pass
        elif not peers.have_mujoco():
            print("MuJoCo not measured: mujoco is not installed (its columns stay empty)")
        else:
            mj_harness, why = harnesses.build_mujoco_harness(tmp / "mujoco")
            if mj_harness is None:
                print(f"MuJoCo not measured: {why}")
        for kind in kinds:
            figures, cms = {}, {}
            for f in FORMULATIONS:
                out = tmp / f"{kind}_{f}"
                figures[f] = generate_in_child(kind, f, out)
                cms[f] = compiled(kind, f, out)
                fg = figures[f]
                n = fg["n"]
                s = fg["seconds"]
                gen_rows.append([kind, f, f"{s['derive']:.2f}", f"{s['cse']:.2f}",
                                 f"{s['emit']:.2f}", f"{s['compile']:.2f}", f"{fg['wall']:.2f}",
                                 f"{fg['rss_mb']:.0f}", str(fg["ops"]["before_cse"]),
                                 str(fg["ops"]["after_cse"]),
                                 f"{fg['ops']['before_cse'] / n:.0f}",
                                 f"{fg['ops']['after_cse'] / n:.0f}"])
            n = figures["aba"]["n"]
            fwd, bwd = agreement(cms["crba"], cms["aba"], n)
            ref = reference_errors(model_spec(kind), cms) if args.reference else {}
            times = {f: None for f in FORMULATIONS}
            mj = mj_rel = None
            if not args.agreement_only:
                rng = np.random.default_rng(1)
                x0 = rng.uniform(-0.5, 0.5, 2 * n)
                exes = {f: harnesses.build_rhs_harness(cms[f], x0, tmp / f"h_{kind}_{f}")[0]
                        for f in FORMULATIONS}
                xml = None
                if mj_harness is not None:
                    params = cms["aba"].parameters
                    xml = tmp / f"chain_{kind}.xml"
                    if kind == "arm7":
                        links = peers.tree_links(model_spec(kind), params)
                        xml.write_text(peers.tree_mjcf("arm7", links, float(params["g"])))
                    else:
                        xml.write_text(peers.chain_mjcf(n, params))
                for _ in range(args.rounds):
                    for f in FORMULATIONS:
                        t = harnesses.run_model_harness(exes[f])
                        times[f] = t if times[f] is None else min(times[f], t)
                    if xml is not None:
                        t = harnesses.run_mj_harness(mj_harness, xml, x0)[0]
                        mj = t if mj is None else min(mj, t)
                if xml is not None:       # the peer timed is the peer checked
                    mj_rel = peers.mujoco_agreement(cms["aba"], [x0], xml)[0]
            run_rows.append([kind, fmt(times["crba"]), fmt(times["aba"]),
                             fmt(times["crba"] / times["aba"] if times["aba"] else None),
                             fmt(mj), fmt(mj / times["aba"] if mj and times["aba"] else None),
                             fmt(mj_rel, ".1e"),
                             f"{fwd:.1e}", f"{bwd:.1e}",
                             fmt(ref.get("crba"), ".1e"), fmt(ref.get("aba"), ".1e")])
            plan_rows.append(plan_row(kind))
            print(f"done {kind}", flush=True)
    print()
    print(markdown(["model", "formulation", "derive s", "cse s", "emit s", "compile s",
                    "total s", "RSS MB", "ops before", "ops after", "before/n",
                    "after/n"], gen_rows, left=2))
    print()
    print(markdown(["model", "crba rhs µs", "aba rhs µs", "crba/aba", "mj_forward µs",
                    "mj/aba", "mj rel", "aba-crba rel", "aba backward err", "crba err (mp)",
                    "aba err (mp)"], run_rows))
    print("\ncrba/aba, mj/aba: time over the ABA rhs's time (above 1: the ABA is faster); "
          "mj rel: MuJoCo's qacc against the ABA's q_ddot at the timed state; "
          "–: not measured")
    print()
    print("ABA rhs operations per coordinate, before / after CSE, by where the "
          "velocity-product accelerations go (o: outwards, in auto's plan)\n")
    print(markdown(["model", "inward (Table 7.1)", "outward (a_vp)", "auto",
                    "auto's plan"], plan_rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
