"""A small, seeded run of the URDF fuzz (``bench/fuzz.py --urdf`` runs tens of thousands).

Real URDFs mutated by :mod:`modelgen.bench.fuzz_urdf` (numbers, axes, structure,
names, XML attacks) are imported; properties:

* only :class:`ModelgenError` subclasses escape, and every ModelError names the
  file and a line;
* every case finishes within :data:`BUDGET` seconds;
* an accepted file's spec says what the file says, by an independent reading of
  the same XML (:func:`check_accepted`: axes, total mass, centre of mass and
  inertia of the moving links, with mpmath).

The check itself is tested first: it must find a wrong axis or inertia.
"""
from __future__ import annotations

import random
import time
import warnings
from pathlib import Path

from modelgen.bench.fuzz_urdf import TINY, check_accepted, mutate
from modelgen.errors import ModelError, ModelgenError
from modelgen.model.urdf import import_urdf_text

DATA = Path(__file__).parent / "data" / "urdf"
BUDGET = 10.0          # seconds per case, generous on a loaded machine
CASES = 300
SOURCE = "fuzz.urdf"


def _spec(text, **options):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return import_urdf_text(text, SOURCE, **options).model.spec()


def test_the_check_finds_a_wrong_axis_a_wrong_inertia_and_a_wrong_count():
    spec = _spec(TINY)
    assert check_accepted(spec, TINY) == []
    tilted = TINY.replace('<axis xyz="0.2 -0.5 0.8"/>', '<axis xyz="0.2 -0.5 0.81"/>')
    assert any("axis" in p for p in check_accepted(spec, tilted))
    heavier = TINY.replace('<mass value="1"/>', '<mass value="1.000001"/>')
    assert any("total mass" in p for p in check_accepted(spec, heavier))
    turned = TINY.replace('rpy="0.3 0.2 0.1"', 'rpy="0.3 0.2 0.1000001"')
    assert any("inertia" in p for p in check_accepted(spec, turned))
    fixed = TINY.replace('type="prismatic"', 'type="fixed"')
    assert any("coordinates" in p for p in check_accepted(spec, fixed))
    nan = TINY.replace('<mass value="1"/>', '<mass value="nan"/>')
    assert any("non-finite" in p for p in check_accepted(spec, nan))


def test_the_check_agrees_with_every_robot_of_the_test_data():
    for path in sorted(DATA.glob("*.urdf")):
        text = path.read_text()
        assert check_accepted(_spec(text), text) == [], path.name
        assert check_accepted(_spec(text, floating_base=True), text, True) == [], path.name


def test_seeded_mutations_are_accepted_as_written_or_refused_with_a_line():
    texts = [TINY] + [(DATA / f).read_text() for f in ("double_pendulum.urdf",
                                                       "ur5_robot.urdf")]
    rng = random.Random(20261126)
    outcomes = {"accepted": 0, "refused": 0}
    for k in range(CASES):
        data, what = mutate(rng.choice(texts), rng)
        floating = rng.random() < 0.2
        start = time.perf_counter()
        try:
            spec = _spec(data, floating_base=floating)
        except ModelError as exc:
            assert exc.file == SOURCE and exc.line, f"case {k} ({what}): {exc}"
            outcomes["refused"] += 1
        except ModelgenError:
            outcomes["refused"] += 1
        else:
            assert check_accepted(spec, data, floating) == [], f"case {k} ({what})"
            outcomes["accepted"] += 1
        assert time.perf_counter() - start < BUDGET, f"case {k} ({what})"
    # the mutations neither break everything nor nothing
    assert outcomes["accepted"] > CASES // 10 and outcomes["refused"] > CASES // 10, outcomes
