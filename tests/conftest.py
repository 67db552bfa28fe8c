"""Shared fixtures: one build directory per test session, models by name."""
from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
SCENES = MODELS / "scenes"


@pytest.fixture(scope="session")
def build_root(tmp_path_factory):
    """A session-wide directory for generated models (shared between tests)."""
    return tmp_path_factory.mktemp("generated")


@pytest.fixture(scope="session")
def compiled(build_root):
    """``compiled(name_or_spec)`` -> CompiledModel, built once per session."""
    import modelgen
    cache = {}

    def get(source):
        key = source if isinstance(source, str) else source.name
        if key not in cache:
            path = MODELS / f"{source}.yaml" if isinstance(source, str) else source
            cache[key] = modelgen.load(path, build_root / key)
        return cache[key]
    return get


#: lines that tests want shown after the run (e.g. the worst errors against references)
SUMMARY: list = []


def pytest_terminal_summary(terminalreporter):
    """Print what tests collected in SUMMARY once, after the progress dots."""
    if SUMMARY:
        terminalreporter.section("figures measured by the tests")
        for line in SUMMARY:
            terminalreporter.write_line(line)
