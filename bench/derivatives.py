"""Analytical derivatives in C: modelgen's ``<name>_derivatives`` against Pinocchio's
``computeABADerivatives``.

Run from the repository root (needs the ``bench`` extra: ``pin`` and ``cmeel-eigen``)::

    .venv/bin/python bench/derivatives.py                 # n = 7 20 50 and arm7
    .venv/bin/python bench/derivatives.py --n 7 --no-arm --rounds 1

Method
    The models and the Pinocchio harness's model reader are those of
    ``bench/codegen_scaling.py`` (the spatial chain of ``spatial_chain(n)`` and
    ``models/arm7.yaml``, built in C++ from the same definition, compiled
    ``-O3 -march=native``), at that script's state x0 and zero inputs.  Both
    compute d qdd / d q and d qdd / d v of forward dynamics (modelgen also
    d qdd / d u when the model has inputs): ``<name>_derivatives`` (rhs for
    qdd, the RNEA derivatives at a = qdd, M^-1 by a sparse LDL^T on all
    columns) and Pinocchio's ``computeABADerivatives(q, v, tau)``.  *agree*:
    the largest difference over the largest entry, of both matrices.  Time:
    each harness calls its function in a loop, perturbing one entry of x from
    the previous output (a dependency chain), minimum over 5 repeats of >= 0.2 s,
    run alternately ``--rounds`` times, minimum kept.  Instructions: callgrind,
    K = 200 calls minus none (``codegen_scaling.instructions_per_call``);
    Pinocchio counted in its build without AVX-512.  Generation: wall and CPU
    seconds (this process and the compilers) and peak memory of
    ``modelgen.load(..., derivatives=True, force=True)`` in a fresh process.
    *ops*: operations after CSE of the ``derivative_terms`` routine (dQ/dq,
    dQ/dv, dQ/du, M) over n^2.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
_spec = importlib.util.spec_from_file_location("codegen_scaling", REPO / "bench" / "codegen_scaling.py")
cs = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(cs)

import modelgen  # noqa: E402
from modelgen.model.api import load_model  # noqa: E402
from modelgen.model.chains import spatial_chain  # noqa: E402

#: the issue's targets: instructions ratio Pinocchio / modelgen, generation seconds
TARGET_RATIO = 2.0
TARGET_SECONDS = {20: 3.0, 100: 30.0}

# Pinocchio's computeABADerivatives in the harness of codegen_scaling (its model
# reader and timing loop), with a main of its own.
_PIN_DERIVATIVES = cs._PIN_HARNESS.split("int main(")[0].replace(
    "#include <pinocchio/algorithm/cholesky.hpp>",
    "#include <pinocchio/algorithm/cholesky.hpp>\n"
    "#include <pinocchio/algorithm/aba-derivatives.hpp>") + r"""
static double run_derivatives(pinocchio::Data &data, long loops, double &sink) {
    const int n = model.nv;
    Eigen::VectorXd q = Eigen::Map<const Eigen::VectorXd>(x0, n);
    Eigen::VectorXd v = Eigen::Map<const Eigen::VectorXd>(x0 + n, n);
    Eigen::VectorXd tau = Eigen::VectorXd::Zero(n);
    const double start = now();
    for (long k = 0; k < loops; ++k) {
        const int j = (int)(k %% n);
        q[j] = x0[j] + 1e-9 * data.ddq_dq(n - 1, j);
        pinocchio::computeABADerivatives(model, data, q, v, tau);
        sink += data.ddq_dv(n - 1, n - 1);
    }
    return now() - start;
}

int main(int argc, char **argv) {
    if (argc < 2 || argc > 3 || !read_chain(argv[1])) {
        std::fprintf(stderr, "usage: pin_derivatives tree.txt [K]\n");
        return 2;
    }
    pinocchio::Data data(model);
    const int n = model.nv;
    double sink = 0.0;
    data.ddq_dq.setZero();
    if (argc == 3) {
        run_derivatives(data, std::atol(argv[2]), sink);
        std::printf("%%.17g\n", sink);
        return 0;
    }
    long loops = 1;
    while (run_derivatives(data, loops, sink) < %(min_seconds)s) loops *= 2;
    double b = 1e300;
    for (int r = 0; r < %(repeats)d; ++r) {
        const double t = run_derivatives(data, loops, sink) / (double)loops;
        if (t < b) b = t;
    }
    std::printf("%%.9e %%.3g\n", b, sink * 0.0);
    Eigen::VectorXd q = Eigen::Map<const Eigen::VectorXd>(x0, n);
    Eigen::VectorXd v = Eigen::Map<const Eigen::VectorXd>(x0 + n, n);
    pinocchio::computeABADerivatives(model, data, q, v, Eigen::VectorXd::Zero(n));
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) std::printf("%%.17g ", data.ddq_dq(i, j));
    std::printf("\n");
    for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) std::printf("%%.17g ", data.ddq_dv(i, j));
    std::printf("\n");
    return 0;
}
"""


def build_pinocchio(work: Path, count: bool = False):
    """The computeABADerivatives harness, like codegen_scaling's build_pinocchio_harness."""
    import os
    import shlex
    paths = cs.pinocchio_paths()
    if paths is None:
        return None
    include, lib = paths
    work.mkdir(parents=True, exist_ok=True)
    src = work / "pin_derivatives.cpp"
    src.write_text(_PIN_DERIVATIVES % {"min_seconds": cs.MIN_SECONDS, "repeats": cs.REPEATS})
    exe = work / ("pin_derivatives_count" if count else "pin_derivatives")
    arch = ["-march=native", "-mno-avx512f"] if count else ["-march=native"]
    cs._run_checked([*shlex.split(os.environ.get("CXX", "c++")), "-O3", *arch, "-DNDEBUG",
                     "-std=c++17", "-DBOOST_MPL_LIMIT_LIST_SIZE=30",
                     "-DBOOST_MPL_LIMIT_VECTOR_SIZE=30",
                     "-DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS",
                     "-DBOOST_FUSION_INVOKE_MAX_ARITY=12", f"-I{include}",
                     f"-I{include / 'eigen3'}", str(src), "-o", str(exe), f"-L{lib}",
                     "-lpinocchio_default", f"-Wl,-rpath,{lib}"])
    return exe


def build_model(cm, x0, work: Path) -> Path:
    """The harness of ``<name>_derivatives`` (codegen_scaling's C harness and build)."""
    from modelgen.codegen.build import compiler
    name, n, nu = cm.name, cm.n, len(cm.inputs)
    cs.compile_model(cm, work)
    du = f"out + {2 * n * n}" if nu else "NULL"
    harness = work / "derivatives_bench.c"
    harness.write_text(cs._MG_HARNESS.format(
        what=f"Harness of {name}_derivatives", name=name, NAME=name.upper(), nx=cm.nx,
        nout=2 * n * n + n * nu, call=f"{name}_derivatives(0.0, x, u, p, out, out + {n * n}, {du})",
        x0=cs._c_array(x0), np_=max(len(cm.parameters), 1), p=cs._c_array(cm.params()) or "0.0",
        nu_=max(nu, 1), min_seconds=cs.MIN_SECONDS, repeats=cs.REPEATS))
    exe = work / "derivatives_bench"
    src_dir = Path(cm.path).parent
    cs._run_checked([*compiler(), "-O2", "-std=c99", f"-I{src_dir}", str(harness),
                     str(work / "model_rhs.o"), str(src_dir / "mg_integrate.c"), "-o", str(exe),
                     "-lm"])
    return exe


_GENERATE = r"""
import json, resource, sys, time
sys.path.insert(0, {repo!r})
import modelgen
from modelgen.model.api import load_model
from modelgen.model.chains import spatial_chain
arg = {arg!r}
spec = load_model(arg) if arg.endswith(".yaml") else spatial_chain(int(arg)).spec()
t0 = time.perf_counter()
cm = modelgen.load(spec, {out!r}, derivatives=True, force=True)
wall = time.perf_counter() - t0
me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
print(json.dumps(dict(wall=wall, cpu=me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime,
                      mb=max(me.ru_maxrss, kids.ru_maxrss) / 1024,
                      ops=cm.manifest["ops"]["derivative_terms"]["after_cse"])))
"""


def generate(arg: str, out: Path) -> dict:
    """Generation of the model with its derivatives in a fresh process (figures above)."""
    code = _GENERATE.format(repo=str(REPO), arg=arg, out=str(out))
    text = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True,
                          text=True).stdout
    return json.loads(text.strip().splitlines()[-1])


def measure(arg: str, work: Path, pin, pin_count, rounds: int) -> dict:
    gen = generate(arg, work / "model")
    spec = load_model(arg) if arg.endswith(".yaml") else spatial_chain(int(arg)).spec()
    cm = modelgen.load(spec, work / "model", derivatives=True)
    n = cm.n
    rng = np.random.default_rng(1000 + n)                # codegen_scaling's state
    x0 = np.concatenate([rng.uniform(-np.pi, np.pi, n), rng.uniform(-2, 2, n)])
    if arg.endswith(".yaml"):
        tree = cs.pinocchio_tree_file(cs.tree_links(spec, cm.parameters),
                                      float(cm.parameters["g"]), x0, work / "pin.txt")
    else:
        tree = cs.pinocchio_chain_file(n, cm.parameters, x0, work / "pin.txt")
    exe = build_model(cm, x0, work / "harness")
    mg_t, pin_t = [], []
    for _ in range(rounds):
        mg_t.append(cs.run_rhs_harness(exe))
        pin_t.append(float(cs._run_checked([str(pin), str(tree)]).split()[0]) * 1e6)
    lines = cs._run_checked([str(pin), str(tree)]).splitlines()
    d = cm.derivatives(0.0, x0)
    agree = max(float(np.max(np.abs(got - np.array(line.split(), float).reshape(n, n)))
                      / np.max(np.abs(got)))
                for got, line in ((d.dqdd_dq, lines[1]), (d.dqdd_dv, lines[2])))
    mg_i = cs.instructions_per_call([str(exe)])
    pin_i = cs.instructions_per_call([str(pin_count), str(tree)]) if pin_count else None
    return {"model": cm.name, "n": n, "gen": gen, "ops_n2": gen["ops"] / n / n,
            "mg_us": min(mg_t), "pin_us": min(pin_t), "mg_i": mg_i, "pin_i": pin_i,
            "agree": agree}


def table(rows) -> str:
    head = ["model", "n", "generate s (wall / CPU)", "peak MB", "ops / n^2",
            "modelgen instr.", "Pinocchio instr.", "Pinocchio / modelgen (instr.)",
            "modelgen µs", "Pinocchio µs", "Pinocchio / modelgen (time)", "agree"]
    out = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for r in rows:
        ratio = r["pin_i"] / r["mg_i"] if r["mg_i"] and r["pin_i"] else None
        out.append("| " + " | ".join([
            r["model"], str(r["n"]), f"{r['gen']['wall']:.1f} / {r['gen']['cpu']:.1f}",
            f"{r['gen']['mb']:.0f}", f"{r['ops_n2']:.0f}", cs.fmt(r["mg_i"], ",.0f"),
            cs.fmt(r["pin_i"], ",.0f"), cs.fmt(ratio, ".2f"), f"{r['mg_us']:.2f}",
            f"{r['pin_us']:.2f}", f"{r['pin_us'] / r['mg_us']:.2f}", f"{r['agree']:.1e}"]) + " |")
    return "\n".join(out)


def goals(rows) -> list:
    lines = []
    for r in rows:
        if r["mg_i"] and r["pin_i"]:
            ratio = r["pin_i"] / r["mg_i"]
            lines.append(f"{r['model']}: {ratio:.2f}x fewer instructions than "
                         f"computeABADerivatives (target >= {TARGET_RATIO}): "
                         + ("met" if ratio >= TARGET_RATIO else "NOT met"))
        if r["n"] in TARGET_SECONDS and r["model"].startswith("spatial_chain"):
            limit = TARGET_SECONDS[r["n"]]
            lines.append(f"{r['model']}: generation {r['gen']['cpu']:.1f} s CPU (target <= "
                         f"{limit} s): " + ("met" if r["gen"]["cpu"] <= limit else "NOT met"))
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, nargs="+", default=[7, 20, 50])
    parser.add_argument("--arm", default=str(REPO / "models" / "arm7.yaml"))
    parser.add_argument("--no-arm", action="store_true")
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        pin = build_pinocchio(root / "pin")
        if pin is None:
            print("Pinocchio is not installed (pip install '.[bench]')")
            return 1
        pin_count = build_pinocchio(root / "pin", count=True)
        cases = [str(n) for n in args.n] + ([] if args.no_arm else [args.arm])
        rows = [measure(arg, root / f"case{k}", pin, pin_count, args.rounds)
                for k, arg in enumerate(cases)]
    print(table(rows))
    print()
    for line in goals(rows):
        print("- " + line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
