"""The C integrator interface is one Python table (modelgen.codegen.capi): the
compiled constants, struct layouts and work size equal it."""
from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from modelgen.codegen import capi
from modelgen.codegen.build import write_sources
from modelgen.codegen.emit import c_dir, integrator_files, integrator_sources
from modelgen.sim import integrate


ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def sp(compiled):
    return compiled("simple_pendulum")


def test_the_compiled_constants_equal_the_python_table(sp):
    compiled = integrate.c_constants(sp)
    assert compiled == capi.define_values()
    assert compiled["MG_ABI_VERSION"] == capi.ABI_VERSION == sp.lib.simple_pendulum_abi_version()
    assert {name: compiled[f"MG_METHOD_{name.upper()}"] for name in capi.METHODS} == \
        {name: m.code for name, m in capi.METHODS.items()}
    assert {s.name: compiled[f"MG_STATUS_{s.name}"] for s in capi.STATUSES} == \
        {s.name: s.code for s in capi.STATUSES}


def test_the_header_defines_exactly_the_table_and_nothing_by_hand():
    header = integrator_sources()["mg_integrate.h"]
    defines = dict(re.findall(r"^#define (MG_\w+) \(?(-?\d+)\)?", header, re.M))
    assert {k: int(v) for k, v in defines.items()} == capi.define_values()
    for name in integrator_files():
        source = integrator_sources()[name]
        assert not re.search(r"^#define MG_(METHOD|STATUS)_", source, re.M), name
        assert not re.search(r"\{%|\{\{ \w|\{#", source), f"{name} is plain C, not a template"


def test_the_integrator_unit_includes_each_of_its_files_once_in_order():
    """mg_integrate.c is the one translation unit: it includes every file of
    mg_integrate/ exactly once (a part left out would be shipped and hashed but never
    compiled), numerics first, since every later part uses it."""
    unit = integrator_sources()["mg_integrate.c"]
    included = re.findall(r'^#include "(mg_integrate/[\w.]+)"', unit, re.M)
    assert sorted(included) == [f for f in integrator_files() if f != "mg_integrate.c"]
    assert len(set(included)) == len(included)
    assert included[:2] == ["mg_integrate/numerics.c", "mg_integrate/system.c"]


@pytest.mark.skipif(not shutil.which("clang-format"), reason="clang-format is not installed")
def test_the_integrator_c_follows_the_repository_clang_format():
    files = [str(c_dir() / f) for f in integrator_files()]
    r = subprocess.run(["clang-format", "--dry-run", "--Werror", *files], cwd=ROOT,
                       stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert r.returncode == 0, r.stdout


def test_struct_fields_of_the_module_follow_the_table(sp):
    for name, _, fields in capi.STRUCTS:
        got = [f for f, _ in sp.ffi.typeof(name).fields]
        assert got == [field for _, field, _ in fields], name
    assert [f for f, _ in sp.ffi.typeof("mg_stats").fields] == list(capi.STAT_NAMES)


def test_status_and_method_codes_are_unique_and_statuses_signed_as_documented():
    codes = [s.code for s in capi.STATUSES]
    assert len(set(codes)) == len(codes)
    assert capi.STATUS[0].name == "SUCCESS" and capi.STATUS[1].name == "EVENT"
    assert all(s.code < 0 for s in capi.STATUSES if s.code not in (0, 1, 2))
    assert "INTERRUPTED" in capi.STATUS_BY_NAME
    methods = [m.code for m in capi.METHOD_LIST]
    assert methods == list(range(len(methods)))
    assert integrate.METHODS is capi.METHODS and integrate.method_of("rodas4").name == "rodas"


def test_work_size_macro_and_function_equal_the_python_formula(sp, tmp_path):
    write_sources(tmp_path, integrator_sources())
    (tmp_path / "main.c").write_text(
        '#include <stdio.h>\n#include "mg_integrate.h"\n'
        "int main(void)\n{\n"
        '    printf("%ld %ld\\n", (long)MG_WORK_SIZE(4, 1, 3), mg_work_size(4, 1, 3));\n'
        "    return 0;\n}\n")
    r = subprocess.run(["cc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "main.c",
                        "mg_integrate.c", "-o", "main", "-lm"], cwd=tmp_path,
                       stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    assert r.returncode == 0, r.stdout
    out = subprocess.run([str(tmp_path / "main")], stdout=subprocess.PIPE, text=True).stdout
    assert out.split() == [str(capi.work_size(4, 1, 3))] * 2
    # and the module's mg_work_size agrees
    assert sp.lib.mg_work_size(4, 1, 3) == capi.work_size(4, 1, 3)
    assert np.all([sp.lib.mg_work_size(n, 0, 0) == capi.work_size(n, 0, 0) for n in (1, 2, 60)])


def test_the_scene_format_names_the_methods_of_the_c_table():
    """Scene files are read by the model stage, which cannot import codegen: its method
    vocabulary must equal the C interface table's, method for method."""
    from modelgen.model import scene
    assert scene.METHODS == tuple(capi.METHODS)
    assert scene.METHOD_ALIASES == capi.ALIASES
    assert set(scene.FIXED_STEP_METHODS) == {m.name for m in capi.METHOD_LIST if not m.adaptive}
