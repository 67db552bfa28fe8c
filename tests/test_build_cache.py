"""The build cache is verified, not trusted; the environment's errors are BuildErrors.

A damaged library or manifest is rebuilt (never imported: each load of a
damaged build runs in a subprocess, whose exit status would show a crash),
a module whose constants disagree with its manifest is refused, a missing or
broken compiler, unsplittable flags and unwritable output directories give a
BuildError that says what to do, and builds clean up after themselves.
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
import shutil
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

import modelgen
from modelgen.codegen import build
from modelgen.codegen.pipeline import runtime
from modelgen.errors import BuildError
from modelgen.sim.runtime import CompiledModel

ROOT = Path(__file__).resolve().parent.parent
PENDULUM = ROOT / "models" / "simple_pendulum.yaml"
#: xdot of the simple pendulum (q'' = -(g/L) sin q, g = 9.81, L = 1) at q = 0.3, q' = 0
XDOT = (0.0, -9.81 * math.sin(0.3))

_LOAD = """
import sys, modelgen
g = modelgen.generate_model(sys.argv[1], sys.argv[2])
cm = modelgen.load(sys.argv[1], sys.argv[2])
print("cached", g.build.cached)
print("because", g.build.rebuilt_because)
print("xdot", *[repr(float(v)) for v in cm.rhs(0.0, [0.3, 0.0])])
"""


@pytest.fixture(autouse=True)
def _environment(monkeypatch, tmp_path_factory):
    """The default compiler and flags, and one integrator cache for the whole file."""
    for var in ("CC", "MODELGEN_CFLAGS"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setenv("MODELGEN_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "mg-cache"))


@pytest.fixture(scope="module")
def pristine(tmp_path_factory):
    """A complete build of the simple pendulum, to be copied and damaged."""
    out = tmp_path_factory.mktemp("pristine")
    with pytest.MonkeyPatch.context() as mp:
        for var in ("CC", "MODELGEN_CFLAGS"):
            mp.delenv(var, raising=False)
        mp.setenv("MODELGEN_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "mg-cache"))
        generated = modelgen.generate_model(PENDULUM, out)
    return out, generated


def _copy(pristine, tmp_path) -> tuple:
    out = tmp_path / "build"
    shutil.copytree(pristine[0], out)
    manifest = json.loads((out / "manifest.json").read_text())
    return out, manifest


def _load_in_subprocess(out: Path) -> dict:
    r = subprocess.run([sys.executable, "-c", _LOAD, str(PENDULUM), str(out)], cwd=ROOT,
                       env=dict(os.environ), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stdout          # a crash (SIGBUS, SIGILL, abort) fails here
    lines = dict(line.split(" ", 1) if " " in line else (line, "")
                 for line in r.stdout.splitlines())
    return {"cached": lines["cached"], "because": lines["because"],
            "xdot": [float(v) for v in lines["xdot"].split()]}


def _truncate(path: Path):
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def _empty(path: Path):
    path.write_bytes(b"")


def _flip(path: Path):
    data = bytearray(path.read_bytes())
    for i in range(len(data) // 3, len(data) // 3 + 4096):
        data[i] ^= 0xFF
    path.write_bytes(bytes(data))


@pytest.mark.parametrize("damage", [_truncate, _empty, _flip, Path.unlink],
                         ids=["truncated", "zero-byte", "bit-flipped", "missing"])
def test_a_damaged_library_is_rebuilt_not_loaded(pristine, tmp_path, damage):
    out, manifest = _copy(pristine, tmp_path)
    damage(out / manifest["module_file"])
    loaded = _load_in_subprocess(out)
    assert loaded["cached"] == "False"
    assert manifest["module_file"] in loaded["because"], loaded
    assert loaded["xdot"] == pytest.approx(XDOT, rel=1e-12)
    again = _load_in_subprocess(out)
    assert again["cached"] == "True" and again["because"] == ""


def _one_coordinate_too_many(m):
    m["coordinates"] = ["q", "r"]


def _five_coordinates(m):
    m["coordinates"] = ["q", "a", "b", "c", "d"]


def _no_parameters(m):
    m["parameters"] = []


def _no_module_file(m):
    del m["module_file"]


@pytest.mark.parametrize("edit", [_one_coordinate_too_many, _five_coordinates, _no_parameters,
                                  _no_module_file, "list", "not json"],
                         ids=["two-coordinates", "five-coordinates", "parameters-empty",
                              "no-module-file", "list", "not-json"])
def test_an_edited_manifest_is_rebuilt_not_trusted(pristine, tmp_path, edit):
    out, manifest = _copy(pristine, tmp_path)
    if edit == "list":
        text = json.dumps([manifest])
    elif edit == "not json":
        text = json.dumps(manifest)[:-20]
    else:
        edit(manifest)
        text = json.dumps(manifest)
    (out / "manifest.json").write_text(text)
    loaded = _load_in_subprocess(out)
    assert loaded["cached"] == "False"
    assert loaded["xdot"] == pytest.approx(XDOT, rel=1e-12)
    assert json.loads((out / "manifest.json").read_text())["coordinates"] == ["q"]


@pytest.mark.parametrize("edit, constant", [
    (_five_coordinates, "SIMPLE_PENDULUM_NQ"), (_no_parameters, "SIMPLE_PENDULUM_NP"),
    (lambda m: m.update(bodies=[]), "SIMPLE_PENDULUM_NBODIES"),
    (lambda m: m.update(inputs=["u"]), "SIMPLE_PENDULUM_NU")])
def test_compiled_model_sizes_come_from_the_module_not_the_manifest(pristine, edit, constant):
    generated = pristine[1]
    manifest = json.loads(json.dumps(generated.manifest))
    edit(manifest)
    with pytest.raises(BuildError, match=constant):
        CompiledModel(manifest, generated.build.module_path)


def test_compiled_model_refuses_a_manifest_without_its_keys(pristine):
    generated = pristine[1]
    manifest = dict(generated.manifest)
    del manifest["module_name"]
    with pytest.raises(BuildError, match="module_name"):
        CompiledModel(manifest, generated.build.module_path)
    with pytest.raises(BuildError, match="not a mapping"):
        CompiledModel([manifest], generated.build.module_path)


@pytest.mark.parametrize("cc", ["/nonexistent/cc", ""])
def test_no_compiler_is_a_build_error_that_says_what_to_do(monkeypatch, tmp_path, cc):
    monkeypatch.setenv("CC", cc)
    with pytest.raises(BuildError, match="set CC") as info:
        modelgen.generate_model(PENDULUM, tmp_path / "out")
    if cc:
        assert cc in str(info.value) and info.value.command[0] == cc


def test_no_cc_on_the_path_is_a_build_error(monkeypatch, tmp_path):
    (tmp_path / "empty").mkdir()
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    monkeypatch.setenv("MODELGEN_CACHE_DIR", str(tmp_path / "cache"))
    with pytest.raises(BuildError, match="install a C compiler") as info:
        modelgen.generate_model(PENDULUM, tmp_path / "out")
    assert info.value.command[0] == "cc"


def test_unsplittable_cflags_are_a_build_error(monkeypatch, tmp_path):
    monkeypatch.setenv("MODELGEN_CFLAGS", '-DX="')
    with pytest.raises(BuildError, match="MODELGEN_CFLAGS") as info:
        modelgen.generate_model(PENDULUM, tmp_path / "out")
    assert "fix:" in str(info.value)


def test_missing_python_headers_name_the_package_to_install(monkeypatch, tmp_path):
    """Only the runtime module (built once, by cffi through setuptools) includes
    Python.h; a model's own library never does."""
    fake = tmp_path / "fakecc"
    fake.write_text('#!/bin/sh\necho "x.c:1:10: fatal error: Python.h: No such file or '
                    'directory"\nexit 1\n')
    fake.chmod(0o755)
    monkeypatch.setenv("CC", str(fake))
    monkeypatch.setenv("MODELGEN_CACHE_DIR", str(tmp_path / "cache"))
    with pytest.raises(BuildError) as info:
        runtime()
    message = str(info.value)
    assert "python3-dev" in message and "fatal error: Python.h" in message


def test_a_model_library_includes_no_python(pristine):
    """The model's code compiles without Python's headers: its C includes none,
    and its library needs no symbol of Python's."""
    out, generated = pristine
    for path in out.glob("*.[ch]"):
        assert "Python.h" not in path.read_text(), path
    if shutil.which("nm") is None:
        pytest.skip("nm (binutils) is not installed: the library's symbols cannot be listed")
    symbols = subprocess.run(["nm", "-D", "--undefined-only", str(generated.build.module_path)],
                             capture_output=True, text=True, check=True)
    assert "sin" in symbols.stdout                   # it lists the library's imports
    assert "Py" not in symbols.stdout, symbols.stdout


def test_a_file_where_the_output_directory_should_be_is_a_build_error(tmp_path):
    (tmp_path / "taken").write_text("not a directory")
    with pytest.raises(BuildError, match="is a file, not a directory") as info:
        modelgen.generate_model(PENDULUM, tmp_path / "taken")
    assert str(tmp_path / "taken") in str(info.value)
    with pytest.raises(BuildError, match="is a file"):
        modelgen.generate_model(PENDULUM, tmp_path / "taken" / "below")


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0,
                    reason="root writes into read-only directories")
def test_a_read_only_output_directory_is_a_build_error(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(stat.S_IRUSR | stat.S_IXUSR)
    try:
        with pytest.raises(BuildError, match="cannot be written") as info:
            modelgen.generate_model(PENDULUM, ro)
        assert str(ro) in str(info.value)
    finally:
        ro.chmod(stat.S_IRWXU)


def test_a_killed_builds_temporary_directory_is_removed_after_an_hour(pristine, tmp_path):
    out, _ = _copy(pristine, tmp_path)
    old, recent = out / ".build-killed", out / ".build-running"
    for d in (old, recent):
        d.mkdir()
        (d / "x.o").write_text("")
    an_hour_ago = time.time() - 3700
    os.utime(old, (an_hour_ago, an_hour_ago))
    modelgen.generate_model(PENDULUM, out, force=True)
    assert not old.exists() and recent.is_dir()


def test_old_modules_are_removed_and_variants_do_not_rebuild_each_other(tmp_path):
    """Four variants of one model built into one directory: the last KEEP_BUILDS
    stay (and load from the cache, in any order), the oldest is deleted."""
    spec = modelgen.as_spec(PENDULUM)
    variants = [dataclasses.replace(spec, parameters=(("L", 1.0 + i),) + spec.parameters[1:])
                for i in range(build.KEEP_BUILDS + 1)]
    first = [modelgen.generate_model(v, tmp_path) for v in variants]
    assert not any(g.build.cached for g in first)
    modules = sorted(p.name for p in tmp_path.glob("lib_mg_simple_pendulum_*"))
    assert len(modules) == build.KEEP_BUILDS
    assert first[0].build.module_path.name not in modules
    assert len(list(tmp_path.glob("manifest*.json"))) == build.KEEP_BUILDS
    for v, g in reversed(list(zip(variants[1:], first[1:]))):    # alternate back: all cached
        again = modelgen.generate_model(v, tmp_path)
        assert again.build.cached and again.build.module_path == g.build.module_path
        assert modelgen.load(v, tmp_path).parameters["L"] == v.parameters[0][1]
    assert not modelgen.generate_model(variants[0], tmp_path).build.cached


def test_the_link_is_the_platforms_with_cc_in_the_compilers_place(monkeypatch):
    """The shared library is linked with sysconfig's LDSHARED (the platform's flags
    as Python was configured), $CC replacing its compiler, or $LDSHARED verbatim."""
    import sysconfig
    configured = sysconfig.get_config_var("LDSHARED").split()
    monkeypatch.delenv("LDSHARED", raising=False)
    monkeypatch.setenv("CC", "mycc -m64")
    cmd = build.link_command(["a.o", "b.o"], "lib.so")
    cc_words = len(sysconfig.get_config_var("CC").split())
    assert cmd[:2] == ["mycc", "-m64"] and cmd[2:2 + len(configured) - cc_words] \
        == configured[cc_words:]
    assert cmd[-5:] == ["a.o", "b.o", "-o", "lib.so", "-lm"]
    monkeypatch.setenv("LDSHARED", "ld.gold -shared -z defs")
    assert build.link_command(["a.o"], "x.so")[:4] == ["ld.gold", "-shared", "-z", "defs"]
    monkeypatch.setenv("LDSHARED", "")
    with pytest.raises(BuildError, match="LDSHARED"):
        build.link_command(["a.o"], "x.so")


def test_the_host_isa_flag_changes_the_encoding_never_a_result(monkeypatch, tmp_path):
    """AVX (when this CPU has it) is in the library's compile commands and its
    cache key, never in an FMU's flags, and the rhs and A are bit for bit those
    of the baseline build: ISO C99 forbids contracting ``a*b + c`` into an FMA."""
    import numpy as np
    from modelgen.model.chains import spatial_chain
    if not build.host_flags():
        pytest.skip("this CPU has no AVX (or is not x86-64 Linux): nothing to compare")
    spec = spatial_chain(4).spec()
    models, commands = {}, {}
    for avx in ("1", "0"):
        monkeypatch.setenv("MODELGEN_AVX", avx)
        cm = modelgen.load(spec, tmp_path / f"avx{avx}")
        models[avx] = cm
        commands[avx] = cm.manifest["compile_commands"]
    assert all("-mavx" in c.split() for c in commands["1"])
    assert not any("-mavx" in c.split() for c in commands["0"])
    assert models["1"].manifest["build_hash"] != models["0"].manifest["build_hash"]
    assert "-mavx" not in build.compile_flags(100, 0)      # the FMU's flags (part 0, not host)
    rng = np.random.default_rng(7)
    for _ in range(20):
        x = rng.uniform(-3, 3, 8)
        a, b = (models[k].rhs(0.0, x) for k in ("1", "0"))
        assert a.tobytes() == b.tobytes()
        a, b = (models[k].mass_matrix(x[:4]) for k in ("1", "0"))
        assert a.tobytes() == b.tobytes()


def test_gcc_only_flags_follow_the_compiler_and_the_level(monkeypatch, tmp_path):
    """The flags only gcc knows go to gcc alone (clang rejects unknown -f flags
    under -Werror), the -O2 ones only to the parts compiled at -O2 and the -O1
    ones only to the parts compiled at -O1."""
    from modelgen.codegen.compilers import GCC_FLAGS, GCC_O1_FLAGS, GCC_O2_FLAGS
    only_gcc = set(GCC_FLAGS + GCC_O1_FLAGS + GCC_O2_FLAGS)
    fake = tmp_path / "clang"
    fake.write_text("#!/bin/sh\necho 'clang version 15.0.7'\n")
    fake.chmod(0o755)
    monkeypatch.setenv("CC", str(fake))
    for statements, part in ((100, 2), (100, 4), (5000, 4), (500, 0), (100, 0)):
        flags = build.compile_flags(statements, part)
        assert not only_gcc & set(flags), (statements, part, flags)
    if shutil.which("gcc") is None:
        return
    monkeypatch.setenv("CC", "gcc")
    o2, o1, o0 = (build.compile_flags(s, p) for s, p in ((100, 4), (5000, 4), (100, 1)))
    assert GCC_O1_FLAGS and not set(GCC_O1_FLAGS) & set(GCC_O2_FLAGS + GCC_FLAGS)
    assert o2[0] == "-O2" and set(GCC_FLAGS + GCC_O2_FLAGS) <= set(o2)
    assert not set(GCC_O1_FLAGS) & set(o2)
    assert o1[0] == "-O1" and set(GCC_FLAGS + GCC_O1_FLAGS) <= set(o1)
    assert not set(GCC_O2_FLAGS) & set(o1)
    assert build.compile_flags(500, 0)[0] == "-O1" and set(GCC_O1_FLAGS) <= set(
        build.compile_flags(500, 0))
    assert o0[0] == "-O0" and not only_gcc & set(o0)


def test_meanwhile_runs_while_the_commands_run_and_failures_still_raise(tmp_path):
    """``run_commands(..., meanwhile=f)`` calls ``f`` once, after the first ``jobs``
    commands started and before they finish: each command here waits for the file
    ``go`` that only ``f`` writes (and fails after 20 s without it)."""
    from modelgen.codegen.compilers import run_commands
    wait = "for i in $(seq 2000); do [ -e go ] && exit {}; sleep 0.01; done; exit 9"
    calls = []

    def meanwhile():
        calls.append(sorted(p.name for p in tmp_path.iterdir()))
        (tmp_path / "go").write_text("")
    run_commands([["sh", "-c", wait.format(0)], ["sh", "-c", wait.format(0)]], tmp_path,
                 jobs=2, meanwhile=meanwhile)
    assert calls == [[]]
    (tmp_path / "go").unlink()
    calls.clear()
    with pytest.raises(BuildError) as err:
        run_commands([["sh", "-c", wait.format(0)], ["sh", "-c", wait.format(3)],
                      ["sh", "-c", wait.format(0)]], tmp_path, jobs=2, meanwhile=meanwhile)
    assert calls == [[]] and err.value.returncode == 3


def test_a_probed_compiler_is_asked_once_in_the_background(tmp_path):
    """``probe_compiler`` starts ``--version`` at once (the script's mark appears
    before ``is_gcc`` is asked), ``is_gcc`` reads that run's answer, and once the
    answer is known a probe starts nothing.  A compiler that cannot run is not gcc,
    probed or not."""
    from modelgen.codegen.compilers import is_gcc, probe_compiler
    mark = tmp_path / "ran"
    for banner, expected in (("gcc (GCC) 12.2.0 Free Software Foundation, Inc.", True),
                             ("clang version 15.0.7", False)):
        fake = tmp_path / f"cc{int(expected)}"
        fake.write_text(f"#!/bin/sh\necho run >> {mark}\necho '{banner}'\n")
        fake.chmod(0o755)
        command = (str(fake),)
        probe_compiler(command)
        for _ in range(2000):
            # the shell creates the file before it writes the line
            if mark.exists() and mark.read_text().endswith("\n"):
                break
            time.sleep(0.01)
        assert mark.read_text() == "run\n"
        assert is_gcc(command) is expected and is_gcc(command) is expected
        probe_compiler(command)
        time.sleep(0.2)
        assert mark.read_text() == "run\n"       # neither is_gcc nor the probe ran it again
        mark.unlink()
    missing = (str(tmp_path / "no-such-cc"),)
    probe_compiler(missing)
    assert is_gcc(missing) is False


def test_a_probe_no_build_read_is_ended_at_exit():
    """A build that stops before compiling leaves its probe unread: the process
    ends it at exit, without waiting for it or a ResourceWarning."""
    code = ("from modelgen.codegen.compilers import probe_compiler\n"
            "probe_compiler(('sh', '-c', 'sleep 60', '--'))")
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-X", "dev", "-W", "error", "-c", code],
                          capture_output=True, text=True, timeout=60,
                          env=dict(os.environ, PYTHONPATH=str(Path(__file__).parent.parent)))
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    assert time.perf_counter() - start < 30
