"""What a build costs, in figures that do not move with the machine's load:
the compiler's instructions per part of the generated C, beside the seconds.

Run from the repository root (valgrind for the instruction counts)::

    .venv/bin/python bench/build_cost.py                    # the 20-link chain
    .venv/bin/python bench/build_cost.py 7 20 models/arm7.yaml --no-derivatives
    .venv/bin/python bench/build_cost.py 20 --python-instructions   # + Python's own

Method
    Each model (a chain size or a YAML file) is generated in a fresh process
    with ``modelgen.load(..., force=True)`` (derivatives on unless
    ``--no-derivatives``), after a 2-link chain's build that makes the shared
    runtime: *generate* is that process's wall and CPU seconds (its own and its
    compilers'), *Python* its own CPU seconds (the derivation, the
    elimination, the printing, the imports the build needs), from the loader
    call on.  Then each compile command of the manifest (one per part of
    ``<name>.c``) is run again in the build directory under ``valgrind
    --tool=callgrind --trace-children=yes``: *compiler Minstr* sums the
    instructions of every process of the command (gcc's driver, ``cc1`` and
    ``as``), in millions.  The counts are the same whatever the other core
    does, so two builds of one model (two checkouts, ``--repo``) compare to
    a fraction of a percent where their seconds differ by 10-30 % from run to
    run on this shared machine.  *s* is the minimum of ``--rounds`` plain runs
    of the command.  Part 1 is compiled at -O0, the others at -O2 (or -O1
    past a size; ``codegen/build.py``).

    With ``--python-instructions`` the generating process itself is counted
    too: the same fresh process runs under ``valgrind --tool=callgrind``
    (its compilers are not traced), and so does one that stops before the
    loader call; *Python Minstr* is the difference, the instructions behind
    *Python* s.  With the compilers' count it gives the whole generation in
    figures that move neither with the load nor with the machine's speed,
    which varies by a factor of two from hour to hour here.  It takes
    minutes: Python runs about fifty times slower under valgrind.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(HERE))

CHILD = """
import json, resource, sys, time
sys.path.insert(0, {repo!r})
import modelgen
from modelgen.model.api import load_model
from modelgen.model.chains import spatial_chain
arg = {arg!r}
spec = load_model(arg) if arg.endswith(".yaml") else spatial_chain(int(arg)).spec()
if {stop!r}:
    raise SystemExit(0)
wall, cpu = time.perf_counter(), time.process_time()
cm = modelgen.load(spec, {out!r}, derivatives={derivatives!r}, force=True)
kids = resource.getrusage(resource.RUSAGE_CHILDREN)
print(json.dumps({{"wall": time.perf_counter() - wall, "python": time.process_time() - cpu,
                  "cpu": time.process_time() - cpu + kids.ru_utime + kids.ru_stime,
                  "commands": cm.manifest["compile_commands"], "name": cm.name}}))
"""


def child(repo: Path, arg: str, out: Path, derivatives: bool, stop: bool = False) -> list:
    """The command of the fresh process that builds ``arg`` (with ``stop``: that
    imports what it needs and makes the model, then stops before the build)."""
    return [sys.executable, "-c", CHILD.format(repo=str(repo), arg=arg, out=str(out),
                                               derivatives=derivatives, stop=stop)]


def generate(repo: Path, arg: str, out: Path, derivatives: bool) -> dict:
    """The figures of one fresh build, in a child process."""
    done = subprocess.run(child(repo, arg, out, derivatives), capture_output=True, text=True,
                          cwd=repo)
    if done.returncode:
        raise RuntimeError(f"building {arg} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def _part(command: str) -> int:
    return int(command.split("-DMG_PART=")[1].split()[0])


def python_instructions(repo: Path, arg: str, out: Path, derivatives: bool) -> int:
    """Instructions of the generating process itself from the loader call on
    (callgrind, its compilers untraced): a fresh build's less one that stops
    before the loader call."""
    from modelgen.bench.harnesses import callgrind_total
    runs = [child(repo, arg, out, derivatives, stop) for stop in (False, True)]
    with ThreadPoolExecutor(2) as pool:
        whole, before = pool.map(lambda cmd: callgrind_total(cmd, cwd=repo), runs)
    return whole - before


def measure(repo: Path, arg: str, work: Path, derivatives: bool, rounds: int,
            python: bool = False) -> dict:
    from modelgen.bench.harnesses import command_instructions, command_seconds
    out = work / arg.replace("/", "_")
    row = generate(repo, arg, out, derivatives)
    if python:
        row["python_instr"] = python_instructions(repo, arg, work / "counted", derivatives)
    commands = sorted(row["commands"], key=_part)
    with ThreadPoolExecutor(2) as pool:      # the two cores; the counts do not care
        counts = list(pool.map(lambda c: command_instructions(c, out), commands))
    row["parts"] = {_part(c): {"instr": n, "s": command_seconds(c, out, rounds)}
                    for c, n in zip(commands, counts, strict=True)}
    return row


def table(rows) -> str:
    parts = sorted({p for r in rows for p in r["parts"]})
    python = any("python_instr" in r for r in rows)
    head = (["checkout", "model", "generate s (wall / CPU)", "Python s"]
            + (["Python Minstr"] if python else [])
            + [f"part {p} Minstr (s)" for p in parts] + ["compiler Minstr"]
            + (["whole Minstr"] if python else []))
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        cells = [r["repo"], r["name"], f"{r['wall']:.2f} / {r['cpu']:.2f}", f"{r['python']:.2f}"]
        if python:
            cells.append(f"{r['python_instr'] / 1e6:,.0f}" if "python_instr" in r else "–")
        cells += [f"{r['parts'][p]['instr'] / 1e6:,.0f} ({r['parts'][p]['s']:.2f})"
                  if p in r["parts"] else "–" for p in parts]
        compilers = sum(v["instr"] for v in r["parts"].values())
        cells.append(f"{compilers / 1e6:,.0f}")
        if python:
            cells.append(f"{(compilers + r['python_instr']) / 1e6:,.0f}"
                         if "python_instr" in r else "–")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("models", nargs="*", default=["20"],
                        help="chain sizes or model files (default: 20)")
    parser.add_argument("--repo", type=Path, nargs="+", default=[HERE],
                        help="checkouts to build with, in turn (default: this one)")
    parser.add_argument("--no-derivatives", action="store_true",
                        help="build without the derivatives")
    parser.add_argument("--rounds", type=int, default=3, help="timed runs of each command")
    parser.add_argument("--python-instructions", action="store_true",
                        help="count the generating process's own instructions too (minutes)")
    args = parser.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, repo in enumerate(args.repo):
            repo = repo.resolve()
            generate(repo, "2", Path(tmp) / f"warm-up{k}", False)    # the shared runtime
            for arg in args.models:
                if arg.endswith(".yaml"):
                    arg = str(Path(arg).resolve())
                row = measure(repo, arg, Path(tmp) / f"repo{k}", not args.no_derivatives,
                              args.rounds, args.python_instructions)
                rows.append(row | {"repo": repo.name})
    print(table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
