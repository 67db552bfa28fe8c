"""The derivatives' per-dof vectors looped over the joints (kernels per joint
signature, ``derive/link_kernels.py``) against one straight line, in one run.

Run from the repository root (valgrind for the instruction counts)::

    .venv/bin/python bench/looped_derivatives.py              # n = 20 and 50
    .venv/bin/python bench/looped_derivatives.py --n 20 50 100

Method
    ``spatial_chain(n)`` built with ``derivatives=True`` both ways
    (``modelgen.codegen.tree_derivatives.LOOPED`` True or False), each in a
    fresh process (after one of a 2-link chain, which builds the shared runtime):
    *generate* is its wall and CPU seconds (the process and its compilers) of
    ``modelgen.load(..., force=True)``; *part 4 s* the minimum of
    3 runs of the compile command of the part that holds the vectors (from the
    manifest).  ``<name>_derivatives`` at the state x0 of ``bench/derivatives.py``
    through ``harness/model_bench.c``: *instr.*, callgrind, 200 calls minus none;
    *µs*, the harness's minimum, the two forms alternating ``--rounds`` times
    and the minimum kept.  *agree*: the largest difference of d qdd / d q and
    d qdd / d v over their largest entry, looped against straight, at x0.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

CHILD = """
import json, resource, sys, time
start = time.perf_counter()
sys.path.insert(0, {repo!r})
import modelgen
from modelgen.codegen import tree_derivatives
from modelgen.model.chains import spatial_chain
tree_derivatives.LOOPED = {looped!r}
modelgen.load(spatial_chain({n}).spec(), {out!r}, derivatives=True, force=True)
me, kids = (resource.getrusage(w) for w in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
print(json.dumps({{"wall": time.perf_counter() - start,
                  "cpu": me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime}}))
"""


def generate(n: int, looped: bool, out: Path) -> dict:
    """Wall and CPU seconds of one fresh build, in a child process."""
    code = CHILD.format(repo=str(REPO), looped=looped, n=n, out=str(out))
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    if done.returncode:
        raise SystemExit(f"building the {n}-link chain (looped={looped}) failed:\n"
                         f"{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def part4_seconds(cm) -> float:
    """The minimum of 3 runs of the model's part-4 compile command."""
    from modelgen.bench.harnesses import command_seconds
    command = next(c for c in cm.manifest["compile_commands"] if "-DMG_PART=4" in c)
    return command_seconds(command, Path(cm.path).parent)


def measure(n: int, work: Path, rounds: int) -> list:
    """The table's two rows for the n-link chain."""
    import numpy as np

    import modelgen
    from modelgen.bench.harnesses import (build_model_harness, instructions_per_call,
                                          run_model_harness)
    rng = np.random.default_rng(1000 + n)
    x0 = np.concatenate([rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n)])
    rows = {}
    for looped in (True, False):
        out = work / f"{'looped' if looped else 'straight'}{n}"
        gen = generate(n, looped, out)
        cm = modelgen.load(_spec(n), out, derivatives=True)     # the child's build
        exe, _ = build_model_harness(cm, x0, out / "harness", "derivatives")
        rows[looped] = {"n": n, "form": "looped" if looped else "straight line", "gen": gen,
                        "part4": part4_seconds(cm), "exe": exe, "cm": cm,
                        "instr": instructions_per_call([str(exe)], 200), "us": float("inf")}
    for _ in range(rounds):
        for row in rows.values():
            row["us"] = min(row["us"], run_model_harness(row["exe"]))
    a, b = rows[True]["cm"].derivatives(0.0, x0), rows[False]["cm"].derivatives(0.0, x0)
    agree = max(float(np.max(np.abs(x - y)) / np.max(np.abs(y)))
                for x, y in zip(a[:2], b[:2], strict=True))
    for row in rows.values():
        row["agree"] = agree
    return [rows[True], rows[False]]


def _spec(n: int):
    from modelgen.model.chains import spatial_chain
    return spatial_chain(n).spec()


def table(rows) -> str:
    lines = ["| n | form | generate s (wall / CPU) | part 4 s | instr. | µs | agree |",
             "|---|---|---|---|---|---|---|"]
    for r in rows:
        instr = "–" if r["instr"] is None else f"{r['instr']:,.0f}"
        lines.append(f"| {r['n']} | {r['form']} | {r['gen']['wall']:.2f} / "
                     f"{r['gen']['cpu']:.2f} | {r['part4']:.2f} | {instr} | {r['us']:.2f} | "
                     f"{r['agree']:.1e} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, nargs="+", default=[20, 50], help="chain sizes")
    parser.add_argument("--rounds", type=int, default=3, help="alternating timing rounds")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        generate(2, True, Path(tmp) / "warm-up")     # the shared runtime, built once
        rows = [row for n in args.n for row in measure(n, Path(tmp), args.rounds)]
    print(table(rows))
    for n in args.n:
        looped, straight = (r for r in rows if r["n"] == n)
        if looped["instr"] and straight["instr"]:
            print(f"n = {n}: looped / straight line: instructions "
                  f"{looped['instr'] / straight['instr']:.3f}, time "
                  f"{looped['us'] / straight['us']:.3f}, generation CPU "
                  f"{looped['gen']['cpu'] / straight['gen']['cpu']:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
