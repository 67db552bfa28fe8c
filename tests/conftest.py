"""Shared fixtures: one build directory per test session, models by name."""
from __future__ import annotations

import os
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


#: Tests left out of the everyday ``make test`` (``-m 'not slow'``) besides those
#: decorated ``@pytest.mark.slow``: each builds large models or runs a symbolic
#: reference for a minute or more, and a faster test covers the same code
#: (``make test-all`` and CI run them).  Node id prefixes.
SLOW = (
    # KanesMethod's closed form of the 7-joint arm and the 5- and 6-link chains
    # (the smaller chains and every other model stay in)
    "tests/test_against_mechanics.py::test_mass_matrix_matches_kanes_method[arm7]",
    "tests/test_against_mechanics.py::test_mass_matrix_matches_kanes_method[spatial_chain_5]",
    "tests/test_against_mechanics.py::test_mass_matrix_matches_kanes_method[spatial_chain_6]",
    # every shipped model's output directory through gcc and g++ -pedantic (the
    # golden model's compile is checked by the fast tests)
    "tests/test_generated_c.py::test_generated_c_compiles_warning_free_as_c99_and_cxx",
    # chains up to 40 links to fit a line through the operation counts
    "tests/test_inverse_dynamics.py::test_inverse_dynamics_of_a_chain_costs_linear_operations",
    # solo12 (18 speeds) built with crba twice
    "tests/test_sparse_solve.py::test_solo12_crba_rhs_agrees_with_aba_through_the_sparse_solve",
    "tests/test_inverse_dynamics.py::test_inverse_dynamics_is_a_qdd_plus_h_minus_tau_and_zero_at_the_rhs[robots/solo12",
)


#: The whole-collection cross-checks: every robot of example-robot-data against
#: Pinocchio and every model of MuJoCo's suites against MuJoCo, over a hundred
#: builds (``bench/urdf_robots.py`` and the docs' tables run them all).  Unless
#: ``MODELGEN_COLLECTION=all`` (``make test-collections``), every
#: :data:`COLLECTION_STRIDE`-th case runs, so every run still checks robots of
#: each kind without making the suite an hour long.
COLLECTION = ("tests/test_urdf_robots.py::test_robot_matches_pinocchio",
              "tests/test_mjcf.py::test_suite_model_matches_mujoco")
COLLECTION_STRIDE = 4


def pytest_collection_modifyitems(config, items):
    slow = pytest.mark.slow
    every = os.environ.get("MODELGEN_COLLECTION", "") == "all"
    seen: dict = {}
    kept, dropped = [], []
    for item in items:
        if item.nodeid.startswith(SLOW):
            item.add_marker(slow)
        prefix = next((c for c in COLLECTION if item.nodeid.startswith(c)), None)
        if prefix is not None and not every:
            k = seen[prefix] = seen.get(prefix, -1) + 1
            if k % COLLECTION_STRIDE:
                dropped.append(item)
                continue
        kept.append(item)
    if dropped:
        config.hook.pytest_deselected(items=dropped)
        items[:] = kept
        SUMMARY.append(f"collections: {len(dropped)} of the robots' and suites' cases left "
                       f"out (every {COLLECTION_STRIDE}th runs); MODELGEN_COLLECTION=all "
                       "(make test-collections) runs them all")
