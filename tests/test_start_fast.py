"""Start fast: a cached model loads through the build cache's fast index, without sympy.

The fast index (:mod:`modelgen.codegen.index`) maps a model file's bytes and the
build options to a build that is then verified like every cache hit.  These
tests run fresh Python processes and read their ``sys.modules``, and check
that a stale or damaged entry falls back to the full path.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import modelgen
from modelgen.codegen import index
from modelgen.codegen.build import cache_dir
from modelgen.codegen.options import BuildOptions

REPO = Path(__file__).resolve().parent.parent
MODEL = REPO / "models" / "double_pendulum.yaml"
SYMBOLIC = ("sympy", "symengine")


def _fresh(code: str, **env) -> list:
    """Run ``code`` in a fresh Python (this checkout, this cache); the symbolic
    packages (and the pipeline) it imported, from its last line of output."""
    script = (code + "\nimport json, sys\nprint(json.dumps(sorted(m for m in sys.modules if "
              f"m.split('.')[0] in {SYMBOLIC!r} or m == 'modelgen.codegen.pipeline')))")
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True,
                          cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO), **env),
                          timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """The double pendulum built from a copy of its file, and that copy."""
    root = tmp_path_factory.mktemp("fast")
    path = root / "double_pendulum.yaml"
    shutil.copy(MODEL, path)
    cm = modelgen.load(path, root / "build")
    return path, root / "build", cm


def test_import_modelgen_imports_no_symbolic_package():
    assert _fresh("import modelgen") == []


def test_help_imports_no_symbolic_package():
    code = ("from modelgen.cli import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit as exc:\n    assert exc.code == 0")
    assert _fresh(code) == []


def test_cached_load_imports_no_symbolic_package_and_gives_the_same_model(built):
    path, out, cm = built
    x = [0.3, -0.2, 0.5, 0.1]
    code = (f"import modelgen\ncm = modelgen.load({str(path)!r}, {str(out)!r})\n"
            f"import json\nprint(json.dumps([float(v) for v in cm.rhs(0.0, {x!r})]))")
    assert _fresh(code) == []
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO)))
    rhs = json.loads(proc.stdout.strip().splitlines()[0])
    assert np.array_equal(rhs, cm.rhs(0.0, x))         # the same library, bit for bit


def test_options_are_part_of_the_fast_key(built):
    path, out, _ = built
    keys = {index.fast_key([path], options, out)
            for options in (BuildOptions(), BuildOptions(jacobian=True),
                            BuildOptions(formulation="crba"), BuildOptions(floating_base=True))}
    assert len(keys) == 4
    assert index.fast_key([path], BuildOptions(), out) != index.fast_key([path], BuildOptions(),
                                                                          None)


def test_compiler_flags_are_part_of_the_fast_key(built, monkeypatch):
    path, out, _ = built
    before = index.fast_key([path], BuildOptions(), out)
    monkeypatch.setenv("MODELGEN_CFLAGS", "-DMG_SOMETHING")
    assert index.fast_key([path], BuildOptions(), out) != before


def _entry(path, out) -> Path:
    key = index.fast_key([path], BuildOptions(), out)
    entry = cache_dir() / "index" / f"{key[:32]}.json"
    assert entry.is_file() and index.lookup(key) is not None
    return entry


def test_a_damaged_index_entry_falls_back_to_the_full_path(built):
    path, out, cm = built
    entry = _entry(path, out)
    entry.write_text("{not json")
    again = modelgen.load(path, out)
    assert again.manifest["build_hash"] == cm.manifest["build_hash"]
    assert json.loads(entry.read_text())["build_hash"] == cm.manifest["build_hash"]   # rewritten


def test_an_entry_naming_another_build_is_a_miss(built):
    path, out, cm = built
    entry = _entry(path, out)
    data = json.loads(entry.read_text())
    entry.write_text(json.dumps(dict(data, build_hash="0" * 64)))
    assert index.lookup(data["key"]) is None
    modelgen.load(path, out)
    assert index.lookup(data["key"]).build.manifest["build_hash"] == cm.manifest["build_hash"]


def test_an_entry_whose_manifest_was_edited_is_a_miss(built):
    path, out, cm = built
    entry = _entry(path, out)
    key = json.loads(entry.read_text())["key"]
    manifest_file = out / "manifest.json"
    original = manifest_file.read_text()
    try:
        manifest = json.loads(original)
        manifest_file.write_text(json.dumps(dict(manifest, n=manifest["n"] + 1)))
        assert index.lookup(key) is None             # verified like every cache hit
    finally:
        manifest_file.write_text(original)
    assert index.lookup(key) is not None


def test_an_edited_model_file_misses_and_builds_the_edit(built, tmp_path):
    path, _, cm = built
    edited = tmp_path / "double_pendulum.yaml"
    text = path.read_text()
    assert "m2: 1.0" in text
    edited.write_text(text.replace("m2: 1.0", "m2: 2.5", 1))
    other = modelgen.load(edited, tmp_path / "build")
    assert other.parameters["m2"] == 2.5 and cm.parameters["m2"] != 2.5


# -- scenes: a scene run before runs from its card, without reading its model ---------

SCENES = sorted((REPO / "models" / "scenes").glob("*.yaml"))


@pytest.fixture(scope="module")
def scene_copy(tmp_path_factory):
    """dp_damped (inputs off, a damper: work outputs) and its model, copied; its build."""
    root = tmp_path_factory.mktemp("scene")
    (root / "scenes").mkdir()
    shutil.copy(REPO / "models" / "scenes" / "dp_damped.yaml", root / "scenes")
    shutil.copy(MODEL, root)
    return root / "scenes" / "dp_damped.yaml", root / "build"


@pytest.mark.parametrize("scene", SCENES, ids=lambda p: p.stem)
def test_every_scene_card_survives_its_json(scene):
    from modelgen.model.scene import load_scene
    from modelgen.sim.scene import SceneCard
    card = SceneCard.of(load_scene(scene))
    again = SceneCard.from_json(json.loads(json.dumps(card.to_json())))
    assert again == card            # so the build options, and the fast key, are equal
    assert again.outputs == card.outputs and again.inputs == card.inputs


def test_a_cached_scene_runs_without_symbolic_packages_and_gives_the_same_run(scene_copy):
    path, out = scene_copy
    first = modelgen.load_scene(path, out).run()
    code = (f"import modelgen\nres = modelgen.load_scene({str(path)!r}, {str(out)!r}).run()\n"
            "import json\nprint(json.dumps([res.y[:, -1].tolist(), "
            "res.energy[-1].tolist(), {k: w[-1] for k, w in res.work.items()}]))")
    assert _fresh(code) == []
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO)), timeout=600)
    y, energy, work = json.loads(proc.stdout.strip().splitlines()[0])
    assert np.array_equal(y, first.y[:, -1]) and np.array_equal(energy, first.energy[-1])
    assert work == {k: w[-1] for k, w in first.work.items()} and work


def test_the_cli_simulates_a_cached_scene_without_symbolic_packages(scene_copy, tmp_path):
    path, out = scene_copy
    modelgen.load_scene(path, out)
    code = ("from modelgen.cli import main\n"
            f"assert main(['simulate', {str(path)!r}, '--build-dir', {str(out)!r}, "
            f"'-o', {str(tmp_path)!r}, '--no-plot', '-q']) == 0")
    assert _fresh(code) == []
    assert (tmp_path / "dp_damped.csv").is_file()


def test_an_edited_model_makes_the_card_stale(scene_copy):
    from modelgen.sim.scene import read_card
    path, out = scene_copy
    modelgen.load_scene(path, out)
    assert read_card(path, out)[1] is None              # the card, nothing read
    model = path.parent.parent / "double_pendulum.yaml"
    text = model.read_text()
    try:
        model.write_text(text + "\n# edited\n")
        card, spec = read_card(path, out)
        assert spec is not None and card == read_card(path, out)[0]
    finally:
        model.write_text(text)


# -- a generation imports no numpy -----------------------------------------------------

def test_a_generation_imports_no_numpy(tmp_path):
    """``modelgen.generate_model`` of a YAML model (principal moments and a diagonal
    3x3 inertia, no constraints) needs no numpy: symengine gets a stand-in
    (:func:`modelgen.codegen.cse.import_symengine`) and the library's mass matrix
    is checked through ctypes (:mod:`modelgen.sim.massmatrix`); the build is
    then found through the fast index by a load."""
    path = tmp_path / "double_pendulum.yaml"
    shutil.copy(MODEL, path)
    code = (
        "import sys, traceback\n"
        "stages, seen = [], []\n"
        "class Finder:\n"
        "    def find_spec(self, name, path=None, target=None):\n"
        "        if name == 'numpy' and not seen:\n"
        "            calls = [f.name for f in traceback.extract_stack()]\n"
        "            seen.append((stages[-1:], 'run_commands' in calls))\n"
        "sys.meta_path.insert(0, Finder())\n"
        "import modelgen\n"
        f"modelgen.generate_model({str(path)!r}, {str(tmp_path / 'out')!r}, force=True, "
        "progress=stages.append)\n"
        "print(seen, stages[-1])")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO)), timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.strip().splitlines()[-1] == "[] compile"
    assert _fresh(f"import modelgen\nmodelgen.load({str(path)!r}, {str(tmp_path / 'out')!r})"
                  ) == []


def test_symengine_imported_without_numpy_gets_numpy_on_first_use():
    code = ("import sys, sympy\n"
            "from modelgen.codegen.cse import import_symengine\n"
            "se = import_symengine()\n"
            "before = 'numpy' in sys.modules\n"
            "x = sympy.Symbol('x')\n"
            "e = se.sympify(2 * x + 1)\n"       # reaches symengine's numpy scalar check
            "import numpy\n"
            "f = se.lambdify([se.Symbol('x')], [e])\n"
            "print(before, type(sys.modules['numpy']).__name__, float(f(3.0)), "
            "se.sympify(numpy.float32(0.5)))")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=REPO, env=dict(os.environ, PYTHONPATH=str(REPO)), timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.split() == ["False", "module", "7.0", "0.5"]
