"""Every command and code block of the README and of the pages in docs/ runs as written.

Python blocks run one by one in a fresh interpreter, shell blocks command by
command through the real ``modelgen`` entry point, both in a scratch directory
that sees the repository's ``models/`` and ``tests/`` (so nothing is written
into the checkout), with the build cache in the scratch directory too.  C
prototypes must appear in the golden header.  A block preceded by
``<!-- readme-test: skip (reason) -->`` is illustration only; there are few.
A block preceded by ``<!-- readme-test: needs MODULE ... -->`` uses an optional
extra: it runs where those modules import and is skipped, naming them, where
they do not (``make test`` installs only the ``test`` extra; CI installs all).
Every page of docs/ is read the same way (tests are named ``<page>:line<N>``);
YAML blocks are not run here: those of docs/model-format.md are loaded by
tests/test_model_format_doc.py.
"""
from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"
PAGES = [README] + sorted((ROOT / "docs").glob("*.md"))
SKIP = "<!-- readme-test: skip"
NEEDS = re.compile(r"^<!-- readme-test: needs ([\w. ]+) -->$")
FENCE = re.compile(r"^(`{3,})\s*([^`\s]*)[^`]*$")


def _blocks(path):
    """(language, code, line, skipped, needs) for every fenced block of the page;
    ``language`` is the first word of the fence's info string (```yaml model ->
    yaml, ```{toctree} -> {toctree}); ``needs``: the modules its
    ``readme-test: needs`` line names."""
    lines = path.read_text().splitlines()
    out, i = [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        start, fence, lang = i + 1, m.group(1), m.group(2)
        skipped = i > 0 and lines[i - 1].startswith(SKIP)
        needs = NEEDS.match(lines[i - 1]) if i > 0 else None
        j = i + 1
        while j < len(lines) and lines[j].rstrip() != fence:
            j += 1
        assert j < len(lines), f"{path.name}:{start}: the block is not closed"
        out.append((lang, "\n".join(lines[i + 1:j]), start, skipped,
                    tuple(needs.group(1).split()) if needs else ()))
        i = j + 1
    return out


BLOCKS = _blocks(README)
PAGE_BLOCKS = {path: _blocks(path) for path in PAGES}


def _page_id(path, line):
    """``line<N>`` for the README (the ids its tests always had), ``<page>:line<N>`` else."""
    return f"line{line}" if path == README else f"{path.name}:line{line}"


def _runnable(kind):
    """pytest params (code, needs) of the blocks of ``kind`` that run, on every page,
    with their ids."""
    return [pytest.param(code, needs, id=_page_id(path, line))
            for path, blocks in PAGE_BLOCKS.items()
            for lang, code, line, skipped, needs in blocks if lang == kind and not skipped]


def _require(needs):
    for module in needs:
        pytest.importorskip(module, reason=f"the block needs {module} (an optional extra)")


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    """One build cache for every block: a reader runs the pages' blocks in turn, and
    the cache is keyed by what is built, so a block never sees another's output."""
    return tmp_path_factory.mktemp("cache")


def _scratch(tmp_path, cache):
    """A directory with models/ and tests/ of the checkout, and the blocks' build cache."""
    for name in ("models", "tests"):
        (tmp_path / name).symlink_to(ROOT / name)
    env = dict(os.environ, MODELGEN_CACHE_DIR=str(cache), MPLBACKEND="Agg",
               PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")
    return env


def test_the_readme_has_blocks_of_every_kind_and_few_are_skipped():
    kinds = {lang for lang, *_ in BLOCKS}
    assert {"python", "sh", "c", "yaml"} <= kinds
    assert sum(skipped for *_, skipped, _ in BLOCKS) <= 3


def test_the_docs_pages_are_read_and_few_blocks_are_skipped():
    """The pages hold runnable blocks, every skip gives its reason, and a marker
    sits on the line right above a fence (a marker elsewhere would skip nothing)."""
    runnable = [b for path in PAGES[1:] for b in PAGE_BLOCKS[path]
                if b[0] in ("python", "sh") and not b[3]]
    assert len(runnable) >= 10
    for path in PAGES:
        lines = path.read_text().splitlines()
        for i, line in enumerate(lines):
            if line.startswith("<!-- readme-test:"):
                assert re.match(r"^<!-- readme-test: (skip \(.+\)|needs [\w. ]+) -->$", line), \
                    f"{path.name}:{i + 1}: {line}"
                assert i + 1 < len(lines) and FENCE.match(lines[i + 1]), \
                    f"{path.name}:{i + 1}: the marker is not right above a block"
    skipped = sum(b[3] for path in PAGES[1:] for b in PAGE_BLOCKS[path])
    assert skipped <= 4, skipped


@pytest.mark.parametrize("code, needs", _runnable("python"))
def test_python_block_runs(tmp_path, cache, code, needs):
    _require(needs)
    env = _scratch(tmp_path, cache)
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]


@pytest.mark.parametrize("code, needs", _runnable("sh"))
def test_shell_block_runs(tmp_path, cache, code, needs):
    _require(needs)
    env = _scratch(tmp_path, cache)
    for line in code.splitlines():
        command = line.split("#", 1)[0].strip()
        if not command:
            continue
        argv = shlex.split(command)
        assert argv[0] == "modelgen", f"only modelgen commands are run here: {command}"
        proc = subprocess.run([sys.executable, "-m", "modelgen", *argv[1:]], cwd=tmp_path,
                              env=env, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, (command, proc.stderr[-3000:])


def test_c_prototypes_are_those_of_the_generated_header():
    header = re.sub(r"\s+", "", (ROOT / "tests" / "golden" / "double_pendulum.h").read_text())
    blocks = [code for blocks in PAGE_BLOCKS.values()
              for lang, code, _, skipped, _ in blocks if lang == "c" and not skipped]
    assert blocks
    for code in blocks:
        for declaration in code.split(";"):
            compact = re.sub(r"\s+", "", declaration)
            if compact:
                assert compact + ";" in header, declaration.strip()
