"""Build stage: C sources -> a model's plain shared library, plus one runtime module.

A model compiles into a plain C shared library (``lib_mg_<name>_<hash>.so``:
the model's code linked with the cached integrators), with no Python in it:
no ``Python.h``, no per-model extension module.  Python calls its functions
through the *runtime module* (:func:`runtime_module`), a cffi extension that
is the same for every model and is built once per compiler, Python and
interface version into the cache: it declares the interface of
``mg_integrate.h`` and holds one trampoline per function signature of
:data:`modelgen.codegen.capi.SIGNATURES`, which the loader
(:mod:`modelgen.sim.library`) binds to the model's function pointers.  So a
changed model costs one compile of its own C and a link (the double
pendulum: about 0.15 s instead of 0.45 s with a cffi wrapper of its own).

The runtime module is compiled by cffi through setuptools' compiler driver
(which knows the platform's flags for Python extensions); a model's library
is compiled by calling the C compiler directly (in parts, in parallel, on a
machine with more than one core), and a failure raises :class:`BuildError`
with the exact command and the compiler's full output (nothing is swallowed).

The integrators (``mg_integrate.c`` and the ``mg_integrate/*.c`` it includes,
the same for every model) are compiled once per compiler, flags and source
into a per-user cache directory (:func:`cache_dir`) and every model's module
links that object; a changed model recompiles only its own code.  They and
``mg_integrate.h`` are also copied next to the model's ``.c``/``.h``, so a C
user compiles the output directory's ``.c`` files and nothing else.

Everything is written to a private temporary directory first and moved into
place with ``os.replace`` under an exclusive lock on the output directory
(``fcntl.flock`` on the directory itself, so no lock file lies about; no lock
where ``fcntl`` is missing); ``manifest.json`` is moved last and marks a
complete build.  Two processes building the same model at once therefore
both succeed and leave one valid build.

The cache is verified, not trusted (:func:`cache_lookup`): the manifest
records its own SHA-256 and the size and SHA-256 of the library, and a
manifest that is not a complete, well-typed dict, was edited, or describes a
missing, truncated or altered library is a cache miss (the build says why in
``BuildResult.rebuilt_because``); the damaged library is never imported.

The other files the cache reuses are verified too: the runtime module and
the integrators' object have their size and SHA-256 recorded beside them
(``<file>.json``, written atomically after a successful build) and are
checked before they are imported or linked (:func:`file_problem`); a
damaged, substituted or unrecorded one is rebuilt with a warning that names
it, and a rebuild that fails too is a BuildError naming it.  (A truncated
shared object can kill its loader with SIGBUS before Python can react, so the
check comes before the import, never after a failure.)

Housekeeping: a build removes the temporary directories of killed builds
(:func:`remove_stale_builds`: in its output directory, and ``.mg-*`` and
``runtime/.build-*`` in the cache): at once when the name records a process
of this machine that is gone, else after an hour; the last :data:`KEEP_BUILDS` modules of a model
name are kept, each with its manifest (``manifest.json`` for the newest,
``manifest-<hash16>.json`` for the others), so two variants of one model
built into one directory do not rebuild each other; older ones are deleted.
"""
from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import os
import re
import sys
import sysconfig
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

try:
    import fcntl
except ImportError:   # not POSIX: builds are not serialised
    fcntl = None

from modelgen.codegen.compilers import (FIX_COMPILER, compiler, core_count, gcc_flags, is_gcc,
                                        library_suffix, link_command, part_order, run_commands,
                                        split_env)
from modelgen.errors import BuildError

# shutil, subprocess and tempfile are imported where a build needs them:
# a cached load (modelgen.codegen.index) imports this module and needs none.

#: -O2 without gcc's basic-block (SLP) vectorizer, which gcc 12 enables at -O2:
#: on the straight-line code of a rhs it packs pairs of scalar operations into
#: vector ones, which costs time at run time as well as at compile time (the
#: figures: docs/generated-c.md, "Compiler flags").
O2 = ("-O2", "-fno-tree-slp-vectorize")
#: Optimisation flags by the statement count of a part's largest routine: per
#: part, (flags, above this many statements) rows, first match wins, else
#: :data:`O2`.  gcc's time grows faster than linearly with code size.
#:
#: Parts 2 (the integration path), 3 (what a controller calls at every step:
#: inverse dynamics, the derivatives' solve, frame kinematics) and 4 (the
#: derivatives' straight line) are at :data:`O2` up to 4,000 statements, -O1
#: above.  Part 1 (A, h, tau, energies, poses: never
#: called by an integrator, only from Python through the runtime, where a call
#: costs about a microsecond anyway, or from a user's C, compiled by the user)
#: is at -O0 at every size, so it compiles beside the others without becoming
#: the critical path.  Part 0 is the whole file in one process (one core, and
#: the FMU): -O1 above 400 statements, else :data:`O2`.
OPT_LEVELS = {0: ((("-O1",), 400),), 1: ((("-O0",), -1),), 2: ((("-O1",), 4000),),
              3: ((("-O1",), 4000),), 4: ((("-O1",), 4000),)}
#: A model's C is compiled in parts (MG_PART 1, 2, 3 and, with derivatives, 4)
#: when the machine has two cores or more, at every size (even the double
#: pendulum gains), at most one compiler per core, the largest part first
#: (:func:`~modelgen.codegen.compilers.part_order`); on one core, as one part
#: (0: the whole file).
BASE_FLAGS = ("-std=c99", "-fPIC", "-Wall", "-Wextra")
#: Flags of mg_integrate.c (compiled once, on the integration hot path).
INTEGRATOR_FLAGS = ("-O2", *BASE_FLAGS, "-Werror")
#: Modules of one model name kept in a directory (the newest built; a cache hit
#: changes no file, so build time is the order).
KEEP_BUILDS = 3
#: Age in seconds after which a ``.build-*`` temporary directory is a dead build's.
STALE_SECONDS = 3600
#: Keys every manifest holds, with their types (checked before any import).
MANIFEST_KEYS = {"name": str, "build_hash": str, "abi_version": int, "n": int,
                 "coordinates": list, "parameters": list, "inputs": list, "bodies": list,
                 "outputs": list, "module_name": str, "module_file": str,
                 "module_size": int, "module_sha256": str, "manifest_sha256": str,
                 "functions": dict}
FIX_PYTHON_H = ("install the Python development headers (e.g. apt install python3-dev, "
                "dnf install python3-devel)")


@dataclass(frozen=True)
class BuildResult:
    directory: Path
    module_name: str
    module_path: Path
    manifest: dict
    cached: bool
    seconds: float
    #: why an existing build was not reused ("" if there was none or it was)
    rebuilt_because: str = ""


#: the stages of a build, in order (each announced to ``progress``); ``Generated.seconds``
#: has them and, first, ``check`` (hashes, formulation, cache, budget), adding up to the build
STAGES = ("derive", "cse", "emit", "compile")


@dataclass(frozen=True)
class Generated:
    """What :func:`modelgen.codegen.pipeline.generate` did: the build and the
    figures of each stage (``manifest["seconds"]``, ``manifest["ops"]``)."""
    build: BuildResult
    manifest: dict

    @property
    def seconds(self) -> dict:
        return self.manifest["seconds"]

    @property
    def ops(self) -> dict:
        return self.manifest["ops"]


def compile_flags(statements: int, part: int = 2, *, host: bool = False) -> list:
    """Compiler flags for one part of a model whose largest routine (in that part)
    has ``statements``; see :data:`OPT_LEVELS`.  With ``host`` (code that only
    ever runs on this machine: the model's library in the cache or an output
    directory, never an FMU) :func:`host_flags` come after the base flags.

    ``$MODELGEN_CFLAGS`` is appended (and is part of the cache key).

    >>> compile_flags(100, 1)[0], compile_flags(100, 2)[:2], compile_flags(5000, 2)[0]
    ('-O0', ['-O2', '-fno-tree-slp-vectorize'], '-O1')
    """
    opt = _opt_level(statements, part)
    gcc = gcc_flags(opt[0])
    gcc = gcc if gcc and is_gcc(tuple(compiler())) else ()
    return [*opt, *gcc, *BASE_FLAGS, *(host_flags() if host else ()),
            *split_env("MODELGEN_CFLAGS", "")]


def unoptimized(part: int, statements: int) -> bool:
    """Whether :data:`OPT_LEVELS` compiles ``part`` at -O0 when its largest routine
    has ``statements`` (then a routine cut into parts is read as one function:
    ``emit.print_routine``'s ``flat``).

    >>> unoptimized(1, 5000), unoptimized(2, 100)
    (True, False)
    """
    return _opt_level(statements, part) == ("-O0",)


def _opt_level(statements: int, part: int) -> tuple:
    """The optimisation flags of :data:`OPT_LEVELS` for a part whose largest routine
    has ``statements``."""
    return next((flags for flags, above in OPT_LEVELS[part] if statements > above), O2)


#: Instruction-set flag for code built for this machine only, when its CPU has
#: AVX.  It does not change a result: the C is compiled as ISO C99, under which
#: gcc and clang never contract ``a*b + c`` into a fused multiply-add, so the
#: same operations are rounded the same way; what changes is the encoding.
#: With VEX's three-operand forms the straight-line rhs needs no register
#: copies, so it runs fewer instructions with bit-identical output
#: (docs/generated-c.md, "Compiler flags").  ``MODELGEN_AVX=0`` turns it off.
HOST_ISA = ("-mavx",)


def host_flags() -> tuple:
    """:data:`HOST_ISA` if this is an x86-64 Linux machine whose CPU (and kernel)
    support AVX and ``$MODELGEN_AVX`` is not ``0`` (set it when ``$CC`` is a
    cross compiler, or the library is to run on an older CPU); else nothing.

    Linux lists ``avx`` in ``/proc/cpuinfo`` only when the kernel also saves the
    AVX registers, so the flag is a complete check.  Elsewhere (macOS, arm64,
    Windows) the build keeps the compiler's baseline.
    """
    if os.environ.get("MODELGEN_AVX", "1") == "0":
        return ()
    return _cpu_has_avx()


@functools.lru_cache(maxsize=1)
def _cpu_has_avx() -> tuple:
    if sys.platform != "linux" or os.uname().machine not in ("x86_64", "AMD64"):
        return ()
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as f:
            for line in f:
                if line.startswith("flags"):
                    return HOST_ISA if "avx" in line.split(":", 1)[1].split() else ()
    except OSError:
        pass
    return ()


def cache_dir() -> Path:
    """The per-user build cache: ``$MODELGEN_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/modelgen``, else ``~/.cache/modelgen``.  It holds the
    compiled integrators (``integrators/``) and every model built without an
    explicit output directory (``models/<name>/``)."""
    if os.environ.get("MODELGEN_CACHE_DIR"):
        return Path(os.environ["MODELGEN_CACHE_DIR"])
    if os.environ.get("XDG_CACHE_HOME"):
        return Path(os.environ["XDG_CACHE_HOME"]) / "modelgen"
    return Path.home() / ".cache" / "modelgen"


def integrator_flags() -> list:
    """Compiler flags of mg_integrate.c (``$MODELGEN_CFLAGS`` appended)."""
    return [*INTEGRATOR_FLAGS, *split_env("MODELGEN_CFLAGS", "")]


def integrator_hash(sources: dict) -> str:
    """Cache key of the integrators' object: every one of their files (name and text),
    the compiler and its flags."""
    h = hashlib.sha256()
    for part in (*(p for name in sorted(sources) for p in (name, sources[name])),
                 " ".join(compiler()), " ".join(integrator_flags())):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()


def write_sources(directory: Path, sources: dict) -> None:
    """Write ``sources`` (path relative to ``directory`` -> text), making their folders."""
    for name, text in sources.items():
        path = Path(directory) / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def integrator_object(sources: dict) -> tuple:
    """(path, cached): the compiled ``mg_integrate.o`` for these sources
    (:func:`modelgen.codegen.emit.integrator_sources`), from the cache or compiled now.

    A cached object is linked only if it has the size and SHA-256 recorded when
    it was compiled (:func:`file_problem`); else it is compiled again, with a
    warning naming it.  Compiled in a private temporary directory and moved into
    the cache with ``os.replace``, so concurrent builds never see a partial object.
    """
    import shutil
    directory = cache_dir()
    target = directory / f"mg_integrate-{integrator_hash(sources)[:20]}.o"
    remove_stale_builds(directory, ".mg-")
    if _reusable(target, directory):
        return target, True
    tmp = private_dir(directory, ".mg-")
    try:
        write_sources(tmp, sources)
        try:
            run_commands([[*compiler(), *integrator_flags(), "-c", "mg_integrate.c",
                           "-o", "mg_integrate.o"]], tmp)
        except BuildError as exc:
            raise _naming(exc, f"the integrators' object {target} could not be compiled") \
                from None
        with _locked(directory):
            os.replace(tmp / "mg_integrate.o", target)
            record_file(target)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return target, False


def _naming(exc: BuildError, what: str) -> BuildError:
    """``exc`` with ``what`` (which names the file being built) before its message."""
    first = str(exc).split("; fix:", 1)[0].split("\n", 1)[0]
    return BuildError(f"{what}: {first}", exc.command, exc.output,
                      returncode=exc.returncode, fix=exc.fix)


def record_path(path: Path) -> Path:
    """Where the size and SHA-256 of a reused cache file are recorded: ``<file>.json``."""
    return Path(path).with_name(Path(path).name + ".json")


def record_file(path: Path) -> None:
    """Record the size and SHA-256 of ``path`` (just built) beside it, atomically."""
    import tempfile
    path = Path(path)
    text = json.dumps({"file": path.name, "size": path.stat().st_size,
                       "sha256": file_sha256(path)})
    fd, tmp = tempfile.mkstemp(prefix=".record-", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, record_path(path))
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def file_problem(path: Path) -> str | None:
    """What is wrong with the cache file ``path`` (a sentence naming it), or None
    when it has the size and SHA-256 recorded when it was built (:func:`record_file`).
    Nothing is loaded: a damaged shared object can crash its loader."""
    path = Path(path)
    try:
        record = json.loads(record_path(path).read_text())
        size, digest = record["size"], record["sha256"]
        if record["file"] != path.name or not isinstance(size, int) \
                or not isinstance(digest, str):
            raise ValueError(record)
    except FileNotFoundError:
        return (f"{path} has no record of its size and SHA-256 (an older modelgen or an "
                f"interrupted build made it)")
    except (OSError, ValueError, KeyError, TypeError):
        return f"the record of {path}'s size and SHA-256 ({record_path(path).name}) is damaged"
    try:
        actual = path.stat().st_size
        if actual != size:
            return f"{path} has {actual} bytes, its build wrote {size}"
        if file_sha256(path) != digest:
            return f"{path} was altered (its SHA-256 is not the one recorded when it was built)"
    except OSError as exc:
        return f"{path} cannot be read ({exc.strerror or exc})"
    return None


def _reusable(target: Path, directory: Path) -> bool:
    """True if ``target`` (a file the cache reuses) verifies; False if it is missing
    or must be rebuilt (then a warning says why, naming it)."""
    if not target.exists():
        return False
    if file_problem(target) is None:
        return True
    # a concurrent build may be between moving the file into place and recording it
    with _locked(directory):
        problem = file_problem(target) if target.exists() else None
    if problem is None:
        return target.exists()
    warnings.warn(f"{problem}; rebuilding it", stacklevel=3)
    return False


def manifest_path(directory: Path, build_hash: str | None = None) -> Path:
    """``manifest.json`` (the newest build), or ``manifest-<hash16>.json`` (an older one)."""
    name = f"manifest-{build_hash[:16]}.json" if build_hash else "manifest.json"
    return Path(directory) / name


def read_manifest(directory: Path, build_hash: str | None = None) -> dict | None:
    """The manifest of the build of ``build_hash`` (default: the newest), unchecked."""
    paths = [manifest_path(directory)]
    if build_hash:
        paths.append(manifest_path(directory, build_hash))
    manifest = None
    for path in paths:
        try:
            manifest = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        if not build_hash or (isinstance(manifest, dict)
                              and manifest.get("build_hash") == build_hash):
            return manifest
    return manifest


def file_sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def manifest_digest(manifest: dict) -> str:
    """SHA-256 of a manifest's content, its own ``manifest_sha256`` and ``seconds`` left out."""
    content = {k: v for k, v in manifest.items() if k not in ("manifest_sha256", "seconds")}
    return hashlib.sha256(json.dumps(content, sort_keys=True).encode()).hexdigest()


def manifest_problem(manifest) -> str | None:
    """What is wrong with the structure of ``manifest``, or None: a dict with every
    key of :data:`MANIFEST_KEYS`, of its type, and names lists of names."""
    if not isinstance(manifest, dict):
        return f"the manifest is a {type(manifest).__name__}, not a mapping"
    for key, kind in MANIFEST_KEYS.items():
        if key not in manifest:
            return f"the manifest has no {key!r}"
        if not isinstance(manifest[key], kind) or isinstance(manifest[key], bool):
            return f"the manifest's {key!r} is not a {kind.__name__}"
    for key in ("coordinates", "inputs", "bodies"):
        if not all(isinstance(v, str) for v in manifest[key]):
            return f"the manifest's {key!r} is not a list of names"
    if not all(isinstance(v, list) and len(v) == 2 and isinstance(v[0], str)
               and isinstance(v[1], (int, float)) for v in manifest["parameters"]):
        return "the manifest's 'parameters' is not a list of [name, value]"
    if not all(isinstance(o, dict) and isinstance(o.get("name"), str)
               and isinstance(o.get("columns"), list) for o in manifest["outputs"]):
        return "the manifest's 'outputs' is not a list of {name, columns}"
    units = manifest.get("units", {})
    if not (isinstance(units, dict) and all(isinstance(v, str) for v in units.values())):
        return "the manifest's 'units' is not a mapping of names to units"
    if Path(manifest["module_file"]).name != manifest["module_file"]:
        return "the manifest's 'module_file' is not a file name"
    return None


def cache_lookup(directory: Path, build_hash: str) -> tuple:
    """(BuildResult or None, why not): the verified build of ``build_hash`` in ``directory``.

    The manifest must be intact (structure and its own digest) and the library
    must have the recorded size and SHA-256; nothing is imported.  ``why not``
    is "" for a hit or for no build at all, else it says what is damaged.
    """
    directory = Path(directory)
    manifest = read_manifest(directory, build_hash)
    if manifest is None:
        return None, ""
    if isinstance(manifest, dict) and manifest.get("build_hash") != build_hash:
        return None, ""          # another model, or this one changed: not damage
    problem = manifest_problem(manifest)
    if problem is None and manifest["manifest_sha256"] != manifest_digest(manifest):
        problem = "the manifest was edited after the build (its SHA-256 does not match)"
    if problem is None:
        module_path = directory / manifest["module_file"]
        try:
            size = module_path.stat().st_size
            if size != manifest["module_size"]:
                problem = (f"{module_path.name} has {size} bytes, the build wrote "
                           f"{manifest['module_size']}")
            elif file_sha256(module_path) != manifest["module_sha256"]:
                problem = f"{module_path.name} was altered (its SHA-256 does not match)"
        except OSError as exc:
            problem = f"{module_path.name} cannot be read ({exc.strerror or exc})"
    if problem:
        return None, f"damaged build in {directory}: {problem}"
    return BuildResult(directory, manifest["module_name"], module_path, manifest, True, 0.0), ""


def default_output(name: str) -> Path:
    """Where a model is built when no output directory is given: the per-user cache
    (``models/<name>`` under :func:`cache_dir`), never the current directory."""
    return cache_dir() / "models" / name


def host_tag() -> str:
    """8 hex digits naming this machine, in a temporary directory's name beside its
    process id (a cache may be shared between machines, whose pids differ); the name
    is uname's, which POSIX's gethostname returns, without importing socket."""
    if not hasattr(os, "uname"):
        import socket
        return hashlib.sha256(socket.gethostname().encode()).hexdigest()[:8]
    return hashlib.sha256(os.uname().nodename.encode()).hexdigest()[:8]


def private_dir(directory: Path, prefix: str) -> Path:
    """A new private temporary directory in ``directory`` (created with its parents),
    named ``<prefix><pid>-<host tag>-...`` so a later build can tell when its
    owner is gone; BuildError naming the path if it cannot be written."""
    import tempfile
    directory = Path(directory)
    try:
        directory.mkdir(parents=True, exist_ok=True)
        return Path(tempfile.mkdtemp(prefix=f"{prefix}{os.getpid()}-{host_tag()}-",
                                     dir=directory))
    except OSError as exc:
        what = "is a file, not a directory" if isinstance(exc, (FileExistsError,
                                                                NotADirectoryError)) \
            else f"cannot be written ({exc.strerror or exc})"
        raise BuildError(f"the build directory {directory} {what}",
                         fix="choose a writable directory (out_dir=..., or "
                             "MODELGEN_CACHE_DIR for the cache)") from None


def _process_gone(pid: int) -> bool:
    """True if no process ``pid`` runs on this machine (POSIX only: elsewhere
    signalling a process is not a harmless probe)."""
    if os.name != "posix":
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except OSError:             # it exists (another user's): not ours to judge
        return False
    return False


def remove_stale_builds(directory: Path, prefix: str = ".build-",
                        age: float = STALE_SECONDS) -> list:
    """Remove the ``prefix*`` temporary directories of killed builds: those whose
    name records a process of this machine that is gone (:func:`private_dir`),
    and any older than ``age`` seconds; returns their paths."""
    import shutil
    removed, now = [], time.time()
    owner = re.compile(rf"{re.escape(prefix)}(\d+)-([0-9a-f]{{8}})-")
    for path in Path(directory).glob(prefix + "*"):
        with contextlib.suppress(OSError, ValueError):
            if not path.is_dir():
                continue
            match = owner.match(path.name)
            dead = bool(match) and match[2] == host_tag() and int(match[1]) != os.getpid() \
                and _process_gone(int(match[1]))
            if dead or now - path.stat().st_mtime > age:
                shutil.rmtree(path)
                removed.append(path)
    return removed


@contextlib.contextmanager
def _locked(directory: Path):
    """Exclusive lock on ``directory`` (flock on the directory itself)."""
    if fcntl is None:
        yield
        return
    fd = os.open(directory, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)                          # releases the lock


def _remove_old_builds(directory: Path, name: str, keep: str) -> None:
    """Keep the newest :data:`KEEP_BUILDS` modules of model ``name`` that have a
    manifest (``keep`` always among them); delete the others and their manifests."""
    pattern = re.compile(rf"lib_mg_{re.escape(name)}_([0-9a-f]{{16}})\.")
    modules = []
    for path in directory.iterdir():
        match = pattern.match(path.name)
        if match and path.is_file():
            with contextlib.suppress(OSError):
                modules.append((path.name == keep, path.stat().st_mtime, path, match[1]))
    modules.sort(reverse=True)
    for rank, (_, _, path, short) in enumerate(modules):
        has_manifest = path.name == keep or manifest_path(directory, short).is_file()
        if rank >= KEEP_BUILDS or not has_manifest:
            with contextlib.suppress(OSError):
                path.unlink()
            with contextlib.suppress(OSError):
                manifest_path(directory, short).unlink()


def _write_if_changed(path: Path, text: str, tmpdir: Path) -> None:
    """Atomically replace ``path`` with ``text`` unless it already holds it."""
    data = text.encode()
    try:
        if path.read_bytes() == data:
            return
    except OSError:
        pass
    tmp = tmpdir / (path.name + ".new")
    tmp.write_bytes(data)
    os.replace(tmp, path)


@contextlib.contextmanager
def _captured_output(path: Path):
    """Send this process's stdout and stderr (file descriptors 1 and 2, which the
    compilers setuptools starts inherit) to ``path`` for the duration."""
    saved = []
    with open(path, "w") as sink:
        for fd in (1, 2):
            try:
                saved.append((fd, os.dup(fd)))
                os.dup2(sink.fileno(), fd)
            except OSError:
                pass
        try:
            with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
                yield
        finally:
            for fd, copy in saved:
                os.dup2(copy, fd)
                os.close(copy)


def runtime_hash(integrator: dict, runtime: dict) -> str:
    """Cache key of the runtime module: its sources, the integrators', the compiler,
    flags, cffi and the Python ABI it is built for."""
    import cffi            # here, not at the top: a cached model's load never needs it
    h = hashlib.sha256()
    for part in (runtime["cdef"], runtime["mg_runtime.c"], integrator_hash(integrator),
                 cffi.__version__, sysconfig.get_config_var("EXT_SUFFIX") or "",
                 sys.version):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()


def runtime_module(integrator: dict, runtime: dict, *, rebuild: bool = False) -> tuple:
    """(module name, path) of the compiled runtime module for these sources, from
    the cache (``runtime/`` in :func:`cache_dir`) or built now (once: about 2 s).

    A cached module is returned only if it has the size and SHA-256 recorded when
    it was built (:func:`file_problem`), since importing a truncated one can kill
    the process; else it is rebuilt, with a warning naming it.  ``rebuild``:
    build it again even so (its import failed); a failed rebuild names it.
    """
    import shutil
    directory = cache_dir() / "runtime"
    module_name = f"_mg_runtime_{runtime_hash(integrator, runtime)[:16]}"
    suffix = sysconfig.get_config_var("EXT_SUFFIX") or ".so"
    target = directory / (module_name + suffix)
    if not rebuild and _reusable(target, directory):
        return module_name, target
    damaged = rebuild or target.exists()
    tmp = private_dir(directory, ".build-")
    remove_stale_builds(directory)
    try:
        with _locked(directory):
            if not rebuild and target.exists() and file_problem(target) is None:
                return module_name, target            # built by another process meanwhile
            try:
                _build_runtime(tmp, module_name, integrator, runtime, target)
            except BuildError as exc:
                if not damaged:
                    raise
                raise _naming(exc, f"the runtime module {target} is damaged and could not "
                                   f"be rebuilt") from None
    except OSError as exc:
        raise BuildError(f"the runtime module cannot be written to {directory} "
                         f"({exc.strerror or exc})",
                         fix="choose a writable cache (MODELGEN_CACHE_DIR)") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return module_name, target


def _build_runtime(tmp: Path, module_name: str, integrator: dict, runtime: dict,
                   target: Path) -> None:
    """Compile the runtime module in ``tmp``, move it to ``target`` and record it."""
    write_sources(tmp, integrator)
    import cffi
    ffi = cffi.FFI()
    ffi.cdef(runtime["cdef"])
    ffi.set_source(module_name, runtime["mg_runtime.c"],
                   sources=[str(tmp / "mg_integrate.c")], include_dirs=[str(tmp)],
                   extra_compile_args=["-O2"],
                   libraries=["m"] if os.name == "posix" else [])
    include = Path(sysconfig.get_paths()["include"])
    if not (include / "Python.h").is_file():
        raise BuildError(f"the Python headers (Python.h) are missing from {include}",
                         fix=FIX_PYTHON_H)
    try:
        with _captured_output(tmp / "compiler.log"):
            built = tmp / ffi.compile(tmpdir=str(tmp), verbose=False)
    except Exception as exc:              # setuptools' and cffi's errors alike
        text = f"{(tmp / 'compiler.log').read_text(errors='replace')}{exc}"
        python_h = "Python.h" in text
        raise BuildError(
            "the Python headers (Python.h) are missing" if python_h
            else "the runtime module (cffi) failed to build",
            ["cffi", "compile", module_name], text,
            fix=FIX_PYTHON_H if python_h else FIX_COMPILER) from None
    os.replace(built, target)
    record_file(target)


def part_command(name: str, part: int, statements: int) -> list:
    """The command compiling ``part`` of ``<name>.c`` (0: all of it) into
    ``<name>_<part>.o``, its largest routine having ``statements``."""
    return [*compiler(), *compile_flags(statements, part, host=True), "-Werror",
            *([f"-DMG_PART={part}"] if part else []), "-c", f"{name}.c", "-o", f"{name}_{part}.o"]


def build_module(directory: Path, name: str, sources: dict, manifest: dict,
                 statements: dict, integrator: dict, while_compiling=None,
                 early=None) -> BuildResult:
    """Compile ``sources`` (``<name>.c``, ``<name>.h``) into a shared library in
    ``directory``, linked with the cached object of ``integrator``
    (``mg_integrate.h``, ``mg_integrate.c`` and ``mg_integrate/*.c``), which are
    copied next to them.

    ``manifest`` must hold ``build_hash``; the library is named after it so a
    changed model never collides with an already loaded one.  ``statements`` maps
    each part to compile (1: the model functions, 2: the integration path, 3:
    what a controller calls, 4: the derivatives' straight line) to its largest
    routine's statement count, which chooses its optimisation level
    (:data:`OPT_LEVELS`; see :func:`modelgen.codegen.pipeline.part_statements`)
    and its place in the order the parts start in
    (:func:`~modelgen.codegen.compilers.part_order`).  ``while_compiling()`` (if
    given) is called while the parts compile (``meanwhile`` of
    :func:`~modelgen.codegen.compilers.run_commands`).  ``early`` (part ->
    :class:`~modelgen.codegen.parts.EarlyPart`, if given): parts already
    compiling, whose objects are used where they are those of these sources.
    """
    import shutil
    start = time.perf_counter()
    directory = Path(directory)
    module_name = f"lib_mg_{name}_{manifest['build_hash'][:16]}"
    module_file = module_name + library_suffix()

    tmp = private_dir(directory, ".build-")
    remove_stale_builds(directory)
    remove_stale_builds(cache_dir() / "runtime")
    try:
        integrator_obj, integrator_cached = integrator_object(integrator)
        for fname in (f"{name}.c", f"{name}.h"):
            (tmp / fname).write_text(sources[fname])
        (tmp / "mg_integrate.h").write_text(integrator["mg_integrate.h"])
        cores = core_count()
        by_part = {**statements, 0: max(statements.values())}
        parts = part_order({part: (count, _opt_level(count, part)[0])
                            for part, count in statements.items()}) if cores > 1 else (0,)
        model_objs = [part_command(name, part, by_part[part]) for part in parts]
        final = {**sources, "mg_integrate.h": integrator["mg_integrate.h"]}
        adopted = sorted(p for p, e in (early or {}).items()
                         if p in parts and e.matches(final, name, model_objs[parts.index(p)]))
        run_commands([c for p, c in zip(parts, model_objs) if p not in adopted],
                     tmp, jobs=cores, meanwhile=while_compiling)
        for part in adopted:
            early[part].finish(tmp / f"{name}_{part}.o")
        run_commands([link_command([*(f"{name}_{part}.o" for part in parts), str(integrator_obj)],
                           module_file)], tmp)

        manifest = dict(manifest, module_name=module_name, module_file=module_file,
                        module_size=(tmp / module_file).stat().st_size,
                        module_sha256=file_sha256(tmp / module_file),
                        compile_commands=[" ".join(c) for c in model_objs],
                        early_parts=adopted,
                        integrators={"path": str(integrator_obj), "cached": integrator_cached})
        manifest["manifest_sha256"] = manifest_digest(manifest)
        (tmp / "manifest.json").write_text(json.dumps(manifest, indent=2, sort_keys=True))
        with _locked(directory):
            _write_if_changed(directory / f"{name}.c", sources[f"{name}.c"], tmp)
            _write_if_changed(directory / f"{name}.h", sources[f"{name}.h"], tmp)
            for fname, text in integrator.items():
                (directory / fname).parent.mkdir(parents=True, exist_ok=True)
                _write_if_changed(directory / fname, text, tmp)
            os.replace(tmp / module_file, directory / module_file)
            newest = read_manifest(directory)
            if isinstance(newest, dict) and isinstance(newest.get("build_hash"), str) \
                    and newest["build_hash"] != manifest["build_hash"]:
                os.replace(manifest_path(directory), manifest_path(directory,
                                                                   newest["build_hash"]))
            with contextlib.suppress(FileNotFoundError):
                manifest_path(directory, manifest["build_hash"]).unlink()
            os.replace(tmp / "manifest.json", manifest_path(directory))
            _remove_old_builds(directory, name, module_file)
    except OSError as exc:
        raise BuildError(f"the build cannot be written to {directory} "
                         f"({exc.strerror or exc}: {exc.filename or ''})",
                         fix="choose a writable output directory") from None
    finally:
        for started in (early or {}).values():
            started.stop()
        shutil.rmtree(tmp, ignore_errors=True)
    return BuildResult(directory, module_name, directory / module_file, manifest, False,
                       time.perf_counter() - start)
