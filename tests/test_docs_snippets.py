"""What the documentation shows, beyond what tests/test_readme.py runs.

tests/test_readme.py runs every ``python`` and ``sh`` block of README.md and of
docs/*.md and checks the ``c`` prototypes against the golden header;
tests/test_model_format_doc.py loads the YAML blocks of docs/model-format.md.
This file checks the rest:

* the YAML blocks of the other pages load, inside the model or scene they are a
  part of (``YAML``: the host of each block, or why it is only read as YAML);
* the C blocks test_readme skips compile, or are declared, against a header
  generated here (a function body, the prototypes of a kinematics and of a
  linearize build), and the header excerpt that docs/generated-c.md shows is in
  the header its command writes;
* what the python blocks print, or say in a comment, where a page shows it
  (``SHOWN``: each block with the code that checks what its page says; the
  other blocks are run by test_readme and show nothing to compare);
* every command-line flag a page names exists (``modelgen <command> --help``,
  or a bench script's own flags), every repository file it names in backticks
  exists, every ``modelgen.<module>.<name>`` it names imports, and the status
  table of docs/python-api.md is the C's.

Blocks are found by a piece of their text, not by line, so editing a page
moves nothing here.  The builds go to a cache of this module's own.
"""
from __future__ import annotations

import importlib
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from modelgen.codegen.build import compiler

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
PAGES = [ROOT / "README.md"] + sorted(DOCS.glob("*.md"))
FENCE = re.compile(r"^(`{3,})\s*([^`\s]*)[^`]*$")


def _blocks(path):
    """(language, code) of every fenced block of the page."""
    lines, out, i = path.read_text().splitlines(), [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        j = i + 1
        while j < len(lines) and lines[j].rstrip() != m.group(1):
            j += 1
        out.append((m.group(2), "\n".join(lines[i + 1:j])))
        i = j + 1
    return out


def block(page, lang, marker):
    """The one block of ``page`` in ``lang`` that contains ``marker``."""
    found = [code for kind, code in _blocks(ROOT / page) if kind == lang and marker in code]
    assert len(found) == 1, f"{page}: {len(found)} {lang} blocks contain {marker!r}"
    return found[0]


@pytest.fixture(scope="module")
def env(tmp_path_factory):
    """The environment of the blocks and commands: a build cache of this module."""
    cache = tmp_path_factory.mktemp("cache")
    return dict(os.environ, MODELGEN_CACHE_DIR=str(cache), MPLBACKEND="Agg",
                PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")


def _scratch(tmp_path):
    for name in ("models", "tests"):
        (tmp_path / name).symlink_to(ROOT / name)
    return tmp_path


def _modelgen(args, cwd, env):
    proc = subprocess.run([sys.executable, "-m", "modelgen", *args], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, (args, proc.stderr[-3000:])
    return proc.stdout


# ---------------------------------------------------------------- YAML blocks

def _merged(host_text, fragment):
    """The host file with the fragment's sections added (a mapping's entries join
    the host's, anything else replaces it)."""
    data = yaml.safe_load(host_text)
    for key, value in yaml.safe_load(fragment).items():
        if isinstance(value, dict) and isinstance(data.get(key), dict):
            data[key] = {**data[key], **value}
        else:
            data[key] = value
    return yaml.safe_dump(data, sort_keys=False)


def _first_model_of_model_format():
    return re.search(r"```yaml model\n(.*?)```", (DOCS / "model-format.md").read_text(),
                     re.DOTALL).group(1)


def _load_scene(text, base_dir):
    from modelgen.model import parse_scene
    return parse_scene(text, source="<doc>", base_dir=base_dir)


def _load_model(text):
    from modelgen.model import parse_model
    return parse_model(text, source="<doc>")


SCENES = ROOT / "models" / "scenes"

#: page, a piece of the block, how it is loaded.  Scenes' ``model:`` paths are
#: relative to models/scenes/, where the pages' scenes live.
YAML = [
    ("README.md", "name: double_pendulum", lambda code: _load_model(code)),
    ("README.md", "scene: dp_damped", lambda code: _load_scene(code, SCENES)),
    ("docs/scenes.md", "scene: dp_damped", lambda code: _load_scene(code, SCENES)),
    # a frame of the first model of docs/model-format.md, which has P2 and B2
    ("docs/kinematics.md", "tool: {point: P2",
     lambda code: _load_model(_merged(_first_model_of_model_format(), code))),
    # a scene's key: the ur5's scene, whose model has the frame tool0
    ("docs/kinematics.md", "kinematics: {frames: [tool0]",
     lambda code: _load_scene(_merged((SCENES / "ur5_damped.yaml").read_text(), code), SCENES)),
    # the four-bar's loop (the scene of its page's forces)
    ("docs/constraints.md", "f_pin: {constraint_force: loop}",
     lambda code: _load_scene(_merged((SCENES / "four_bar_swing.yaml").read_text(), code),
                              SCENES)),
]


@pytest.mark.parametrize("page, marker, load", YAML, ids=[f"{p}:{m}" for p, m, _ in YAML])
def test_yaml_block_loads_where_it_belongs(page, marker, load):
    assert load(block(page, "yaml", marker))


def test_the_constraint_kinds_block_uses_each_kind_with_its_keys():
    """docs/constraints.md's first block names points of no one model: each entry
    is checked against the kinds' keys, and ``dependent`` against its keys."""
    from modelgen.model.constraints import KIND_FIELDS
    data = yaml.safe_load(block("docs/constraints.md", "yaml", "type: rolling"))
    kinds = set()
    for name, entry in data["constraints"].items():
        allowed, required = KIND_FIELDS[entry["type"]]
        keys = set(entry) - {"type"}
        assert keys <= set(allowed) and set(required) <= keys, (name, entry)
        kinds.add(entry["type"])
    assert kinds == set(KIND_FIELDS)
    assert set(data["dependent"]) == {"coordinates", "speeds"}


def test_every_yaml_block_outside_model_format_is_checked():
    """A new YAML block on a page is added to YAML above (or here, with a reason)."""
    checked = {(page, marker) for page, marker, _ in YAML}
    checked.add(("docs/constraints.md", "type: rolling"))      # the kinds' keys, above
    for path in PAGES:
        page = str(path.relative_to(ROOT))
        if page == "docs/model-format.md":                       # test_model_format_doc.py
            continue
        for kind, code in _blocks(path):
            if kind == "yaml":
                assert any(p == page and m in code for p, m in checked), (page, code[:60])


# ---------------------------------------------------------------- C blocks

@pytest.fixture(scope="module")
def dp_kinematics(tmp_path_factory, env):
    """docs/generated-c.md's command: the double pendulum with the frame F2."""
    command = block("docs/generated-c.md", "sh", "--frame F2")
    argv = command.split("#")[0].split()
    assert argv[:2] == ["modelgen", "generate"]
    cwd = _scratch(tmp_path_factory.mktemp("gen"))
    _modelgen(argv[1:], cwd, env)
    out = argv[argv.index("-o") + 1]
    return cwd / out


def test_the_header_excerpt_is_the_generated_header(dp_kinematics):
    excerpt = block("docs/generated-c.md", "text", "#define DOUBLE_PENDULUM_NFRAMES")
    header = (dp_kinematics / "double_pendulum.h").read_text()
    assert excerpt.strip() in header


def test_the_integration_fragment_compiles_and_runs(dp_kinematics, tmp_path):
    """docs/generated-c.md's fragment of a C program, inside a main(), built from the
    output directory alone with the flags the page promises."""
    code = block("docs/generated-c.md", "c", "double_pendulum_integrate(")
    includes = [line for line in code.splitlines() if line.startswith("#include")]
    body = [line for line in code.splitlines() if not line.startswith("#include")]
    program = "\n".join(includes + ["#include <stdio.h>", "int main(void) {", *body,
                                    'printf("%d %.17g\\n", status, x1[0]);',
                                    "return status;", "}"])
    (tmp_path / "main.c").write_text(program)
    sources = [str(p) for p in sorted(dp_kinematics.glob("*.c"))]
    subprocess.run([*compiler(), "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O1",
                    f"-I{dp_kinematics}", str(tmp_path / "main.c"), *sources, "-lm",
                    "-o", str(tmp_path / "main")], check=True, capture_output=True, text=True)
    run = subprocess.run([str(tmp_path / "main")], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0 and run.stdout.startswith("0 "), run.stdout


def _declared(code, header):
    header = re.sub(r"\s+", "", header)
    code = re.sub(r"/\*.*?\*/", "", code, flags=re.DOTALL)
    declarations = [re.sub(r"\s+", "", d) for d in code.split(";") if d.strip()]
    assert declarations
    for declaration in declarations:
        assert declaration + ";" in header, declaration


def test_the_linearize_prototype_is_the_generated_one(tmp_path, env):
    """The cart-pole's build with linearize=True (docs/python-api.md's, from the
    cache of this module when that block ran first)."""
    load = "import modelgen; print(modelgen.load('models/cart_pole.yaml', linearize=True).path)"
    proc = subprocess.run([sys.executable, "-c", load], cwd=_scratch(tmp_path), env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    header = Path(proc.stdout.strip()).parent / "cart_pole.h"
    code = block("docs/linearize.md", "c", "_linearize(").replace("<name>", "cart_pole")
    _declared(code, header.read_text())


@pytest.mark.slow
def test_the_kinematics_prototypes_are_those_of_a_ur5_build(tmp_path, env):
    """docs/kinematics.md's prototypes: the ur5 with a frame, the centre of mass and
    the centroidal map (a build of its own, some seconds)."""
    _modelgen(["generate", "tests/data/urdf/ur5_robot.urdf", "-o", "ur5", "-q",
               "--frame", "tool0", "--com", "--centroidal"], _scratch(tmp_path), env)
    _declared(block("docs/kinematics.md", "c", "ur5_frame_poses"),
              (tmp_path / "ur5" / "ur5.h").read_text())


# ---------------------------------------------------------------- what blocks show

#: page, a piece of the python block, code run after it (what the page says the
#: block gives, in its comments or its prose), a regular expression its output
#: must match (None: nothing printed to compare), and whether it is slow.
SHOWN = [
    ("docs/integrators.md", "bottom.direction = 1",
     "assert abs(res.t_events[0][0] - 0.75 * 2.367841947576237) < 2e-11\n"
     "assert res.status == 0 and res.success\n"
     "assert cm.simulate_batch(X0, (0, 1), t_eval=np.linspace(0, 1, 11)).y.shape"
     " == (100, 2, 11)\n", None, False),
    ("docs/scenes.md", "dp_damped.yaml",
     "assert res.y.shape == (4, len(res.t)) and res['elbow'].shape == (len(res.t), 3)\n"
     "import matplotlib.figure; assert isinstance(fig, matplotlib.figure.Figure)\n",
     r"scene dp_damped: model double_pendulum, n = 2\neffects on: gravity, hinge_damping\n",
     False),
    ("docs/constraints.md", "print(lin.states, lin.A.shape)", "",
     r"\('q1', 'q1_dot'\) \(2, 2\)", False),
    ("docs/constraints.md", "cm.constraint_residuals(res.y[:3, -1])",
     "assert np.abs(cm.constraint_residuals(res.y[:3, -1])).max() < 1e-14\n"
     "assert np.abs(cm.constraint_jacobian(q0) @ qd0).max() < 1e-14\n", None, False),
    ("docs/fmu.md", "build_fmu(",
     "assert fmu.names('parameter') == ['M', 'm', 'L', 'g'] and fmu.names('input') == ['F']\n",
     None, False),
    ("docs/python-api.md", "print(lin.table())", "", r"-3\.97\d* \+ 0j", False),
    # the kinematics page's tables and prose: the IK converges, the tool's
    # tracking error peaks at a few millimetres, then decays
    ("docs/kinematics.md", "Rotation.from_matrix", "",
     r"^\d+ iterations, pose error \d\.\de-1[2-9]", True),
    ("docs/kinematics.md", "def control(t, x)", "",
     r"largest tracking error \d\.\de-03 m", True),
    ("docs/urdf.md", 'res["root_joint_z"]', "", r"^-19\.6\d", True),
    # the table of eigenvalues at 5 m/s and the weave and capsize speeds
    ("docs/constraints.md", "stability_speeds(cm)", "",
     r"-14\.07838\d*\+0\.j +-0\.77534\d*-4\.46486\d*j[\s\S]*-0\.32286\d*\+0\.j"
     r"[\s\S]*4\.2923825363\d*\)?, (np\.float64\()?6\.0242620153", True),
]


def _shown_params():
    for page, marker, check, output, slow in SHOWN:
        marks = [pytest.mark.slow] if slow else []
        yield pytest.param(page, marker, check, output, marks=marks, id=f"{page}:{marker}")


@pytest.mark.parametrize("page, marker, check, output", list(_shown_params()))
def test_a_block_gives_what_its_page_shows(tmp_path, env, page, marker, check, output):
    code = block(page, "python", marker) + "\n" + check
    proc = subprocess.run([sys.executable, "-c", code], cwd=_scratch(tmp_path), env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    if output is not None:
        assert re.search(output, proc.stdout, re.MULTILINE), proc.stdout[-2000:]


# ---------------------------------------------------------------- names in prose

def _flags():
    """Every flag of every modelgen command, and of the bench scripts."""
    from modelgen.cli.parsers import build_parser
    parser = build_parser()
    flags = {s for a in parser._actions for s in a.option_strings}
    for action in parser._actions:
        for sub in (getattr(action, "choices", None) or {}).values():
            flags |= {s for a in sub._actions for s in a.option_strings}
    bench = set()
    for path in list((ROOT / "bench").glob("*.py")) + list((ROOT / "modelgen/bench").glob("*.py")):
        bench |= set(re.findall(r"[\"'](--[a-z][a-z0-9-]*)", path.read_text()))
    return flags, bench


#: flags of other tools that the pages name (valgrind's)
OTHER_TOOLS_FLAGS = {"--cache-sim", "--trace-children"}


def test_every_flag_a_page_names_exists():
    flags, bench = _flags()
    unknown = []
    for path in PAGES:
        for number, line in enumerate(path.read_text().splitlines(), 1):
            for flag in re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", line):
                if flag not in flags | bench | OTHER_TOOLS_FLAGS:
                    unknown.append(f"{path.name}:{number}: {flag}")
    assert not unknown, unknown


#: what a repository path may start with, and where such a path lives
TOP = {"models", "tests", "bench", "modelgen", "docs", "examples", "generated"}
PACKAGE = {"model", "derive", "codegen", "sim", "cli", "templates"}


def test_every_repository_file_a_page_names_exists():
    missing = []
    for path in PAGES:
        for number, line in enumerate(path.read_text().splitlines(), 1):
            for token in re.findall(r"`([A-Za-z_][\w.\-]*/[\w./\-]*)`", line):
                first = token.split("/")[0]
                if token.startswith("docs/_build") or "<" in token:
                    continue
                if first in TOP:
                    where = [ROOT / token]
                elif first in PACKAGE:
                    where = [ROOT / "modelgen" / token, ROOT / "modelgen/codegen" / token]
                else:
                    continue
                if not any(p.exists() for p in where):
                    missing.append(f"{path.name}:{number}: {token}")
    assert not missing, missing


def test_every_modelgen_name_a_page_names_imports():
    missing = []
    names = {n for path in PAGES
             for n in re.findall(r"\bmodelgen(?:\.[A-Za-z_]\w*)+", path.read_text())}
    for name in sorted(names):
        parts = name.split(".")
        for cut in range(len(parts), 0, -1):
            try:
                obj = importlib.import_module(".".join(parts[:cut]))
                break
            except ImportError:
                continue
        try:
            for attr in parts[cut:]:
                obj = getattr(obj, attr)
        except AttributeError:
            missing.append(name)
    assert not missing, missing


def test_the_status_table_is_the_c_one():
    from modelgen.codegen.capi import STATUSES
    text = (DOCS / "python-api.md").read_text()
    rows = {int(code.replace("−", "-"))
            for code in re.findall(r"^\| *([−-]?\d+) \|", text, re.MULTILINE)}
    internal = {s.code for s in STATUSES if s.name == "BUFFER_FULL"}
    assert rows == {s.code for s in STATUSES} - internal


def test_every_compiled_model_member_a_page_names_exists():
    """``cm.<name>``: a method or property of CompiledModel, or an attribute its
    constructor sets."""
    import inspect

    from modelgen.sim import runtime
    source = inspect.getsource(runtime.CompiledModel)
    missing = sorted({f"{path.name}: cm.{name}" for path in PAGES
                      for name in re.findall(r"\bcm\.([A-Za-z_]\w*)", path.read_text())
                      if not hasattr(runtime.CompiledModel, name)
                      and f"self.{name} =" not in source})
    assert not missing, missing


#: error messages the pages show, and a file that gives each (the line is the 5th)
ERRORS = [
    ("README.md", "models/bad.yaml:5: bases.B1.axis:",
     "name: x\ncoordinates: [q1]\nparameters: {l: 1.0}\nbases:\n"
     "  B1: {parent: E, axis: 7, angle: q1}\n"),
    ("docs/model-format.md", "models/arm.yaml:5: bases.B2.parent:",
     "name: arm\ncoordinates: [q1, q2]\nbases:\n  B1: {parent: E, axis: 3, angle: q1}\n"
     "  B2: {parent: B11, axis: 3, angle: q2}\n"),
]


@pytest.mark.parametrize("page, shown, text", ERRORS, ids=[e[0] for e in ERRORS])
def test_an_error_a_page_shows_is_the_loaders(page, shown, text):
    from modelgen.errors import ModelError
    line = next(line.strip() for line in (ROOT / page).read_text().splitlines()
                if line.strip().startswith(shown))
    with pytest.raises(ModelError) as exc:
        _load_model_from(text, shown.split(":")[0])
    assert str(exc.value) == line


def _load_model_from(text, source):
    from modelgen.model import parse_model
    return parse_model(text, source=source)
