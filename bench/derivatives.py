"""Analytical derivatives in C: modelgen's ``<name>_derivatives`` against Pinocchio's
``computeABADerivatives``.

Run from the repository root (needs the ``bench`` extra: ``pin`` and ``cmeel-eigen``;
valgrind for the instruction counts)::

    .venv/bin/python bench/derivatives.py                  # chain n = 7 and arm7
    .venv/bin/python bench/derivatives.py --n 7 20 50 --rounds 5
    .venv/bin/python bench/derivatives.py --quick          # n = 7, no arm7, one round
    .venv/bin/python bench/derivatives.py --n 100 --no-arm --max-operations 400000

Method
    The models are the spatial chain of ``spatial_chain(n)`` and ``models/arm7.yaml``,
    written for Pinocchio by ``modelgen.bench.peers.write_peer_models`` (as
    ``bench/codegen_scaling.py`` does), at the state x0 of that script (seed
    1000 + n) and zero inputs.  Both compute d qdd / d q and d qdd / d v of forward
    dynamics (modelgen also d qdd / d u when the model has inputs):
    ``<name>_derivatives`` through ``harness/model_bench.c -DMG_DERIVATIVES``, and
    ``computeABADerivatives(q, v, tau)`` through ``harness/pinocchio_bench.cpp``'s
    mode 3 (C++ ``-O3 -march=native``).  Time: each harness calls its function in a
    loop, perturbing one entry of x from the previous call's derivatives (a
    dependency chain), minimum over 5 repeats of >= 0.2 s; the two harnesses run
    alternately ``--rounds`` times and the minimum is kept.  Instructions: callgrind,
    K = 200 calls minus K = 0 (``harnesses.instructions_per_call``), Pinocchio in
    its build without AVX-512.  *agree*: the largest difference over the largest
    entry, of both matrices, ``cm.derivatives`` at x0 against Pinocchio's.
    Generation: wall and CPU seconds (the process and its compilers) and peak RSS of
    ``modelgen.load(..., derivatives=True, force=True)`` in a fresh process, started
    before this one imports numpy or the library, so that its ``ru_maxrss`` is its
    own.  ``--max-operations`` raises the build budget of every generation (a
    100-link chain with its derivatives is over the default 250,000).  *ops / n^2*:
    operations after CSE of the ``derivative_terms`` routine over n^2 (for a joint
    tree the per-dof vectors and the effects, O(n): the O(n^2) dot products are a
    loop in the C and not counted).  Prints the table, then the issue's targets
    (issue 25) with met / NOT met.
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
# numpy and modelgen are imported inside the functions: the generation children
# are started before the parent has loaded them (see the docstring).

ARM = REPO / "models" / "arm7.yaml"
GENERATE_MARK = "@@derivatives@@ "
#: the issue's targets: instructions and time, Pinocchio / modelgen; generation s
TARGET_INSTR = 2.0
TARGET_TIME = 1.5
TARGET_SECONDS = {20: 3.0, 100: 30.0}


def model_spec(arg: str):
    """The chain ``spatial_chain(int(arg))`` or the model file ``arg``."""
    from modelgen.model.api import load_model
    from modelgen.model.chains import spatial_chain
    return load_model(arg) if arg.endswith(".yaml") else spatial_chain(int(arg)).spec()


def generate_child(arg: str, out: str, budget: str = "") -> None:
    """The fresh process: generate ``arg`` with its derivatives into ``out`` (with the
    build budget ``budget`` if not empty) and print the figures of the docstring's
    *Generation* as a marked JSON line."""
    import modelgen
    spec = model_spec(arg)
    wall, cpu = time.perf_counter(), time.process_time()
    cm = modelgen.load(spec, out, derivatives=True, force=True,
                       max_operations=int(budget) if budget else None)
    wall = time.perf_counter() - wall
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    mb = max(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, kids.ru_maxrss) / 1024
    print(GENERATE_MARK + json.dumps({
        "wall": wall, "cpu": time.process_time() - cpu + kids.ru_utime + kids.ru_stime,
        "mb": mb, "ops": cm.manifest["ops"]["derivative_terms"]["after_cse"]}))


def generate(arg: str, out: Path, budget=None) -> dict:
    """Run :func:`generate_child` in a fresh interpreter; its figures."""
    proc = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--generate", arg,
                           str(out), str(budget or "")], capture_output=True, text=True)
    for line in proc.stdout.splitlines():
        if line.startswith(GENERATE_MARK):
            return json.loads(line[len(GENERATE_MARK):])
    raise RuntimeError(f"generating {arg} failed (exit {proc.returncode}):\n"
                       f"{proc.stdout}{proc.stderr}")


def measure(arg: str, gen: dict, work: Path, pin, pin_count, rounds: int,
            count: bool, budget=None) -> dict:
    """One model: time, count and compare both sides (the row of the table).  ``pin``,
    ``pin_count``: Pinocchio's harness and its build for callgrind, or None."""
    import numpy as np

    import modelgen
    from modelgen.bench import harnesses as hn
    from modelgen.bench import peers
    spec = model_spec(arg)
    cm = modelgen.load(spec, work / "model", derivatives=True,      # generate()'s build
                       max_operations=budget)
    n = cm.n
    rng = np.random.default_rng(1000 + n)                 # codegen_scaling's x0
    x0 = np.concatenate([rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n)])
    exe, _ = hn.build_model_harness(cm, x0, work / "harness", "derivatives")
    files = peers.write_peer_models(spec, cm, x0, work / "peers", not arg.endswith(".yaml"))
    tree = files[1] if files else None
    runs = {"mg": lambda: hn.run_model_harness(exe)}
    if pin and tree:
        runs["pin"] = lambda: hn.run_pinocchio_derivatives(pin, tree)
    times = hn.alternate(rounds, runs)
    row = {"model": cm.name, "n": n, "gen": gen, "ops_n2": gen["ops"] / n / n,
           "mg_us": min(times["mg"]), "pin_us": None, "agree": None,
           "mg_i": hn.instructions_per_call([str(exe)]) if count else None, "pin_i": None}
    if "pin" in times:
        d = cm.derivatives(0.0, x0)
        _, pin_dq, pin_dv = times["pin"][-1]
        row["pin_us"] = min(t for t, _, _ in times["pin"])
        row["agree"] = max(float(np.max(np.abs(got - want)) / np.max(np.abs(got)))
                           for got, want in ((d.dqdd_dq, pin_dq), (d.dqdd_dv, pin_dv)))
        if count and pin_count:
            row["pin_i"] = hn.instructions_per_call([str(pin_count), str(tree), "3"])
    return row


def ratio(a, b):
    return a / b if a and b else None


def table(rows) -> str:
    from modelgen.bench.tables import fmt, markdown
    head = ["model", "n", "generate s (wall / CPU)", "peak MB", "ops / n^2",
            "modelgen instr.", "Pinocchio instr.", "Pinocchio / modelgen (instr.)",
            "modelgen µs", "Pinocchio µs", "Pinocchio / modelgen (time)", "agree"]
    body = [[r["model"], r["n"], f"{r['gen']['wall']:.1f} / {r['gen']['cpu']:.1f}",
             f"{r['gen']['mb']:.0f}", f"{r['ops_n2']:.0f}", fmt(r["mg_i"], ",.0f"),
             fmt(r["pin_i"], ",.0f"), fmt(ratio(r["pin_i"], r["mg_i"]), ".2f"),
             f"{r['mg_us']:.2f}", fmt(r["pin_us"], ".2f"),
             fmt(ratio(r["pin_us"], r["mg_us"]), ".2f"), fmt(r["agree"], ".1e")]
            for r in rows]
    return markdown(head, body)


def goals(rows) -> list:
    """The issue's targets against this run's rows, each with met / NOT met."""
    def verdict(ok):
        return "met" if ok else "NOT met"
    lines = []
    for r in rows:
        instr, speed = ratio(r["pin_i"], r["mg_i"]), ratio(r["pin_us"], r["mg_us"])
        if instr is not None:
            lines.append(f"{r['model']}: {instr:.2f}x fewer instructions than "
                         f"computeABADerivatives (target >= {TARGET_INSTR}): "
                         + verdict(instr >= TARGET_INSTR))
        if speed is not None:
            lines.append(f"{r['model']}: {speed:.2f}x faster than computeABADerivatives "
                         f"(target >= {TARGET_TIME}): " + verdict(speed >= TARGET_TIME))
        if r["agree"] is not None:
            lines.append(f"{r['model']}: agreement {r['agree']:.1e} (target <= 1e-9): "
                         + verdict(r["agree"] <= 1e-9))
        if r["n"] in TARGET_SECONDS and r["model"].startswith("spatial_chain"):
            limit = TARGET_SECONDS[r["n"]]
            lines.append(f"{r['model']}: generation {r['gen']['cpu']:.1f} s CPU (target <= "
                         f"{limit} s): " + verdict(r["gen"]["cpu"] <= limit))
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, nargs="+", default=[7], help="chain sizes")
    parser.add_argument("--arm", default=str(ARM), help="a model file measured as well")
    parser.add_argument("--no-arm", action="store_true")
    parser.add_argument("--rounds", type=int, default=3, help="alternated timing rounds")
    parser.add_argument("--no-count", action="store_true", help="skip callgrind")
    parser.add_argument("--quick", action="store_true", help="n = 7 only, one round")
    parser.add_argument("--max-operations", type=int, default=None,
                        help="build budget of the generations (default: the library's)")
    parser.add_argument("--generate", nargs=3, metavar=("MODEL", "OUT", "BUDGET"),
                        help=argparse.SUPPRESS)     # the fresh process of generate()
    args = parser.parse_args(argv)
    if args.generate:
        generate_child(*args.generate)
        return 0
    if args.quick:
        args.n, args.no_arm, args.rounds = [7], True, 1
    cases = [str(n) for n in args.n] + ([] if args.no_arm else [args.arm])
    loadavg = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        # every generation first, while this process is still small
        gens = [generate(arg, root / f"case{k}" / "model", args.max_operations)
                for k, arg in enumerate(cases)]
        from modelgen.bench import harnesses as hn
        pin, why = hn.build_pinocchio_harness(root / "pin")
        notes = [f"Pinocchio not measured: {why}"] if pin is None else []
        count = not args.no_count and shutil.which("valgrind") is not None
        if not args.no_count and not count:
            notes.append("valgrind not found: no instruction counts")
        pin_count = None
        if count and pin is not None:
            pin_count, why = hn.build_pinocchio_harness(root / "pin", count=True)
            if pin_count is None:
                notes.append(f"Pinocchio's instructions not counted: {why}")
        rows = [measure(arg, gen, root / f"case{k}", pin, pin_count, args.rounds, count,
                        args.max_operations)
                for k, (arg, gen) in enumerate(zip(cases, gens, strict=True))]
    env = hn.environment()
    print(f"{env['cpu']}, {env['cores']} cores, {env['compiler']}; load average "
          f"{loadavg:.2f} at start\n")
    print(table(rows))
    print()
    for line in [*goals(rows), *notes]:
        print("- " + line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
