"""Kinematics in C: a tool frame's Jacobian and the centroidal map, modelgen's
generated functions against Pinocchio's ``computeFrameJacobian`` and
``computeCentroidalMap``.

Run from the repository root (needs the ``bench`` extra: ``pin`` and ``cmeel-eigen``;
valgrind for the instruction counts)::

    .venv/bin/python bench/kinematics.py              # ur5, panda (7 joints), floating G1
    .venv/bin/python bench/kinematics.py --quick      # ur5 and panda only

Method
    Robots: the URDFs of tests/data/urdf (ur5: frame ``tool0``; panda, the
    7-joint arm: frame ``panda_link8``, nv 8 with its finger joint, whose column
    is zero; G1 with a floating base: the whole-body centroidal map).  modelgen builds each with ``kinematics=`` asking for that
    one quantity (the Jacobian in LOCAL_WORLD_ALIGNED, rows linear first); the
    harness ``modelgen/bench/harness/kinematics_mg.c`` calls
    ``<name>_frame_jacobians`` or ``<name>_centroidal_momentum_matrix``, compiled by the command modelgen's
    build used.  Pinocchio's harness ``harness/kinematics_pin.cpp`` (-O3
    -march=native) rebuilds the robot from Pinocchio's own URDF model (written
    out as text) and calls ``computeFrameJacobian(model, data, q, frame,
    LOCAL_WORLD_ALIGNED, J)`` (forward kinematics of the joints on the frame's
    branch included) or ``computeCentroidalMap(model, data, q)``.  Both loops
    perturb one entry of q from the previous result (a dependency chain).
    Time: minimum over 5 repeats of >= 0.05 s, per call.  Instructions:
    callgrind, 200 calls minus 0 (``harnesses.instructions_per_call``; none without
    valgrind);
    Pinocchio counted in its build without AVX-512.  *agree*: the largest
    difference of the two matrices at q0 (Pinocchio's Python bindings), over
    the largest entry.  Target (issue 27): >= 3x fewer instructions than
    Pinocchio for a single frame's Jacobian.
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
import modelgen  # noqa: E402
from modelgen.bench import harnesses as cs  # noqa: E402
from modelgen.bench.tables import fmt, markdown  # noqa: E402

DATA = REPO / "tests" / "data" / "urdf"
HARNESS = Path(cs.__file__).resolve().parent / "harness"
#: (label, URDF, floating base, modelgen frame or None for the centroidal map,
#: Pinocchio's frame)
CASES = (("ur5 tool0 Jacobian", "ur5_robot.urdf", False, "tool0", "tool0"),
         ("panda link8 Jacobian", "panda.urdf", False, "panda_link8", "panda_link8"),
         ("G1 centroidal map", "g1_29dof_rev_1_0.urdf", True, None, None))
_KINDS = {"JointModelRX": "RX", "JointModelRY": "RY", "JointModelRZ": "RZ",
          "JointModelPX": "PX", "JointModelPY": "PY", "JointModelPZ": "PZ",
          "JointModelFreeFlyer": "FF", "JointModelRevoluteUnaligned": "RU",
          "JointModelPrismaticUnaligned": "PU"}


def _se3(M) -> str:
    return " ".join(repr(float(x)) for x in (*M.rotation.flatten(), *M.translation))


def pinocchio_text(pin, model, frame, q) -> str:
    """The robot as kinematics_pin.cpp reads it (see its header)."""
    lines = [f"{model.nq} {model.nv} {model.njoints}"]
    for i in range(1, model.njoints):
        joint = model.joints[i]
        kind = _KINDS[joint.shortname()]
        Y = model.inertias[i]
        I = Y.inertia
        line = (f"{kind} {model.parents[i]} {_se3(model.jointPlacements[i])} {Y.mass!r} "
                + " ".join(repr(float(x)) for x in Y.lever) + " "
                + " ".join(repr(float(I[a, b])) for a, b in
                           ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))))
        if kind in ("RU", "PU"):
            line += " " + " ".join(repr(float(x)) for x in joint.extract().axis)
        lines.append(line)
    if frame is None:
        lines.append("centroidal")
    else:
        f = model.frames[model.getFrameId(frame)]
        lines.append(f"frame {f.parentJoint} {_se3(f.placement)}")
    lines.append("q " + " ".join(repr(float(x)) for x in q))
    return "\n".join(lines) + "\n"


def build_mg_harness(cm, routine: str, q0, work: Path) -> Path:
    """kinematics_mg.c on ``<name>_<routine>``, linked with the model's parts 2 and 3."""
    from modelgen.codegen.build import compiler
    objects, _ = cs.compile_model(cm, work)
    nout = (len(cm.frames) * 6 if routine == "frame_jacobians" else 6) * cm.n
    (work / "kin_case.h").write_text(
        f'#include "{cm.name}.h"\n#define NQ {cm.nq}\n#define NV {cm.n}\n#define NOUT {nout}\n'
        f"#define CALL(q, p, out) {cm.name}_{routine}(q, p, out)\n"
        f"static const double q0[NQ] = {{{cs.c_array(q0)}}};\n"
        f"static const double p[{max(len(cm.parameters), 1)}] = "
        f"{{{cs.c_array(cm.params()) or '0.0'}}};\n")
    exe = work / "kinematics_mg"
    src_dir = Path(cm.path).parent
    cs.run_checked([*compiler(), "-O2", "-std=c99", f"-I{src_dir}", f"-I{work}",
                     str(HARNESS / "kinematics_mg.c"), *objects,
                     str(src_dir / "mg_integrate.c"), "-o", str(exe), "-lm"])
    return exe


def build_pin_harness(work: Path, count: bool) -> Path:
    """kinematics_pin.cpp, compiled as the other Pinocchio harnesses are (cached)."""
    exe = work / ("kinematics_pin_count" if count else "kinematics_pin")
    cs.cached_build(cs.pinocchio_command(HARNESS / "kinematics_pin.cpp", exe, count), exe)
    return exe


def measure(case, pin, pin_exe, pin_count, work: Path, rounds: int) -> dict:
    label, file, floating, frame, pin_frame = case
    path = DATA / file
    kinematics = ({"frames": [frame], "bias_acceleration": False} if frame
                  else {"centroidal": True})
    cm = modelgen.load(str(path), work / "model", floating_base=floating or None,
                       kinematics=kinematics)
    model = (pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer()) if floating
             else pin.buildModelFromUrdf(str(path)))
    data = model.createData()
    rng = np.random.default_rng(27)
    q_pin = pin.randomConfiguration(model, -np.ones(model.nq), np.ones(model.nq)) \
        if floating else rng.uniform(-1, 1, model.nq)
    if floating:
        q_pin[:3] = rng.uniform(-1, 1, 3)
    # modelgen's q: the angles (Pinocchio's names, in its order), then x y z, qw qx qy qz
    names = [model.names[i] for i in range(1, model.njoints)
             if model.joints[i].shortname() != "JointModelFreeFlyer"]
    index = {n: model.joints[model.getJointId(n)].idx_q for n in names}
    q = np.array([q_pin[index[c]] if c in index else 0.0 for c in cm.coordinates])
    if floating:
        q[-7:] = [*q_pin[:3], q_pin[6], *q_pin[3:6]]
    v_index = {n: model.joints[model.getJointId(n)].idx_v for n in names}
    simple = [c for c in cm.coordinates if c in v_index]
    cols = [v_index[c] for c in simple] + (list(range(6)) if floating else [])
    if frame:
        mine = cm.frame_jacobian(q, frame, "local_world_aligned")
        theirs = pin.computeFrameJacobian(model, data, q_pin, model.getFrameId(pin_frame),
                                          pin.LOCAL_WORLD_ALIGNED)[:, cols]
        routine = "frame_jacobians"
    else:
        mine = cm.centroidal_map(q)
        theirs = pin.computeCentroidalMap(model, data, q_pin)[:, cols]
        routine = "centroidal_momentum_matrix"
    agree = float(np.abs(mine - theirs).max() / np.abs(theirs).max())
    exe = build_mg_harness(cm, routine, q, work / "mg")
    text = work / "pin.txt"
    text.write_text(pinocchio_text(pin, model, pin_frame, q_pin))
    mg_t, pin_t = [], []
    for _ in range(rounds):
        mg_t.append(float(cs.run_checked([str(exe)]).split()[0]) * 1e6)
        pin_t.append(float(cs.run_checked([str(pin_exe), str(text)]).split()[0]) * 1e6)
    ops = cm.manifest["ops"][routine]["after_cse"]
    return {"case": label, "nv": cm.n, "ops": ops, "mg_us": min(mg_t), "pin_us": min(pin_t),
            "mg_instr": cs.instructions_per_call([str(exe)]),
            "pin_instr": cs.instructions_per_call([str(pin_count), str(text)])
            if pin_count else None, "agree": agree}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="ur5 and panda only")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)
    try:
        import pinocchio as pin
    except ImportError:
        print("Pinocchio not available (pip install '.[bench]')", file=sys.stderr)
        return 1
    if cs.pinocchio_paths() is None:
        print("Pinocchio's C++ headers not available (cmeel-eigen)", file=sys.stderr)
        return 1
    root = Path(tempfile.mkdtemp(prefix="modelgen-kinematics-"))
    print("... Pinocchio's harness", file=sys.stderr, flush=True)
    pin_exe = build_pin_harness(root, count=False)
    pin_count = build_pin_harness(root, count=True) if shutil.which("valgrind") else None
    rows = []
    for i, case in enumerate(CASES[:2] if args.quick else CASES):
        print(f"... {case[0]}", file=sys.stderr, flush=True)
        rows.append(measure(case, pin, pin_exe, pin_count, root / f"case{i}", args.rounds))
    print("# Kinematics in C: modelgen against Pinocchio (computeFrameJacobian, "
          "computeCentroidalMap)\n")

    def ratio(peer, mine):
        return f"**{fmt(peer / mine if peer and mine else None)}**"
    body = [[r["case"], r["nv"], r["ops"], fmt(r["mg_us"]), fmt(r["pin_us"]),
             ratio(r["pin_us"], r["mg_us"]), fmt(r["mg_instr"], ",.0f"),
             fmt(r["pin_instr"], ",.0f"), ratio(r["pin_instr"], r["mg_instr"]),
             f"{r['agree']:.1e}"] for r in rows]
    print(markdown(["case", "nv", "modelgen ops", "modelgen µs", "Pinocchio µs",
                       "time: pin / mg", "modelgen instr", "Pinocchio instr",
                       "instr: pin / mg", "agree"], body))
    jac = [r for r in rows if "Jacobian" in r["case"] and r["pin_instr"] and r["mg_instr"]]
    if jac:
        worst = min(r["pin_instr"] / r["mg_instr"] for r in jac)
        print(f"\nTarget: a single frame's Jacobian in >= 3x fewer instructions than "
              f"Pinocchio: worst {worst:.1f}x, {'met' if worst >= 3 else 'NOT met'}.")
    print(f"Load average: {' '.join(f'{x:.2f}' for x in os.getloadavg())}")
    shutil.rmtree(root, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
