"""Every command and code block of the README runs as written.

Python blocks run one by one in a fresh interpreter, shell blocks command by
command through the real ``modelgen`` entry point, both in a scratch directory
that sees the repository's ``models/`` and ``tests/`` (so nothing is written
into the checkout), with the build cache in the scratch directory too.  C
prototypes must appear in the golden header.  A block preceded by
``<!-- readme-test: skip (reason) -->`` is illustration only; there are few.
A block preceded by ``<!-- readme-test: needs MODULE ... -->`` uses an optional
extra: it runs where those modules import and is skipped, naming them, where
they do not (``make test`` installs only the ``test`` extra; CI installs all).
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
SKIP = "<!-- readme-test: skip"
NEEDS = re.compile(r"^<!-- readme-test: needs ([\w. ]+) -->$")


def _blocks(page=README):
    """(language, code, line, skipped, needs) for every fenced block of the README
    (or ``page``); ``needs``: the modules its ``readme-test: needs`` line names."""
    lines = page.read_text().splitlines()
    out, i = [], 0
    while i < len(lines):
        m = re.match(r"^```(\w*)\s*$", lines[i])
        if not m:
            i += 1
            continue
        start, lang = i + 1, m.group(1)
        skipped = i > 0 and lines[i - 1].startswith(SKIP)
        needs = NEEDS.match(lines[i - 1]) if i > 0 else None
        j = i + 1
        while not lines[j].startswith("```"):
            j += 1
        out.append((lang, "\n".join(lines[i + 1:j]), start, skipped,
                    tuple(needs.group(1).split()) if needs else ()))
        i = j + 1
    return out


BLOCKS = _blocks()


def _runnable(kind):
    """pytest params (code, needs) of the blocks of ``kind`` that run, with their ids."""
    return [pytest.param(code, needs, id=f"line{line}")
            for lang, code, line, skipped, needs in BLOCKS if lang == kind and not skipped]


def _require(needs):
    for module in needs:
        pytest.importorskip(module, reason=f"the block needs {module} (an optional extra)")


def _scratch(tmp_path):
    """A directory with models/ and tests/ of the checkout, and its own build cache."""
    for name in ("models", "tests"):
        (tmp_path / name).symlink_to(ROOT / name)
    env = dict(os.environ, MODELGEN_CACHE_DIR=str(tmp_path / "cache"), MPLBACKEND="Agg",
               PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")
    return env


def test_the_readme_has_blocks_of_every_kind_and_few_are_skipped():
    kinds = {lang for lang, *_ in BLOCKS}
    assert {"python", "sh", "c", "yaml"} <= kinds
    assert sum(skipped for *_, skipped, _ in BLOCKS) <= 3


@pytest.mark.parametrize("code, needs", _runnable("python"))
def test_python_block_runs(tmp_path, code, needs):
    _require(needs)
    env = _scratch(tmp_path)
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]


#: pages of docs/ whose python blocks run too; a page's blocks share one build cache
#: (they build the same model, as a reader running them in turn would)
DOC_PAGES = ("kinematics.md",)


def _doc_blocks():
    return [pytest.param(page, code, needs, id=f"{page}:line{line}") for page in DOC_PAGES
            for lang, code, line, skipped, needs in _blocks(ROOT / "docs" / page)
            if lang == "python" and not skipped]


@pytest.fixture(scope="module")
def doc_caches(tmp_path_factory):
    return {page: tmp_path_factory.mktemp("doc-cache") for page in DOC_PAGES}


@pytest.mark.parametrize("page, code, needs", _doc_blocks())
def test_doc_python_block_runs(tmp_path, doc_caches, page, code, needs):
    _require(needs)
    env = dict(_scratch(tmp_path), MODELGEN_CACHE_DIR=str(doc_caches[page]))
    proc = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]


@pytest.mark.parametrize("code, needs", _runnable("sh"))
def test_shell_block_runs(tmp_path, code, needs):
    _require(needs)
    env = _scratch(tmp_path)
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
    blocks = [code for lang, code, _, skipped, _ in BLOCKS if lang == "c" and not skipped]
    assert blocks
    for code in blocks:
        for declaration in code.split(";"):
            compact = re.sub(r"\s+", "", declaration)
            if compact:
                assert compact + ";" in header, declaration.strip()
