"""The benchmark scripts of ``bench/`` start, and take the options their docs give.

Benchmarks are scripts, never timed tests: nothing here measures or compares a
speed.  Each script runs ``--help`` in a fresh interpreter from a directory
outside the repository (a script must not depend on the current directory),
and every option the documentation shows for a script (its docstring, the
other scripts' docstrings, docs/benchmarks.md, README.md, the Makefile,
modelgen/bench/README.md) must be one its ``--help`` lists: a renamed option
otherwise leaves commands in the docs that fail.
"""
from __future__ import annotations

import ast
import os
import re
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
BENCH = ROOT / "bench"
SCRIPTS = sorted(p.stem for p in BENCH.glob("*.py"))
#: where commands of the scripts are written down, besides their own docstrings
DOCUMENTS = ("docs/benchmarks.md", "README.md", "Makefile", "modelgen/bench/README.md")
#: ``bench/<script>.py`` and what follows it on the line (not ``modelgen/bench/...``)
COMMAND = re.compile(r"(?<![\w/.])bench/(\w+)\.py([^\n`|]*)")
OPTION = re.compile(r"(?<![\w-])(--[a-z][a-z0-9-]*|-[a-zA-Z])\b")


def docstring(script: str) -> str:
    return ast.get_docstring(ast.parse((BENCH / f"{script}.py").read_text())) or ""


def documented_options() -> dict:
    """script -> {option: where it is written}, for every command line the docs show."""
    found: dict = {}
    texts = [(f"bench/{s}.py's docstring", docstring(s)) for s in SCRIPTS]
    texts += [(name, (ROOT / name).read_text()) for name in DOCUMENTS if (ROOT / name).is_file()]
    for where, text in texts:
        for script, rest in COMMAND.findall(text):
            # a comment after the command describes it; its words are not options
            for option in OPTION.findall(rest.split("#")[0]):
                found.setdefault(script, {}).setdefault(option, where)
    return found


@pytest.fixture(scope="module")
def helps(tmp_path_factory) -> dict:
    """script -> (exit status, output) of ``python bench/<script>.py --help``, run from a
    directory outside the repository, two at a time (the imports take seconds)."""
    cwd = tmp_path_factory.mktemp("elsewhere")
    env = dict(os.environ, MPLBACKEND="Agg")

    def run(script):
        proc = subprocess.run([sys.executable, str(BENCH / f"{script}.py"), "--help"],
                              capture_output=True, text=True, cwd=cwd, env=env, timeout=120)
        return script, (proc.returncode, proc.stdout + proc.stderr)
    with ThreadPoolExecutor(2) as pool:
        return dict(pool.map(run, SCRIPTS))


def test_there_are_scripts_to_check():
    assert "codegen_scaling" in SCRIPTS and len(SCRIPTS) >= 10


@pytest.mark.parametrize("script", SCRIPTS)
def test_help_exits_0_from_another_directory(helps, script):
    status, output = helps[script]
    assert status == 0, f"bench/{script}.py --help exited {status}:\n{output[-2000:]}"
    assert output.startswith("usage:"), output[:500]


@pytest.mark.parametrize("script", SCRIPTS)
def test_docstring_says_how_to_run_it(script):
    text = docstring(script)
    assert text, f"bench/{script}.py has no docstring"
    assert f"bench/{script}.py" in text, f"bench/{script}.py's docstring shows no command"


@pytest.mark.parametrize("script", SCRIPTS)
def test_every_documented_option_exists(helps, script):
    status, output = helps[script]
    assert status == 0
    listed = set(OPTION.findall(output))
    missing = {option: where for option, where in documented_options().get(script, {}).items()
               if option not in listed}
    assert not missing, (f"bench/{script}.py has no option " + ", ".join(
        f"{option} (written in {where})" for option, where in sorted(missing.items())))


def test_the_documented_commands_name_existing_scripts():
    unknown = sorted(set(documented_options()) - set(SCRIPTS))
    assert not unknown, f"the docs run scripts that are not in bench/: {unknown}"


def test_the_option_reader_reads_commands():
    text = ("    .venv/bin/python bench/derivatives.py --n 7 --quick   # n = 7 only, --x\n"
            "`modelgen/bench/hard_cases.py --nope` and `bench/trig.py -o out --rounds 9`")
    got = {(s, o) for s, rest in COMMAND.findall(text)
           for o in OPTION.findall(rest.split("#")[0])}
    assert got == {("derivatives", "--n"), ("derivatives", "--quick"), ("trig", "-o"),
                   ("trig", "--rounds")}
