"""How long an edited model takes to become a loaded module, stage by stage.

Run from the repository root::

    .venv/bin/python bench/load_time.py                  # 7 rounds each
    .venv/bin/python bench/load_time.py --rounds 3
    .venv/bin/python bench/load_time.py --profile 30     # also cProfile, top 30 functions

Measures, beside the figures of today (before the "One house" work) and the targets:

(a) **edit -> loaded model.**  ``models/double_pendulum.yaml`` is copied to a
    temporary directory; every round changes the default of ``m2`` to a new
    value (so the build cache misses, as after a real edit) and times
    ``modelgen.load(path, out_dir)`` from the file to a loaded
    ``CompiledModel`` (``modelgen.as_spec`` then ``modelgen.load``), in this
    running Python with the package imported and one untimed warm-up load done
    (the first load of a process also pays for lazy imports; it is printed
    apart).  *load* is the YAML read into a ModelSpec; derive, cse, emit and
    compile are modelgen's own timers (``cm.manifest["seconds"]``); *other* is
    the rest of the total (hashing, cache look-up, import of the extension,
    the mass-matrix check); *py cpu* and *cc cpu* are the CPU time of this
    process and of the compilers over the round (less sensitive to a busy
    machine than wall time; the compilers run in parallel, so on an idle
    machine the wall time of compile is below *cc cpu*).
    Min and median of each column over the rounds.
(b) **generate the 6-link chain.**  ``modelgen.model.chains.spatial_chain(6)``
    through ``modelgen.generate_model`` into a fresh directory every round;
    the stage total is the sum of ``Generated.seconds``.  Min over the rounds.
(c) **does a changed model recompile the integrators?**  Read from the build
    manifest: an ``integrators`` entry if the build reports one, else the
    compile commands (the integrators compiled as ``-DMG_PART=3`` of the
    model's own C means yes); "n/a" when neither says.

(d) **what the compiler spends**: each compile command of the last builds
    (from the manifest) rerun alone, serially, min of 3, wall and CPU time.

A shared machine is noisy: compare the minimum, and rerun when the load
average (printed) is high.
"""
from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import re
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import modelgen  # noqa: E402
from modelgen.model.chains import spatial_chain  # noqa: E402

DOUBLE_PENDULUM = REPO / "models" / "double_pendulum.yaml"
#: the stages of Generated.seconds, in pipeline order
STAGES = ("derive", "cse", "emit", "compile")
#: figures of today (before the work) and the targets, in seconds
TODAY_EDIT, TARGET_EDIT = "0.30-0.33", 0.2
TODAY_CHAIN, TARGET_CHAIN = "1.04", 0.6
CHAIN_LINKS = 6


def edited(text: str, value: float) -> str:
    """The double pendulum's YAML with the default of ``m2`` set to ``value``."""
    new, count = re.subn(r"(\bm2:\s*)[-+0-9.eE]+", lambda m: f"{m.group(1)}{value!r}", text,
                         count=1)
    if count != 1:
        raise SystemExit(f"{DOUBLE_PENDULUM}: no parameter default 'm2: <number>' to edit")
    return new


def integrators_recompiled(manifest: dict) -> str:
    """'yes', 'no' or 'n/a': did this build compile the integrators again?"""
    entry = manifest.get("integrators")
    if isinstance(entry, dict) and "cached" in entry:
        return "no (reused: " + str(entry.get("path", "cached")) + ")" if entry["cached"] \
            else "yes (built now)"
    commands = manifest.get("compile_commands")
    if commands:
        part3 = any("-DMG_PART=3" in c for c in commands)
        return ("yes: compiled again as part 3 (-DMG_PART=3) of the model's own C" if part3
                else "no: the model's build compiles no integrator part")
    return "n/a"


def compiler_cpu() -> float:
    """CPU time of this process's finished children (the compilers), s."""
    children = resource.getrusage(resource.RUSAGE_CHILDREN)
    return children.ru_utime + children.ru_stime


def edit_round(path: Path, text: str, value: float, out_dir: Path) -> dict:
    """Write the edit, load it; returns the total and the stage seconds."""
    path.write_text(edited(text, value))
    p0, c0, t0 = time.process_time(), compiler_cpu(), time.perf_counter()
    spec = modelgen.as_spec(path)
    t1 = time.perf_counter()
    cm = modelgen.load(spec, out_dir)
    total = time.perf_counter() - t0
    py_cpu, cc_cpu = time.process_time() - p0, compiler_cpu() - c0
    row = {"load": t1 - t0, **{s: cm.manifest["seconds"].get(s, 0.0) for s in STAGES}}
    if abs(cm.parameters["m2"] - value) > 1e-12:
        raise SystemExit(f"the loaded model has m2 = {cm.parameters['m2']}, not {value}")
    row["other"] = total - sum(row.values())
    row["total"] = total
    row["py cpu"], row["cc cpu"] = py_cpu, cc_cpu
    row["integrators"] = integrators_recompiled(cm.manifest)
    return row


def chain_round(root: Path, k: int) -> dict:
    """``generate`` of the chain into a fresh directory; the stage seconds and their sum."""
    g = modelgen.generate_model(spatial_chain(CHAIN_LINKS), root / f"chain{k}")
    if g.build.cached:
        raise SystemExit("the chain's build was cached: the output directory is not fresh")
    row = {s: g.seconds.get(s, 0.0) for s in STAGES}
    row["total"] = sum(row.values())
    return row


def compile_breakdown(cm_or_generated, repeats: int = 3) -> list:
    """Each of the build's compile commands run alone (serially), min of ``repeats``, s.

    The commands are the manifest's ``compile_commands`` (the model's C parts),
    rerun in the build directory with the object written to a scratch file.
    """
    manifest = cm_or_generated.manifest
    directory = Path(getattr(cm_or_generated, "path", None) or
                     cm_or_generated.build.module_path).parent
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        for command in manifest.get("compile_commands", ()):
            argv = command.split()
            argv[argv.index("-o") + 1] = str(Path(scratch) / "part.o")
            times, cpus = [], []
            for _ in range(repeats):
                c0, t0 = compiler_cpu(), time.perf_counter()
                subprocess.run(argv, cwd=directory, check=True, capture_output=True)
                times.append(time.perf_counter() - t0)
                cpus.append(compiler_cpu() - c0)
            part = next((a for a in argv if a.startswith("-DMG_PART=")), "-")
            level = " ".join(a for a in argv if a.startswith(("-O", "-f")) and a != "-fPIC") \
                or "-"
            rows.append((part.removeprefix("-D"), level, min(times), min(cpus)))
    return rows


def table(rows, columns, how) -> list:
    head = "| | " + " | ".join(columns) + " |"
    lines = [head, "|---" * (len(columns) + 1) + "|"]
    for name, pick in how:
        lines.append(f"| {name} | " + " | ".join(f"{pick([r[c] for r in rows]) * 1e3:.0f}"
                                                  for c in columns) + " |")
    return lines


def profile(function, top: int, title: str) -> None:
    prof = cProfile.Profile()
    prof.enable()
    function()
    prof.disable()
    print(f"\n### cProfile: {title} (top {top} by own time, then by cumulative time)\n")
    stats = pstats.Stats(prof, stream=sys.stdout).strip_dirs()
    stats.sort_stats("tottime").print_stats(top)
    stats.sort_stats("cumulative").print_stats(top)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=7, help="timed rounds of each (default 7)")
    parser.add_argument("--profile", type=int, default=0, metavar="TOP",
                        help="also profile one round of each and print the TOP functions")
    args = parser.parse_args(argv)
    text = DOUBLE_PENDULUM.read_text()
    root = Path(tempfile.mkdtemp(prefix="modelgen-load-time-"))
    try:
        path = root / "double_pendulum.yaml"
        out_dir = root / "dp"
        first = edit_round(path, text, 1.0, out_dir)      # the first load of this process
        rows = [edit_round(path, text, 1.0 + 1e-3 * (k + 1), out_dir)
                for k in range(args.rounds)]
        chain_first = chain_round(root, 0)
        chains = [chain_round(root, k + 1) for k in range(args.rounds)]
        load_avg = ", ".join(f"{v:.2f}" for v in os.getloadavg())
        print(f"# Load time ({args.rounds} rounds; modelgen {modelgen.__version__}, Python "
              f"{sys.version.split()[0]}, load average {load_avg})\n")
        print(f"## (a) edited double pendulum (m2's default changed) -> loaded CompiledModel, "
              f"in a running Python, ms\n")
        columns = ["load", *STAGES, "other", "total", "py cpu", "cc cpu"]
        print("\n".join(table(rows, columns, (("min", min), ("median", statistics.median)))))
        print(f"\nfirst load of the process (lazy imports included): "
              f"{first['total'] * 1e3:.0f} ms")
        best = min(r["total"] for r in rows)
        print(f"\ntotal: min {best:.3f} s, median "
              f"{statistics.median(r['total'] for r in rows):.3f} s; today {TODAY_EDIT} s, "
              f"target <= {TARGET_EDIT} s: {'met' if best <= TARGET_EDIT else 'NOT met'} "
              f"(min)\n")
        print(f"## (b) generate spatial_chain({CHAIN_LINKS}), fresh output directory, ms\n")
        print("\n".join(table(chains, [*STAGES, "total"], (("min", min),
                                                           ("median", statistics.median)))))
        best = min(r["total"] for r in chains)
        print(f"\nfirst generate of the process: {chain_first['total'] * 1e3:.0f} ms")
        print(f"\nstage total: min {best:.3f} s; today {TODAY_CHAIN} s, target <= "
              f"{TARGET_CHAIN} s: {'met' if best <= TARGET_CHAIN else 'NOT met'}\n")
        print("## (c) a changed model recompiles the integrators?\n")
        print(f"{rows[-1]['integrators']}\n")
        print("## (d) the compile commands of the builds, each alone (serial), min of 3, ms\n")
        print("| model | part | flags | wall ms | cpu ms |\n|---|---|---|---|---|")
        dp = modelgen.load(path, out_dir)
        chain = modelgen.generate_model(spatial_chain(CHAIN_LINKS), root / "chain0")
        for name, built in (("double pendulum", dp), (f"chain {CHAIN_LINKS}", chain)):
            for part, level, seconds, cpu in compile_breakdown(built):
                print(f"| {name} | {part} | {level} | {seconds * 1e3:.0f} | {cpu * 1e3:.0f} |")
        print("\n(the builds run the two parts in parallel, then link; no per-model cffi wrapper is compiled: Python calls the library through the runtime module, built once)")
        if args.profile:
            profile(lambda: edit_round(path, text, 2.0, out_dir), args.profile,
                    "edited double pendulum -> loaded")
            profile(lambda: chain_round(root, args.rounds + 1), args.profile,
                    f"generate spatial_chain({CHAIN_LINKS})")
    finally:
        shutil.rmtree(root, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
