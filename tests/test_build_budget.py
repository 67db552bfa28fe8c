"""Build cost is bounded before the compiler runs (modelgen.codegen.budget).

A model over the budget is refused with its figure and the three ways to raise
the budget: up front from its size (a 300-link chain, in seconds, where it
used to run for more than ten minutes), or after CSE from the exact count,
which is checked here against the operators and ``mg_sin``/``mg_cos`` calls in
the C of the same model built within the budget.
"""
from __future__ import annotations

import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from modelgen.codegen import budget
from modelgen.codegen.pipeline import generate
from modelgen.errors import ModelError
from modelgen.model import load_model
from modelgen.model.chains import spatial_chain

ROOT = Path(__file__).resolve().parent.parent
HOW_TO_RAISE = ("max_operations=", "$MODELGEN_MAX_OPERATIONS=", "--max-operations")


def _long_sum_model(tmp_path: Path, terms: int) -> Path:
    """A one-coordinate pendulum whose bob's x is a long sum of sin and cos."""
    expr = " + ".join(f"0.0{k % 9 + 1}*sin({k}*q)*cos(q)" for k in range(1, terms + 1))
    path = tmp_path / "long_sum.yaml"
    path.write_text(f"""name: long_sum
coordinates: [q]
parameters: {{L: 1.0, m: 1.0, g: 9.81}}
bases:
  B1: {{parent: E, axis: 3, angle: q}}
points:
  P: {{from: O, base: B1, coordinates: [{expr}, -L, 0]}}
bodies:
  bob: {{mass: m, G: P, base: B1}}
gravity: [0, -g, 0]
""")
    return path


@pytest.fixture(autouse=True)
def _no_budget_from_the_environment(monkeypatch):
    monkeypatch.delenv(budget.ENV, raising=False)


def test_a_300_link_chain_is_refused_up_front_with_its_estimate(tmp_path):
    spec = spatial_chain(300).spec()
    start = time.perf_counter()
    with pytest.raises(ModelError) as info:
        generate(spec, tmp_path / "out")
    elapsed = time.perf_counter() - start
    message = str(info.value)
    assert elapsed < 30, elapsed           # it ran for more than 600 s before
    # the mass matrix of a chain has n(n+1)/2 nonzero entries below its diagonal
    estimate = budget.PER_MASS_ENTRY * 300 * 301 // 2 + budget.PER_COORDINATE * 300
    assert f"{estimate:,}" in message and f"{budget.MAX_OPERATIONS:,}" in message
    assert all(how in message for how in HOW_TO_RAISE), message
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("n", [1, 3, 12])
def test_the_estimate_before_deriving_is_below_the_cost_after_cse(n):
    """The estimate must not refuse what the exact count would admit."""
    from modelgen.codegen.options import BuildOptions
    from modelgen.codegen.pipeline import _derive, _eliminate, choose_formulation
    spec = spatial_chain(n).spec()
    formulation, tree = choose_formulation(spec)
    derived = _derive(spec, BuildOptions(formulation=formulation), tree)
    cost = budget.build_cost(_eliminate(derived))
    assert budget.estimated_operations(spec.n, tree) <= cost.weighted


def test_the_cost_after_cse_is_what_the_c_holds_and_refused_past_the_budget(tmp_path):
    model = load_model(_long_sum_model(tmp_path, 12))
    g = generate(model, tmp_path / "ok")
    c_text = (tmp_path / "ok" / "long_sum.c").read_text()
    body = c_text[c_text.index("/* ---- end mg_sin, mg_cos ---- */"):]
    calls = len(re.findall(r"\bmg_(?:sin|cos)\(", body))
    operations = sum(o["after_cse"] for o in g.ops.values())
    figure = operations + (budget.TRIG_OPERATIONS - 1) * calls
    assert calls > 12
    with pytest.raises(ModelError) as info:
        generate(model, tmp_path / "refused", force=True, max_operations=figure - 1)
    message = str(info.value)
    assert f"{figure:,} operations after CSE" in message, message
    assert f"{calls:,} calls of sin or cos" in message and f"{figure - 1:,}" in message
    assert all(how in message for how in HOW_TO_RAISE), message
    assert not list((tmp_path / "refused").glob("*.c"))          # nothing was emitted
    again = generate(model, tmp_path / "exact", force=True, max_operations=figure)
    assert sum(o["after_cse"] for o in again.ops.values()) == operations


def test_the_budget_comes_from_the_environment_and_is_checked(tmp_path, monkeypatch):
    monkeypatch.setenv(budget.ENV, "1_000")
    assert budget.max_operations() == 1000
    assert budget.max_operations(5) == 5            # the keyword wins
    with pytest.raises(ModelError, match=r"\$MODELGEN_MAX_OPERATIONS"):
        generate(spatial_chain(3).spec(), tmp_path / "out", force=True)
    monkeypatch.setenv(budget.ENV, "lots")
    with pytest.raises(ModelError, match="must be a positive integer"):
        budget.max_operations()
    for bad in (0, -5, 2.5, True):
        with pytest.raises(ModelError, match="max_operations must be a positive integer"):
            budget.max_operations(bad)


def test_a_cached_build_is_reused_whatever_the_budget(tmp_path):
    spec = spatial_chain(3).spec()
    generate(spec, tmp_path / "out")
    again = generate(spec, tmp_path / "out", max_operations=1)
    assert again.build.cached


def test_the_stage_times_add_up_to_the_whole_call(tmp_path):
    model = load_model(ROOT / "models" / "double_pendulum.yaml")
    start = time.perf_counter()
    g = generate(model, tmp_path / "out", force=True)
    wall = time.perf_counter() - start
    assert list(g.seconds) == ["check", "derive", "cse", "emit", "compile"]
    # a stage left out would miss a tenth of a second or more; a loaded machine's
    # scheduling between the stages moves the sum by a few hundredths
    assert sum(g.seconds.values()) == pytest.approx(wall, rel=0.05, abs=0.05)


@pytest.mark.parametrize("command", [["generate"], ["simulate", "--t-end", "0.01"]])
def test_the_command_line_flag_refuses_with_exit_2_and_names_itself(tmp_path, command):
    r = subprocess.run([sys.executable, "-m", "modelgen", *command,
                        str(ROOT / "models" / "double_pendulum.yaml"), "--max-operations", "50",
                        "--force" if command == ["generate"] else "--no-plot",
                        "-o", str(tmp_path / "out"),
                        *(["--build-dir", str(tmp_path / "build")] if command[0] == "simulate"
                          else [])],
                       cwd=ROOT, capture_output=True, text=True, timeout=300, check=False)
    assert r.returncode == 2, r.stdout + r.stderr
    assert "over the budget of 50" in r.stderr and "--max-operations" in r.stderr, r.stderr


def test_a_pendulum_of_2002_parameters_builds_without_polynomial_algebra(tmp_path,
                                                                        monkeypatch):
    """Issue 24: 2,002 parameters took 224 s to build.  The bob's centre h/m was
    put through sympy.cancel, which turned the sums of 1,000 parameters into
    polynomials in all of them, once per algorithm; a quotient that is already a
    sum of monomials is kept as it is.  The stage times still add up, and the
    model is the pendulum of the closed form."""
    import numpy as np
    import sympy

    import modelgen
    n = 2002
    first = "+".join(f"p{i}" for i in range(1000))
    second = "+".join(f"p{i}" for i in range(1000, n))
    path = tmp_path / "many_params.yaml"
    path.write_text(f"""name: many_params
coordinates: [q]
parameters: {{m: 1.0, g: 9.81, {", ".join(f"p{i}: 0.001" for i in range(n))}}}
bases:
  B1: {{parent: E, axis: 3, angle: q}}
points:
  P: {{from: O, base: B1, coordinates: ["{first}", "-({second})", 0]}}
bodies:
  bob: {{mass: m, G: P, base: B1}}
gravity: [0, -g, 0]
""")
    cancelled = []
    real_cancel = sympy.cancel

    def cancel(expr, *args, **kwargs):
        cancelled.append(expr)
        return real_cancel(expr, *args, **kwargs)
    monkeypatch.setattr(sympy, "cancel", cancel)
    model = load_model(path)
    start = time.perf_counter()
    g = generate(model, tmp_path / "out", force=True)
    wall = time.perf_counter() - start
    assert not [e for e in cancelled if len(e.free_symbols) > 100], len(cancelled)
    assert sum(g.seconds.values()) == pytest.approx(wall, rel=0.1)
    monkeypatch.setattr(sympy, "cancel", real_cancel)
    cm = modelgen.load(path, tmp_path / "out")
    # the bob at (a, -b) in the rod's frame: (a^2 + b^2) q'' = -g (a cos q + b sin q)
    a, b, q = 1000 * 0.001, 1002 * 0.001, 0.3
    expected = -9.81 * (a * np.cos(q) + b * np.sin(q)) / (a * a + b * b)
    assert cm.rhs(0.0, [q, 0.0])[1] == pytest.approx(expected, rel=1e-12)
