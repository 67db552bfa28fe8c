"""What the model-independent integrators cost: this checkout against an older one.

Three figures, each printed as a table with ratios:

(a) the indirect call: dop853 on the double pendulum over 10 s at
    rtol = atol = 1e-6 ... 1e-12, wall time (min of repeats, through
    ``cm.simulate``) and, with ``--callgrind``, the instructions executed inside
    ``double_pendulum_integrate`` (valgrind's callgrind, noise-free);
(b) an edited double pendulum (a parameter default changed) from file to
    loaded module in a running Python;
(c) C dop853 against ``scipy.integrate.solve_ivp(method="DOP853")`` on the
    same compiled rhs, at the same tolerance.

Usage::

    python bench/integrator_overhead.py --old /path/to/older/checkout [--callgrind]
    python bench/integrator_overhead.py --repeats 5     # this checkout alone

Without ``--old`` only this checkout is measured (no new/old ratios).  In (c)
both integrators run at the same tolerance from the same state, so the
difference of their final states (printed) shows that they solved the same
problem to comparable accuracy; the double pendulum is chaotic over 10 s, so
at loose tolerances the two legitimately part.

Each checkout runs in its own subprocess with ``PYTHONPATH`` set to it, its
builds in a temporary directory and its integrator cache there too (so the
first build of each compiles the integrators, as a fresh install would).
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent
TOLERANCES = (1e-6, 1e-8, 1e-10, 1e-12)
X0 = [1.0, -0.5, 0.0, 0.0]
T_END = 10.0


def _simulate(cm, tol):
    return cm.simulate(X0, (0.0, T_END), t_eval=[T_END], method="dop853", rtol=tol, atol=tol)


def worker(out_dir: Path, repeats: int, callgrind: bool) -> dict:
    """Runs inside the checkout under test (``import modelgen`` is that one)."""
    import numpy as np
    import scipy.integrate
    import modelgen

    model = HERE / "models" / "double_pendulum.yaml"
    cm = modelgen.load(model, out_dir / "dp")
    if callgrind:                      # one run per tolerance; callgrind counts them
        return {"nfev": {str(tol): int(_simulate(cm, tol).nfev) for tol in TOLERANCES}}
    result = {"module": modelgen.__file__, "runs": {}, "edit": [], "scipy": {}}
    for tol in TOLERANCES:
        best = np.inf
        for _ in range(repeats):
            start = time.perf_counter()
            res = _simulate(cm, tol)
            best = min(best, time.perf_counter() - start)
        assert res.success, res.message
        result["runs"][str(tol)] = {"seconds": best, "nfev": int(res.nfev),
                                    "x": [float(v) for v in res.y[:, -1]]}
        f = cm.rhs_function()
        best = np.inf
        for _ in range(max(1, repeats // 5)):
            start = time.perf_counter()
            ref = scipy.integrate.solve_ivp(f, (0.0, T_END), X0, method="DOP853", rtol=tol,
                                            atol=tol)
            best = min(best, time.perf_counter() - start)
        result["scipy"][str(tol)] = {"seconds": best, "nfev": int(ref.nfev),
                                     "x": [float(v) for v in ref.y[:, -1]]}

    text = model.read_text()
    for k, g in enumerate((9.80, 9.79, 9.78, 9.77, 9.76)):
        edited = out_dir / f"edit{k}" / "double_pendulum.yaml"
        edited.parent.mkdir()
        new = re.sub(r"\bg: [0-9.]+", f"g: {g}", text, count=1)
        assert new != text, "no default of g found to edit"
        edited.write_text(new)
        start = time.perf_counter()
        cm_k = modelgen.load(edited, out_dir / "edited")
        result["edit"].append(time.perf_counter() - start)
        assert cm_k.parameters["g"] == g
    return result


def _run_worker(root: Path, repeats: int, callgrind: bool) -> dict:
    tmp = Path(tempfile.mkdtemp(prefix="mg-overhead-"))
    try:
        env = dict(os.environ, PYTHONPATH=str(root), MODELGEN_CACHE_DIR=str(tmp / "cache"))
        cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", str(tmp),
               "--repeats", str(repeats)]
        if callgrind:
            # warm the build first, then count only the integrator's instructions
            subprocess.run(cmd + ["--callgrind-worker"], env=env, check=True, cwd=root,
                           stdout=subprocess.DEVNULL)
            out_file = tmp / "callgrind.out"
            cmd = ["valgrind", "--tool=callgrind", f"--callgrind-out-file={out_file}",
                   "--toggle-collect=double_pendulum_integrate", *cmd, "--callgrind-worker"]
        r = subprocess.run(cmd, env=env, cwd=root, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
        if r.returncode:
            raise SystemExit(f"worker in {root} failed:\n{r.stdout}\n{r.stderr}")
        data = json.loads(r.stdout.strip().splitlines()[-1])
        if callgrind:
            totals = re.search(r"^(?:summary|totals):\s+(\d+)", out_file.read_text(), re.M)
            data["instructions"] = int(totals[1])
        return data
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--old", type=Path, help="an older modelgen checkout to compare with")
    ap.add_argument("--repeats", type=int, default=50)
    ap.add_argument("--callgrind", action="store_true", help="also count instructions")
    ap.add_argument("--worker", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--callgrind-worker", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        print(json.dumps(worker(args.worker, args.repeats, args.callgrind_worker)))
        return 0

    roots = {"new": HERE}
    if args.old:
        roots = {"old": args.old.resolve(), "new": HERE}
    data = {label: _run_worker(root, args.repeats, False) for label, root in roots.items()}
    counts = ({label: _run_worker(root, 1, True) for label, root in roots.items()}
              if args.callgrind else {})

    print(f"(a) dop853, double pendulum, 10 s, min of {args.repeats} runs through cm.simulate")
    print(f"{'rtol':>8} " + " ".join(f"{label + ' ms':>10} {label + ' nfev':>10}" for label in roots)
          + ("   new/old" if "old" in roots else ""))
    for tol in map(str, TOLERANCES):
        row = f"{float(tol):8.0e} " + " ".join(
            f"{1e3 * data[k]['runs'][tol]['seconds']:10.3f} {data[k]['runs'][tol]['nfev']:10d}"
            for k in roots)
        if "old" in roots:
            row += f"   {data['new']['runs'][tol]['seconds'] / data['old']['runs'][tol]['seconds']:7.3f}"
        print(row)
    if "old" in roots:
        same = all(data["new"]["runs"][t]["x"] == data["old"]["runs"][t]["x"]
                   for t in map(str, TOLERANCES))
        print(f"final states bitwise equal old/new: {same}")
        total = {k: sum(r["seconds"] for r in data[k]["runs"].values()) for k in roots}
        print(f"sum over tolerances: new/old = {total['new'] / total['old']:.3f}")
    if counts:
        print("\ninstructions inside double_pendulum_integrate (callgrind, one run per rtol)")
        for k in roots:
            print(f"{k:>8} {counts[k]['instructions']:>14,d}")
        if "old" in roots:
            print(f"new/old = {counts['new']['instructions'] / counts['old']['instructions']:.4f}")

    print("\n(b) edited double pendulum (default of g changed): file -> loaded module, s")
    for k in roots:
        edits = sorted(data[k]["edit"])
        print(f"{k:>8} min {edits[0]:.3f}  median {edits[len(edits) // 2]:.3f}  "
              f"all {' '.join(f'{e:.3f}' for e in data[k]['edit'])}")
    if "old" in roots:
        print(f"median new/old = {sorted(data['new']['edit'])[2] / sorted(data['old']['edit'])[2]:.3f}")

    print("\n(c) C dop853 against solve_ivp DOP853 on the compiled rhs (same rtol = atol); "
          "scipy/C: scipy's time over C's (above 1: C is faster); |x_C - x_scipy|: the "
          "largest difference of the final states")
    print(f"{'rtol':>8} {'C ms':>10} {'scipy ms':>10} {'scipy/C':>8} {'C nfev':>8} "
          f"{'scipy nfev':>10} {'|x_C - x_scipy|':>16}")
    for tol in map(str, TOLERANCES):
        c, s = data["new"]["runs"][tol], data["new"]["scipy"][tol]
        diff = max(abs(a - b) for a, b in zip(c["x"], s["x"], strict=True))
        print(f"{float(tol):8.0e} {1e3 * c['seconds']:10.3f} {1e3 * s['seconds']:10.3f} "
              f"{s['seconds'] / c['seconds']:8.1f} {c['nfev']:8d} {s['nfev']:10d} "
              f"{diff:16.1e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
