"""Build, run and count the C/C++ harnesses of ``harness/``: modelgen's rhs,
inverse dynamics or derivatives, MuJoCo's mj_forward / mj_step / mj_inverse /
mjd_transitionFD, Pinocchio's ABA, CRBA + Cholesky, rnea and computeABADerivatives.

Every harness calls its function in a loop, perturbing one entry of the state
from the previous output (so consecutive calls form a dependency chain), and
prints the minimum per-call time over :data:`REPEATS` runs of at least
:data:`MIN_SECONDS`; with a count K as its last argument it makes K calls
untimed instead, for :func:`instructions_per_call` under callgrind.  The
timing rule and the model reach the harnesses as ``-D`` macros and files, so
the sources are plain C/C++ that ship with the package.

>>> sorted(p.name for p in HARNESS_DIR.iterdir())
['kinematics_mg.c', 'kinematics_pin.cpp', 'model_bench.c', 'mujoco_bench.c', 'pinocchio_bench.cpp']
"""
from __future__ import annotations

import hashlib
import importlib.util
import os
import platform
import shlex
import shutil
import subprocess
import tempfile
import timeit
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from modelgen.codegen.build import cache_dir, compile_flags, compiler

#: the harnesses' sources (package data)
HARNESS_DIR = Path(__file__).resolve().with_name("harness")
MIN_SECONDS = 0.2        # each timing repeat runs at least this long
REPEATS = 5              # minimum over this many repeats
STEP_RESET = 1000        # mj_step harness: restart from x0 every this many steps
COUNT_CALLS = 200        # calls per callgrind count (instructions_per_call)
#: calls per callgrind count of mjd_transitionFD, each 2 (2 nv) + 1 MuJoCo steps
TRANSITION_COUNT_CALLS = 10


def run_checked(cmd, cwd=None) -> str:
    """Run a command; raise RuntimeError with its full output if it fails."""
    proc = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"command failed (exit {proc.returncode}): {shlex.join(cmd)}\n"
                           f"{proc.stdout}{proc.stderr}")
    return proc.stdout


def alternate(rounds: int, runs: dict) -> dict:
    """Call each of ``runs`` (name -> function) in turn, ``rounds`` times; returns
    name -> the list of results.  A busy spell of a shared machine then hits every
    side, and the minimum of each list is comparable with the others.

    >>> alternate(2, {"a": lambda: 1, "b": lambda: 2})
    {'a': [1, 1], 'b': [2, 2]}
    """
    out = {name: [] for name in runs}
    for _ in range(rounds):
        for name, run in runs.items():
            out[name].append(run())
    return out


def per_call_python(stmt: str, namespace: dict) -> float:
    """Per-call time of the Python statement ``stmt`` in µs, by the harnesses' rule:
    min over REPEATS runs of >= MIN_SECONDS."""
    timer = timeit.Timer(stmt, globals=namespace)
    loops, elapsed = 1, 0.0
    while elapsed < MIN_SECONDS:
        loops *= 2
        elapsed = timer.timeit(loops)
    return min(timer.repeat(REPEATS, loops)) / loops * 1e6


def environment() -> dict:
    """The machine, the C compiler (``$CC``), Python and the load average: the header
    of a benchmark's tables."""
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
        cc_version = run_checked([*cc, "--version"]).splitlines()[0]
    except (RuntimeError, OSError):
        cc_version = "unknown"
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(),
            "loadavg_at_start": os.getloadavg()[0],
            "compiler": cc_version, "MODELGEN_CFLAGS": os.environ.get("MODELGEN_CFLAGS", "")}


def c_array(values) -> str:
    return ",".join(repr(float(v)) for v in values)


# -- modelgen -----------------------------------------------------------------------

def compile_model(cm, work: Path) -> tuple:
    """``<name>.c``'s integration path (part 2: the rhs), what a controller calls
    (part 3: the inverse dynamics, the derivatives' solve, frame kinematics) and
    the derivatives' straight line (part 4, with derivatives), each compiled by
    the exact command modelgen's build used (from the manifest) into ``work``;
    returns (the object files, the commands as one text)."""
    name, manifest = cm.name, cm.manifest
    src_dir = Path(cm.path).parent
    work.mkdir(parents=True, exist_ok=True)
    commands = [shlex.split(c) for c in manifest.get("compile_commands", [])]
    objects, texts = [], []
    for part in (2, 3, 4):
        built = [c for c in commands if f"-DMG_PART={part}" in c]
        if part == 4 and "derivative_terms" not in manifest["ops"]:
            continue            # no derivatives: nothing in part 4
        obj = work / f"model_part{part}.o"
        if built:
            cmd = list(built[0])
            cmd[cmd.index("-o") + 1] = str(obj)
            cmd[cmd.index(f"{name}.c")] = str(src_dir / f"{name}.c")
        else:   # no compile_commands in the manifest: rebuild them from compile_flags
            statements = max(r["statements"] for r in manifest["ops"].values())
            cmd = [*compiler(), *compile_flags(statements, part), f"-DMG_PART={part}", "-c",
                   str(src_dir / f"{name}.c"), "-o", str(obj)]
        run_checked(cmd)
        objects.append(str(obj))
        texts.append(shlex.join(cmd))
    return objects, "; ".join(texts)


#: the functions model_bench.c can time: name -> (its -D macros, the output's length)
_MODEL_FUNCTIONS = {
    "rhs_prepared": lambda cm: ([], cm.nx),
    "inverse_dynamics": lambda cm: (["-DMG_INVERSE"], cm.n),
    # dqdd_dq, dqdd_dv, then dqdd_du (n x nu) when the model has inputs
    "derivatives": lambda cm: (["-DMG_DERIVATIVES", f"-DMG_N={cm.n}"],
                               2 * cm.n * cm.n + cm.n * len(cm.inputs)),
    "jacobian": lambda cm: (["-DMG_JACOBIAN"], cm.nx * cm.nx),
}


def build_model_harness(cm, x0, work: Path, function: str = "rhs_prepared"):
    """Compile ``harness/model_bench.c`` for ``<name>_rhs_prepared``, for
    ``<name>_inverse_dynamics`` (at the accelerations 0.3 (i mod 3) - 0.2) or for
    ``<name>_derivatives`` (the model built with ``derivatives=True``); returns
    (executable, the command that compiled the model's C).  The harness itself is
    compiled at -O2.  It times the function, or with an argument K calls it K times
    for :func:`instructions_per_call`.
    """
    if function not in _MODEL_FUNCTIONS:
        raise ValueError(f"no harness for {function!r}")
    name = cm.name
    src_dir = Path(cm.path).parent
    objects, command = compile_model(cm, work)
    mode, nout = _MODEL_FUNCTIONS[function](cm)
    defines = [f'-DMG_HEADER="{name}.h"', f"-DMG_MODEL={name}",
               f"-DMG_NPD_ALLOC={name.upper()}_NPD_ALLOC", f"-DMG_NX={cm.nx}",
               f"-DMG_NOUT={nout}",
               f"-DMG_NP={max(len(cm.parameters), 1)}", f"-DMG_NU={max(len(cm.inputs), 1)}",
               f"-DMG_X0={c_array(x0)}", f"-DMG_P={c_array(cm.params()) or '0.0'}",
               f"-DMIN_SECONDS={MIN_SECONDS}", f"-DREPEATS={REPEATS}", *mode]
    exe = work / f"{function}_bench"
    # the model's integrate wrappers call the shared integrators, copied beside it
    run_checked([*compiler(), "-O2", "-std=c99", *defines, f"-I{src_dir}",
                 str(HARNESS_DIR / "model_bench.c"), *objects,
                 str(src_dir / "mg_integrate.c"), "-o", str(exe), "-lm"])
    return exe, command


def build_rhs_harness(cm, x0, work: Path):
    """The harness of ``<name>_rhs_prepared`` (:func:`build_model_harness`)."""
    return build_model_harness(cm, x0, work)


def run_model_harness(exe: Path) -> float:
    """One run of a harness of :func:`build_model_harness`: per-call time in µs (min
    over REPEATS)."""
    best, _loops, status, _sink = run_checked([str(exe)]).split()
    if int(status):
        raise RuntimeError(f"{exe}: the model's function returned status {status}")
    return float(best) * 1e6


# -- callgrind ----------------------------------------------------------------------

def callgrind_total(cmd, cwd=None, children: bool = False) -> int:
    """Instructions that ``cmd`` executes, by valgrind's callgrind (no load dependence);
    with ``children``, summed over every process it starts (a compiler's driver,
    ``cc1`` and ``as``)."""
    with tempfile.TemporaryDirectory() as tmp:
        flags = ["--trace-children=yes", f"--callgrind-out-file={tmp}/callgrind.%p"] \
            if children else [f"--callgrind-out-file={tmp}/callgrind.out"]
        run_checked(["valgrind", "--tool=callgrind", *flags, *cmd], cwd=cwd)
        totals = []
        for out in Path(tmp).glob("callgrind.*"):
            for line in out.read_text(errors="replace").splitlines():
                if line.startswith(("summary:", "totals:")):
                    totals.append(int(line.split()[1]))
                    break
        if totals:
            return sum(totals)
    raise RuntimeError(f"no instruction total in callgrind's output of {shlex.join(cmd)}")


def compile_command(command: str, output: Path) -> list:
    """A part's compile command of a manifest (``compile_commands``) as arguments,
    writing its object to ``output`` instead."""
    args = shlex.split(command)
    args[args.index("-o") + 1] = str(output)
    return args


def command_seconds(command: str, directory: Path, rounds: int = 3) -> float:
    """The minimum wall seconds of ``rounds`` runs of a part's compile command in the
    build ``directory`` (its object into a temporary directory)."""
    best = float("inf")
    with tempfile.TemporaryDirectory() as tmp:
        args = compile_command(command, Path(tmp) / "part.o")
        for _ in range(rounds):
            start = timeit.default_timer()
            subprocess.run(args, cwd=directory, check=True)
            best = min(best, timeit.default_timer() - start)
    return best


def command_instructions(command: str, directory: Path) -> int:
    """Instructions of every process of a part's compile command (callgrind)."""
    with tempfile.TemporaryDirectory() as tmp:
        return callgrind_total(compile_command(command, Path(tmp) / "part.o"), cwd=directory,
                               children=True)


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


# -- MuJoCo -------------------------------------------------------------------------

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
    """Compile ``harness/mujoco_bench.c``; returns (its path, None), or (None, reason)."""
    paths = mujoco_paths()
    if paths is None:
        return None, "mujoco headers or library not found in the wheel"
    include, lib = paths
    work.mkdir(parents=True, exist_ok=True)
    exe = work / "mj_bench"
    cmd = [*shlex.split(os.environ.get("CC", "cc")), "-O2", "-std=c99",
           f"-DMIN_SECONDS={MIN_SECONDS}", f"-DREPEATS={REPEATS}", f"-DSTEP_RESET={STEP_RESET}",
           f"-I{include}", str(HARNESS_DIR / "mujoco_bench.c"), "-o", str(exe), str(lib),
           f"-Wl,-rpath,{lib.parent}", "-lm"]
    try:
        run_checked(cmd)
    except RuntimeError as exc:
        return None, f"MuJoCo harness did not build: {exc}"
    return exe, None


def run_mj_harness(harness: Path, xml_path: Path, x0) -> tuple:
    """One run of the MuJoCo harness: (mj_forward µs, mj_step µs / 4, bad-qacc warnings).
    The state goes to ``xml_path`` with the suffix ``.state``."""
    state_path = xml_path.with_suffix(".state")
    state_path.write_text(" ".join(repr(float(v)) for v in x0) + "\n")
    forward, step, bad, _sink = run_checked([str(harness), str(xml_path),
                                             str(state_path)]).split()
    return float(forward) * 1e6, float(step) * 1e6 / 4, int(bad)


def mj_command(harness: Path, xml_path: Path, state, mode: str) -> list:
    """The MuJoCo harness's command for ``mode`` (``inverse`` or ``transition``) at
    MuJoCo's ``state`` (qpos then qvel), which goes to ``xml_path`` with the suffix
    ``.state``; add ``str(K)`` for K untimed calls (:func:`instructions_per_call`)."""
    state_path = xml_path.with_suffix(".state")
    state_path.write_text(" ".join(repr(float(v)) for v in state) + "\n")
    return [str(harness), str(xml_path), str(state_path), mode]


def run_mj_transition(cmd) -> float:
    """One timed run of ``mj_command(..., "transition")``: µs per mjd_transitionFD
    call (central differences, eps 1e-6, Euler; min over REPEATS)."""
    return float(run_checked(cmd).split()[0]) * 1e6


# -- Pinocchio ----------------------------------------------------------------------

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


def pinocchio_command(source: Path, exe: Path, count: bool = False) -> list:
    """The command that compiles a Pinocchio harness ``source`` into ``exe`` (-O3
    -march=native, with ``count`` also -mno-avx512f), or None without the wheels."""
    paths = pinocchio_paths()
    if paths is None:
        return None
    include, lib = paths
    # the definitions are those of Pinocchio's exported CMake target; without
    # AVX-512 on the CPU the counted build is the timed one (and its cached copy)
    arch = ["-march=native", "-mno-avx512f"] if count and _has_avx512() else ["-march=native"]
    return [*shlex.split(os.environ.get("CXX", "c++")), "-O3", *arch, "-DNDEBUG",
            "-std=c++17", "-DBOOST_MPL_LIMIT_LIST_SIZE=30", "-DBOOST_MPL_LIMIT_VECTOR_SIZE=30",
            "-DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS", "-DBOOST_FUSION_INVOKE_MAX_ARITY=12",
            f"-DMIN_SECONDS={MIN_SECONDS}", f"-DREPEATS={REPEATS}", "-w",
            f"-I{include}", f"-I{include / 'eigen3'}", str(source),
            "-o", str(exe), f"-L{lib}", "-lpinocchio_default", f"-Wl,-rpath,{lib}"]


def _has_avx512() -> bool:
    """Whether the CPU has AVX-512 (which valgrind cannot decode); True when unknown."""
    try:
        return " avx512f" in Path("/proc/cpuinfo").read_text()
    except OSError:
        return True


def cached_build(cmd: list, exe: Path) -> None:
    """Run the compile command ``cmd`` that writes ``exe``, or copy the executable an
    identical earlier build left in the cache (``<cache_dir>/bench-harnesses/``).
    A Pinocchio harness takes gcc minutes and gigabytes, and every benchmark
    script builds it twice; the key is the command (the output path left out),
    the sources it names, the compiler's version and the CPU (-march=native)."""
    out = cmd.index("-o") + 1
    digest = hashlib.sha256()
    for i, arg in enumerate(cmd):
        digest.update(b"\0" + (b"<exe>" if i == out else arg.encode()))
        if Path(arg).suffix in (".c", ".cpp", ".h") and Path(arg).is_file():
            digest.update(Path(arg).read_bytes())
    machine = environment()
    digest.update(f"{machine['cpu']}\0{machine['compiler']}\0{platform.machine()}".encode())
    try:
        import pinocchio
        digest.update(pinocchio.__version__.encode())
    except ImportError:
        pass
    cached = cache_dir() / "bench-harnesses" / digest.hexdigest()[:24] / "harness"
    exe.parent.mkdir(parents=True, exist_ok=True)
    if cached.is_file():
        shutil.copy2(cached, exe)
        return
    run_checked(cmd)
    try:
        cached.parent.mkdir(parents=True, exist_ok=True)
        partial = cached.with_name(f".harness.{os.getpid()}")
        shutil.copy2(exe, partial)
        os.replace(partial, cached)       # whole or absent, for a concurrent reader
    except OSError:
        pass                              # a read-only cache: build every time


def build_pinocchio_harness(work: Path, count: bool = False):
    """Compile ``harness/pinocchio_bench.cpp`` (-O3 -march=native; :func:`cached_build`);
    it reads the model from a file (:func:`modelgen.bench.peers.pinocchio_tree_file`).
    Returns (path, None) or (None, reason).

    ``count``: the build that callgrind runs, ``pin_count``, with ``-mno-avx512f``
    added, because valgrind does not decode AVX-512 (on a CPU without AVX-512 it is
    the timed build's code)."""
    exe = work / ("pin_count" if count else "pin_bench")
    cmd = pinocchio_command(HARNESS_DIR / "pinocchio_bench.cpp", exe, count)
    if cmd is None:
        return None, "pin or cmeel-eigen not installed (pip install '.[bench]')"
    try:
        cached_build(cmd, exe)
    except RuntimeError as exc:
        return None, f"Pinocchio harness did not build: {exc}"
    return exe, None


def run_pinocchio_derivatives(exe: Path, tree_file: Path) -> tuple:
    """One run of computeABADerivatives at tau = 0 (the harness's mode 3): (µs per call,
    d q_ddot / d q, d q_ddot / d v at x0, each n x n)."""
    lines = run_checked([str(exe), str(tree_file), "3"]).splitlines()
    dq, dv = (np.array(line.split(), float) for line in lines[1:3])
    n = int(round(np.sqrt(dq.size)))
    return float(lines[0].split()[0]) * 1e6, dq.reshape(n, n), dv.reshape(n, n)


def run_pinocchio_harness(exe: Path, tree_file: Path) -> tuple:
    """One run: (ABA µs, CRBA + Cholesky µs, q_ddot by ABA, q_ddot by CRBA) at x0."""
    lines = run_checked([str(exe), str(tree_file)]).splitlines()
    aba, crba, _ = lines[0].split()
    return (float(aba) * 1e6, float(crba) * 1e6, np.array(lines[1].split(), float),
            np.array(lines[2].split(), float))


# -- the peers of one run -----------------------------------------------------------

@dataclass(frozen=True)
class PeerHarnesses:
    """The peers' harnesses of one run, None where a peer is missing (``notes`` say why)."""
    mujoco: Path | None
    pinocchio: Path | None
    pinocchio_count: Path | None        # Pinocchio's build for callgrind
    notes: tuple


def build_peer_harnesses(work: Path, count: bool) -> PeerHarnesses:
    """Build MuJoCo's and Pinocchio's harnesses under ``work``, and with ``count``
    (and valgrind installed) Pinocchio's build for callgrind."""
    notes, mujoco = [], None
    if importlib.util.find_spec("mujoco") is None:
        notes.append("mujoco is not installed: MuJoCo columns skipped")
    else:
        mujoco, why = build_mujoco_harness(work / "mujoco")
        if mujoco is None:
            notes.append(f"MuJoCo timed through Python (py): {why}")
    pinocchio, why = build_pinocchio_harness(work / "pinocchio")
    if pinocchio is None:
        notes.append(f"Pinocchio not timed: {why}")
    if count and shutil.which("valgrind") is None:
        notes.append("valgrind not found: no instruction counts")
    pinocchio_count = None
    if count and shutil.which("valgrind") and pinocchio is not None:
        pinocchio_count, why = build_pinocchio_harness(work / "pinocchio", count=True)
        if pinocchio_count is None:
            notes.append(f"Pinocchio's instructions not counted: {why}")
    return PeerHarnesses(mujoco, pinocchio, pinocchio_count, tuple(notes))
