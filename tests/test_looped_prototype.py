"""bench/looped_derivatives.py's hand-written looped prototype computes the W of
the generated straight line of the 20-link chain (its driver's 10 states, 5 of
them with random masses and lengths), in both forms the bench times: the
prototype's figures stand for a loop that gives the same numbers."""
from __future__ import annotations

import importlib.util
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")


def _bench():
    spec = importlib.util.spec_from_file_location("looped_derivatives",
                                                  ROOT / "bench" / "looped_derivatives.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_looped_prototype_gives_the_straight_lines_vectors(tmp_path):
    bench = _bench()
    _, command, wrap_o, _ = bench.build(20, tmp_path, rounds=1)
    for defines in bench.VARIANTS.values():
        exe, _ = bench.driver(20, tmp_path, command, wrap_o, defines, rounds=1)
        assert bench.agreement(exe) <= 1e-12
