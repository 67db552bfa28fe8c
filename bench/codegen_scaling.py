"""How modelgen scales with the size of a model, and how it compares with MuJoCo.

Run from the repository root::

    .venv/bin/python bench/codegen_scaling.py            # n = 2 4 7 10 15 20 30 50
    .venv/bin/python bench/codegen_scaling.py --quick    # n = 2 4 7 10
    .venv/bin/python bench/codegen_scaling.py --n 2 4 7 --json out.json

Model
    ``modelgen.model.chains.spatial_chain(n)``: n uniform rods hanging from the
    origin, hinge axes alternating z (odd joints) and y (even joints).  If
    ``models/arm7.yaml`` exists (``--arm``), the 7-joint arm gets a row too; it is the
    official target of the per-call goals.  A model file that is a tree of revolute
    joints with gravity (0, 0, -g) and no effects (actions only through inputs, which
    the harnesses hold at 0), like the arm, is also timed in MuJoCo and Pinocchio,
    written for them by :mod:`modelgen.bench.peers` from modelgen's joint tree.

Method
    * Generation.  Every model is generated in a fresh subprocess (memory per model)
      into a temporary directory, with ``modelgen.load(spec, out_dir, force=True)``:
      derive, CSE, emit and compile are modelgen's own stage timers
      (``manifest["seconds"]``); *total* is the wall time from the ModelSpec to a
      loaded ``CompiledModel`` (also hashing, import of the extension and the
      mass-matrix check; the difference is *other*).  The child's import of modelgen
      (with sympy and numpy; *import*) and the building of the spec are not in
      *total*.  Peak RSS: the child's own VmHWM just after loading (:func:`peak_rss_mb`;
      the Python side) and ``RUSAGE_CHILDREN`` (the largest compiler process).  A
      2-link build in a process of its own comes first and is not shown: it makes
      the runtime every build shares (the integrators and the loader's module,
      compiled once per build cache), which would otherwise land in the first
      row's *compile*.
    * Operation counts are modelgen's counts for the ``rhs`` routine (the mass matrix
      A and b = tau - h, or the ABA program) before and after CSE, as C operators
      (:func:`modelgen.codegen.printer.c_operations`); after CSE without the
      parameter-only statements ``<name>_prepare`` computes.  They do not include the
      Cholesky solve that ``<name>_rhs`` runs on A in a C loop (about n^3/6
      multiply-adds).  Exponent: least squares of log(ops) on log(n) over the chains
      run; *local*: the slope between the two largest n (closer to the asymptotic).
    * rhs in C: ``modelgen/bench/harness/model_bench.c`` (-O2), linked with
      ``<name>.c`` compiled by the exact command of modelgen's build (the manifest's
      ``compile_commands``), calls ``<name>_prepare`` once and ``<name>_rhs_prepared``
      in a loop (as an integration does; the peers too keep their inertias
      precomputed), perturbing one entry of x from the previous output (no hoisting; a
      dependency chain); min per-call time over 5 repeats of >= 0.2 s.  The three
      engines' harnesses run alternately ``--rounds`` times (default 3), minimum of
      each kept, so a busy spell of a shared machine hits every side.
    * rhs from Python: ``f.inplace(t)`` (state in ``f.x``), ``f(t, x, out)`` (``f =
      cm.rhs_function()``) and ``cm.rhs(t, x)``; ``timeit``, the same 5 x 0.2 s rule.
    * MuJoCo: the identical model in MJCF (:func:`modelgen.bench.peers.chain_mjcf`).
      Agreement: at 5 seeded random states, ``qacc`` after ``mj_forward`` against
      modelgen's qdd, max over states of ||qacc - qdd||_inf / ||qdd||_inf. Timing:
      ``harness/mujoco_bench.c`` against the wheel's libmujoco times ``mj_forward``
      (one rhs call) by the same rule, and ``mj_step`` with RK4 divided by 4 (four
      force evaluations per step; restart from x0 every 1000 steps).  *mj_forward py*
      is the call from a Python loop (binding overhead), timed instead (``py``) if the
      wheel's headers or library are not usable; without mujoco its columns are empty.
    * Pinocchio (``pin`` and ``cmeel-eigen``, the ``bench`` extra):
      ``harness/pinocchio_bench.cpp`` (``-O3 -march=native``) builds the same model and
      times ``pinocchio::aba`` and the CRBA path (``crba`` + ``nonLinearEffects`` +
      the tree-sparse ``cholesky::decompose/solve``) by the same rule.  *agree (4
      engines)*: q_ddot at x0 by modelgen, MuJoCo, Pinocchio ABA and CRBA, the largest
      pairwise max-norm difference over max |q_ddot|.
    * Instructions (unless ``--no-count``; valgrind): the same loops, run K = 200 times
      and not at all under callgrind; the difference over K is the instructions per
      call, whatever the load, harness loop included (alike for the three engines).
      Pinocchio is counted in a build with ``-mno-avx512f`` (valgrind lacks AVX-512).

Reading the tables
    Times in seconds (generation) or microseconds (per call); RSS in MB. The header
    gives the 1-minute load average before the run: on a 2-core machine above ~0.5 the
    per-call times (and ratios near 1) are noisy; run it again when quiet.  *-O*: the
    optimisation levels of the two compiled parts of ``<name>.c`` (-O1 for big
    routines).  ``mj/mg``: mj_forward time over modelgen's rhs time, both in C (above
    1: modelgen is faster).  ``rel diff`` should be around 1e-9 or below (it grows
    with cond(A), roughly n^4 for these chains).  The goals state the measured value
    and whether it is met (``not run`` when the n it needs was not in this run).
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
# modelgen is imported inside the functions, not here: the child times its own
# import of modelgen and measures its memory before anything else is loaded.

DEFAULT_NS = (2, 4, 7, 10, 15, 20, 30, 50)
QUICK_NS = (2, 4, 7, 10)
RESULT_MARK = "@@codegen_scaling@@ "
N_CHECK_STATES = 5       # random states for the MuJoCo agreement check


def peak_rss_mb() -> float:
    """This process's own peak RSS in MB (VmHWM).  Not ru_maxrss: exec carries the
    parent's peak into it, and the parent has imported modelgen.bench."""
    status = Path("/proc/self/status")
    if status.is_file():
        return next(int(line.split()[1]) for line in status.read_text().splitlines()
                    if line.startswith("VmHWM:")) / 1024
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


# -- the child: one model, one fresh process ----------------------------------------

def child(kind: str, arg: str, work: str, rounds: int, count: bool, mujoco=None,
          pinocchio=None, pinocchio_count=None) -> dict:
    """Generate one model and measure it; returns the row as a dict.  ``mujoco``,
    ``pinocchio``, ``pinocchio_count``: the paths of ``harnesses.PeerHarnesses``;
    ``count``: also count each engine's instructions per call with callgrind."""
    loadavg = os.getloadavg()[0]
    t = time.perf_counter()
    import numpy as np

    import modelgen
    from modelgen.model.chains import spatial_chain
    from modelgen.model.api import load_model
    import_s = time.perf_counter() - t

    t = time.perf_counter()
    spec = spatial_chain(int(arg)).spec() if kind == "chain" else load_model(arg)
    spec_s = time.perf_counter() - t

    work = Path(work)
    t = time.perf_counter()
    cm = modelgen.load(spec, work / "model", force=True)
    total = time.perf_counter() - t
    rss_self = peak_rss_mb()
    rss_cc = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    from modelgen.bench import harnesses as hn
    from modelgen.bench import peers

    seconds, ops = cm.manifest["seconds"], cm.manifest["ops"]["rhs"]
    row = {"kind": kind, "model": cm.name, "n": cm.n, "import_s": import_s, "spec_s": spec_s,
           "loadavg_before": loadavg,
           **{f"{k}_s": v for k, v in seconds.items()}, "total_s": total,
           "other_s": total - sum(seconds.values()),
           "rss_py_mb": rss_self, "rss_cc_mb": rss_cc,
           "ops_before": ops["before_cse"], "ops_after": ops["after_cse"],
           "statements": ops["statements"],
           "compile_flags": sorted({c.split()[1] for c in cm.manifest.get("compile_commands",
                                                                           [])})}

    rng = np.random.default_rng(1000 + cm.n)
    states = [np.concatenate([rng.uniform(-np.pi, np.pi, cm.n), rng.uniform(-2, 2, cm.n)])
              for _ in range(N_CHECK_STATES)]
    x0 = states[0]
    rhs_exe, row["rhs_compile_command"] = hn.build_rhs_harness(cm, x0, work / "harness")

    f, out, xp = cm.rhs_function(), np.empty(2 * cm.n), x0.copy()
    row["rhs_py_fast_us"] = hn.per_call_python("f(0.0, x, out)", {"f": f, "x": xp, "out": out})
    f.x[:] = x0
    row["rhs_py_inplace_us"] = hn.per_call_python("inplace(0.0)", {"inplace": f.inplace})
    row["rhs_py_plain_us"] = hn.per_call_python("rhs(0.0, x)", {"rhs": cm.rhs, "x": xp})

    # a model file is timed against the peers when it is a tree of revolute joints
    # with gravity only (motor inputs are 0 in the harnesses)
    files = peers.write_peer_models(spec, cm, x0, work, kind == "chain")
    xml_path = files[0] if files and peers.have_mujoco() else None
    if xml_path is not None:
        from mujoco import __version__ as mujoco_version, mj_forward
        worst, qacc_x0, model, data = peers.mujoco_agreement(cm, states, xml_path)
        row.update(mujoco_version=mujoco_version, mj_rel_diff=worst, mj_qacc_x0=qacc_x0,
                   mj_forward_py_us=hn.per_call_python("mj_forward(m, d)", {
                       "mj_forward": mj_forward, "m": model, "d": data}))
    pinocchio, pin_file = (pinocchio, files[1]) if files else (None, None)

    # The C timings, alternating modelgen, MuJoCo and Pinocchio
    runs = {"mg": lambda: hn.run_model_harness(rhs_exe)}
    if xml_path is not None and mujoco:
        runs["mj"] = lambda: hn.run_mj_harness(Path(mujoco), xml_path, x0)
    if pinocchio:
        runs["pin"] = lambda: hn.run_pinocchio_harness(Path(pinocchio), pin_file)
    times = hn.alternate(rounds, runs)
    rhs_c = times["mg"]
    if pinocchio:
        pin_aba, pin_crba, qdd_aba, qdd_crba = zip(*times["pin"], strict=True)
        # q_ddot at x0 by the four engines
        engines = {"modelgen": cm.rhs(0.0, x0)[cm.n:], "pin_aba": qdd_aba[-1],
                   "pin_crba": qdd_crba[-1]}
        if "mj_qacc_x0" in row:
            engines["mujoco"] = np.array(row["mj_qacc_x0"])
        row["agreement_4"] = peers.agreement(engines)
        scale = max(float(np.max(np.abs(v))) for v in engines.values())
        row["pin_vs_mg"] = float(np.max(np.abs(engines["pin_aba"] - engines["modelgen"])) / scale)
        row.update(pin_aba_us=min(pin_aba), pin_crba_us=min(pin_crba),
                   pin_over_mg=min(pin_aba) / min(rhs_c))
    row["rhs_c_us"], row["rhs_c_us_rounds"] = min(rhs_c), rhs_c
    if xml_path is not None:
        if "mj" in times:
            forward, step, bad = zip(*times["mj"], strict=True)
            row.update(mj_forward_us=min(forward), mj_step4_us=min(step), mj_timing="C",
                       mj_forward_us_rounds=list(forward), mj_badqacc_warnings=sum(bad))
        else:
            row.update(mj_forward_us=row["mj_forward_py_us"], mj_step4_us=None,
                       mj_timing="py")
        row["mj_over_mg"] = row["mj_forward_us"] / row["rhs_c_us"]
    if count and shutil.which("valgrind"):
        instr = {"mg": hn.rhs_instructions(cm, x0, work / "count")}
        if xml_path is not None and mujoco:
            instr["mj_forward"] = hn.instructions_per_call(
                [str(mujoco), str(xml_path), str(xml_path.with_suffix(".state"))])
        for which, key in ((0, "pin_aba"), (1, "pin_crba")) if pin_file and pinocchio_count else ():
            instr[key] = hn.instructions_per_call([pinocchio_count, str(pin_file), str(which)])
        row["instructions"] = instr
    return row


# -- the parent: run the children, fit, print --------------------------------------

def run_one(job: dict, timeout) -> dict:
    """Run :func:`child` (``job``: its arguments) in a fresh interpreter; a failure
    becomes an ``error`` row."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", json.dumps(job)]
    start = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"kind": job["kind"], "arg": job["arg"], "error": f"timed out after {timeout} s"}
    wall = time.perf_counter() - start
    for line in proc.stdout.splitlines():
        if line.startswith(RESULT_MARK):
            return dict(json.loads(line[len(RESULT_MARK):]), child_wall_s=wall)
    tail = (proc.stderr or proc.stdout).strip().splitlines()[-15:]
    return {"kind": job["kind"], "arg": job["arg"],
            "error": f"exit {proc.returncode}: " + "\n".join(tail)}


def warm_up(out: Path) -> None:
    """Build a 2-link chain in a fresh process: the shared runtime, once per cache."""
    code = ("import modelgen; from modelgen.model.chains import spatial_chain; "
            f"modelgen.load(spatial_chain(2).spec(), {str(out)!r}, force=True)")
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)


def fit_exponent(ns, values):
    """Least-squares slope of log(values) against log(ns), or None."""
    import numpy as np
    if len(ns) < 2:
        return None
    return float(np.polyfit(np.log(ns), np.log(values), 1)[0])


def label(row) -> str:
    return str(row["n"]) if row.get("kind") == "chain" else f"{row['model']} ({row['n']})"


def generation_table(rows) -> str:
    from modelgen.bench.tables import fmt, markdown
    headers = ["n", "import s", "derive s", "CSE s", "emit s", "compile s", "other s",
               "**total s**", "RSS py MB", "RSS cc MB", "ops before", "ops after", "stmts", "-O"]
    body = []
    for r in rows:
        if "error" in r:
            body.append([r.get("arg"), "**failed**"] + [""] * (len(headers) - 2))
            continue
        body.append([label(r), fmt(r["import_s"]), fmt(r["derive_s"]), fmt(r["cse_s"]),
                     fmt(r["emit_s"]), fmt(r["compile_s"]), fmt(r["other_s"]),
                     f"**{fmt(r['total_s'])}**",
                     fmt(r["rss_py_mb"], ".0f"), fmt(r["rss_cc_mb"], ".0f"),
                     r["ops_before"], r["ops_after"], r["statements"],
                     "/".join(f.lstrip("-") for f in r["compile_flags"])])
    return markdown(headers, body)


def runtime_table(rows, with_mujoco) -> str:
    from modelgen.bench.tables import fmt, markdown
    headers = ["n", "rhs C µs", "py f.inplace µs", "py f(t,x,out) µs", "py cm.rhs µs"]
    if with_mujoco:
        headers += ["mj_forward µs", "mj_step/4 µs", "mj_forward py µs", "**mj/mg**",
                    "rel diff"]
    with_pin = any("pin_aba_us" in r for r in rows)
    if with_pin:
        headers += ["pin ABA µs", "pin CRBA+chol µs", "**pin/mg**", "agree (4 engines)",
                    "mg vs pin ABA"]
    body = []
    for r in rows:
        if "error" in r:
            continue
        line = [label(r), fmt(r["rhs_c_us"]), fmt(r.get("rhs_py_inplace_us")),
                fmt(r["rhs_py_fast_us"]), fmt(r["rhs_py_plain_us"])]
        if with_mujoco:
            if "mj_forward_us" in r:
                mark = "" if r["mj_timing"] == "C" else " (py)"
                line += [fmt(r["mj_forward_us"]) + mark, fmt(r["mj_step4_us"]),
                         fmt(r["mj_forward_py_us"]), f"**{fmt(r['mj_over_mg'])}**",
                         fmt(r["mj_rel_diff"], ".1e")]
            else:
                line += ["–"] * 5
        if with_pin:
            if "pin_aba_us" in r:
                line += [fmt(r["pin_aba_us"]), fmt(r["pin_crba_us"]),
                         f"**{fmt(r['pin_over_mg'])}**", fmt(r["agreement_4"], ".1e"),
                         fmt(r["pin_vs_mg"], ".1e")]
            else:
                line += ["–"] * 5
        body.append(line)
    return markdown(headers, body)


def instructions_table(rows) -> str:
    """Instructions per forward-dynamics call of each engine, and the ratios to modelgen."""
    from modelgen.bench.tables import fmt, markdown
    headers = ["n", "modelgen rhs", "mj_forward", "pin ABA", "pin CRBA+chol", "**mj/mg**",
               "**pin ABA/mg**"]
    body = []
    for r in rows:
        c = r.get("instructions")
        if not c:
            continue
        mg = c["mg"]
        body.append([label(r), fmt(mg, ",.0f"), fmt(c.get("mj_forward"), ",.0f"),
                     fmt(c.get("pin_aba"), ",.0f"), fmt(c.get("pin_crba"), ",.0f"),
                     f"**{fmt(c['mj_forward'] / mg if 'mj_forward' in c else None)}**",
                     f"**{fmt(c['pin_aba'] / mg if 'pin_aba' in c else None)}**"])
    return markdown(headers, body)


def goals(rows) -> list:
    """[(goal, measured, verdict)] for the goals of the issue."""
    chain = {r["n"]: r for r in rows if r.get("kind") == "chain" and "error" not in r}
    failed = {int(r["arg"]) for r in rows if r.get("kind") == "chain" and "error" in r}
    arms = [r for r in rows if r.get("kind") == "file" and "error" not in r]
    arm = arms[0] if arms else None
    out = []

    def verdict(ok):
        return "met" if ok else "**NOT met**"

    def by_n(n, goal, measure, test):
        if n in chain:
            value = measure(chain[n])
            out.append((goal, value[0], verdict(test(*value[1:]))))
        elif n in failed:
            out.append((goal, "failed", "**NOT met**"))
        else:
            out.append((goal, "n not run", "not run"))

    def cost(r):
        return (f"{r['total_s']:.2f} s, {r['rss_py_mb'] + r['rss_cc_mb']:.0f} MB",
                r["total_s"], r["rss_py_mb"] + r["rss_cc_mb"])

    by_n(10, "n=10: model to importable module ≤ 3 s",
         lambda r: (f"{r['total_s']:.2f} s", r["total_s"]), lambda t: t <= 3)
    by_n(30, "n=30: ≤ 15 s and ≤ 1 GB (python + largest compiler RSS)", cost,
         lambda t, mb: t <= 15 and mb <= 1024)
    by_n(50, "n=50 completes", lambda r: (f"{r['total_s']:.2f} s",), lambda: True)

    def per_call_goal(goal, key, limit):
        if arm is not None:
            out.append((goal + f" [{arm['model']}]", f"{arm[key]:.3g} µs",
                        verdict(arm[key] <= limit)))
        if 7 in chain:
            note = "chain n=7" + ("" if arm is not None else "; proxy, arm7.yaml not found")
            out.append((goal + f" [{note}]", f"{chain[7][key]:.3g} µs",
                        verdict(chain[7][key] <= limit)))
        elif arm is None:
            out.append((goal, "neither arm7 nor n=7 run", "not run"))

    per_call_goal("7-dof rhs in C ≤ 0.28 µs", "rhs_c_us", 0.28)

    # issue 10 (fast at every size): ratios to the peers in the same run, C against C
    def ratio_goal(label, r, need):
        for key, peer, floor in (("mj_over_mg", "MuJoCo mj_forward", need[0]),
                                 ("pin_over_mg", "Pinocchio ABA", need[1])):
            goal = f"{label}: ≥ {floor:g}× {peer}"
            if r is None:
                out.append((goal, "not run", "not run"))
            elif key not in r:
                out.append((goal, f"{peer} not available", "not run"))
            else:
                out.append((goal, f"{r[key]:.3g}×", verdict(r[key] >= floor)))

    ratio_goal(arm["model"] if arm is not None else "arm7", arm, (4, 5))
    for n in (20, 50, 100):
        ratio_goal(f"n={n}", chain.get(n), (2, 2))
    by_n(100, "n=100: generation ≤ 30 s and ≤ 1 GB (python + largest compiler RSS)", cost,
         lambda t, mb: t <= 30 and mb <= 1024)
    if chain:
        n = max(chain)
        per = chain[n]["ops_after"] / n
        out.append((f"rhs operations per coordinate after CSE ≤ 250 (largest n run, {n})",
                    f"{per:.1f}", verdict(per <= 250)))
    agreements = [r["agreement_4"] for r in [*chain.values(), *arms] if "agreement_4" in r]
    if agreements:
        out.append(("q̈ agreement of the 4 engines ≤ 1e-10 (worst model)",
                    f"{max(agreements):.1e}", verdict(max(agreements) <= 1e-10)))
    per_call_goal("Python low-overhead call (f.inplace) ≤ 1 µs", "rhs_py_inplace_us", 1.0)
    return out


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, nargs="+", metavar="N",
                        help=f"chain sizes (default {' '.join(map(str, DEFAULT_NS))})")
    parser.add_argument("--quick", action="store_true",
                        help=f"chain sizes {' '.join(map(str, QUICK_NS))}")
    parser.add_argument("--arm", default=str(REPO / "models" / "arm7.yaml"),
                        help="model file of the 7-joint arm, included if it exists "
                             "(default: models/arm7.yaml); '' to skip")
    parser.add_argument("--json", metavar="PATH", help="also save the results as JSON")
    parser.add_argument("--timeout", type=float, default=3600,
                        help="seconds allowed per model (default 3600)")
    parser.add_argument("--rounds", type=int, default=3,
                        help="alternating rounds of the C timings of modelgen, MuJoCo and "
                             "Pinocchio; the minimum is kept (default 3)")
    parser.add_argument("--no-count", action="store_true",
                        help="skip the callgrind instruction counts (they need valgrind)")
    parser.add_argument("--keep", action="store_true",
                        help="keep the temporary directory (its path is printed)")
    parser.add_argument("--child", help=argparse.SUPPRESS)    # a model's job, as JSON
    return parser.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.child:
        print(RESULT_MARK + json.dumps(child(**json.loads(args.child))), flush=True)
        return 0

    from modelgen.bench import harnesses as hn
    from modelgen.bench.peers import have_mujoco
    from modelgen.bench.tables import markdown
    ns = sorted(set(args.n or (QUICK_NS if args.quick else DEFAULT_NS)))
    env = hn.environment()
    mujoco_ok = have_mujoco()
    root = Path(tempfile.mkdtemp(prefix="modelgen-scaling-"))
    try:
        peer = hn.build_peer_harnesses(root, count=not args.no_count)
        notes = list(peer.notes)
        paths = {k: str(getattr(peer, k)) if getattr(peer, k) else None
                 for k in ("mujoco", "pinocchio", "pinocchio_count")}
        count = not args.no_count and shutil.which("valgrind") is not None
        jobs = [("chain", n) for n in ns]
        if args.arm and Path(args.arm).is_file():
            jobs.append(("file", str(Path(args.arm).resolve())))
        elif args.arm:
            notes.append(f"{args.arm} not found: per-call goals use chain n=7 as a proxy")
        print("... the shared runtime (a 2-link build, not timed)", file=sys.stderr, flush=True)
        warm_up(root / "warm-up")
        rows = []
        for kind, arg in jobs:
            print(f"... {kind} {arg}", file=sys.stderr, flush=True)
            work = root / (f"chain_{arg}" if kind == "chain" else Path(arg).stem)
            row = run_one(dict(kind=kind, arg=str(arg), work=str(work), rounds=args.rounds,
                               count=count, **paths), args.timeout)
            rows.append(row)
            if "error" in row:
                print(f"    FAILED: {row['error']}", file=sys.stderr, flush=True)
            else:
                print(f"    total {row['total_s']:.2f} s, rhs {row['rhs_c_us']:.3g} µs",
                      file=sys.stderr, flush=True)
    finally:
        if args.keep:
            print(f"kept {root}", file=sys.stderr)
        else:
            shutil.rmtree(root, ignore_errors=True)

    good = [r for r in rows if r.get("kind") == "chain" and "error" not in r]
    fits = {key: fit_exponent([r["n"] for r in good], [r[key] for r in good])
            for key in ("ops_before", "ops_after", "total_s", "rhs_c_us")}
    if len(good) >= 2:
        a, b = good[-2], good[-1]
        fits["ops_after_local"] = fit_exponent([a["n"], b["n"]], [a["ops_after"], b["ops_after"]])
    if any("mujoco_version" in r for r in rows):
        env["mujoco"] = next(r["mujoco_version"] for r in rows if "mujoco_version" in r)

    print("# modelgen code generation scaling: spatial chain\n")
    print(f"{env['cpu']}, {env['cores']} cores; {env['compiler']}; Python {env['python']}"
          + (f"; MuJoCo {env['mujoco']}" if "mujoco" in env else "")
          + f"; load average before the run {env['loadavg_at_start']:.2f}")
    print("\n## Model to importable module (fresh process per model)\n")
    print(generation_table(rows))
    print("\n## Per-call time of the right-hand side (one forward-dynamics evaluation)\n")
    print(runtime_table(rows, mujoco_ok))
    if any("instructions" in r for r in rows):
        print("\n## Instructions per call (callgrind: the same on every run, whatever the "
              "load)\n")
        print(instructions_table(rows))
    print("\n## Fitted exponents (least squares on log-log over the chains run)\n")
    for key, what in (("ops_before", "rhs ops before CSE"), ("ops_after", "rhs ops after CSE"),
                      ("ops_after_local", "rhs ops after CSE, last two n"),
                      ("total_s", "total generation time"), ("rhs_c_us", "rhs time in C")):
        if fits.get(key) is not None:
            print(f"- {what}: n^{fits[key]:.2f}")
    print("\n## Goals\n")
    print(markdown(["goal", "measured", "verdict"], goals(rows), left=3))
    for r in rows:
        if "error" in r:
            notes.append(f"{r['kind']} {r['arg']} failed: {r['error']}")
        elif r.get("mj_badqacc_warnings"):
            notes.append(f"n={r['n']}: MuJoCo reported bad qacc during mj_step timing")
    if notes:
        print("\nNotes:\n" + "\n".join(f"- {n}" for n in notes))

    if args.json:
        Path(args.json).write_text(json.dumps(
            {"environment": env, "ns": ns, "rows": rows, "fits": fits,
             "goals": [dict(zip(("goal", "measured", "verdict"), g, strict=True))
                       for g in goals(rows)], "notes": notes}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
