"""Which C compiler a build runs (``$CC``), for flags only one compiler knows, how it
links a shared library (``$LDSHARED``), and how its commands run: in parallel, at
most one per core."""
from __future__ import annotations

import atexit
import functools
import os
import shlex
import sysconfig
from pathlib import Path

from modelgen.errors import BuildError

FIX_COMPILER = "install a C compiler (e.g. apt install gcc) or set CC to one"


def split_env(variable: str, default: str) -> list:
    """``$variable`` split as a shell would; BuildError if it cannot be."""
    value = os.environ.get(variable, default)
    try:
        return shlex.split(value)
    except ValueError as exc:
        raise BuildError(f"${variable}={value!r} cannot be split into arguments ({exc})",
                         fix=f"quote {variable} as in a shell, e.g. "
                             f"{variable}='-DNAME=\\\"text\\\"'") from None


def compiler() -> list:
    """The C compiler command: ``$CC`` if set, else ``cc``."""
    command = split_env("CC", "cc")
    if not command:
        raise BuildError("$CC is set but empty, so there is no C compiler to run",
                         fix="unset CC or set it to a C compiler, e.g. CC=gcc")
    return command


def library_suffix() -> str:
    """File suffix of a model's shared library on this platform."""
    return sysconfig.get_config_var("SHLIB_SUFFIX") or ".so"


def link_command(objects: list, output: str) -> list:
    """The command linking ``objects`` into the shared library ``output``: the
    platform's shared-object link as this Python was configured (sysconfig's
    ``LDSHARED``: ``gcc -shared ...`` on Linux, ``clang -bundle -undefined
    dynamic_lookup ...`` on macOS), or ``$LDSHARED``; with ``$CC`` set (and not
    ``$LDSHARED``) its compiler takes the configured one's place, as distutils does.

    >>> link_command(["m.o"], "libm.so")[-4:]
    ['m.o', '-o', 'libm.so', '-lm']
    """
    command = split_env("LDSHARED", sysconfig.get_config_var("LDSHARED") or "")
    if not command:
        raise BuildError("this Python's configuration names no command to link a shared "
                         "library (sysconfig's LDSHARED is empty)",
                         fix="set LDSHARED to one, e.g. LDSHARED='gcc -shared'")
    configured = shlex.split(sysconfig.get_config_var("CC") or "")
    if "CC" in os.environ and "LDSHARED" not in os.environ and configured \
            and command[:len(configured)] == configured:
        command = [*compiler(), *command[len(configured):]]
    return [*command, *objects, "-o", output, "-lm"]


#: Added to an optimised level when the compiler is gcc: its dead-store passes,
#: which find no dead store in generated code (the same machine code with and
#: without, up to the stack slots of spills, on the 20- and 50-link chains with
#: their derivatives), but walk the aliasing stores behind each of the many
#: stores of a large routine (a seventh of the compile time of the derivatives'
#: part).  clang has no such flags.
GCC_FLAGS = ("-fno-tree-dse", "-fno-dse")
#: Added to -O2 (not -O1, which runs none of these passes) when the compiler is
#: gcc: RTL passes that cost compile time in proportion to a routine's size and
#: give generated code nothing it keeps.  The tree passes (FRE, PRE, the
#: forward propagation) have already removed the redundancy that RTL GCSE and
#: the second CSE (``-frerun-cse-after-loop``) look for; code hoisting moves
#: expressions out of branches, of which the straight-line code has few; the
#: x86 peephole2 patterns split memory operands of the arithmetic into separate
#: loads, lengthening straight-line code; the second scheduling pass only
#: reorders instructions, which an out-of-order CPU does by itself.  Without
#: them the same results are computed by no more instructions (docs/benchmarks.md,
#: bench/derivatives.py, "Session 12").  Two tree and IPA passes likewise: value
#: range propagation looks for integer ranges, and generated code is arithmetic
#: on doubles; identical code folding compares every function with the others,
#: and generated functions are never identical ("Session 17").  clang has none
#: of these flags.
GCC_O2_FLAGS = ("-fno-gcse", "-fno-rerun-cse-after-loop", "-fno-code-hoisting",
                "-fno-peephole2", "-fno-schedule-insns2", "-fno-tree-vrp", "-fno-ipa-icf")
#: Added to -O1 (the parts above 4,000 statements) when the compiler is gcc:
#: tree passes that visit every statement of a large routine and find nothing
#: to do in generated code.  Conditional constant propagation looks for
#: constants the generator already folded; scalar replacement of aggregates
#: looks for small structures and arrays to split into scalars, and the arrays
#: of generated routines are the caller's or large work arrays.  Without them gcc
#: writes the same instructions, computing the same bits, on the chains and the
#: largest robots (docs/benchmarks.md, "Session 12"), in less time.  The other
#: -O1 passes that find nothing either cost too little to be worth a flag.
#: clang has none of these flags.
GCC_O1_FLAGS = ("-fno-tree-ccp", "-fno-tree-sra")


def gcc_flags(level: str) -> tuple:
    """The gcc-only flags of an optimisation ``level`` ("-O0", "-O1", "-O2"):
    :data:`GCC_FLAGS` and the level's own (:data:`GCC_O1_FLAGS`,
    :data:`GCC_O2_FLAGS`); none at -O0, which runs none of their passes.

    >>> gcc_flags("-O0"), gcc_flags("-O1")[-2:]
    ((), ('-fno-tree-ccp', '-fno-tree-sra'))
    """
    if level == "-O0":
        return ()
    return (*GCC_FLAGS, *{"-O1": GCC_O1_FLAGS, "-O2": GCC_O2_FLAGS}.get(level, ()))


@functools.lru_cache(maxsize=4)
def is_gcc(command: tuple) -> bool:
    """True if the C compiler ``command`` is gcc (its ``--version`` names the Free
    Software Foundation; clang, Apple's cc and Intel's icx do not); False if it
    does not run.  Reads the run :func:`probe_compiler` started, if any.

    >>> is_gcc(("no-such-compiler-xyz",))
    False
    """
    import subprocess     # imported by a build only (a cached load needs none)
    _answered.add(command)
    pid, proc = _probes.pop(command, (None, None))
    if pid != os.getpid():          # none, or a forked parent's child
        proc = _version(command)
    if proc is None:
        return False
    try:
        out = proc.communicate(timeout=30)[0]
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        return False
    except OSError:
        return False
    return "Free Software Foundation" in out


def probe_compiler(command: tuple) -> None:
    """Start ``command --version`` in the background for :func:`is_gcc`, which a
    build first asks when it needs the compile flags: the run then overlaps the
    derivation instead of delaying the first compile.  Nothing if the answer is
    known or the run under way."""
    if command not in _answered and command not in _probes:
        _probes[command] = (os.getpid(), _version(command))


#: the ``--version`` runs :func:`probe_compiler` started, by command: (pid, Popen or None)
_probes: dict = {}
#: the commands :func:`is_gcc` was asked about
_answered: set = set()


def _reap_probes() -> None:
    """End and wait for the probes of builds that stopped before compiling (a model
    over the budget, an error), so no run outlives this process unwaited."""
    for pid, proc in _probes.values():
        if pid == os.getpid() and proc is not None:
            proc.kill()
            # wait for the process, not for its pipe's end: a wrapper's own child
            # (a shell script's command) still holds the pipe after the kill
            proc.wait()
            proc.stdout.close()
    _probes.clear()


atexit.register(_reap_probes)


def _version(command: tuple):
    """The running ``command --version`` (its output piped), or None if it cannot start."""
    import subprocess
    try:
        return subprocess.Popen([*command, "--version"], stdout=subprocess.PIPE,
                                stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL,
                                text=True)
    except (OSError, subprocess.SubprocessError):
        return None


def core_count() -> int:
    """The cores this process may run on (its CPU affinity where the platform
    tells it, else the machine's)."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except (AttributeError, OSError):
        return os.cpu_count() or 1


#: Rough cost per statement of compiling at a level (:func:`part_order`'s order).
COMPILE_WEIGHT = {"-O0": 1, "-O1": 1, "-O2": 2}


def part_order(parts: dict) -> tuple:
    """The parts of ``parts`` (part -> (its largest routine's statements, its
    optimisation level)), the most expensive to compile first: with more parts
    than cores, the largest then has a core to itself from the start while the
    others share the rest, instead of finishing last.

    >>> part_order({1: (1500, "-O0"), 2: (2300, "-O2"), 3: (1400, "-O2"), 4: (3800, "-O2")})
    (4, 2, 3, 1)
    """
    def cost(part: int) -> int:
        statements, level = parts[part]
        return statements * COMPILE_WEIGHT[level]
    return tuple(sorted(parts, key=lambda part: (-cost(part), part)))


def run_commands(commands: list, cwd: Path, what: str = "C compiler failed",
                 jobs: int | None = None, meanwhile=None) -> None:
    """Run compiler commands in parallel, at most ``jobs`` at once (default: all),
    each started in ``commands``' order as soon as one before it has finished;
    raise BuildError (``what``, the command, its full output and exit status) on
    the first failure in that order, once all have finished.

    ``meanwhile()`` (if given) is called in this thread once the first commands
    (``jobs`` of them, or all) have started, while they run: work of the caller's
    that waits for no compiler, e.g. an import, then takes no wall time from them
    on a core they leave free (and none of Python's from starting them)."""
    import threading
    from concurrent.futures import ThreadPoolExecutor
    started = threading.Semaphore(0)

    def run(cmd: list) -> BuildError | None:
        try:
            proc = start_command(cmd, cwd)
        except OSError as exc:
            return BuildError(f"the C compiler {cmd[0]!r} cannot be run "
                              f"({exc.strerror or exc})", cmd, fix=FIX_COMPILER)
        finally:
            started.release()
        return command_failure(proc, cmd, what)

    if not commands:
        return
    workers = max(1, min(jobs or len(commands), len(commands)))
    with ThreadPoolExecutor(max_workers=workers) as pool:
        results = pool.map(run, commands)
        if meanwhile is not None:
            for _ in range(workers):
                started.acquire()
            meanwhile()
        failures = list(results)
    failure = next((f for f in failures if f is not None), None)
    if failure:
        raise failure


def start_command(cmd: list, cwd: Path):
    """``cmd`` started in ``cwd``, its output and errors in one pipe (OSError if it
    cannot start)."""
    import subprocess
    return subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def command_failure(proc, cmd: list, what: str = "C compiler failed") -> BuildError | None:
    """Wait for ``proc`` (``cmd``, from :func:`start_command`): None if it succeeded,
    else the BuildError (``what``, the command, its full output and exit status)."""
    out, _ = proc.communicate()
    return BuildError(what, cmd, out, returncode=proc.returncode) \
        if proc.returncode != 0 else None
