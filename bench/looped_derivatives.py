"""The derivatives' per-dof vectors as a loop over the links: a hand-written
prototype against modelgen's generated straight line, for issue 25's generation
targets.

Run from the repository root (valgrind for the instruction counts)::

    .venv/bin/python bench/looped_derivatives.py            # n = 20 and 50
    .venv/bin/python bench/looped_derivatives.py --n 20

Method
    ``<name>_derivative_terms_eval`` of ``spatial_chain(n)`` built with
    ``derivatives=True`` writes, for every dof, the 51 numbers of
    :data:`modelgen.derive.rnea_partials.VECTORS` (58 with the articulated-body
    factor above 30 dofs) into W, as one straight line of O(n) statements.
    ``prototypes/looped_derivatives/looped.c`` computes the same W by hand as a
    generator could emit it: a table of per-link constants filled from p once
    (what ``prepare`` does for the rhs), a forward kernel per joint signature
    (revolute about z, about y, and the root with the ground as parent), one
    backward kernel, called in loops over the links.  Both are compiled with
    the model's own part-4 command from the manifest; *looped, calls* keeps the
    kernels as functions, *looped, inlined* inlines them into the loops
    (``-DPROTO_INLINE``).  *agree*: the largest difference over all of W over
    the largest entry, at 10 random states (5 with random masses and lengths).
    *instr.*: callgrind, 200 calls minus none.  *compile s*: minimum of 3 runs
    of the compiler, the straight line's being the model's whole part 4 (with
    the dot products' loops, a few hundred lines).  *µs*: the driver's minimum
    over 15 repeats of 2,000 calls, unrolled and looped in one process.
    Prints the table; the ratios are looped / unrolled.
"""
from __future__ import annotations

import argparse
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import modelgen  # noqa: E402
from modelgen.bench.harnesses import instructions_per_call  # noqa: E402
from modelgen.codegen.build import compile_flags, compiler  # noqa: E402
from modelgen.model.chains import spatial_chain  # noqa: E402

PROTO = REPO / "bench" / "prototypes" / "looped_derivatives"
TRIG_END = "/* ---- end mg_sin, mg_cos ---- */"
VARIANTS = {"looped, calls": ["-DPROTO_ROOT", "-DPROTO_EARLY", "-DPROTO_NORESTRICT"],
            "looped, inlined": ["-DPROTO_ROOT", "-DPROTO_EARLY", "-DPROTO_NORESTRICT",
                                "-DPROTO_INLINE"]}


def compile_seconds(cmd, rounds: int = 3) -> float:
    """The minimum wall time of ``rounds`` runs of the compile command ``cmd``."""
    best = float("inf")
    for _ in range(rounds):
        start = time.perf_counter()
        subprocess.run(cmd, check=True)
        best = min(best, time.perf_counter() - start)
    return best


def part4_flags(cm) -> list:
    """The model's part-4 compile command without its source and output."""
    command = next(c for c in cm.manifest["compile_commands"] if "-DMG_PART=4" in c)
    args = shlex.split(command)
    out = args.index("-o")
    del args[out:out + 2]
    return [a for a in args if not a.endswith(".c") and a != "-c"]


def build(n: int, work: Path, rounds: int = 3) -> tuple:
    """Generate the n-link chain into ``work`` and compile its straight line
    (``rounds`` times); returns (the model, the compile command's prefix, the
    straight line's object, its compile s)."""
    gen = work / f"gen{n}"
    cm = modelgen.load(spatial_chain(n).spec(), gen, derivatives=True, force=True)
    source = gen / f"{cm.name}.c"
    text = source.read_text()
    (work / "mgtrig.h").write_text(text[:text.index(TRIG_END) + len(TRIG_END)] + "\n")
    command = part4_flags(cm) + [f"-I{work}", f"-I{gen}"]
    wrap = work / f"wrap{n}.c"
    wrap.write_text(f'#include "{source}"\n'
                    "void gen_eval(const double *x, const double *p, const double *a, "
                    "double *W)\n{\n"
                    f"    {cm.name}_derivative_terms_eval(0.0, x, 0, p, a, W);\n}}\n")
    wrap_o = work / f"wrap{n}.o"
    seconds = compile_seconds([*command, "-c", str(wrap), "-o", str(wrap_o)], rounds)
    return cm, command, wrap_o, seconds


def driver(n: int, work: Path, command, wrap_o: Path, defines, rounds: int = 3) -> tuple:
    """Compile the prototype with ``defines`` and link it with the straight line
    into the driver; returns (the driver, the prototype's compile s)."""
    obj, exe = work / f"looped{n}.o", work / f"driver{n}"
    # a few hundred statements: the flags modelgen gives a part of that size
    small = [*compiler(), *compile_flags(600, 4, host=True), *command[-2:]]
    seconds = compile_seconds([*small, *defines, f"-DN={n}", "-c", str(PROTO / "looped.c"),
                               "-o", str(obj)], rounds)
    subprocess.run([command[0], "-O2", "-std=gnu99", f"-DN={n}", str(PROTO / "driver.c"),
                    str(wrap_o), str(obj), "-lm", "-o", str(exe)], check=True)
    return exe, seconds


def agreement(exe: Path) -> float:
    """The driver's worst difference of W over the largest entry."""
    check = subprocess.run([str(exe), "check"], capture_output=True, text=True)
    return float(check.stdout.split("worst ratio")[1].split()[0])


def measure(n: int, work: Path) -> list:
    """The table's rows for the n-link chain."""
    _, command, wrap_o, unrolled_s = build(n, work)
    rows = []
    for variant, defines in VARIANTS.items():
        exe, looped_s = driver(n, work, command, wrap_o, defines)
        agree = agreement(exe)
        if not agree <= 1e-12:
            raise SystemExit(f"n = {n}, {variant}: W differs, {agree:.1e}")
        instr = {mode: instructions_per_call([str(exe), mode], 200)
                 for mode in ("gen", "proto")}
        timed = subprocess.run([str(exe), "time", "2000"], capture_output=True, text=True,
                               check=True).stdout.split("\n")
        us = {line.split(":")[0]: float(line.split()[1]) for line in timed if "us/call" in line}
        rows.append({"n": n, "variant": variant, "agree": agree, "instr": instr,
                     "compile": (unrolled_s, looped_s), "us": (us["unrolled"], us["looped"])})
    return rows


def table(rows) -> str:
    def num(x, fmt):
        return "–" if x is None else format(x, fmt)
    lines = ["| n | form | instr. unrolled | instr. looped | looped / unrolled | "
             "compile s unrolled / looped | µs unrolled / looped | agree |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        g, p = r["instr"]["gen"], r["instr"]["proto"]
        ratio = p / g if g and p else None
        lines.append(f"| {r['n']} | {r['variant']} | {num(g, ',.0f')} | {num(p, ',.0f')} | "
                     f"{num(ratio, '.3f')} | {r['compile'][0]:.2f} / {r['compile'][1]:.2f} | "
                     f"{r['us'][0]:.2f} / {r['us'][1]:.2f} | {r['agree']:.1e} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, nargs="+", default=[20, 50], help="chain sizes")
    args = parser.parse_args(argv)
    if shutil.which("cc") is None:
        raise SystemExit("no C compiler (cc) on PATH")
    with tempfile.TemporaryDirectory() as tmp:
        rows = [row for n in args.n for row in measure(n, Path(tmp))]
    print(table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
