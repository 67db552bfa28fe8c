"""Inverse dynamics in C: modelgen's ``<name>_inverse_dynamics`` against Pinocchio's ``rnea``
and MuJoCo's ``mj_inverse``.

Run from the repository root (needs the ``bench`` extra: ``pin`` and ``cmeel-eigen``)::

    .venv/bin/python bench/inverse_dynamics.py                 # n = 7 20 50 100 and arm7
    .venv/bin/python bench/inverse_dynamics.py --n 7 20 --rounds 5
    .venv/bin/python bench/inverse_dynamics.py --quick         # n = 7 and arm7, one round

Method
    The models and the harnesses are those of ``bench/codegen_scaling.py``
    (the spatial chain of ``spatial_chain(n)`` and ``models/arm7.yaml``, written
    for the peers by ``modelgen.bench.peers``; ``modelgen/bench/harness/``, the
    Pinocchio one compiled ``-O3 -march=native``).  The
    state x0 is the one that script uses; the accelerations are
    ``0.3 (i mod 3) - 0.2``.  All compute the generalized forces that give
    those accelerations: Pinocchio's ``rnea(q, v, a)`` = M a + C v + g,
    MuJoCo's ``mj_inverse`` (``qfrc_inverse``; the MJCF of ``peers``, no
    contacts, damping or armature) and modelgen's Q = A a + h - tau, the same
    thing for a model whose only effect is gravity (*agree rnea*, *agree
    mj_inverse*: each peer's largest difference to modelgen over the largest |Q|
    at x0, in the same run).
    Time: each harness calls its function in a loop, perturbing one entry of x
    from the previous output (a dependency chain), minimum over 5 repeats of >= 0.2 s,
    run alternately ``--rounds`` times, minimum kept.  Instructions: callgrind,
    K = 200 calls minus none (``modelgen.bench.harnesses.instructions_per_call``;
    ``--no-count`` or no valgrind: not counted); Pinocchio counted in its build
    without AVX-512.  Ratios are the peer's figure over modelgen's (above 1:
    modelgen is faster).  Without MuJoCo its columns are empty (a note says why);
    without Pinocchio the script stops with a message (exit 1).
"""
from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

import modelgen  # noqa: E402
from modelgen.bench import harnesses  # noqa: E402
from modelgen.bench.peers import write_peer_models  # noqa: E402
from modelgen.bench.tables import fmt, markdown  # noqa: E402
from modelgen.model.api import load_model  # noqa: E402
from modelgen.model.chains import spatial_chain  # noqa: E402


def accelerations(n: int) -> np.ndarray:
    """The accelerations every harness uses (``modelgen/bench/harness/``)."""
    return np.array([0.3 * (i % 3) - 0.2 for i in range(n)])


def measure(kind, arg, work: Path, pin, pin_count, mj, rounds: int, count: bool = True) -> dict:
    spec = spatial_chain(arg).spec() if kind == "chain" else load_model(arg)
    cm = modelgen.load(spec, work / "model")
    rng = np.random.default_rng(1000 + cm.n)           # codegen_scaling's state
    x0 = np.concatenate([rng.uniform(-np.pi, np.pi, cm.n), rng.uniform(-2, 2, cm.n)])
    a = accelerations(cm.n)
    exe, _ = harnesses.build_model_harness(cm, x0, work / "harness", "inverse_dynamics")
    files = write_peer_models(spec, cm, x0, work, kind == "chain")
    if files is None:
        raise SystemExit(f"{arg}: not a tree of revolute joints with gravity only, which "
                         "the peers' models are written from")
    xml_path, tree = files
    state = work / "model.state"
    state.write_text(" ".join(repr(float(v)) for v in x0) + "\n")
    mj_cmd = [str(mj), str(xml_path), str(state), "inverse"] if mj else None
    mg_t, pin_t, mj_t = [], [], []
    for _ in range(rounds):
        mg_t.append(harnesses.run_model_harness(exe))
        pin_t.append(float(harnesses.run_checked([str(pin), str(tree), "2"]).split()[0]) * 1e6)
        if mj_cmd:
            mj_t.append(float(harnesses.run_checked(mj_cmd).split()[0]) * 1e6)
    Q = cm.inverse_dynamics(0.0, x0, a)
    peers = [np.array(harnesses.run_checked([str(pin), str(tree)]).splitlines()[3].split(), float)]
    if mj_cmd:
        import mujoco
        model = mujoco.MjModel.from_xml_path(str(xml_path))
        data = mujoco.MjData(model)
        data.qpos[:], data.qvel[:], data.qacc[:] = x0[:cm.n], x0[cm.n:], a
        mujoco.mj_inverse(model, data)
        peers.append(np.array(data.qfrc_inverse))
    agree = [float(np.max(np.abs(Q - tau)) / np.max(np.abs(Q))) for tau in peers]
    row = {"model": cm.name if kind == "file" else str(arg), "n": cm.n,
           "ops": cm.manifest["ops"]["inverse_dynamics"]["after_cse"],
           "mg_us": min(mg_t), "pin_us": min(pin_t), "mj_us": min(mj_t) if mj_t else None,
           "agree_pin": agree[0], "agree_mj": agree[1] if mj_cmd else None}
    row["mg_instr"] = harnesses.instructions_per_call([str(exe)]) if count else None
    row["pin_instr"] = (harnesses.instructions_per_call([str(pin_count), str(tree), "2"])
                        if pin_count and count else None)
    row["mj_instr"] = harnesses.instructions_per_call(mj_cmd) if mj_cmd and count else None
    return row


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, nargs="+", default=[7, 20, 50, 100],
                        help="chain sizes (default 7 20 50 100)")
    parser.add_argument("--arm", default=str(REPO / "models" / "arm7.yaml"),
                        help="a model file measured as well (default models/arm7.yaml); "
                             "'' to skip")
    parser.add_argument("--rounds", type=int, default=3,
                        help="alternating timing rounds, minimum kept (default 3)")
    parser.add_argument("--no-count", action="store_true",
                        help="skip the callgrind instruction counts")
    parser.add_argument("--quick", action="store_true", help="n = 7 and the arm, one round")
    args = parser.parse_args(argv)
    if args.quick:
        args.n, args.rounds = [7], 1
    root = Path(tempfile.mkdtemp(prefix="modelgen-inverse-"))
    try:
        rows, notes = _run(args, root)
    finally:
        shutil.rmtree(root, ignore_errors=True)
    if rows is None:
        print("Pinocchio not available: " + "; ".join(notes), file=sys.stderr)
        return 1
    print("# Inverse dynamics in C: modelgen against Pinocchio's rnea and MuJoCo's mj_inverse\n")

    def ratio(peer, mine):
        return f"**{fmt(peer / mine if peer and mine else None)}**"
    body = [[r["model"], r["n"], f"{r['ops'] / r['n']:.1f}", fmt(r["mg_us"]),
             fmt(r["pin_us"]), fmt(r["mj_us"]), ratio(r["pin_us"], r["mg_us"]),
             ratio(r["mj_us"], r["mg_us"]), fmt(r["mg_instr"], ",.0f"),
             fmt(r["pin_instr"], ",.0f"), fmt(r["mj_instr"], ",.0f"),
             ratio(r["pin_instr"], r["mg_instr"]), ratio(r["mj_instr"], r["mg_instr"]),
             fmt(r["agree_pin"], ".1e"), fmt(r["agree_mj"], ".1e")] for r in rows]
    print(markdown(["model", "n", "ops / coordinate", "modelgen µs", "rnea µs",
                    "mj_inverse µs", "rnea / mg", "mj_inverse / mg", "modelgen instr",
                    "rnea instr", "mj_inverse instr", "instr: rnea / mg",
                    "instr: mj_inverse / mg", "agree rnea", "agree mj_inverse"], body))
    print("\nRatios: the peer's time or instructions over modelgen's (above 1: modelgen is "
          "faster); agree: the peer's Q against modelgen's at x0, over max |Q|; –: not "
          "measured")
    for note in notes:
        print(f"- {note}")
    return 0


def _run(args, root: Path) -> tuple:
    """(the rows, the notes), or (None, why) when Pinocchio is missing."""
    peer = harnesses.build_peer_harnesses(root, count=not args.no_count)
    pin, pin_count, mj = peer.pinocchio, peer.pinocchio_count, peer.mujoco
    if pin is None:
        return None, list(peer.notes)
    # this script has no Python fallback for mj_inverse: the MuJoCo columns stay empty
    notes = [n.replace("MuJoCo timed through Python (py)", "MuJoCo not measured")
             for n in peer.notes]
    count = not args.no_count and shutil.which("valgrind") is not None
    jobs = [("chain", n) for n in args.n] + ([("file", args.arm)] if args.arm else [])
    rows = []
    for kind, arg in jobs:
        print(f"... {kind} {arg}", file=sys.stderr, flush=True)
        rows.append(measure(kind, arg, root / f"{kind}_{Path(str(arg)).stem}", pin, pin_count,
                            mj, args.rounds, count))
    return rows, notes


if __name__ == "__main__":
    sys.exit(main())
