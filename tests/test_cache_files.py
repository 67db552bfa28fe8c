"""Every file the build cache reuses is verified before use, not only model libraries.

The runtime module (``runtime/_mg_runtime_*.so``) and the integrators' object
(``mg_integrate-*.o``) have their size and SHA-256 recorded beside them when
built; a truncated, emptied or substituted one is rebuilt (with a warning that
names it) before it is imported or linked, and a rebuild that fails too is a
BuildError naming it.  Each load runs in a subprocess with a private copy of a
complete cache, because a truncated shared object can kill its loader with
SIGBUS before Python can react; the subprocess's exit status shows a crash.

Killed builds' temporary folders (``.build-*``, ``.mg-*``) are removed by the
next build: at once when they name a process of this machine that is gone,
else after :data:`modelgen.codegen.build.STALE_SECONDS`.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import subprocess
import sys
import sysconfig
import time
from pathlib import Path

import pytest

import modelgen
from modelgen.codegen import build, index
from modelgen.codegen.emit import integrator_sources
from modelgen.codegen.options import BuildOptions

ROOT = Path(__file__).resolve().parent.parent
PENDULUM = ROOT / "models" / "simple_pendulum.yaml"
#: xdot of the simple pendulum (q'' = -(g/L) sin q, g = 9.81, L = 1) at q = 0.3, q' = 0
XDOT = (0.0, -9.81 * math.sin(0.3))

_LOAD = """
import sys, warnings, modelgen
warnings.simplefilter("always")
cm = modelgen.{call}(sys.argv[1], sys.argv[2]{force})
cm = cm if hasattr(cm, "rhs") else modelgen.load(sys.argv[1], sys.argv[2])
print("xdot", *[repr(float(v)) for v in cm.rhs(0.0, [0.3, 0.0])])
"""


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def pristine(tmp_path_factory):
    """A complete cache (runtime module, integrators' object, index) and a build of
    the simple pendulum in it, to be copied and damaged."""
    cache = tmp_path_factory.mktemp("pristine-cache")
    with pytest.MonkeyPatch.context() as mp:
        for var in ("CC", "MODELGEN_CFLAGS", "CFLAGS"):
            mp.delenv(var, raising=False)
        mp.setenv("MODELGEN_CACHE_DIR", str(cache))
        modelgen.load(PENDULUM, cache / "models" / "pendulum")
    return cache


@pytest.fixture
def cache(pristine, tmp_path, monkeypatch):
    """A private copy of the pristine cache, made the cache of this test."""
    copy = tmp_path / "cache"
    shutil.copytree(pristine, copy)
    for var in ("CC", "MODELGEN_CFLAGS", "CFLAGS"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setenv("MODELGEN_CACHE_DIR", str(copy))
    return copy


def _load(cache: Path, *, call="load", force=False, env=None) -> subprocess.CompletedProcess:
    script = _LOAD.format(call=call, force=", force=True" if force else "")
    return subprocess.run([sys.executable, "-c", script, str(PENDULUM),
                           str(cache / "models" / "pendulum")], cwd=ROOT,
                          env={**os.environ, "MODELGEN_CACHE_DIR": str(cache), **(env or {})},
                          capture_output=True, text=True, timeout=300, check=False)


def _xdot(r: subprocess.CompletedProcess) -> list:
    assert r.returncode == 0, r.stdout + r.stderr     # a crash (SIGBUS: -7) fails here
    line = next(line for line in r.stdout.splitlines() if line.startswith("xdot "))
    return [float(v) for v in line.split()[1:]]


def _runtime_file(cache: Path) -> Path:
    (path,) = (cache / "runtime").glob("_mg_runtime_*" + (
        sysconfig.get_config_var("EXT_SUFFIX") or ".so"))
    return path


def _integrator_file(cache: Path) -> Path:
    (path,) = cache.glob("mg_integrate-*.o")
    return path


def _truncate(path: Path):
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 5])   # past the loaded segments


def _empty(path: Path):
    path.write_bytes(b"")


def _substitute(path: Path):
    """Another valid file of the same kind: the same object compiled at -O0, or, for
    the runtime module, a shared object with a different body (the pendulum's library)."""
    if path.suffix == ".o":
        tmp = path.parent / "substitute"
        build.write_sources(tmp, integrator_sources())
        subprocess.run(["cc", "-O0", "-fPIC", "-std=c99", "-c", "mg_integrate.c", "-o",
                        str(path)], cwd=tmp, check=True)
        shutil.rmtree(tmp)
    else:
        (library,) = (path.parent.parent / "models" / "pendulum").glob("lib_mg_*")
        shutil.copyfile(library, path)


DAMAGES = pytest.mark.parametrize("damage", [_truncate, _empty, _substitute],
                                  ids=["truncated", "emptied", "substituted"])


@DAMAGES
def test_a_damaged_runtime_module_is_rebuilt_before_it_is_imported(cache, damage):
    runtime = _runtime_file(cache)
    damage(runtime)
    r = _load(cache)
    assert _xdot(r) == pytest.approx(XDOT, rel=1e-12)
    assert str(runtime) in r.stderr and "rebuil" in r.stderr, r.stderr
    assert build.file_problem(runtime) is None  # rebuilt and recorded anew
    again = _load(cache)
    assert _xdot(again) == pytest.approx(XDOT, rel=1e-12)
    assert "rebuil" not in again.stderr, again.stderr


def test_a_runtime_module_whose_rebuild_fails_is_an_error_naming_it(cache):
    runtime = _runtime_file(cache)
    _truncate(runtime)
    # setuptools passes $CFLAGS to the runtime's compile, which no other build uses
    r = _load(cache, env={"CFLAGS": "-fno-such-flag-for-modelgen"})
    assert r.returncode == 1 and "BuildError" in r.stderr, r.stdout + r.stderr
    assert str(runtime) in r.stderr.split("BuildError", 1)[1], r.stderr


def test_the_fast_index_verifies_the_runtime_module_it_names(cache):
    out = cache / "models" / "pendulum"
    key = index.fast_key([PENDULUM], BuildOptions(), out)
    manifest = json.loads((out / "manifest.json").read_text())
    runtime = _runtime_file(cache)
    index.record(key, build.cache_lookup(out, manifest["build_hash"])[0],
                 (runtime.name.split(".")[0], runtime))
    assert index.lookup(key) is not None
    _empty(runtime)
    assert index.lookup(key) is None
    runtime.unlink()
    assert index.lookup(key) is None


def test_a_runtime_module_without_its_record_is_rebuilt(cache):
    runtime = _runtime_file(cache)
    for record in (cache / "runtime").glob("*.json"):
        record.unlink()
    r = _load(cache)
    assert _xdot(r) == pytest.approx(XDOT, rel=1e-12)
    assert str(runtime) in r.stderr, r.stderr


@DAMAGES
def test_a_damaged_integrator_object_is_rebuilt_before_it_is_linked(cache, damage):
    obj = _integrator_file(cache)
    good = _sha256(obj)
    damage(obj)
    r = _load(cache, call="generate_model", force=True)
    assert _xdot(r) == pytest.approx(XDOT, rel=1e-12)
    assert str(obj) in r.stderr and "rebuil" in r.stderr, r.stderr
    assert _sha256(obj) == good
    manifest = json.loads((cache / "models" / "pendulum" / "manifest.json").read_text())
    assert manifest["integrators"]["cached"] is False
    again = _load(cache, call="generate_model", force=True)
    assert _xdot(again) == pytest.approx(XDOT, rel=1e-12)
    assert "rebuil" not in again.stderr, again.stderr


def test_an_integrator_object_whose_rebuild_fails_is_an_error_naming_it(cache, monkeypatch):
    obj = _integrator_file(cache)
    _truncate(obj)
    # the object's name is its compiler's and flags' hash: break its sources instead
    sources = dict(integrator_sources(), **{"mg_integrate.c": "#error broken\n"})
    real = build.integrator_hash(integrator_sources())
    monkeypatch.setattr(build, "integrator_hash", lambda _: real)
    with pytest.warns(UserWarning, match=str(obj)), pytest.raises(build.BuildError) as info:
        build.integrator_object(sources)
    assert str(obj) in str(info.value).splitlines()[0]


# -- killed builds' temporary folders --------------------------------------------------

def _dead_pid() -> int:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def _leftover(directory: Path, name: str, age: float = 0.0) -> Path:
    path = directory / name
    path.mkdir(parents=True)
    (path / "part.o").write_bytes(b"\0" * 16)
    if age:
        then = time.time() - age
        os.utime(path, (then, then))
    return path


def test_killed_builds_temporary_folders_are_cleaned_by_the_next_build(cache):
    out = cache / "models" / "pendulum"
    host = build.host_tag()
    dead, alive = _dead_pid(), os.getpid()
    stale = [
        _leftover(out, ".build-old", age=build.STALE_SECONDS + 60),
        _leftover(cache, ".mg-old", age=build.STALE_SECONDS + 60),
        _leftover(cache / "runtime", ".build-old", age=build.STALE_SECONDS + 60),
        _leftover(out, f".build-{dead}-{host}-x1"),
        _leftover(cache, f".mg-{dead}-{host}-x2"),
        _leftover(cache / "runtime", f".build-{dead}-{host}-x3"),
    ]
    kept = [
        _leftover(out, ".build-recent"),
        _leftover(cache, f".mg-{alive}-{host}-x4"),
        _leftover(cache / "runtime", f".build-{alive}-{host}-x5"),
        _leftover(out, f".build-{dead}-0123abcd-x6"),      # another machine's process
    ]
    modelgen.generate_model(PENDULUM, out, force=True)
    assert [p for p in stale if p.exists()] == []
    assert [p for p in kept if not p.is_dir()] == []


def test_a_builds_own_temporary_folder_names_its_process(cache):
    made = build.private_dir(cache, ".build-")
    try:
        assert made.name.startswith(f".build-{os.getpid()}-{build.host_tag()}-")
        assert build.remove_stale_builds(cache) == []
    finally:
        shutil.rmtree(made)


def test_a_recorded_runtime_module_that_fails_to_import_is_rebuilt_once(cache):
    """A substitute whose record was rewritten to match passes the check; its import
    fails (no module init), and the loader rebuilds it once, naming it."""
    runtime = _runtime_file(cache)
    _substitute(runtime)
    build.record_file(runtime)
    r = _load(cache)
    assert _xdot(r) == pytest.approx(XDOT, rel=1e-12)
    assert str(runtime) in r.stderr and "cannot be imported" in r.stderr, r.stderr
    assert build.file_problem(runtime) is None
