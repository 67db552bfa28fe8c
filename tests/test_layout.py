"""The package's architecture: imports run down the pipeline only, with no cycles.

Every import of every module counts, function-level ones included (read with
``ast``, nothing is executed): a module may import from its own stage or from
stages before it in ``model -> derive -> codegen -> sim -> bench -> cli``,
never from a later one; ``errors`` and ``version`` are importable by all; no
module imports another module's private (``_name``) names.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "modelgen"
#: rank of each stage; a module may import ranks <= its own
STAGES = {"errors": 0, "version": 0, "model": 1, "derive": 2, "codegen": 3, "sim": 4,
          "bench": 5, "cli": 6, "__main__": 7, "__init__": 7}


def _modules() -> dict:
    """Dotted module name -> path, for every module of the package."""
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        out[name] = path
    return out


MODULES = _modules()


def _stage(module: str) -> int:
    parts = module.split(".")
    if len(parts) == 1:                      # the package itself: its __init__
        return STAGES["__init__"]
    return STAGES[parts[1]]


def _resolve(target: str) -> str | None:
    """The package module an import name refers to (its longest known prefix)."""
    while target and target not in MODULES:
        target = target.rpartition(".")[0]
    return target or None


def _imports(module: str) -> list:
    """(imported module, imported name or None, line) for every import in ``module``."""
    path = MODULES[module]
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.split(".")[0] == "modelgen":
                    out.append((_resolve(alias.name), None, node.lineno))
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([base] if base else []))
            if base.split(".")[0] != "modelgen":
                continue
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                if sub in MODULES:                     # `from pkg import module`
                    out.append((sub, None, node.lineno))
                else:
                    out.append((_resolve(base), alias.name, node.lineno))
    return [(m, name, line) for m, name, line in out if m is not None]


def test_every_module_belongs_to_a_stage():
    for module in MODULES:
        parts = module.split(".")
        assert len(parts) == 1 or parts[1] in STAGES, (
            f"{module}: put it in one of the stages {', '.join(STAGES)}")


def test_imports_run_down_the_pipeline_only():
    wrong = []
    for module in MODULES:
        for target, _, line in _imports(module):
            if target != module and _stage(target) > _stage(module):
                wrong.append(f"{MODULES[module].relative_to(PACKAGE.parent)}:{line}: "
                             f"{module} imports {target}, a later stage")
    assert not wrong, "\n".join(wrong)


def test_no_module_imports_private_names_of_another():
    wrong = []
    for module in MODULES:
        for target, name, line in _imports(module):
            if name and name.startswith("_") and not name.startswith("__") and target != module:
                wrong.append(f"{MODULES[module].relative_to(PACKAGE.parent)}:{line}: "
                             f"{module} imports {target}.{name}")
    assert not wrong, "\n".join(wrong)


def test_there_is_no_import_cycle():
    graph = {m: {t for t, _, _ in _imports(m) if t != m and not m.startswith(t + ".")}
             for m in MODULES}
    # Tarjan's strongly connected components
    index, low, stack, on, cycles, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    assert not cycles, "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)


@pytest.mark.parametrize("source, expected", [
    ("from modelgen.sim.runtime import CompiledModel", "modelgen.sim.runtime"),
    ("from modelgen.sim import runtime", "modelgen.sim.runtime"),
    ("import modelgen.codegen.build", "modelgen.codegen.build"),
])
def test_the_import_reader_resolves_each_form(tmp_path, monkeypatch, source, expected):
    """The checks above are only as good as this reader: each import form resolves."""
    fake = tmp_path / "modelgen" / "model" / "probe.py"
    fake.parent.mkdir(parents=True)
    fake.write_text(f"def f():\n    {source}\n")
    monkeypatch.setitem(MODULES, "modelgen.model.probe", fake)
    assert [t for t, _, _ in _imports("modelgen.model.probe")] == [expected]
    assert _stage(expected) > _stage("modelgen.model.probe")


#: The size limits a reader can hold in mind (issue 22): a module fits in one
#: sitting, a function on a screen or two.
MAX_MODULE_LINES = 800
MAX_FUNCTION_LINES = 120


def test_modules_and_functions_stay_readable():
    wrong = []
    for path in MODULES.values():
        text = path.read_text()
        lines = len(text.splitlines())
        if lines > MAX_MODULE_LINES:
            wrong.append(f"{path.relative_to(PACKAGE.parent)}: {lines} lines "
                         f"(split it by job; at most {MAX_MODULE_LINES})")
        for node in ast.walk(ast.parse(text, str(path))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - node.lineno + 1
                if length > MAX_FUNCTION_LINES:
                    wrong.append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno}: "
                                 f"{node.name} has {length} lines (at most "
                                 f"{MAX_FUNCTION_LINES}: name its parts)")
    assert not wrong, "\n".join(wrong)


def _subpackages():
    return sorted(p.parent for p in PACKAGE.rglob("__init__.py") if p.parent != PACKAGE)


@pytest.mark.parametrize("package", _subpackages(), ids=lambda p: p.name)
def test_every_subpackage_readme_lists_its_modules(package):
    """A newcomer finds each module's job in its subpackage's README."""
    readme = package / "README.md"
    assert readme.is_file(), f"{package.relative_to(PACKAGE.parent)}: add a README.md"
    text = readme.read_text()
    missing = [p.name for p in sorted(package.glob("*.py"))
               if p.name != "__init__.py" and f"`{p.name}`" not in text]
    assert not missing, (f"{readme.relative_to(PACKAGE.parent)} does not name "
                         f"{', '.join(missing)}: add a row `module.py` | its job")
