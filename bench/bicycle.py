"""The Whipple bicycle benchmark: lean and steer eigenvalues from ``cm.linearize``
on ``models/whipple_bicycle.yaml``, the weave and capsize speeds, and the
model's generation time and rhs cost against the targets of issue 26.

Run from the repository root::

    .venv/bin/python bench/bicycle.py                          # table, timings
    .venv/bin/python bench/bicycle.py --json --speeds 0:10:21 --set mB=90 --set c=0.1
    .venv/bin/python bench/bicycle.py --plot docs/images/bicycle_eigenvalues.png

Method
    The eigenvalues are those of the (roll, steer, roll_dot, steer_dot) block of
    the minimal linearization about upright straight running at each speed
    (``modelgen.bench.bicycle``; the block is decoupled from the cyclic
    coordinates there), with the parameters of the paper's Table 1 changed by
    ``--set``.  The weave and capsize speeds are the sign changes of the largest
    real part, bracketed on a 0.1 m/s grid over [0, 10] and bisected to 1e-12 m/s.
    *error vs Table 2*: the largest difference to the paper's Table 2 over its
    speeds (only with the benchmark parameters).  Generation: a fresh build
    (``force=True``) into a temporary directory, once as the integrators use the
    model and once with ``linearize=True``; wall seconds including the C
    compiler.  rhs: ``<name>_rhs_prepared`` in the C harness of
    ``modelgen.bench.harnesses`` at 1 m/s upright with a small lean (minimum over
    5 repeats of >= 0.2 s), and callgrind's instructions per call (200 calls
    minus none).  ``--no-timing`` skips generation and rhs.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import modelgen  # noqa: E402
from modelgen.bench import harnesses  # noqa: E402
from modelgen.bench.bicycle import (CAPSIZE_SPEED, TABLE_2, WEAVE_SPEED,  # noqa: E402
                                    lean_steer_eigenvalues, stability_speeds, upright_state)
from modelgen.bench.tables import fmt, markdown  # noqa: E402

MODEL = REPO / "models" / "whipple_bicycle.yaml"
#: issue 26's targets: generation seconds and rhs microseconds per call
TARGETS = {"generation_seconds": 10.0, "rhs_us": 0.8}


def speeds_arg(text: str) -> np.ndarray:
    """``start:stop:count`` (np.linspace) or one speed."""
    parts = text.split(":")
    try:
        if len(parts) == 3:
            return np.linspace(float(parts[0]), float(parts[1]), int(parts[2]))
        if len(parts) == 1:
            return np.array([float(text)])
    except ValueError:
        pass
    raise argparse.ArgumentTypeError(f"--speeds takes start:stop:count, got {text!r}")


def set_arg(text: str) -> tuple:
    name, sep, value = text.partition("=")
    try:
        return name.strip(), float(value)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--set takes NAME=VALUE, got {text!r}") from None


def generation_seconds(work: Path) -> dict:
    out = {}
    for label, options in (("rhs", {}), ("linearize", {"linearize": True})):
        start = time.perf_counter()
        modelgen.load(MODEL, work / label, force=True, **options)
        out[label] = time.perf_counter() - start
    return out


def rhs_cost(cm, work: Path) -> tuple:
    x0 = upright_state(cm, 1.0)
    x0[cm.coordinates.index("roll")] = 0.05
    x0[:cm.n] = cm.assemble(x0[:cm.n], keep=[c for c in cm.coordinates
                                             if c not in ("z", "pitch")])
    x0[cm.n:] = cm.consistent_speeds(x0[:cm.n], x0[cm.n:])
    exe, _ = harnesses.build_model_harness(cm, x0, work / "harness")
    return harnesses.run_model_harness(exe), harnesses.instructions_per_call([str(exe)])


def plot(path: Path, speeds, eigenvalues) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7, 4.5))
    lam = np.array(eigenvalues)
    # dots, not lines: sorted eigenvalues swap places where modes meet
    v = np.repeat(np.asarray(speeds, dtype=float), lam.shape[1])
    ax.plot(v, lam.real.ravel(), ".", color="C0", ms=2)
    ax.plot(v, np.abs(lam.imag).ravel(), ".", color="C1", ms=2)
    paper = np.array([TABLE_2[v] for v in TABLE_2])
    v_paper = np.array(list(TABLE_2), dtype=float)
    ax.plot(np.repeat(v_paper, 4), paper.real.ravel(), "o", mfc="none", color="k", ms=5,
            label="Meijaard et al. 2007, Table 2")
    ax.plot(np.repeat(v_paper, 4), np.abs(paper.imag).ravel(), "s", mfc="none", color="k", ms=4)
    ax.plot([], [], ".", color="C0", label="Re(λ), modelgen cm.linearize")
    ax.plot([], [], ".", color="C1", label="|Im(λ)|, modelgen cm.linearize")
    for v, name in ((WEAVE_SPEED, "weave"), (CAPSIZE_SPEED, "capsize")):
        ax.axvline(v, color="0.6", lw=0.8)
        ax.text(v, 8.5, f" {name}\n {v:.4f}", fontsize=8, color="0.3")
    ax.set_ylim(-10, 10)
    ax.set_xlabel("forward speed v [m/s]")
    ax.set_ylabel("eigenvalue [1/s]")
    ax.set_title("Whipple bicycle: lean and steer eigenvalues")
    ax.legend(loc="lower left", fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--speeds", type=speeds_arg, default=speeds_arg("0:10:21"),
                        help="start:stop:count [m/s] (default 0:10:21)")
    parser.add_argument("--set", type=set_arg, action="append", default=[],
                        metavar="NAME=VALUE", help="a parameter of Table 1 (repeatable)")
    parser.add_argument("--json", action="store_true", help="print JSON")
    parser.add_argument("--plot", type=Path, help="write the eigenvalue plot to this file")
    parser.add_argument("--no-timing", action="store_true",
                        help="skip the generation time and the rhs cost")
    args = parser.parse_args(argv)

    cm = modelgen.load(MODEL, linearize=True)
    changed = dict(args.set)
    unknown = [k for k in changed if k not in cm.parameters]
    if unknown:
        parser.error(f"unknown parameter(s) {', '.join(unknown)}; the model's are "
                     + ", ".join(cm.parameters))
    p = dict(cm.parameters) | changed
    eig = [lean_steer_eigenvalues(cm, float(v), p) for v in args.speeds]
    weave, capsize = stability_speeds(cm, p)
    result = {
        "model": str(MODEL.relative_to(REPO)),
        "parameters": p,
        "speeds": [float(v) for v in args.speeds],
        "eigenvalues": [[[float(e.real), float(e.imag)] for e in row] for row in eig],
        "weave_speed": weave,
        "capsize_speed": capsize,
    }
    if not changed:
        result["error_vs_table_2"] = max(
            float(np.max(np.abs(lean_steer_eigenvalues(cm, float(v), p)
                                - np.sort_complex(np.array(want, complex)))))
            for v, want in TABLE_2.items())
        result["weave_error"] = abs(weave - WEAVE_SPEED)
        result["capsize_error"] = abs(capsize - CAPSIZE_SPEED)
    if not args.no_timing:
        with tempfile.TemporaryDirectory() as tmp:
            seconds = generation_seconds(Path(tmp))
            # the build the integrators use (no linearization)
            rhs_us, instructions = rhs_cost(modelgen.load(MODEL), Path(tmp))
        result |= {"generation_seconds": seconds, "rhs_us": rhs_us,
                   "rhs_instructions": instructions, "targets": TARGETS,
                   "meets": {"generation_seconds": seconds["rhs"]
                             <= TARGETS["generation_seconds"],
                             "rhs_us": rhs_us <= TARGETS["rhs_us"]}}
    if args.plot:
        dense = np.linspace(0.0, 10.0, 401)
        plot(args.plot, dense, [lean_steer_eigenvalues(cm, v, p) for v in dense])
    if args.json:
        print(json.dumps(result, indent=1))
        return 0
    rows = [[fmt(v, ".2f")] + [f"{e.real:+.6f}{e.imag:+.6f}j" for e in row]
            for v, row in zip(args.speeds, eig)]
    print(markdown(["v [m/s]", "λ1", "λ2", "λ3", "λ4"], rows))
    print(f"\nweave speed {fmt(weave, '.10f')} m/s, capsize speed {fmt(capsize, '.10f')} m/s")
    if "error_vs_table_2" in result:
        print(f"error vs Table 2 {result['error_vs_table_2']:.2e}; weave "
              f"{result['weave_error']:.1e}, capsize {result['capsize_error']:.1e} m/s")
    if not args.no_timing:
        met = {k: "met" if v else "NOT met" for k, v in result["meets"].items()}
        print(f"generation {seconds['rhs']:.1f} s (with linearize {seconds['linearize']:.1f} s; "
              f"target <= {TARGETS['generation_seconds']:g} s: {met['generation_seconds']}); "
              f"rhs {rhs_us:.3f} µs (target <= {TARGETS['rhs_us']:g} µs: {met['rhs_us']}), "
              f"{fmt(instructions, '.0f')} instructions")
    return 0


if __name__ == "__main__":
    sys.exit(main())
