"""Build stage: C sources -> a per-model cffi extension module.

cffi runs in API mode, but we drive the compiler ourselves instead of going
through setuptools: it is faster, it lets the model source and the wrapper
compile in parallel, and a failure raises :class:`BuildError` with the exact
command and the compiler's full output (nothing is swallowed).

The integrators (``mg_integrate.c``, the same for every model) are compiled
once per compiler, flags and source into a per-user cache directory
(:func:`cache_dir`) and every model's module links that object; a changed
model recompiles only its own code.  ``mg_integrate.c``/``.h`` are also
copied next to the model's ``.c``/``.h``, so a C user compiles the output
directory and nothing else.

Everything is written to a private temporary directory first and moved into
place with ``os.replace``; ``manifest.json`` is moved last and marks a
complete build.  Two processes building the same model at once therefore
both succeed and leave one valid build.
"""
from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import shlex
import shutil
import subprocess
import sysconfig
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import cffi

from modelgen.errors import BuildError

#: Optimisation level: -O2, or -O1 above a statement count.  gcc's time grows
#: faster than linearly with code size; at n = 30 links, part 2 (rhs, 3,800
#: statements) compiles in 3.4 s at -O2 and runs 12% faster than at -O1, while
#: part 1 (the other functions) takes 4.7 s at -O2 against 2.3 s at -O1, and
#: at n = 10 part 1 alone takes 1.1 s at -O2 and 0.66 s at -O1 while the whole
#: build waits for it.  Part 1 (not the integration hot path) therefore drops
#: to -O1 as soon as its routines are cut into parts.
O1_ABOVE = {0: 400, 1: 400, 2: 4000}
#: Models whose largest routine has more statements are compiled as two parts
#: in parallel (MG_PART 1 and 2); smaller ones in one process (part 0: the
#: whole file), which beside the cffi wrapper's compile keeps both cores busy
#: without a third process.
SPLIT_ABOVE = 400
BASE_FLAGS = ("-std=c99", "-fPIC", "-Wall", "-Wextra")
#: Flags of mg_integrate.c (compiled once, on the integration hot path).
INTEGRATOR_FLAGS = ("-O2", *BASE_FLAGS, "-Werror")


@dataclass(frozen=True)
class BuildResult:
    directory: Path
    module_name: str
    module_path: Path
    manifest: dict
    cached: bool
    seconds: float


def compiler() -> list:
    """The C compiler command: ``$CC`` if set, else ``cc``."""
    return shlex.split(os.environ.get("CC", "cc"))


def compile_flags(statements: int, part: int = 2) -> list:
    """Compiler flags for one part of a model whose largest routine has ``statements``.

    ``$MODELGEN_CFLAGS`` is appended (and is part of the cache key).
    """
    opt = "-O1" if statements > O1_ABOVE[part] else "-O2"
    extra = shlex.split(os.environ.get("MODELGEN_CFLAGS", ""))
    return [opt, *BASE_FLAGS, *extra]


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
    return [*INTEGRATOR_FLAGS, *shlex.split(os.environ.get("MODELGEN_CFLAGS", ""))]


def integrator_hash(sources: dict) -> str:
    """Cache key of the integrators' object: their source, the compiler and its flags."""
    h = hashlib.sha256()
    for part in (sources["mg_integrate.h"], sources["mg_integrate.c"], " ".join(compiler()),
                 " ".join(integrator_flags())):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()


def integrator_object(sources: dict) -> tuple:
    """(path, cached): the compiled ``mg_integrate.o`` for these sources, from the
    cache or compiled now.

    Compiled in a private temporary directory and moved into the cache with
    ``os.replace``, so concurrent builds never see a partial object.
    """
    directory = cache_dir()
    target = directory / f"mg_integrate-{integrator_hash(sources)[:20]}.o"
    if target.is_file():
        return target, True
    directory.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=".mg-", dir=directory))
    try:
        for name in ("mg_integrate.h", "mg_integrate.c"):
            (tmp / name).write_text(sources[name])
        _run([[*compiler(), *integrator_flags(), "-c", "mg_integrate.c", "-o", "mg_integrate.o"]],
             tmp)
        os.replace(tmp / "mg_integrate.o", target)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return target, False


def manifest_path(directory: Path) -> Path:
    return Path(directory) / "manifest.json"


def read_manifest(directory: Path) -> dict | None:
    try:
        return json.loads(manifest_path(directory).read_text())
    except (OSError, ValueError):
        return None


def cached_build(directory: Path, build_hash: str) -> BuildResult | None:
    """The existing build in ``directory`` if it matches ``build_hash``."""
    manifest = read_manifest(directory)
    if not manifest or manifest.get("build_hash") != build_hash:
        return None
    module_path = Path(directory) / manifest["module_file"]
    if not module_path.is_file():
        return None
    return BuildResult(Path(directory), manifest["module_name"], module_path, manifest, True, 0.0)


def _run(commands: list, cwd: Path) -> None:
    """Run compiler commands in parallel; raise BuildError on the first failure."""
    procs = [(cmd, subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE,
                                    stderr=subprocess.STDOUT, text=True)) for cmd in commands]
    failure = None
    for cmd, proc in procs:
        out, _ = proc.communicate()
        if proc.returncode != 0 and failure is None:
            failure = BuildError(f"C compiler failed (exit {proc.returncode})", cmd, out)
    if failure:
        raise failure


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


def build_module(directory: Path, name: str, sources: dict, manifest: dict,
                 statements: int, integrator: dict) -> BuildResult:
    """Compile ``sources`` (``<name>.c``, ``<name>.h``, ``cdef``) into ``directory``
    and link them with the cached object of ``integrator`` (``mg_integrate.h``/``.c``).

    ``manifest`` must hold ``build_hash``; the module is named after it so a
    changed model never collides with an already imported one.
    """
    start = time.perf_counter()
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    module_name = f"_mg_{name}_{manifest['build_hash'][:16]}"
    suffix = sysconfig.get_config_var("EXT_SUFFIX") or ".so"
    module_file = module_name + suffix

    tmp = Path(tempfile.mkdtemp(prefix=".build-", dir=directory))
    try:
        integrator_obj, integrator_cached = integrator_object(integrator)
        for fname in (f"{name}.c", f"{name}.h"):
            (tmp / fname).write_text(sources[fname])
        (tmp / "mg_integrate.h").write_text(integrator["mg_integrate.h"])
        ffi = cffi.FFI()
        ffi.cdef(sources["cdef"])
        ffi.set_source(module_name, f'#include "{name}.h"')
        with contextlib.redirect_stdout(io.StringIO()):   # cffi announces the file
            ffi.emit_c_code(str(tmp / f"{module_name}.c"))

        cc = compiler()
        py_include = sysconfig.get_paths()["include"]
        parts = (1, 2) if statements > SPLIT_ABOVE else (0,)
        model_objs = [[*cc, *compile_flags(statements, part), "-Werror",
                       *([f"-DMG_PART={part}"] if part else []), "-c", f"{name}.c",
                       "-o", f"{name}_{part}.o"] for part in parts]
        wrap_obj = [*cc, "-O1", "-fPIC", "-w", f"-I{py_include}", "-I.", "-c",
                    f"{module_name}.c", "-o", f"{module_name}.o"]
        _run([*model_objs, wrap_obj], tmp)
        link = [*cc, "-shared", f"{module_name}.o", *(f"{name}_{part}.o" for part in parts),
                str(integrator_obj), "-o", module_file, "-lm"]
        _run([link], tmp)

        manifest = dict(manifest, module_name=module_name, module_file=module_file,
                        compile_commands=[" ".join(c) for c in model_objs],
                        integrators={"path": str(integrator_obj), "cached": integrator_cached})
        _write_if_changed(directory / f"{name}.c", sources[f"{name}.c"], tmp)
        _write_if_changed(directory / f"{name}.h", sources[f"{name}.h"], tmp)
        for fname in ("mg_integrate.h", "mg_integrate.c"):
            _write_if_changed(directory / fname, integrator[fname], tmp)
        os.replace(tmp / module_file, directory / module_file)
        (tmp / "manifest.json").write_text(json.dumps(manifest, indent=2, sort_keys=True))
        os.replace(tmp / "manifest.json", manifest_path(directory))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return BuildResult(directory, module_name, directory / module_file, manifest, False,
                       time.perf_counter() - start)
