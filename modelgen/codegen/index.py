"""The build cache's fast index: a model file's bytes and the options -> its verified build.

The build key (:func:`modelgen.codegen.pipeline.build_hash`) is the authority
on what is built, but computing it needs the spec, so the symbolic pipeline
(sympy, symengine: about a second of imports).  A model built before is
found here without them: the *fast key* hashes what the build key is made
from, read as plain files and the environment:

* the bytes and the name of every file the model was read from (a scene and
  its model file);
* the build options (:meth:`~modelgen.codegen.options.BuildOptions.key_text`,
  the read-time ones included) and the output directory;
* modelgen's version and the bytes of its ``model``, ``derive`` and
  ``codegen`` packages (so templates, integrators and every line that could
  change the C: an upgrade or an edit never reuses a stale entry);
* the compiler command, ``$MODELGEN_CFLAGS``, the host flags, and the Python
  and cffi versions the runtime module is built for.

An entry (``index/<key>.json`` in :func:`~modelgen.codegen.build.cache_dir`)
names the build's directory, its build key and the runtime module.  A hit is
then verified like every cache hit (:func:`~modelgen.codegen.build.cache_lookup`:
the manifest's own digest, the library's size and SHA-256; the runtime
module's recorded size and SHA-256, :func:`~modelgen.codegen.build.file_problem`,
before anything imports it); a missing,
stale or damaged entry is a miss, and the caller takes the full path and
records the entry again.  This module imports nothing symbolic.
"""
from __future__ import annotations

import contextlib
import functools
import hashlib
import json
import os
import sys
import sysconfig
from dataclasses import dataclass
from pathlib import Path

from modelgen.codegen.build import (BuildResult, cache_dir, cache_lookup, compiler,
                                    file_problem, host_flags, integrator_flags)
from modelgen.codegen.capi import ABI_VERSION
from modelgen.codegen.options import BuildOptions
from modelgen.version import __version__

#: Changes when the entries or the key change meaning (old entries are then misses).
INDEX_FORMAT = "modelgen-fast-index-1"
#: The packages whose files decide what a model's build is (read, derived, emitted, built).
BUILD_PACKAGES = ("model", "derive", "codegen")
#: Files of those packages that count (sources, templates, C).
BUILD_SUFFIXES = (".py", ".j2", ".c", ".h")


@dataclass(frozen=True)
class Hit:
    """A verified build found through the index, and the runtime module to call it."""
    build: BuildResult
    runtime: tuple          # (module name, path) of the runtime module


def _build_files() -> list:
    """(relative path, path) of every file of :data:`BUILD_PACKAGES` that counts, sorted."""
    root = Path(__file__).resolve().parent.parent
    found = []
    stack = [root / package for package in BUILD_PACKAGES]
    while stack:
        with os.scandir(stack.pop()) as entries:
            for entry in entries:
                if entry.is_dir(follow_symlinks=False):
                    if entry.name != "__pycache__":
                        stack.append(Path(entry.path))
                elif os.path.splitext(entry.name)[1] in BUILD_SUFFIXES:
                    path = Path(entry.path)
                    found.append((path.relative_to(root).as_posix(), path))
    return sorted(found)


@functools.lru_cache(maxsize=1)
def code_digest() -> str:
    """SHA-256 of the files of :data:`BUILD_PACKAGES` (paths and bytes), once per
    process.

    Reading and hashing them all is most of a cached load's own time, so the
    digest is remembered in the cache under a key of every file's path, size,
    modification time and inode (what a package upgrade or an edit changes);
    a memo that is missing or unreadable means reading the files again."""
    files = _build_files()
    stamp = hashlib.sha256()
    for relative, path in files:
        st = path.stat()
        stamp.update(f"{relative}\0{st.st_size}\0{st.st_mtime_ns}\0{st.st_ino}\0".encode())
    memo = cache_dir() / "index" / f"code-{stamp.hexdigest()[:32]}.txt"
    try:
        text = memo.read_text()
        if len(text) == 64 and all(c in "0123456789abcdef" for c in text):
            return text
    except OSError:
        pass
    h = hashlib.sha256()
    for relative, path in files:
        h.update(relative.encode() + b"\0")
        h.update(path.read_bytes())
        h.update(b"\0")
    digest = h.hexdigest()
    write_best_effort(memo, digest)
    return digest


def _cffi_version() -> str:
    """The cffi backend's version (what the runtime module is compiled against; the
    backend is imported anyway to load that module, the cffi package is not)."""
    try:
        import _cffi_backend
    except ImportError:
        return ""
    return getattr(_cffi_backend, "__version__", "")


def environment_text() -> str:
    """What of the environment the build key and the runtime module depend on."""
    return "\0".join((INDEX_FORMAT, __version__, str(ABI_VERSION), code_digest(),
                      " ".join(compiler()), " ".join(host_flags()), " ".join(integrator_flags()),
                      os.environ.get("MODELGEN_CFLAGS", ""), sys.version,
                      sysconfig.get_config_var("EXT_SUFFIX") or "", _cffi_version()))


def fast_key(files, options: BuildOptions, out_dir=None) -> str | None:
    """The fast key of a model read from ``files`` (paths: the file given first,
    then any it names) built with ``options`` into ``out_dir`` (None: the cache);
    None if a file cannot be read (the full path then says why)."""
    h = hashlib.sha256(environment_text().encode())
    try:
        for path in files:
            path = Path(path)
            h.update(b"\0" + path.name.encode() + b"\0")
            h.update(path.read_bytes())
    except OSError:
        return None
    h.update(b"\0" + options.key_text().encode())
    h.update(b"\0" + (str(Path(out_dir).resolve()) if out_dir is not None else "").encode())
    return h.hexdigest()


def _entry_path(key: str) -> Path:
    return cache_dir() / "index" / f"{key[:32]}.json"


def lookup(key: str | None) -> Hit | None:
    """The verified build the entry of ``key`` names, or None (no entry, or one
    that is damaged or points to a build that no longer verifies)."""
    if key is None:
        return None
    try:
        entry = json.loads(_entry_path(key).read_text())
        directory, build_hash = Path(entry["directory"]), entry["build_hash"]
        runtime = (entry["runtime"][0], Path(entry["runtime"][1]))
        if entry["key"] != key or not isinstance(build_hash, str) \
                or not isinstance(runtime[0], str):
            return None
    except (OSError, ValueError, KeyError, TypeError, IndexError):
        return None
    if file_problem(runtime[1]) is not None:     # the full path rebuilds it, saying why
        return None
    build, _ = cache_lookup(directory, build_hash)
    if build is None or build.manifest.get("version") != __version__:
        return None
    return Hit(build, runtime)


def record(key: str | None, build: BuildResult, runtime: tuple) -> None:
    """Write the entry of ``key``: ``build`` and the ``runtime`` (module name, path).
    Best effort: an index that cannot be written only costs the next load time."""
    if key is None:
        return
    entry = {"key": key, "directory": str(Path(build.directory).resolve()),
             "build_hash": build.manifest["build_hash"],
             "runtime": [runtime[0], str(Path(runtime[1]).resolve())]}
    write_best_effort(_entry_path(key), json.dumps(entry))


def write_best_effort(path: Path, text: str) -> None:
    """Replace ``path`` with ``text`` atomically (a reader sees the old file or the
    new one, never a part); an error is ignored: the index is only a shortcut."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp.write_text(text)
        os.replace(tmp, path)
    except OSError:
        with contextlib.suppress(OSError):
            tmp.unlink()
