"""How modelgen scales with the size of a model, and how it compares with MuJoCo.

Run from the repository root::

    .venv/bin/python bench/codegen_scaling.py            # n = 2 4 7 10 15 20 30 50
    .venv/bin/python bench/codegen_scaling.py --quick    # n = 2 4 7 10
    .venv/bin/python bench/codegen_scaling.py --n 2 4 7 --json out.json

Model
    ``modelgen.model.chains.spatial_chain(n)``: n uniform rods hanging from the
    origin, hinge axes alternating z (odd joints) and y (even joints).  If
    ``models/arm7.yaml`` exists (``--arm``), the 7-joint arm gets a row too;
    it is the official target of the per-call goals.  A model file that is a
    tree of revolute joints with gravity (0, 0, -g) and no effects (actions
    only through inputs, which the harnesses hold at 0), like the arm, is
    also timed in MuJoCo and Pinocchio: :func:`tree_links` reads its joints
    and inertias off modelgen's joint tree, :func:`tree_mjcf` and
    :func:`pinocchio_tree_file` write them for the peers.

Method
    * Generation.  Every model is generated in a fresh subprocess (so memory
      is measured per model) into a temporary directory, with
      ``modelgen.load(spec, out_dir, force=True)``: derive, CSE, emit and
      compile are modelgen's own stage timers (``manifest["seconds"]``);
      *total* is the wall time from the ModelSpec in hand to a loaded
      ``CompiledModel`` (it also covers hashing, import of the extension and
      the mass-matrix sanity check; the difference is the column *other*).
      The child's import of modelgen (with sympy and numpy; column *import*)
      and the building of the spec (JSON only) are not in *total*.  Peak RSS is
      ``getrusage(RUSAGE_SELF).ru_maxrss`` of the child just after loading
      (the Python side, including the interpreter and sympy) and
      ``RUSAGE_CHILDREN`` (the largest compiler process).
    * Operation counts are modelgen's counts for the ``rhs`` routine (the
      mass matrix A and b = tau - h, or the ABA program) before and after CSE,
      as C operators (:func:`modelgen.codegen.printer.c_operations`); after
      CSE without the parameter-only statements ``<name>_prepare`` computes.  They do not
      include the Cholesky solve that ``<name>_rhs`` runs on A in a C loop
      (about n^3/6 multiply-adds).  The exponent is a least-squares fit of
      log(ops) against log(n) over the chains run; the *local* exponent is
      the slope between the two largest n (closer to the asymptotic one).
    * rhs in C.  A small harness that includes the generated ``<name>.h`` is
      compiled at -O2 and linked with ``<name>.c`` compiled by the exact
      command modelgen's build used for the rhs part (from the manifest's
      ``compile_commands``, i.e. ``build.compile_flags``).  It calls
      ``<name>_prepare`` once and ``<name>_rhs_prepared`` in a loop (what an
      integration runs; the peers too keep their models' inertias
      precomputed), perturbing one entry of x from the previous
      output every iteration (so nothing can be hoisted and consecutive calls
      form a dependency chain), and reports the minimum per-call time over 5
      repeats of at least 0.2 s each.  The modelgen and MuJoCo harnesses are
      run alternately ``--rounds`` times (default 3) and the minimum of each
      is kept, so a busy spell of a shared machine hits both sides.
    * rhs from Python: ``f.inplace(t)`` (state in ``f.x``, no copies) and
      ``f = cm.rhs_function(); f(t, x, out)`` with a
      preallocated ``out`` (the low-overhead path), and plain
      ``cm.rhs(t, x)``; ``timeit`` with the same min-of-5 x >= 0.2 s rule.
    * MuJoCo.  The identical chain is written as MJCF (hinges about z / y of
      the body frame, which sits at the joint; inertial at (l/2, 0, 0) with
      the rods' principal moments; gravity (0, 0, -g); contacts disabled; no
      damping or armature; timestep 0.001, RK4).  Agreement: at 5 seeded
      random states, ``qacc`` after ``mj_forward`` against modelgen's qdd,
      reported as max over states of ||qacc - qdd||_inf / ||qdd||_inf.
      Timing: a C harness linked against the wheel's libmujoco times
      ``mj_forward`` (one forward-dynamics evaluation = one rhs call) with
      the same perturbation rule, and ``mj_step`` with RK4 divided by 4 (four
      force evaluations per step; the state restarts from x0 every 1000
      steps).  Column *mj_forward py* is the same call from a Python loop, for
      the binding overhead.  If the MuJoCo headers or library are not
      usable the Python loop ``mujoco.mj_forward(m, d)`` is timed instead
      (marked ``py``); if mujoco is not installed its columns are skipped.

    * Pinocchio (``pin`` and ``cmeel-eigen`` from the package index, the
      ``bench`` extra).  The chain is built in C++ from the same definition
      (:func:`modelgen.bench.hard_case_models.chain_pinocchio_cpp`) and a
      harness compiled with ``-O3 -march=native`` against the wheels'
      headers times ``pinocchio::aba`` and the CRBA path
      (``crba`` + ``nonLinearEffects`` + Pinocchio's tree-sparse
      ``cholesky::decompose/solve``) with the same perturbation rule, in the
      same alternating rounds.  *agree (4 engines)*: q_ddot at x0 by
      modelgen, MuJoCo, Pinocchio ABA and Pinocchio CRBA, the largest
      pairwise max-norm difference over max |q_ddot|.

    * Instructions (unless ``--no-count``; needs valgrind).  The same three
      loops, run untimed K = 200 times and not at all under valgrind's
      callgrind: the difference over K is the instructions per call, the same
      on every run whatever else the machine does (the timings are not).
      Each call carries the harness loop's few instructions, alike for the
      three engines.  Pinocchio is counted in a second build with
      ``-mno-avx512f`` added, since valgrind does not decode AVX-512 (on a CPU
      without it, the timed build's code).

Reading the tables
    Times in seconds (generation) or microseconds (per call); RSS in MB.
    The header gives the 1-minute load average before the run: on a 2-core
    machine anything above ~0.5 means something else is running and the
    per-call times (and ratios near 1) are noisy; run it again when quiet.
    Column *-O* gives the optimisation levels modelgen's build chose for the
    two compiled parts of ``<name>.c`` (it drops to -O1 for big routines).
    ``mj/mg`` is MuJoCo's mj_forward time over modelgen's rhs time, both in
    C: above 1 means modelgen is faster.  ``rel diff`` should be around 1e-9
    or below (it grows with cond(A), roughly n^4 for these chains).  The goal
    list at the end states each goal, the measured value and whether it is
    met (``not run`` when the n it needs was not in this run).
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import resource
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
import timeit
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
DEFAULT_NS = (2, 4, 7, 10, 15, 20, 30, 50)
QUICK_NS = (2, 4, 7, 10)
RESULT_MARK = "@@codegen_scaling@@ "
MIN_SECONDS = 0.2        # each timing repeat runs at least this long
REPEATS = 5              # minimum over this many repeats
N_CHECK_STATES = 5       # random states for the MuJoCo agreement check
STEP_RESET = 1000        # mj_step harness: restart from x0 every this many steps
COUNT_CALLS = 200        # calls per callgrind count (instructions_per_call)


# ---------------------------------------------------------------------------------
# C harnesses
# ---------------------------------------------------------------------------------

_MG_HARNESS = r"""/* {what}, written by bench/codegen_scaling.py.
 * No argument: prints the best time per call, the loops, the status and a sink.
 * K: K calls untimed, then the status and the sink (for callgrind). */
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "{name}.h"

#define NX {nx}
#define NOUT {nout}

static double now(void)
{{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}}

static const double x0[NX] = {{{x0}}};
static const double p[{np_}] = {{{p}}};
static double pd[{NAME}_NPD_ALLOC];
static double u[{nu_}];
static double x[NX], a[NX], out[NOUT];
static int status;
static double sink;

/* ``loops`` calls; x[j] is reset to x0[j] plus a tiny amount taken from the
 * previous output, so every call depends on the one before. */
static double run(long loops)
{{
    long k;
    const double start = now();
    for (k = 0; k < loops; ++k) {{
        const int j = (int)(k % NX);
        x[j] = x0[j] + 1e-9 * out[NOUT - 1 - j % NOUT];
        status |= {call};
        sink += out[NOUT - 1];
    }}
    return now() - start;
}}

int main(int argc, char **argv)
{{
    long loops = 1;
    int r, i;
    double best = 1e300;
    for (i = 0; i < NX; ++i) {{
        x[i] = x0[i];
        a[i] = 0.3 * (double)(i % 3) - 0.2;     /* accelerations, for inverse dynamics */
    }}
    {name}_prepare(p, pd);      /* once, as the peers' models hold their inertias */
    status = {call};
    if (argc == 2) {{
        run(atol(argv[1]));
        printf("%d %.17g\n", status, sink);
        return 0;
    }}
    while (run(loops) < {min_seconds})
        loops *= 2;
    for (r = 0; r < {repeats}; ++r) {{
        const double t = run(loops) / (double)loops;
        if (t < best)
            best = t;
    }}
    printf("%.9e %ld %d %.17g\n", best, loops, status, sink);
    return 0;
}}
"""

_MJ_HARNESS = r"""/* Timing harness for MuJoCo's mj_forward and mj_step, written by
 * bench/codegen_scaling.py.  Usage: mjbench model.xml state.txt [K]
 * where state.txt holds qpos then qvel (nq + nv numbers).  With K, it calls
 * mj_forward K times untimed and exits (for callgrind).  mjbench model.xml
 * state.txt inverse [K] does the same with mj_inverse at the accelerations
 * 0.3 (i mod 3) - 0.2 (bench/inverse_dynamics.py), printing its best time. */
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <mujoco/mujoco.h>

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static mjModel *m;
static mjData *d;
static double q0[1024], v0[1024];
static double sink;

static void reset(void)
{
    memcpy(d->qpos, q0, sizeof(double) * (size_t)m->nq);
    memcpy(d->qvel, v0, sizeof(double) * (size_t)m->nv);
    d->time = 0.0;
}

static double run_forward(long loops)
{
    long k;
    const int nv = m->nv;
    const double start = now();
    for (k = 0; k < loops; ++k) {
        const int j = (int)(k % nv);
        d->qpos[j] = q0[j] + 1e-9 * d->qacc[nv - 1 - j];
        mj_forward(m, d);
        sink += d->qacc[nv - 1];
    }
    return now() - start;
}

static double run_inverse(long loops)
{
    long k;
    int i;
    const int nv = m->nv;
    double start;
    for (i = 0; i < nv; ++i)
        d->qacc[i] = 0.3 * (double)(i % 3) - 0.2;
    start = now();
    for (k = 0; k < loops; ++k) {
        const int j = (int)(k % nv);
        d->qpos[j] = q0[j] + 1e-9 * d->qfrc_inverse[nv - 1 - j];
        mj_inverse(m, d);
        sink += d->qfrc_inverse[nv - 1];
    }
    return now() - start;
}

static double run_step(long loops)
{
    long k;
    double start;
    reset();
    start = now();
    for (k = 0; k < loops; ++k) {
        if (k % STEP_RESET == 0)
            reset();
        mj_step(m, d);
        sink += d->qacc[0];
    }
    return now() - start;
}

static double best_of(double (*run)(long))
{
    long loops = 1;
    int r;
    double best = 1e300;
    while (run(loops) < MIN_SECONDS)
        loops *= 2;
    for (r = 0; r < REPEATS; ++r) {
        const double t = run(loops) / (double)loops;
        if (t < best)
            best = t;
    }
    return best;
}

int main(int argc, char **argv)
{
    char error[1000] = "";
    FILE *f;
    int i;
    double forward, step;
    if (argc < 3 || argc > 5) {
        fprintf(stderr, "usage: %s model.xml state.txt [inverse] [K]\n", argv[0]);
        return 2;
    }
    m = mj_loadXML(argv[1], NULL, error, sizeof(error));
    if (!m) {
        fprintf(stderr, "mj_loadXML: %s\n", error);
        return 1;
    }
    if (m->nq > 1024 || m->nv > 1024) {
        fprintf(stderr, "model too large for the harness\n");
        return 1;
    }
    d = mj_makeData(m);
    f = fopen(argv[2], "r");
    if (!f) {
        fprintf(stderr, "cannot open %s\n", argv[2]);
        return 1;
    }
    for (i = 0; i < m->nq; ++i)
        if (fscanf(f, "%lf", &q0[i]) != 1) return 1;
    for (i = 0; i < m->nv; ++i)
        if (fscanf(f, "%lf", &v0[i]) != 1) return 1;
    fclose(f);
    reset();
    mj_forward(m, d);
    if (argc >= 4 && strcmp(argv[3], "inverse") == 0) {
        if (argc == 5)
            run_inverse(atol(argv[4]));
        else
            printf("%.9e ", best_of(run_inverse));
        printf("%.17g\n", sink);
        return 0;
    }
    if (argc == 4) {
        run_forward(atol(argv[3]));
        printf("%.17g\n", sink);
        return 0;
    }
    forward = best_of(run_forward);
    step = best_of(run_step);
    printf("%.9e %.9e %d %.17g\n", forward, step,
           d->warning[mjWARN_BADQACC].number, sink);
    mj_deleteData(d);
    mj_deleteModel(m);
    return 0;
}
"""


def _run_checked(cmd, cwd=None) -> str:
    """Run a command; raise RuntimeError with its full output if it fails."""
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"command failed (exit {proc.returncode}): {shlex.join(cmd)}\n"
                           f"{proc.stdout}{proc.stderr}")
    return proc.stdout


def _c_array(values) -> str:
    return ", ".join(repr(float(v)) for v in values)


def compile_model(cm, work: Path):
    """``<name>.c``'s integration path (part 2: the rhs, inverse dynamics...) compiled
    by the exact command modelgen's build used (from the manifest) into
    ``work/model_rhs.o``; returns that command."""
    from modelgen.codegen.build import compile_flags, compiler
    name, manifest = cm.name, cm.manifest
    src_dir = Path(cm.path).parent
    work.mkdir(parents=True, exist_ok=True)
    commands = [shlex.split(c) for c in manifest.get("compile_commands", [])]
    part2 = [c for c in commands if "-DMG_PART=2" in c]
    if part2:
        cmd = list(part2[0])
        cmd[cmd.index("-o") + 1] = str(work / "model_rhs.o")
        cmd[cmd.index(f"{name}.c")] = str(src_dir / f"{name}.c")
    else:   # no compile_commands in the manifest: rebuild them from compile_flags
        statements = max(r["statements"] for r in manifest["ops"].values())
        cmd = [*compiler(), *compile_flags(statements, 2), "-DMG_PART=2", "-c",
               str(src_dir / f"{name}.c"), "-o", str(work / "model_rhs.o")]
    _run_checked(cmd)
    return shlex.join(cmd)


def build_model_harness(cm, x0, work: Path, function: str = "rhs_prepared"):
    """Compile the C harness (:data:`_MG_HARNESS`) of ``<name>_rhs_prepared`` or of
    ``<name>_inverse_dynamics`` (at the accelerations 0.3 (i mod 3) - 0.2); returns
    (executable, the command that compiled the model's C).  The harness itself is
    compiled at -O2.  It times the function, or with an argument K calls it K times
    for :func:`instructions_per_call`.
    """
    from modelgen.codegen.build import compiler
    name = cm.name
    src_dir = Path(cm.path).parent
    command = compile_model(cm, work)
    if function == "rhs_prepared":
        call, nout = f"{name}_rhs_prepared(0.0, x, u, p, pd, out)", cm.nx
    elif function == "inverse_dynamics":
        call, nout = f"({name}_inverse_dynamics(0.0, x, a, u, p, out), 0)", cm.n
    else:
        raise ValueError(f"no harness for {function!r}")
    harness = work / f"{function}_bench.c"
    harness.write_text(_MG_HARNESS.format(
        what=f"Harness of {name}_{function}", name=name, NAME=name.upper(), nx=cm.nx,
        nout=nout, call=call, x0=_c_array(x0), np_=max(len(cm.parameters), 1),
        p=_c_array(cm.params()) or "0.0", nu_=max(len(cm.inputs), 1),
        min_seconds=MIN_SECONDS, repeats=REPEATS))
    exe = work / f"{function}_bench"
    # the model's integrate wrappers call the shared integrators, copied beside it
    _run_checked([*compiler(), "-O2", "-std=c99", f"-I{src_dir}", str(harness),
                  str(work / "model_rhs.o"), str(src_dir / "mg_integrate.c"), "-o", str(exe),
                  "-lm"])
    return exe, command


def build_rhs_harness(cm, x0, work: Path):
    """The harness of ``<name>_rhs_prepared`` (:func:`build_model_harness`)."""
    return build_model_harness(cm, x0, work)


def callgrind_total(cmd) -> int:
    """Instructions that ``cmd`` executes, by valgrind's callgrind (no load dependence)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "callgrind.out"
        _run_checked(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", *cmd])
        for line in out.read_text().splitlines():
            if line.startswith(("summary:", "totals:")):
                return int(line.split()[1])
    raise RuntimeError(f"no instruction total in callgrind's output of {shlex.join(cmd)}")


def instructions_per_call(cmd, calls: int = COUNT_CALLS):
    """Instructions per call of the loop a harness runs with ``cmd + [str(K)]``: the
    difference between K = ``calls`` and K = 0, so loading and setting up cancel.  Each
    call carries the harness loop's few instructions (the perturbation of x and the
    sum), the same in every engine's harness.  None without valgrind."""
    if shutil.which("valgrind") is None:
        return None
    return (callgrind_total([*cmd, str(calls)]) - callgrind_total([*cmd, "0"])) / calls


def rhs_instructions(cm, x0, work: Path, calls: int = COUNT_CALLS):
    """Instructions per ``<name>_rhs_prepared`` call (callgrind, inclusive of sin/cos and
    of the harness loop; :func:`instructions_per_call`), or None without valgrind."""
    if shutil.which("valgrind") is None:
        return None
    exe, _ = build_rhs_harness(cm, x0, work)
    return instructions_per_call([str(exe)], calls)


def run_rhs_harness(exe: Path) -> float:
    """One run of a harness of :func:`build_model_harness`: per-call time in µs (min
    over REPEATS)."""
    best, _loops, status, _sink = _run_checked([str(exe)]).split()
    if int(status):
        raise RuntimeError(f"{exe}: the rhs returned status {status}")
    return float(best) * 1e6


def have_mujoco() -> bool:
    """Whether the mujoco Python package imports."""
    try:
        import mujoco  # noqa: F401
    except ImportError:
        return False
    return True


def mujoco_paths():
    """(include dir, library file) of the installed mujoco wheel, or None."""
    spec = importlib.util.find_spec("mujoco")
    if spec is None or not spec.submodule_search_locations:
        return None
    root = Path(list(spec.submodule_search_locations)[0])
    include = root / "include"
    libs = sorted(root.glob("libmujoco.so*")) or sorted(root.glob("libmujoco*.dylib"))
    if not (include / "mujoco" / "mujoco.h").is_file() or not libs:
        return None
    return include, libs[0]


def build_mujoco_harness(work: Path):
    """Compile the MuJoCo timing harness; returns its path, or (None, reason)."""
    paths = mujoco_paths()
    if paths is None:
        return None, "mujoco headers or library not found in the wheel"
    include, lib = paths
    work.mkdir(parents=True, exist_ok=True)
    src = work / "mj_bench.c"
    src.write_text(_MJ_HARNESS)
    exe = work / "mj_bench"
    cmd = [*shlex.split(os.environ.get("CC", "cc")), "-O2", "-std=c99",
           f"-DMIN_SECONDS={MIN_SECONDS}", f"-DREPEATS={REPEATS}", f"-DSTEP_RESET={STEP_RESET}",
           f"-I{include}", str(src), "-o", str(exe), str(lib), f"-Wl,-rpath,{lib.parent}",
           "-lm"]
    try:
        _run_checked(cmd)
    except RuntimeError as exc:
        return None, f"MuJoCo harness did not build: {exc}"
    return exe, None


_PIN_HARNESS = r"""// Timing harness for Pinocchio's ABA and CRBA + Cholesky, written by
// bench/codegen_scaling.py.  Usage: pin_bench tree.txt, the file holding n,
// then per joint (parents first) "parent(0 = ground, else 1-based) axis(0 = z,
// 1 = y, 2 = x) R(9, row-major, joint frame in the parent's) p(3) mass c(3)
// Ixx Iyy Izz Ixy Ixz Iyz (about c)", then g, then x0 (2n numbers).
// Prints: aba_s crba_s, then q_ddot at x0 by each, then rnea's tau at x0 and the
// accelerations ACC(i).  pin_bench tree.txt WHICH prints the time of ABA (WHICH 0),
// the CRBA path (1) or rnea (2) alone; pin_bench tree.txt WHICH K instead calls it
// K times untimed (for callgrind).
#include <cstdlib>
#include <cstdio>
#include <ctime>
#include <string>
#include <pinocchio/multibody.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/algorithm/cholesky.hpp>

static double now() {
    timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static pinocchio::Model model;
static double x0[2048];

// the accelerations given to rnea (bench/inverse_dynamics.py uses the same)
#define ACC(i) (0.3 * (double)((i) %% 3) - 0.2)

static void crba_path(pinocchio::Data &data, const Eigen::VectorXd &q, const Eigen::VectorXd &v,
                      const Eigen::VectorXd &tau, Eigen::VectorXd &qdd) {
    pinocchio::crba(model, data, q);
    pinocchio::nonLinearEffects(model, data, q, v);
    qdd = tau - data.nle;
    pinocchio::cholesky::decompose(model, data);   // reads the upper triangle of M
    pinocchio::cholesky::solve(model, data, qdd);
}

template <int WHICH> static double run(pinocchio::Data &data, long loops, double &sink) {
    const int n = model.nv;
    Eigen::VectorXd q = Eigen::Map<const Eigen::VectorXd>(x0, n);
    Eigen::VectorXd v = Eigen::Map<const Eigen::VectorXd>(x0 + n, n);
    Eigen::VectorXd tau = Eigen::VectorXd::Zero(n), qdd = Eigen::VectorXd::Zero(n);
    Eigen::VectorXd acc(n);
    for (int i = 0; i < n; ++i) acc[i] = ACC(i);
    const double start = now();
    for (long k = 0; k < loops; ++k) {
        const int j = (int)(k %% n);
        q[j] = x0[j] + 1e-9 * qdd[n - 1 - j];
        if (WHICH == 0) {
            pinocchio::aba(model, data, q, v, tau);
            qdd = data.ddq;
        } else if (WHICH == 1) {
            crba_path(data, q, v, tau, qdd);
        } else {
            pinocchio::rnea(model, data, q, v, acc);
            qdd = data.tau;
        }
        sink += qdd[n - 1];
    }
    return now() - start;
}

template <int WHICH> static double best(pinocchio::Data &data, double &sink) {
    long loops = 1;
    while (run<WHICH>(data, loops, sink) < %(min_seconds)s) loops *= 2;
    double b = 1e300;
    for (int r = 0; r < %(repeats)d; ++r) {
        const double t = run<WHICH>(data, loops, sink) / (double)loops;
        if (t < b) b = t;
    }
    return b;
}

static int read_chain(const char *path) {
    std::FILE *f = std::fopen(path, "r");
    int n = 0;
    if (!f || std::fscanf(f, "%%d", &n) != 1 || n < 1 || n > 1024) return 0;
    for (int i = 0; i < n; ++i) {
        int parent, axis;
        double v[22];
        if (std::fscanf(f, "%%d %%d", &parent, &axis) != 2 || parent < 0 || parent > i)
            return 0;
        for (int k = 0; k < 22; ++k)
            if (std::fscanf(f, "%%lf", &v[k]) != 1) return 0;
        Eigen::Matrix3d R;
        R << v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8];
        const pinocchio::SE3 placement(R, Eigen::Vector3d(v[9], v[10], v[11]));
        const std::string name = "q" + std::to_string(i + 1);
        pinocchio::Model::JointIndex id;
        const pinocchio::Model::JointIndex p = (pinocchio::Model::JointIndex)parent;
        if (axis == 0)
            id = model.addJoint(p, pinocchio::JointModelRZ(), placement, name);
        else if (axis == 1)
            id = model.addJoint(p, pinocchio::JointModelRY(), placement, name);
        else
            id = model.addJoint(p, pinocchio::JointModelRX(), placement, name);
        Eigen::Matrix3d I;
        I << v[16], v[19], v[20], v[19], v[17], v[21], v[20], v[21], v[18];
        model.appendBodyToJoint(id, pinocchio::Inertia(v[12], Eigen::Vector3d(v[13], v[14], v[15]),
                                                       I), pinocchio::SE3::Identity());
    }
    double g;
    if (std::fscanf(f, "%%lf", &g) != 1) return 0;
    model.gravity.linear(Eigen::Vector3d(0.0, 0.0, -g));
    for (int i = 0; i < 2 * n; ++i)
        if (std::fscanf(f, "%%lf", &x0[i]) != 1) return 0;
    std::fclose(f);
    return n;
}

int main(int argc, char **argv) {
    if (argc < 2 || argc > 4 || !read_chain(argv[1])) {
        std::fprintf(stderr, "usage: pin_bench chain.txt (see the source)\n");
        return 2;
    }
    pinocchio::Data data(model);
    double sink = 0.0;
    if (argc >= 3) {
        const int which = std::atoi(argv[2]);
        if (argc == 3) {
            const double t = which == 0 ? best<0>(data, sink) : which == 1 ? best<1>(data, sink)
                                                                           : best<2>(data, sink);
            std::printf("%%.9e %%.3g\n", t, sink * 0.0);
            return 0;
        }
        const long loops = std::atol(argv[3]);
        if (which == 0)
            run<0>(data, loops, sink);
        else if (which == 1)
            run<1>(data, loops, sink);
        else
            run<2>(data, loops, sink);
        std::printf("%%.17g\n", sink);
        return 0;
    }
    const double aba = best<0>(data, sink), crba = best<1>(data, sink);
    const int n = model.nv;
    Eigen::VectorXd q = Eigen::Map<const Eigen::VectorXd>(x0, n);
    Eigen::VectorXd v = Eigen::Map<const Eigen::VectorXd>(x0 + n, n);
    Eigen::VectorXd tau = Eigen::VectorXd::Zero(n), qdd(n);
    std::printf("%%.9e %%.9e %%.3g\n", aba, crba, sink * 0.0);
    pinocchio::aba(model, data, q, v, tau);
    for (int i = 0; i < n; ++i) std::printf("%%.17g ", data.ddq[i]);
    std::printf("\n");
    crba_path(data, q, v, tau, qdd);
    for (int i = 0; i < n; ++i) std::printf("%%.17g ", qdd[i]);
    std::printf("\n");
    Eigen::VectorXd acc(n);
    for (int i = 0; i < n; ++i) acc[i] = ACC(i);
    pinocchio::rnea(model, data, q, v, acc);
    for (int i = 0; i < n; ++i) std::printf("%%.17g ", data.tau[i]);
    std::printf("\n");
    return 0;
}
"""


def pinocchio_paths():
    """(include dir, library dir) of the ``pin`` and ``cmeel-eigen`` wheels, or None."""
    try:
        import pinocchio
    except ImportError:
        return None
    root = Path(pinocchio.__file__).resolve()
    for parent in root.parents:
        prefix = parent / "cmeel.prefix"
        if (prefix / "include" / "pinocchio").is_dir():
            if not (prefix / "include" / "eigen3" / "Eigen").is_dir():
                return None
            return prefix / "include", prefix / "lib"
    return None


def build_pinocchio_harness(work: Path, count: bool = False):
    """Compile the Pinocchio harness (-O3 -march=native) once; it reads the chain
    from a file (:func:`pinocchio_chain_file`).  Returns (path, None) or (None, reason).

    ``count``: the build that callgrind runs, ``pin_count``, with ``-mno-avx512f``
    added, because valgrind does not decode AVX-512 (on a CPU without AVX-512 it is
    the timed build's code)."""
    paths = pinocchio_paths()
    if paths is None:
        return None, "pin or cmeel-eigen not installed (pip install '.[bench]')"
    include, lib = paths
    work.mkdir(parents=True, exist_ok=True)
    src = work / "pin_bench.cpp"
    src.write_text(_PIN_HARNESS % {"min_seconds": MIN_SECONDS, "repeats": REPEATS})
    exe = work / ("pin_count" if count else "pin_bench")
    # the definitions are those of Pinocchio's exported CMake target
    arch = ["-march=native", "-mno-avx512f"] if count else ["-march=native"]
    cmd = [*shlex.split(os.environ.get("CXX", "c++")), "-O3", *arch, "-DNDEBUG",
           "-std=c++17", "-DBOOST_MPL_LIMIT_LIST_SIZE=30", "-DBOOST_MPL_LIMIT_VECTOR_SIZE=30",
           "-DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS", "-DBOOST_FUSION_INVOKE_MAX_ARITY=12",
           f"-I{include}", f"-I{include / 'eigen3'}", str(src), "-o", str(exe),
           f"-L{lib}", "-lpinocchio_default", f"-Wl,-rpath,{lib}"]
    try:
        _run_checked(cmd)
    except RuntimeError as exc:
        return None, f"Pinocchio harness did not build: {exc}"
    return exe, None


def pinocchio_chain_file(n: int, params: dict, x0, path: Path) -> Path:
    """The input of the Pinocchio harness: ``spatial_chain(n)`` from its written
    definition (:func:`modelgen.bench.hard_case_models.chain_links`) and the state x0."""
    from modelgen.bench.hard_case_models import chain_links
    links = [(i, axis, ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)), (offset, 0.0, 0.0),
              m, (c, 0.0, 0.0), tuple(diag) + (0.0, 0.0, 0.0))
             for i, (offset, axis, m, c, diag) in enumerate(chain_links(n, params))]
    return pinocchio_tree_file(links, float(params["g"]), x0, path)


def pinocchio_tree_file(links, g: float, x0, path: Path) -> Path:
    """The input of the Pinocchio harness for ``links`` as :func:`tree_links` gives them."""
    lines = [str(len(links))]
    for parent, axis, R, p, m, c, inertia in links:
        lines.append(" ".join([str(parent), str("zyx".index(axis)),
                               *(repr(float(x)) for row in R for x in row),
                               *(repr(float(x)) for x in (*p, m, *c, *inertia))]))
    lines += [repr(g), " ".join(repr(float(v)) for v in x0)]
    path.write_text("\n".join(lines) + "\n")
    return path


def tree_links(spec, params: dict):
    """A model of revolute joints about base axes, numerically, for Pinocchio and MuJoCo:
    per joint (parent's 1-based index or 0, axis 'x' | 'y' | 'z', R = the joint frame's
    axes in the parent's (rows), p its origin, mass, centre of mass, inertia about it
    as (xx, yy, zz, xy, xz, yz)).  Read from modelgen's joint tree of ``spec``, so it
    is the same model; None if the model is not such a tree (or has actions or
    effects other than gravity, which the peers would not see)."""
    import numpy as np
    import sympy
    from modelgen.derive.joint_tree import extract_joint_tree
    from modelgen.errors import ModelError
    from modelgen.model.spec import symbol
    try:
        tree = extract_joint_tree(spec)
    except ModelError:
        return None
    values = {symbol(name): float(v) for name, v in params.items()}
    values.update({symbol(name): 0.0 for name in spec.inputs})
    g = symbol("g")
    if spec.effects or "g" not in params or tuple(spec.gravity or ()) != (0, 0, -g):
        return None
    for act in spec.actions:          # the harnesses run with zero inputs
        if any(sympy.sympify(x).xreplace(values) != 0 for x in (*act.torque, *act.force)):
            return None

    def num(e):
        return float(sympy.sympify(e).xreplace(values))
    links = []
    for joint, body in zip(tree.joints, tree.inertias):
        if joint.kind != "revolute" or sympy.sympify(joint.angle) != symbol(joint.name):
            return None
        E, r = joint.fixed
        R = np.array([[num(x) for x in row] for row in E]).T     # E maps parent -> child
        m = num(body.m)
        c = np.array([num(x) for x in body.h]) / m
        I = np.array([num(x) for x in body.I])                     # about the link origin
        shift = m * (np.dot(c, c) * np.array([1, 1, 1, 0, 0, 0])
                     - np.array([c[0] * c[0], c[1] * c[1], c[2] * c[2],
                                 c[0] * c[1], c[0] * c[2], c[1] * c[2]]))
        links.append((joint.parent + 1, "xyz"[joint.axis - 1], tuple(map(tuple, R)),
                      tuple(num(x) for x in r), m, tuple(c), tuple(I - shift)))
    return links


def tree_mjcf(name: str, links, g: float) -> str:
    """MJCF of ``links`` (:func:`tree_links`), with the chain's options."""
    import numpy as np
    children: dict = {}
    for i, link in enumerate(links, start=1):
        children.setdefault(link[0], []).append(i)
    lines = [f'<mujoco model="{name}">', '  <compiler inertiafromgeom="false"/>',
             f'  <option timestep="0.001" integrator="RK4" gravity="0 0 {-g!r}">',
             '    <flag contact="disable"/>', '  </option>', '  <worldbody>']

    def quat(R):
        R = np.asarray(R)
        w = np.sqrt(max(0.0, 1.0 + np.trace(R))) / 2
        if w > 1e-6:
            return (w, (R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w),
                    (R[1, 0] - R[0, 1]) / (4 * w))
        x = np.sqrt(max(0.0, 1.0 + R[0, 0] - R[1, 1] - R[2, 2])) / 2
        return ((R[2, 1] - R[1, 2]) / (4 * x), x, (R[0, 1] + R[1, 0]) / (4 * x),
                (R[0, 2] + R[2, 0]) / (4 * x))

    def body(i, depth):
        _, axis, R, p, m, c, inertia = links[i - 1]
        pad = "  " * depth
        lines.append(f'{pad}<body name="link{i}" pos="{" ".join(repr(float(x)) for x in p)}" '
                     f'quat="{" ".join(repr(float(x)) for x in quat(R))}">')
        lines.append(f'{pad}  <joint name="q{i}" type="hinge" axis="'
                     + {"x": "1 0 0", "y": "0 1 0", "z": "0 0 1"}[axis]
                     + '" damping="0" armature="0"/>')
        lines.append(f'{pad}  <inertial pos="{" ".join(repr(float(x)) for x in c)}" mass="{m!r}" '
                     f'fullinertia="{" ".join(repr(float(x)) for x in inertia)}"/>')
        for k in children.get(i, []):
            body(k, depth + 1)
        lines.append(f"{pad}</body>")
    for i in children.get(0, []):
        body(i, 2)
    lines += ['  </worldbody>', '</mujoco>', '']
    return "\n".join(lines)


def run_pinocchio_harness(exe: Path, chain_file: Path) -> tuple:
    """One run: (ABA µs, CRBA + Cholesky µs, q_ddot by ABA, q_ddot by CRBA) at x0."""
    import numpy as np
    lines = _run_checked([str(exe), str(chain_file)]).splitlines()
    aba, crba, _ = lines[0].split()
    return (float(aba) * 1e6, float(crba) * 1e6, np.array(lines[1].split(), float),
            np.array(lines[2].split(), float))


# ---------------------------------------------------------------------------------
# MuJoCo model of the chain
# ---------------------------------------------------------------------------------

def chain_mjcf(n: int, params: dict) -> str:
    """MJCF of ``spatial_chain(n)`` with the given parameter values (one definition,
    in :func:`modelgen.bench.hard_case_models.chain_mjcf`)."""
    from modelgen.bench.hard_case_models import chain_mjcf as mjcf
    return mjcf(n, params)


def mujoco_check(cm, n: int, states, work: Path, xml: str | None = None):
    """Build the MuJoCo chain (or the model ``xml``), check qacc against modelgen's
    qdd, time mj_forward from Python.

    Returns (row fields, path of the MJCF file).
    """
    import mujoco
    import numpy as np
    xml_path = work / f"{cm.name}.xml"
    xml_path.write_text(xml if xml is not None else chain_mjcf(n, cm.parameters))
    model = mujoco.MjModel.from_xml_path(str(xml_path))
    data = mujoco.MjData(model)
    worst = 0.0
    for x in states:
        data.qpos[:], data.qvel[:] = x[:n], x[n:]
        mujoco.mj_forward(model, data)
        qdd = cm.rhs(0.0, x)[n:]
        worst = max(worst, float(np.max(np.abs(data.qacc - qdd)) / np.max(np.abs(qdd))))
    data.qpos[:], data.qvel[:] = states[0][:n], states[0][n:]
    mujoco.mj_forward(model, data)
    qacc_x0 = [float(v) for v in data.qacc]
    py_us = per_call_python("mj_forward(m, d)", {"mj_forward": mujoco.mj_forward,
                                                 "m": model, "d": data})
    return {"mujoco_version": mujoco.__version__, "mj_rel_diff": worst,
            "mj_forward_py_us": py_us, "mj_qacc_x0": qacc_x0}, xml_path


def run_mj_harness(harness: Path, xml_path: Path, x0) -> tuple:
    """One run of the MuJoCo harness: (mj_forward µs, mj_step µs / 4, bad-qacc warnings)."""
    state_path = xml_path.with_suffix(".state")
    state_path.write_text(" ".join(repr(float(v)) for v in x0) + "\n")
    forward, step, bad, _sink = _run_checked([str(harness), str(xml_path),
                                              str(state_path)]).split()
    return float(forward) * 1e6, float(step) * 1e6 / 4, int(bad)


# ---------------------------------------------------------------------------------
# The child: one model, one fresh process
# ---------------------------------------------------------------------------------

def per_call_python(stmt: str, namespace: dict) -> float:
    """Per-call time of ``stmt`` in µs: min over REPEATS runs of >= MIN_SECONDS."""
    timer = timeit.Timer(stmt, globals=namespace)
    loops, elapsed = 1, 0.0
    while elapsed < MIN_SECONDS:
        loops *= 2
        elapsed = timer.timeit(loops)
    return min(timer.repeat(REPEATS, loops)) / loops * 1e6


def child(kind: str, arg: str, work: Path, mj_harness, rounds: int, pin_harness=None,
          pin_count=None, count: bool = True) -> dict:
    """Generate one model and measure it; returns the row as a dict.

    ``count``: also count each engine's instructions per call with callgrind
    (:func:`instructions_per_call`; ``pin_count`` is Pinocchio's counting build)."""
    loadavg = os.getloadavg()[0]
    t = time.perf_counter()
    sys.path.insert(0, str(REPO))
    import numpy as np

    import modelgen
    from modelgen.model.chains import spatial_chain
    from modelgen.model.api import load_model
    import_s = time.perf_counter() - t

    t = time.perf_counter()
    spec = spatial_chain(int(arg)).spec() if kind == "chain" else load_model(arg)
    spec_s = time.perf_counter() - t

    t = time.perf_counter()
    cm = modelgen.load(spec, work / "model", force=True)
    total = time.perf_counter() - t
    rss_self = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024      # kB -> MB
    rss_cc = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024

    seconds, ops = cm.manifest["seconds"], cm.manifest["ops"]["rhs"]
    row = {"kind": kind, "model": cm.name, "n": cm.n, "import_s": import_s, "spec_s": spec_s,
           "loadavg_before": loadavg,
           **{f"{k}_s": v for k, v in seconds.items()}, "total_s": total,
           "other_s": total - sum(seconds.values()),
           "rss_py_mb": rss_self, "rss_cc_mb": rss_cc,
           "ops_before": ops["before_cse"], "ops_after": ops["after_cse"],
           "statements": ops["statements"],
           "compile_flags": sorted({c.split()[1] for c in cm.manifest.get("compile_commands",
                                                                           [])})}

    rng = np.random.default_rng(1000 + cm.n)
    states = [np.concatenate([rng.uniform(-np.pi, np.pi, cm.n), rng.uniform(-2, 2, cm.n)])
              for _ in range(N_CHECK_STATES)]
    x0 = states[0]
    rhs_exe, row["rhs_compile_command"] = build_rhs_harness(cm, x0, work / "harness")

    f, out, xp = cm.rhs_function(), np.empty(2 * cm.n), x0.copy()
    row["rhs_py_fast_us"] = per_call_python("f(0.0, x, out)", {"f": f, "x": xp, "out": out})
    f.x[:] = x0
    row["rhs_py_inplace_us"] = per_call_python("inplace(0.0)", {"inplace": f.inplace})
    row["rhs_py_plain_us"] = per_call_python("rhs(0.0, x)", {"rhs": cm.rhs, "x": xp})

    # a model file is timed against the peers when it is a tree of revolute joints
    # with gravity only (motor inputs are 0 in the harnesses)
    links = tree_links(spec, cm.parameters) if kind == "file" else None
    xml_path = None
    if (kind == "chain" or links) and have_mujoco():
        xml = tree_mjcf(cm.name, links, float(cm.parameters["g"])) if links else None
        fields, xml_path = mujoco_check(cm, cm.n, states, work, xml)
        row.update(fields)

    pin_exe = None
    if (kind == "chain" or links) and pin_harness:
        pin_exe = Path(pin_harness)
        chain_file = (pinocchio_tree_file(links, float(cm.parameters["g"]), x0,
                                          work / "pin_tree.txt") if links else
                      pinocchio_chain_file(cm.n, cm.parameters, x0, work / "pin_chain.txt"))

    # The C timings, alternating modelgen, MuJoCo and Pinocchio over ``rounds``
    # rounds and keeping the minimum of each, so that a slow spell of a shared
    # machine hits all of them and the ratios stay meaningful.
    rhs_c, forward, step, bad, pin_aba, pin_crba = [], [], [], 0, [], []
    for _ in range(rounds):
        rhs_c.append(run_rhs_harness(rhs_exe))
        if xml_path is not None and mj_harness:
            fwd, stp, warnings = run_mj_harness(Path(mj_harness), xml_path, x0)
            forward.append(fwd)
            step.append(stp)
            bad += warnings
        if pin_exe is not None:
            t_aba, t_crba, qdd_aba, qdd_crba = run_pinocchio_harness(pin_exe, chain_file)
            pin_aba.append(t_aba)
            pin_crba.append(t_crba)
    if pin_exe is not None:
        # q_ddot at x0 by the four engines; agreement = the largest pairwise
        # max-norm difference over the largest |q_ddot|
        engines = {"modelgen": cm.rhs(0.0, x0)[cm.n:], "pin_aba": qdd_aba, "pin_crba": qdd_crba}
        if "mj_qacc_x0" in row:
            engines["mujoco"] = np.array(row["mj_qacc_x0"])
        scale = max(float(np.max(np.abs(v))) for v in engines.values())
        names = sorted(engines)
        row["agreement_4"] = max(float(np.max(np.abs(engines[a] - engines[b]))) / scale
                                 for i, a in enumerate(names) for b in names[i + 1:])
        row["pin_vs_mg"] = float(np.max(np.abs(engines["pin_aba"] - engines["modelgen"])) / scale)
        row.update(pin_aba_us=min(pin_aba), pin_crba_us=min(pin_crba),
                   pin_over_mg=min(pin_aba) / min(rhs_c))
    row["rhs_c_us"], row["rhs_c_us_rounds"] = min(rhs_c), rhs_c
    if xml_path is not None:
        if forward:
            row.update(mj_forward_us=min(forward), mj_step4_us=min(step), mj_timing="C",
                       mj_forward_us_rounds=forward, mj_badqacc_warnings=bad)
        else:
            row.update(mj_forward_us=row["mj_forward_py_us"], mj_step4_us=None,
                       mj_timing="py")
        row["mj_over_mg"] = row["mj_forward_us"] / row["rhs_c_us"]
    if count and shutil.which("valgrind"):
        instr = {"mg": rhs_instructions(cm, x0, work / "count")}
        if xml_path is not None and mj_harness:
            instr["mj_forward"] = instructions_per_call(
                [str(mj_harness), str(xml_path), str(xml_path.with_suffix(".state"))])
        if pin_exe is not None and pin_count:
            for which, key in ((0, "pin_aba"), (1, "pin_crba")):
                instr[key] = instructions_per_call([str(pin_count), str(chain_file), str(which)])
        row["instructions"] = instr
    return row


# ---------------------------------------------------------------------------------
# The parent: run the children, fit, print
# ---------------------------------------------------------------------------------

def run_one(kind, arg, work: Path, mj_harness, rounds, timeout, pin_harness=None,
            pin_count=None, count: bool = True) -> dict:
    """Run :func:`child` in a fresh interpreter; a failure becomes an ``error`` row."""
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", f"{kind}:{arg}",
           "--workdir", str(work), "--mj-harness", str(mj_harness or ""),
           "--pin-harness", str(pin_harness or ""), "--pin-count", str(pin_count or ""),
           "--rounds", str(rounds), *([] if count else ["--no-count"])]
    start = time.perf_counter()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"kind": kind, "arg": arg, "error": f"timed out after {timeout} s"}
    wall = time.perf_counter() - start
    for line in proc.stdout.splitlines():
        if line.startswith(RESULT_MARK):
            return dict(json.loads(line[len(RESULT_MARK):]), child_wall_s=wall)
    tail = (proc.stderr or proc.stdout).strip().splitlines()[-15:]
    return {"kind": kind, "arg": arg, "error": f"exit {proc.returncode}: " + "\n".join(tail)}


def fit_exponent(ns, values):
    """Least-squares slope of log(values) against log(ns), or None."""
    import numpy as np
    if len(ns) < 2:
        return None
    return float(np.polyfit(np.log(ns), np.log(values), 1)[0])


def fmt(value, spec=".3g", missing="–") -> str:
    """``value`` formatted with ``spec``, or ``missing`` for None."""
    return missing if value is None else format(value, spec)


def markdown(headers, rows, left=1) -> str:
    """A markdown table; the first ``left`` columns are left-aligned, the rest right."""
    lines = ["| " + " | ".join(headers) + " |",
             "|" + "|".join(":---" if i < left else "---:" for i in range(len(headers))) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def label(row) -> str:
    return str(row["n"]) if row.get("kind") == "chain" else f"{row['model']} ({row['n']})"


def generation_table(rows) -> str:
    headers = ["n", "import s", "derive s", "CSE s", "emit s", "compile s", "other s",
               "**total s**",
               "RSS py MB", "RSS cc MB", "ops before", "ops after", "stmts", "-O"]
    body = []
    for r in rows:
        if "error" in r:
            body.append([r.get("arg"), "**failed**"] + [""] * (len(headers) - 2))
            continue
        body.append([label(r), fmt(r["import_s"]), fmt(r["derive_s"]), fmt(r["cse_s"]), fmt(r["emit_s"]),
                     fmt(r["compile_s"]), fmt(r["other_s"]), f"**{fmt(r['total_s'])}**",
                     fmt(r["rss_py_mb"], ".0f"), fmt(r["rss_cc_mb"], ".0f"),
                     r["ops_before"], r["ops_after"], r["statements"],
                     "/".join(f.lstrip("-") for f in r["compile_flags"])])
    return markdown(headers, body)


def runtime_table(rows, with_mujoco) -> str:
    headers = ["n", "rhs C µs", "py f.inplace µs", "py f(t,x,out) µs", "py cm.rhs µs"]
    if with_mujoco:
        headers += ["mj_forward µs", "mj_step/4 µs", "mj_forward py µs", "**mj/mg**",
                    "rel diff"]
    with_pin = any("pin_aba_us" in r for r in rows)
    if with_pin:
        headers += ["pin ABA µs", "pin CRBA+chol µs", "**pin/mg**", "agree (4 engines)",
                    "mg vs pin ABA"]
    body = []
    for r in rows:
        if "error" in r:
            continue
        line = [label(r), fmt(r["rhs_c_us"]), fmt(r.get("rhs_py_inplace_us")),
                fmt(r["rhs_py_fast_us"]),
                fmt(r["rhs_py_plain_us"])]
        if with_mujoco:
            if "mj_forward_us" in r:
                mark = "" if r["mj_timing"] == "C" else " (py)"
                line += [fmt(r["mj_forward_us"]) + mark, fmt(r["mj_step4_us"]),
                         fmt(r["mj_forward_py_us"]), f"**{fmt(r['mj_over_mg'])}**",
                         fmt(r["mj_rel_diff"], ".1e")]
            else:
                line += ["–"] * 5
        if with_pin:
            if "pin_aba_us" in r:
                line += [fmt(r["pin_aba_us"]), fmt(r["pin_crba_us"]),
                         f"**{fmt(r['pin_over_mg'])}**", fmt(r["agreement_4"], ".1e"),
                         fmt(r["pin_vs_mg"], ".1e")]
            else:
                line += ["–"] * 5
        body.append(line)
    return markdown(headers, body)


def instructions_table(rows) -> str:
    """Instructions per forward-dynamics call of each engine, and the ratios to modelgen."""
    headers = ["n", "modelgen rhs", "mj_forward", "pin ABA", "pin CRBA+chol", "**mj/mg**",
               "**pin ABA/mg**"]
    body = []
    for r in rows:
        c = r.get("instructions")
        if not c:
            continue
        mg = c["mg"]
        body.append([label(r), fmt(mg, ",.0f"), fmt(c.get("mj_forward"), ",.0f"),
                     fmt(c.get("pin_aba"), ",.0f"), fmt(c.get("pin_crba"), ",.0f"),
                     f"**{fmt(c['mj_forward'] / mg if 'mj_forward' in c else None)}**",
                     f"**{fmt(c['pin_aba'] / mg if 'pin_aba' in c else None)}**"])
    return markdown(headers, body)


def goals(rows) -> list:
    """[(goal, measured, verdict)] for the goals of the issue."""
    chain = {r["n"]: r for r in rows if r.get("kind") == "chain" and "error" not in r}
    failed = {int(r["arg"]) for r in rows if r.get("kind") == "chain" and "error" in r}
    arms = [r for r in rows if r.get("kind") == "file" and "error" not in r]
    arm = arms[0] if arms else None
    out = []

    def verdict(ok):
        return "met" if ok else "**NOT met**"

    def by_n(n, goal, measure, test):
        if n in chain:
            value = measure(chain[n])
            out.append((goal, value[0], verdict(test(*value[1:]))))
        elif n in failed:
            out.append((goal, "failed", "**NOT met**"))
        else:
            out.append((goal, "n not run", "not run"))

    by_n(10, "n=10: model to importable module ≤ 3 s",
         lambda r: (f"{r['total_s']:.2f} s", r["total_s"]), lambda t: t <= 3)
    by_n(30, "n=30: ≤ 15 s and ≤ 1 GB (python + largest compiler RSS)",
         lambda r: (f"{r['total_s']:.2f} s, {r['rss_py_mb'] + r['rss_cc_mb']:.0f} MB",
                    r["total_s"], r["rss_py_mb"] + r["rss_cc_mb"]),
         lambda t, mb: t <= 15 and mb <= 1024)
    if 50 in chain:
        out.append(("n=50 completes", f"{chain[50]['total_s']:.2f} s", "met"))
    else:
        out.append(("n=50 completes", "failed" if 50 in failed else "n not run",
                    "**NOT met**" if 50 in failed else "not run"))

    def per_call_goal(goal, key, limit):
        if arm is not None:
            out.append((goal + f" [{arm['model']}]", f"{arm[key]:.3g} µs",
                        verdict(arm[key] <= limit)))
        if 7 in chain:
            note = "chain n=7" + ("" if arm is not None else "; proxy, arm7.yaml not found")
            out.append((goal + f" [{note}]", f"{chain[7][key]:.3g} µs",
                        verdict(chain[7][key] <= limit)))
        elif arm is None:
            out.append((goal, "neither arm7 nor n=7 run", "not run"))

    per_call_goal("7-dof rhs in C ≤ 0.28 µs", "rhs_c_us", 0.28)

    # issue 10 (fast at every size): ratios to the peers in the same run, C against C
    def ratio_goal(label, r, need):
        for key, peer, floor in (("mj_over_mg", "MuJoCo mj_forward", need[0]),
                                 ("pin_over_mg", "Pinocchio ABA", need[1])):
            goal = f"{label}: ≥ {floor:g}× {peer}"
            if r is None:
                out.append((goal, "not run", "not run"))
            elif key not in r:
                out.append((goal, f"{peer} not available", "not run"))
            else:
                out.append((goal, f"{r[key]:.3g}×", verdict(r[key] >= floor)))

    ratio_goal(arm["model"] if arm is not None else "arm7", arm, (4, 5))
    for n in (20, 50, 100):
        ratio_goal(f"n={n}", chain.get(n), (2, 2))
    by_n(100, "n=100: generation ≤ 30 s and ≤ 1 GB (python + largest compiler RSS)",
         lambda r: (f"{r['total_s']:.2f} s, {r['rss_py_mb'] + r['rss_cc_mb']:.0f} MB",
                    r["total_s"], r["rss_py_mb"] + r["rss_cc_mb"]),
         lambda t, mb: t <= 30 and mb <= 1024)
    if chain:
        n = max(chain)
        per = chain[n]["ops_after"] / n
        out.append((f"rhs operations per coordinate after CSE ≤ 250 (largest n run, {n})",
                    f"{per:.1f}", verdict(per <= 250)))
    agreements = [r["agreement_4"] for r in [*chain.values(), *arms] if "agreement_4" in r]
    if agreements:
        out.append(("q̈ agreement of the 4 engines ≤ 1e-10 (worst model)",
                    f"{max(agreements):.1e}", verdict(max(agreements) <= 1e-10)))
    per_call_goal("Python low-overhead call (f.inplace) ≤ 1 µs", "rhs_py_inplace_us", 1.0)
    return out


def environment() -> dict:
    cpu = platform.processor()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    cc = shlex.split(os.environ.get("CC", "cc"))
    try:
        cc_version = _run_checked([*cc, "--version"]).splitlines()[0]
    except (RuntimeError, OSError):
        cc_version = "unknown"
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(),
            "loadavg_at_start": os.getloadavg()[0],
            "compiler": cc_version, "MODELGEN_CFLAGS": os.environ.get("MODELGEN_CFLAGS", "")}


def parse_args(argv):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--n", type=int, nargs="+", metavar="N",
                        help=f"chain sizes (default {' '.join(map(str, DEFAULT_NS))})")
    parser.add_argument("--quick", action="store_true",
                        help=f"chain sizes {' '.join(map(str, QUICK_NS))}")
    parser.add_argument("--arm", default=str(REPO / "models" / "arm7.yaml"),
                        help="model file of the 7-joint arm, included if it exists "
                             "(default: models/arm7.yaml); '' to skip")
    parser.add_argument("--json", metavar="PATH", help="also save the results as JSON")
    parser.add_argument("--timeout", type=float, default=3600,
                        help="seconds allowed per model (default 3600)")
    parser.add_argument("--rounds", type=int, default=3,
                        help="alternating rounds of the C timings of modelgen and MuJoCo; "
                             "the minimum is kept (default 3)")
    parser.add_argument("--no-count", action="store_true",
                        help="skip the callgrind instruction counts (they need valgrind)")
    parser.add_argument("--keep", action="store_true",
                        help="keep the temporary directory (its path is printed)")
    # Internal: the per-model child process.
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--workdir", help=argparse.SUPPRESS)
    parser.add_argument("--mj-harness", default="", help=argparse.SUPPRESS)
    parser.add_argument("--pin-harness", default="", help=argparse.SUPPRESS)
    parser.add_argument("--pin-count", default="", help=argparse.SUPPRESS)
    return parser.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    if args.child:
        kind, arg = args.child.split(":", 1)
        row = child(kind, arg, Path(args.workdir), args.mj_harness or None, args.rounds,
                    args.pin_harness or None, args.pin_count or None, not args.no_count)
        print(RESULT_MARK + json.dumps(row), flush=True)
        return 0

    ns = sorted(set(args.n or (QUICK_NS if args.quick else DEFAULT_NS)))
    env = environment()
    mujoco_ok = have_mujoco()
    root = Path(tempfile.mkdtemp(prefix="modelgen-scaling-"))
    notes = []
    try:
        harness = None
        if mujoco_ok:
            harness, why = build_mujoco_harness(root / "mujoco")
            if harness is None:
                notes.append(f"MuJoCo timed through Python (py): {why}")
        else:
            notes.append("mujoco is not installed: MuJoCo columns skipped")

        pin_harness, why = build_pinocchio_harness(root / "pinocchio")
        if pin_harness is None:
            notes.append(f"Pinocchio not timed: {why}")
        count = not args.no_count and shutil.which("valgrind") is not None
        if not args.no_count and not count:
            notes.append("valgrind not found: no instruction counts")
        pin_count = None
        if count and pin_harness is not None:
            pin_count, why = build_pinocchio_harness(root / "pinocchio", count=True)
            if pin_count is None:
                notes.append(f"Pinocchio's instructions not counted: {why}")
        jobs = [("chain", n) for n in ns]
        if args.arm and Path(args.arm).is_file():
            jobs.append(("file", str(Path(args.arm).resolve())))
        elif args.arm:
            notes.append(f"{args.arm} not found: per-call goals use chain n=7 as a proxy")
        rows = []
        for kind, arg in jobs:
            print(f"... {kind} {arg}", file=sys.stderr, flush=True)
            work = root / (f"chain_{arg}" if kind == "chain" else Path(arg).stem)
            row = run_one(kind, arg, work, harness, args.rounds, args.timeout, pin_harness,
                          pin_count, count)
            rows.append(row)
            if "error" in row:
                print(f"    FAILED: {row['error']}", file=sys.stderr, flush=True)
            else:
                print(f"    total {row['total_s']:.2f} s, rhs {row['rhs_c_us']:.3g} µs",
                      file=sys.stderr, flush=True)
    finally:
        if args.keep:
            print(f"kept {root}", file=sys.stderr)
        else:
            shutil.rmtree(root, ignore_errors=True)

    good = [r for r in rows if r.get("kind") == "chain" and "error" not in r]
    fits = {key: fit_exponent([r["n"] for r in good], [r[key] for r in good])
            for key in ("ops_before", "ops_after", "total_s", "rhs_c_us")}
    if len(good) >= 2:
        a, b = good[-2], good[-1]
        fits["ops_after_local"] = fit_exponent([a["n"], b["n"]], [a["ops_after"], b["ops_after"]])
    if any("mujoco_version" in r for r in rows):
        env["mujoco"] = next(r["mujoco_version"] for r in rows if "mujoco_version" in r)

    print("# modelgen code generation scaling: spatial chain\n")
    print(f"{env['cpu']}, {env['cores']} cores; {env['compiler']}; Python {env['python']}"
          + (f"; MuJoCo {env['mujoco']}" if "mujoco" in env else "")
          + f"; load average before the run {env['loadavg_at_start']:.2f}")
    print("\n## Model to importable module (fresh process per model)\n")
    print(generation_table(rows))
    print("\n## Per-call time of the right-hand side (one forward-dynamics evaluation)\n")
    print(runtime_table(rows, mujoco_ok))
    if any("instructions" in r for r in rows):
        print("\n## Instructions per call (callgrind: the same on every run, whatever the "
              "load)\n")
        print(instructions_table(rows))
    print("\n## Fitted exponents (least squares on log-log over the chains run)\n")
    for key, what in (("ops_before", "rhs ops before CSE"), ("ops_after", "rhs ops after CSE"),
                      ("ops_after_local", "rhs ops after CSE, last two n"),
                      ("total_s", "total generation time"), ("rhs_c_us", "rhs time in C")):
        if fits.get(key) is not None:
            print(f"- {what}: n^{fits[key]:.2f}")
    print("\n## Goals\n")
    print(markdown(["goal", "measured", "verdict"], goals(rows), left=3))
    for r in rows:
        if "error" in r:
            notes.append(f"{r['kind']} {r['arg']} failed: {r['error']}")
        elif r.get("mj_badqacc_warnings"):
            notes.append(f"n={r['n']}: MuJoCo reported bad qacc during mj_step timing")
    if notes:
        print("\nNotes:\n" + "\n".join(f"- {n}" for n in notes))

    if args.json:
        Path(args.json).write_text(json.dumps(
            {"environment": env, "ns": ns, "rows": rows, "fits": fits,
             "goals": [dict(zip(("goal", "measured", "verdict"), g))
                       for g in goals(rows)], "notes": notes}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
