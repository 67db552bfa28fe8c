"""A small, seeded run of the MJCF fuzz (``bench/fuzz.py --mjcf`` runs tens of thousands).

MJCF files mutated by :mod:`modelgen.bench.fuzz_mjcf` (numbers, joint types,
structure, equality constraints, names, XML) are imported from a file; properties:

* only :class:`ModelgenError` subclasses escape, and every ModelError names the
  file and a line (MuJoCo's, when its compiler refuses the file) or a key (an
  element of the compiled model), an empty file alone having neither;
* every case finishes within :data:`BUDGET` seconds;
* an accepted file has MuJoCo's numbers of coordinates and speeds and its
  total moving mass (:func:`check_accepted`).

The check itself is tested first: it must find a wrong count or mass.
"""
from __future__ import annotations

import random
import time

import pytest

mujoco = pytest.importorskip("mujoco", reason="MJCF import needs the mujoco package")

from modelgen.bench.fuzz_mjcf import TINY, base_texts, check_accepted, mutate  # noqa: E402
from modelgen.errors import ModelError, ModelgenError  # noqa: E402
from modelgen.model.mjcf import import_mjcf, import_mjcf_text  # noqa: E402

BUDGET = 10.0          # seconds per case, generous on a loaded machine
CASES = 200


@pytest.fixture(autouse=True)
def _mujoco_log_outside_the_checkout(tmp_path, monkeypatch):
    """MuJoCo writes its warnings (a NaN in a file...) to ./MUJOCO_LOG.TXT."""
    monkeypatch.chdir(tmp_path)


def test_the_check_finds_a_wrong_count_and_a_wrong_mass():
    imported = import_mjcf_text(TINY, "tiny.xml")
    assert check_accepted(imported, mujoco.MjModel.from_xml_string(TINY)) == []
    heavier = TINY.replace('mass="0.7"', 'mass="0.7000001"')
    assert any("mass" in p for p in check_accepted(imported,
                                                   mujoco.MjModel.from_xml_string(heavier)))
    welded = TINY.replace('<joint name="slider" type="slide" axis="0 0 1" '
                          'frictionloss="0.05"/>', "")
    problems = check_accepted(imported, mujoco.MjModel.from_xml_string(welded))
    assert any("coordinates" in p for p in problems) and any("speeds" in p for p in problems)


def test_seeded_mutations_are_imported_or_refused_saying_where(tmp_path):
    texts = base_texts()
    rng = random.Random(20261128)
    path = tmp_path / "fuzz.xml"
    outcomes = {"accepted": 0, "refused": 0}
    for k in range(CASES):
        name, text = rng.choice(texts)
        data, what = mutate(text, rng)
        path.write_bytes(data.encode() if isinstance(data, str) else data)
        start = time.perf_counter()
        try:
            imported = import_mjcf(path)
        except ModelError as exc:
            assert exc.file == str(path), f"case {k} ({name}: {what}): {exc}"
            assert exc.line or exc.key or not data.strip(), f"case {k} ({name}: {what}): {exc}"
            outcomes["refused"] += 1
        except ModelgenError:
            outcomes["refused"] += 1
        else:
            problems = check_accepted(imported, mujoco.MjModel.from_xml_path(str(path)))
            assert problems == [], f"case {k} ({name}: {what})"
            outcomes["accepted"] += 1
        assert time.perf_counter() - start < BUDGET, f"case {k} ({name}: {what})"
    # the mutations neither break everything nor nothing
    assert outcomes["accepted"] > CASES // 10 and outcomes["refused"] > CASES // 10, outcomes
