"""Analytical derivatives in C: modelgen's ``<name>_derivatives`` against Pinocchio's
``computeABADerivatives`` and MuJoCo's ``mjd_transitionFD``.

Run from the repository root (needs the ``bench`` extra: ``pin`` and ``cmeel-eigen``;
valgrind for the instruction counts)::

    .venv/bin/python bench/derivatives.py                  # chain n = 7, arm7, solo12
    .venv/bin/python bench/derivatives.py --n 7 20 50 --rounds 5
    .venv/bin/python bench/derivatives.py --quick          # n = 7 only, one round
    .venv/bin/python bench/derivatives.py --n 100 --no-arm

Method
    The models are the spatial chain of ``spatial_chain(n)`` and ``models/arm7.yaml``,
    written for Pinocchio by ``modelgen.bench.peers.write_peer_models`` (as
    ``bench/codegen_scaling.py`` does), at the state x0 of that script (seed
    1000 + n) and zero inputs; and floating-base solo12, example-robot-data's
    ``solo12.urdf`` imported with ``floating_base=True`` (a free joint at the root)
    against ``buildModelFromUrdf(urdf, JointModelFreeFlyer())``, written for the
    harness and as MJCF from Pinocchio's model (``peers.write_pinocchio_peer_models``),
    at q = ``cm.project`` of uniform(-pi, pi), v uniform(-2, 2) (seed 1000 + n).  Its
    free joint's speeds are body-frame in both, the derivatives in the tangent space
    in both; Pinocchio's q and v are modelgen's reordered (``robots.pinocchio_maps``:
    quaternion (x, y, z, w) last, the free flyer first), MuJoCo's have the
    quaternion scalar first and the linear velocity in the world frame.  modelgen
    and Pinocchio compute d qdd / d q and d qdd / d v of forward
    dynamics (modelgen also d qdd / d u when the model has inputs):
    ``<name>_derivatives`` through ``harness/model_bench.c -DMG_DERIVATIVES``, and
    ``computeABADerivatives(q, v, tau)`` through ``harness/pinocchio_bench.cpp``'s
    mode 3 (C++ ``-O3 -march=native``).  Time: each harness calls its function in a
    loop, perturbing one entry of x from the previous call's derivatives (a
    dependency chain), minimum over 5 repeats of >= 0.2 s; the harnesses (modelgen,
    Pinocchio, MuJoCo) run alternately ``--rounds`` times and the minimum is kept.  Instructions: callgrind,
    K = 200 calls minus K = 0 (``harnesses.instructions_per_call``), Pinocchio in
    its build without AVX-512.  *agree*: the largest difference over the largest
    entry, of both matrices, ``cm.derivatives`` at x0 against Pinocchio's.
    *MuJoCo FD*: ``mjd_transitionFD`` (central differences, eps 1e-6, the model's
    integrator set to Euler, timestep 0.001) through ``harness/mujoco_bench.c``'s
    mode ``transition``, the same timing rule, in the same alternation, and
    callgrind over K = 10 calls minus K = 0.  It computes another thing: the
    Jacobian of the discrete transition x -> x_next of one step (2 (2 nv) + 1 steps
    a call), not d qdd / d x, so its matrix is not compared; MuJoCo's qacc at x0
    against modelgen's q_ddot is printed below the table (the MJCF is the same model).
    Generation: wall and CPU seconds (the process and its compilers) and peak RSS of
    ``modelgen.load(..., derivatives=True, force=True)`` in a fresh process, started
    before this one imports numpy or the library, so that its ``ru_maxrss`` is its
    own.  ``--max-operations`` sets the build budget of every generation.  *ops / n^2*:
    operations of the per-dof vectors and the effects in one call, over n^2: after
    CSE of the ``derivative_terms`` routine, plus, where the vectors are loops over
    the joints, the kernels' operations in one call (the manifest's
    ``derivative_kernels``; O(n): the O(n^2) dot products are a loop in the C and
    not counted).  Prints the table, then the issue's targets
    (issue 25) with met / NOT met, and the ops / n^2 constants.
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
FLOATING = "solo12"            # the floating-base row's case name
SOLO12 = "solo_description/robots/solo12.urdf"       # in example-robot-data's robots
GENERATE_MARK = "@@derivatives@@ "
#: the issue's targets: instructions and time, Pinocchio / modelgen; generation s
TARGET_INSTR = 2.0
TARGET_TIME = 1.5
TARGET_SECONDS = {20: 3.0, 100: 30.0}


def solo12_urdf():
    """example-robot-data's solo12 URDF, or None when it is not installed."""
    from modelgen.bench.robots import robots_directory
    robots = robots_directory()
    return robots / SOLO12 if robots is not None and (robots / SOLO12).is_file() else None


def solo12_import():
    """solo12 imported with a free joint at its root (Pinocchio's free flyer)."""
    from modelgen.model.urdf import import_urdf
    return import_urdf(solo12_urdf(), floating_base=True)


def model_spec(arg: str):
    """The chain ``spatial_chain(int(arg))``, the model file ``arg`` or floating solo12."""
    from modelgen.model.api import load_model
    from modelgen.model.chains import spatial_chain
    if arg == FLOATING:
        return solo12_import().model
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
        "mb": mb, "ops": cm.manifest["ops"]["derivative_terms"]["after_cse"]
        + cm.manifest.get("derivative_kernels", {}).get("operations", 0)}))


def generate(arg: str, out: Path, budget=None) -> dict:
    """Run :func:`generate_child` in a fresh interpreter; its figures."""
    proc = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--generate", arg,
                           str(out), str(budget or "")], capture_output=True, text=True)
    for line in proc.stdout.splitlines():
        if line.startswith(GENERATE_MARK):
            return json.loads(line[len(GENERATE_MARK):])
    raise RuntimeError(f"generating {arg} failed (exit {proc.returncode}):\n"
                       f"{proc.stdout}{proc.stderr}")


def peer_models(arg: str, spec, cm, x0, work: Path):
    """The peers' files of one case: (MJCF, the Pinocchio harness's input, MuJoCo's
    state, P with Pinocchio's v = P v, MuJoCo's qacc of modelgen's q_ddot as a
    function), or None when the peers cannot see the model."""
    import numpy as np

    from modelgen.bench import peers
    if arg != FLOATING:
        files = peers.write_peer_models(spec, cm, x0, work, not arg.endswith(".yaml"))
        return None if files is None else (*files, x0, np.eye(cm.n), lambda a: a)
    import pinocchio as pin

    from modelgen.bench.robots import pinocchio_maps
    model = pin.buildModelFromUrdf(str(solo12_urdf()), pin.JointModelFreeFlyer())
    q_pin, P = pinocchio_maps(model, solo12_import(), cm)
    q, v = q_pin(x0[:cm.nq]), P @ x0[cm.nq:]
    files = peers.write_pinocchio_peer_models(cm.name, model, q, v, work)
    if files is None:
        return None
    links = peers.pinocchio_links(model)
    return (*files, P, lambda a: peers.mujoco_acceleration(links, q, v, P @ a))


def mujoco_qacc_agreement(xml: Path, state, qacc_of, cm, x0) -> float:
    """MuJoCo's qacc after mj_forward at ``state`` against modelgen's q_ddot at x0
    (mapped by ``qacc_of``): the largest difference over the largest entry."""
    import mujoco
    import numpy as np
    model = mujoco.MjModel.from_xml_path(str(xml))
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = state[:model.nq], state[model.nq:]
    mujoco.mj_forward(model, data)
    want = qacc_of(cm.rhs(0.0, x0)[cm.nq:])
    return float(np.max(np.abs(data.qacc - want)) / np.max(np.abs(want)))


def measure(arg: str, gen: dict, work: Path, pin, pin_count, mj, rounds: int,
            count: bool, budget=None) -> dict:
    """One model: time, count and compare every side (the row of the table).  ``pin``,
    ``pin_count``, ``mj``: Pinocchio's harness, its build for callgrind and MuJoCo's
    harness, or None."""
    import numpy as np

    import modelgen
    from modelgen.bench import harnesses as hn
    spec = model_spec(arg)
    cm = modelgen.load(spec, work / "model", derivatives=True,      # generate()'s build
                       max_operations=budget)
    n = cm.n
    rng = np.random.default_rng(1000 + n)                 # codegen_scaling's x0
    q0 = rng.uniform(-np.pi, np.pi, cm.nq)
    x0 = np.concatenate([cm.project(q0), rng.uniform(-2, 2, n)])
    exe, _ = hn.build_model_harness(cm, x0, work / "harness", "derivatives")
    files = peer_models(arg, spec, cm, x0, work / "peers") if pin or mj else None
    runs = {"mg": lambda: hn.run_model_harness(exe)}
    if pin and files:
        runs["pin"] = lambda: hn.run_pinocchio_derivatives(pin, files[1])
    mj_cmd = hn.mj_command(mj, files[0], files[2], "transition") if mj and files else None
    if mj_cmd:
        runs["mj"] = lambda: hn.run_mj_transition(mj_cmd)
    times = hn.alternate(rounds, runs)
    row = {"model": f"{FLOATING} (floating)" if arg == FLOATING else cm.name, "n": n, "gen": gen, "ops_n2": gen["ops"] / n / n,
           "mg_us": min(times["mg"]), "pin_us": None, "agree": None, "mj_us": None,
           "mj_i": None, "mj_qacc": None,
           "mg_i": hn.instructions_per_call([str(exe)]) if count else None, "pin_i": None}
    if "pin" in times:
        d = cm.derivatives(0.0, x0)
        _, pin_dq, pin_dv = times["pin"][-1]
        P = files[3]
        row["pin_us"] = min(t for t, _, _ in times["pin"])
        row["agree"] = max(float(np.max(np.abs(got - P.T @ want @ P)) / np.max(np.abs(got)))
                           for got, want in ((d.dqdd_dq, pin_dq), (d.dqdd_dv, pin_dv)))
        if count and pin_count:
            row["pin_i"] = hn.instructions_per_call([str(pin_count), str(files[1]), "3"])
    if mj_cmd:
        row["mj_us"] = min(times["mj"])
        row["mj_qacc"] = mujoco_qacc_agreement(files[0], files[2], files[4], cm, x0)
        if count:
            row["mj_i"] = hn.instructions_per_call(mj_cmd, hn.TRANSITION_COUNT_CALLS)
    return row


def ratio(a, b):
    return a / b if a and b else None


def table(rows) -> str:
    from modelgen.bench.tables import fmt, markdown
    head = ["model", "n", "generate s (wall / CPU)", "peak MB", "ops / n^2",
            "modelgen instr.", "Pinocchio instr.", "Pinocchio / modelgen (instr.)",
            "modelgen µs", "Pinocchio µs", "Pinocchio / modelgen (time)", "agree",
            "MuJoCo FD instr.", "MuJoCo FD µs", "MuJoCo FD / modelgen (time)"]
    body = [[r["model"], r["n"], f"{r['gen']['wall']:.1f} / {r['gen']['cpu']:.1f}",
             f"{r['gen']['mb']:.0f}", f"{r['ops_n2']:.0f}", fmt(r["mg_i"], ",.0f"),
             fmt(r["pin_i"], ",.0f"), fmt(ratio(r["pin_i"], r["mg_i"]), ".2f"),
             f"{r['mg_us']:.2f}", fmt(r["pin_us"], ".2f"),
             fmt(ratio(r["pin_us"], r["mg_us"]), ".2f"), fmt(r["agree"], ".1e"),
             fmt(r["mj_i"], ",.0f"), fmt(r["mj_us"], ".1f"),
             fmt(ratio(r["mj_us"], r["mg_us"]), ".0f")]
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
    parser.add_argument("--no-floating", action="store_true",
                        help="skip floating-base solo12")
    parser.add_argument("--rounds", type=int, default=3, help="alternated timing rounds")
    parser.add_argument("--no-count", action="store_true", help="skip callgrind")
    parser.add_argument("--quick", action="store_true",
                        help="n = 7 only (no arm7, no solo12), one round")
    parser.add_argument("--max-operations", type=int, default=None,
                        help="build budget of the generations (default: the library's)")
    parser.add_argument("--generate", nargs=3, metavar=("MODEL", "OUT", "BUDGET"),
                        help=argparse.SUPPRESS)     # the fresh process of generate()
    args = parser.parse_args(argv)
    if args.generate:
        generate_child(*args.generate)
        return 0
    if args.quick:
        args.n, args.no_arm, args.no_floating, args.rounds = [7], True, True, 1
    notes = []
    floating = not args.no_floating and solo12_urdf() is not None
    if not args.no_floating and not floating:
        notes.append("solo12 not measured: example-robot-data is not installed")
    cases = [str(n) for n in args.n] + ([] if args.no_arm else [args.arm]) \
        + ([FLOATING] if floating else [])
    loadavg = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        # every generation first, while this process is still small
        gens = [generate(arg, root / f"case{k}" / "model", args.max_operations)
                for k, arg in enumerate(cases)]
        from modelgen.bench import harnesses as hn
        pin, why = hn.build_pinocchio_harness(root / "pin")
        if pin is None:
            notes.append(f"Pinocchio not measured: {why}")
        mj, why = hn.build_mujoco_harness(root / "mujoco")
        if mj is None:
            notes.append(f"MuJoCo not measured: {why}")
        count = not args.no_count and shutil.which("valgrind") is not None
        if not args.no_count and not count:
            notes.append("valgrind not found: no instruction counts")
        pin_count = None
        if count and pin is not None:
            pin_count, why = hn.build_pinocchio_harness(root / "pin", count=True)
            if pin_count is None:
                notes.append(f"Pinocchio's instructions not counted: {why}")
        rows = [measure(arg, gen, root / f"case{k}", pin, pin_count, mj, args.rounds, count,
                        args.max_operations)
                for k, (arg, gen) in enumerate(zip(cases, gens, strict=True))]
    env = hn.environment()
    print(f"{env['cpu']}, {env['cores']} cores, {env['compiler']}; load average "
          f"{loadavg:.2f} at start\n")
    print(table(rows))
    print()
    for line in [*goals(rows), *notes]:
        print("- " + line)
    print("\nOperations per coordinate^2 (derivative_terms after CSE / n^2): "
          + ", ".join(f"{r['model']} {r['ops_n2']:.1f} ({r['gen']['ops']:,} / {r['n']}^2)"
                      for r in rows))
    mj_rows = [r for r in rows if r["mj_qacc"] is not None]
    if mj_rows:
        print("MuJoCo's qacc against modelgen's q_ddot at x0 (the same model): "
              + ", ".join(f"{r['model']} {r['mj_qacc']:.1e}" for r in mj_rows))
    return 0


if __name__ == "__main__":
    sys.exit(main())
