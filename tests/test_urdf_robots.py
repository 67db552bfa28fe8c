"""Every URDF of example-robot-data through modelgen, against Pinocchio (issue 23).

One test per robot and base (fixed; floating too for legged robots, humanoids and
flying robots): A, h - tau(q, 0) and q'' at 3 random states agree with
Pinocchio to 1e-10 relative, with the reading options the robot's refusal names
(``modelgen.bench.robots.OPTIONS``); without them it is refused, and the fix
names them.  Marked ``slow`` (about a hundred builds, minutes): ``-m "not slow"``
skips them.  Skipped with the reason when Pinocchio or example-robot-data is
missing.
"""
from __future__ import annotations

import warnings

import pytest

from modelgen.errors import ModelError
from modelgen.model.urdf import import_urdf

pin = pytest.importorskip("pinocchio", reason="the reference is Pinocchio "
                                               "(pip install -e '.[robots]')")
from modelgen.bench.robots import (FLOATING, NOT_LOADED, OPTIONS, compare,
                                   robot_files, robots_directory)
from conftest import SUMMARY

DIRECTORY = robots_directory()
FILES = robot_files(DIRECTORY) if DIRECTORY else []
TOL = 1e-10
CASES = [(f, floating) for f in FILES if f not in NOT_LOADED
         for floating in (False, True)
         if (floating and f.startswith(FLOATING)) or
         (not floating and not OPTIONS.get(f, {}).get("floating_base"))]

needs_robots = pytest.mark.skipif(DIRECTORY is None, reason="example-robot-data is not "
                                  "installed (pip install example-robot-data)")


@needs_robots
def test_the_collection_is_the_one_the_table_describes():
    assert len(FILES) == 69
    assert set(OPTIONS) | set(NOT_LOADED) <= set(FILES)
    assert sorted(NOT_LOADED) == ["ur_description/urdf/ur3.urdf"]     # not a robot: empty


@needs_robots
@pytest.mark.slow
@pytest.mark.parametrize("robot, floating", CASES,
                         ids=[f"{f.split('/')[-1][:-5]}-{'floating' if fl else 'fixed'}"
                              for f, fl in CASES])
def test_robot_matches_pinocchio(robot, floating, build_root):
    out = build_root / "robots" / f"{robot.replace('/', '_')}_{int(floating)}"
    result = compare(DIRECTORY, robot, out, floating=floating)
    SUMMARY.append(f"{robot} {'floating' if floating else 'fixed'}: n = {result.n}, "
                   f"{result.seconds:.1f} s, errors A, h, qdd = "
                   + ", ".join(f"{e:.1e}" for e in result.errors))
    assert max(result.errors) <= TOL, result.errors
    assert bool(result.warnings) == bool({"inertia", "min_mass", "mimic"}
                                         & set(result.options))


@needs_robots
@pytest.mark.parametrize("robot", sorted(OPTIONS))
def test_robots_needing_an_option_are_refused_by_default_with_a_fix_naming_it(robot):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ModelError) as err:
            import_urdf(DIRECTORY / robot)
    fix = err.value.fix
    for option in OPTIONS[robot]:
        if option == "inertia":
            assert f'inertia="{OPTIONS[robot]["inertia"]}"' in fix or \
                "min_mass" in fix, fix          # the first refusal names the first need
        else:
            assert option in fix or "inertia=" in fix, fix


@needs_robots
@pytest.mark.parametrize("robot", sorted(NOT_LOADED))
def test_files_pinocchio_cannot_read_either_are_refused(robot):
    with pytest.raises(ModelError) as err:
        import_urdf(DIRECTORY / robot)
    assert err.value.file == str(DIRECTORY / robot) and err.value.line and err.value.fix
    with pytest.raises(ValueError):
        pin.buildModelFromUrdf(str(DIRECTORY / robot), mimic=True)
