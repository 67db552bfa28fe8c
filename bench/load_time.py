"""How fast modelgen starts: import, a cached load, the CLI, and generation against PyDy.

Run from the repository root::

    .venv/bin/python bench/load_time.py                 # 5 rounds (PyDy: 2)
    .venv/bin/python bench/load_time.py --quick         # 2 rounds (PyDy: 1)

Every figure is the wall time of a fresh Python process, interpreter start and
imports included (what a user, a CLI call, a Dask worker or a multiprocessing
child pays), min and median over the rounds, on a private build cache
(``MODELGEN_CACHE_DIR`` in a temporary directory) warmed by one untimed run,
which also writes the bytecode caches (``PYTHONDONTWRITEBYTECODE`` is unset
for the children, as for an installed package):

(a) ``python -c pass``: the interpreter alone, for reference.
(b) cold import: ``import modelgen``.
(c) cached load: ``modelgen.load("models/double_pendulum.yaml")``, the build
    already in the cache (found through its fast index, see
    ``modelgen/codegen/index.py``); the symbolic packages the process imported
    are printed too (none is the point).
(d) ``modelgen --help`` (``python -m modelgen``, which runs what the console
    script runs: ``modelgen.cli.run``).
(e) cached ``modelgen simulate models/scenes/dp_free.yaml`` end to end (read
    the scene, find its build, integrate, write CSV, NPZ and PNG).
(f) the 6-link spatial chain (``modelgen.model.chains.spatial_chain(6)``,
    written to a YAML file) generated from the command line,
    ``modelgen generate chain.yaml -o DIR --force``, against PyDy on the same
    model (``modelgen/bench/pydy_models.py``: sympy's ``KanesMethod`` and
    PyDy's Cython backend, ``generate_ode_function(..., generator="cython")``),
    each in a fresh process into a fresh directory, the two alternated in the
    same run; the ratio PyDy / modelgen.  Skipped, with the reason, when pydy or
    cython is missing.  After the timing, the two generated rhs are compared
    at one state (every q and u 0.1, the chain's default parameters): the
    largest difference over the largest |x'|, so the ratio is between
    generators that produced the same equations.

The figures of the issue (before the work) and the targets are printed beside
the measurement.  A shared machine is noisy: compare the minimum, and rerun
when the load average (printed) is high.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import os
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

from modelgen.model.chains import spatial_chain  # noqa: E402
from modelgen.model.writer import spec_to_yaml  # noqa: E402

DOUBLE_PENDULUM = REPO / "models" / "double_pendulum.yaml"
DP_FREE = REPO / "models" / "scenes" / "dp_free.yaml"
CHAIN_LINKS = 6
#: (figure before the work, target) in seconds, or for the chain the ratio
TARGETS = {"cached load": ("1.25", 0.15), "--help": ("1.4 (CPU)", 0.2),
           "chain ratio": ("4.6", 10.0)}
SYMBOLIC = ("sympy", "symengine")


def children_cpu() -> float:
    """CPU seconds of this process's finished children (and theirs: the compilers)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def run(argv, env, cwd=REPO) -> tuple:
    """(wall seconds, CPU seconds, stdout) of one fresh process (CPU: it and its
    children, e.g. the C compiler); SystemExit with its output on failure."""
    c0, t0 = children_cpu(), time.perf_counter()
    proc = subprocess.run(argv, capture_output=True, text=True, env=env, cwd=cwd)
    wall, cpu = time.perf_counter() - t0, children_cpu() - c0
    if proc.returncode:
        raise SystemExit(f"{' '.join(map(str, argv))} failed:\n{proc.stdout}{proc.stderr}")
    return wall, cpu, proc.stdout


def timed(argv, env, rounds: int) -> list:
    """(wall, CPU) seconds of ``rounds`` runs."""
    return [run(argv, env)[:2] for _ in range(rounds)]


def python(code: str) -> list:
    return [sys.executable, "-c", code]


def modelgen_cli(*args) -> list:
    return [sys.executable, "-m", "modelgen", *(str(a) for a in args)]


def row(name: str, times: list, note: str = "") -> str:
    wall, cpu = [t[0] for t in times], [t[1] for t in times]
    return (f"| {name} | {min(wall) * 1e3:.0f} | {statistics.median(wall) * 1e3:.0f} | "
            f"{min(cpu) * 1e3:.0f} | {note} |")


def verdict(name: str, value: float, higher_is_better: bool = False) -> str:
    before, target = TARGETS[name]
    met = value >= target if higher_is_better else value <= target
    return f"before {before}, target {'>=' if higher_is_better else '<='} {target:g}: " \
           f"{'met' if met else 'NOT met'}"


def pydy_missing() -> str:
    missing = [m for m in ("pydy", "Cython") if importlib.util.find_spec(m) is None]
    return ", ".join(missing)


def pydy_agreement(pydy_out: str, chain: Path, build: Path) -> float:
    """PyDy's rhs (its output ``pydy_out``) against modelgen's build of ``chain`` in
    ``build``, at the state and parameters of :mod:`modelgen.bench.pydy_models`."""
    import numpy as np

    import modelgen
    from modelgen.bench.pydy_models import CHECK_STATE, XDOT_MARK, chain_constants
    line = next(x for x in pydy_out.splitlines() if x.startswith(XDOT_MARK))
    theirs = np.array(json.loads(line[len(XDOT_MARK):]))
    cm = modelgen.load(chain, build)        # the build the CLI made: found, not rebuilt
    if not np.allclose(cm.params(), chain_constants(CHAIN_LINKS), rtol=0, atol=0):
        raise SystemExit("the chain's default parameters are not PyDy's constants")
    mine = cm.rhs(0.0, np.full(cm.nx, CHECK_STATE))
    return float(np.max(np.abs(mine - theirs)) / np.max(np.abs(mine)))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rounds", type=int, default=5, help="rounds of each (default 5)")
    parser.add_argument("--pydy-rounds", type=int, default=2,
                        help="rounds of the chain generation (default 2)")
    parser.add_argument("--quick", action="store_true", help="2 rounds, 1 of the chain")
    args = parser.parse_args(argv)
    rounds, chain_rounds = (2, 1) if args.quick else (args.rounds, args.pydy_rounds)
    root = Path(tempfile.mkdtemp(prefix="modelgen-load-time-"))
    env = dict(os.environ, PYTHONPATH=str(REPO), MODELGEN_CACHE_DIR=str(root / "cache"),
               MPLBACKEND="Agg")
    # as installed: the warm-up run writes the bytecode caches a user's later runs read
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    try:
        load = (f"import modelgen, sys, json; modelgen.load({str(DOUBLE_PENDULUM)!r}); "
                f"print(json.dumps(sorted(m for m in sys.modules "
                f"if m.split('.')[0] in {SYMBOLIC!r})))")
        run(python(load), env)                                     # warm: build and index
        simulate = modelgen_cli("simulate", DP_FREE, "-o", root / "out", "--quiet")
        run(simulate, env)                                         # warm
        rows = {"python -c pass": timed(python("pass"), env, rounds),
                "import modelgen": timed(python("import modelgen"), env, rounds),
                "cached load": timed(python(load), env, rounds),
                "--help": timed(modelgen_cli("--help"), env, rounds),
                "simulate dp_free": timed(simulate, env, rounds)}
        imported = run(python(load), env)[2]
        symbolic = json.loads(imported.strip().splitlines()[-1])

        chain = root / f"spatial_chain_{CHAIN_LINKS}.yaml"
        chain.write_text(spec_to_yaml(spatial_chain(CHAIN_LINKS).spec()))
        generate = modelgen_cli("generate", chain, "-o", root / "chain", "--force")
        pydy = [sys.executable, "-m", "modelgen.bench.pydy_models", str(CHAIN_LINKS),
                str(root / "pydy")]
        missing = pydy_missing()
        gen_times, pydy_times, pydy_out = [], [], ""
        # alternated, so that a machine that slows down or speeds up during the
        # run moves both sides of the ratio alike
        for _ in range(chain_rounds):
            gen_times.append(run(generate, env)[:2])
            if not missing:
                shutil.rmtree(root / "pydy", ignore_errors=True)
                (root / "pydy").mkdir()
                wall, cpu, pydy_out = run(pydy, env)
                pydy_times.append((wall, cpu))

        load_avg = ", ".join(f"{v:.2f}" for v in os.getloadavg())
        print(f"# Start-up and generation time ({rounds} rounds, chain {chain_rounds}; "
              f"Python {sys.version.split()[0]}, load average {load_avg})\n")
        print("| fresh process | min ms | median ms | min CPU ms | |\n|---|---|---|---|---|")
        print(row("python -c pass", rows["python -c pass"], "the interpreter alone"))
        print(row("import modelgen", rows["import modelgen"]))
        print(row("cached modelgen.load (double pendulum)", rows["cached load"],
                  verdict("cached load", min(t[0] for t in rows["cached load"]))
                  + f"; symbolic packages imported: {', '.join(symbolic) or 'none'}"))
        print(row("modelgen --help", rows["--help"],
                  verdict("--help", min(t[0] for t in rows["--help"]))))
        print(row("cached modelgen simulate dp_free.yaml", rows["simulate dp_free"],
                  "end to end: scene read, build found, run, CSV/NPZ/PNG written"))
        print(f"\n## spatial_chain({CHAIN_LINKS}) generated from the command line, "
              f"fresh process and directory\n")
        print("| generator | min wall s | median wall s | min CPU s (with compilers) |\n"
              "|---|---|---|---|")
        for name, times in (("modelgen generate", gen_times),
                            ("PyDy (KanesMethod + Cython)", pydy_times)):
            if times:
                wall, cpu = [t[0] for t in times], [t[1] for t in times]
                print(f"| {name} | {min(wall):.2f} | {statistics.median(wall):.2f} | "
                      f"{min(cpu):.2f} |")
        if pydy_times:
            ratio = min(t[0] for t in pydy_times) / min(t[0] for t in gen_times)
            ratio_cpu = min(t[1] for t in pydy_times) / min(t[1] for t in gen_times)
            medians = statistics.median(t[0] for t in pydy_times) \
                / statistics.median(t[0] for t in gen_times)
            print(f"\nPyDy / modelgen = {ratio:.1f}x wall, {ratio_cpu:.1f}x CPU (min over min), "
                  f"{medians:.1f}x wall (median over median); "
                  f"{verdict('chain ratio', ratio, higher_is_better=True)} (wall)")
            print(f"PyDy's rhs against modelgen's (the two builds timed above): "
                  f"{pydy_agreement(pydy_out, chain, root / 'chain'):.1e} "
                  f"(largest difference over the largest |x'|)")
        else:
            print(f"\nPyDy not measured: {missing} not installed "
                  f"(pip install pydy cython)")
    finally:
        shutil.rmtree(root, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
