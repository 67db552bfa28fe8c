"""Property-based fuzzing of expressions through the model loader.

Expression texts (grammar-shaped, random characters, deep nesting, huge
numbers, Unicode) are put into a small pendulum model and given to
:func:`modelgen.model.parse_model`.  Properties:

* only :class:`ModelgenError` subclasses escape;
* every :class:`ModelError` names the file and the line of the key;
* every case finishes within :data:`BUDGET` seconds;
* a model that validates either compiles or is refused with a ModelError
  before the compiler runs (a small sample: compiling is slow).

The generators are :mod:`modelgen.bench.fuzz_cases`.  The run is bounded and
reproducible (``derandomize=True``); ``bench/fuzz.py`` runs the same generators
for thousands of cases and prints a table.
"""
from __future__ import annotations

import time

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import modelgen
from modelgen.bench.fuzz_cases import (SLOTS, expressions, grammar_expressions, model_text,
                                       yaml_numbers)
from modelgen.errors import BuildError, ModelError, ModelgenError
from modelgen.model import parse_model

#: Seconds one model may take to load (validation only).
BUDGET = 2.0

SOURCE = "fuzz.yaml"


def check_outcome(text: str):
    """Load one model text; return the spec or the ModelError, after the properties."""
    start = time.perf_counter()
    try:
        spec = parse_model(text, SOURCE)
    except ModelError as exc:
        result = exc
        assert exc.file == SOURCE, str(exc)
        assert exc.line is not None, str(exc)
    except ModelgenError as exc:
        result = exc
    elapsed = time.perf_counter() - start
    assert elapsed < BUDGET, f"{elapsed:.2f} s"
    return result if "result" in locals() else spec


# -- properties ----------------------------------------------------------------------

FUZZ = settings(max_examples=300, deadline=None, derandomize=True, database=None,
                suppress_health_check=list(HealthCheck))


@FUZZ
@given(slot=st.sampled_from(sorted(SLOTS)), expression=expressions())
def test_any_expression_text_gives_a_spec_or_a_located_model_error(slot, expression):
    check_outcome(model_text(slot, expression))


@settings(FUZZ, max_examples=100)
@given(slot=st.sampled_from(sorted(SLOTS)), value=yaml_numbers())
def test_any_yaml_number_gives_a_spec_or_a_located_model_error(slot, value):
    check_outcome(model_text(slot, value))


@pytest.mark.parametrize("slot, text", [
    ("angle", "(q/100)**(10**8)"), ("angle", "tanh(tan(sinh(1e99)))"),
    ("angle", "acos(cos(cosh(1.7976931348623157e308)))"), ("angle", "(2*q)**(10**9)"),
    ("angle", "sin(" * 199 + "q" + ")" * 199), ("angle", "sin(" * 120 + "q" + ")" * 120),
    ("angle", "q*\u00b2"), ("angle", "q + \u0661"), ("angle", "acos(cos(10**300))"),
    ("y", "(-1)**(1/3)"), ("y", "acos(2) + L"), ("y", "asin(2)*L"), ("mass", "log(0)*m"),
])
def test_pathological_texts_are_refused_within_the_budget(slot, text):
    outcome = check_outcome(model_text(slot, text))
    assert isinstance(outcome, ModelError)
    assert outcome.line == SLOTS[slot]


@pytest.mark.parametrize("slot, text", [("mass", "1e100*m"), ("mass", "1e-100*m"),
                                        ("mass", "2**333*m"), ("mass", 10**300),
                                        ("y", 1e-320)])
def test_numbers_within_the_documented_range_load(slot, text):
    assert not isinstance(check_outcome(model_text(slot, text)), ModelgenError)


@settings(FUZZ, max_examples=4)
@given(slot=st.sampled_from(["angle", "y"]), expression=grammar_expressions(max_leaves=5))
def test_a_model_that_validates_compiles_or_is_refused_before_the_compiler(
        tmp_path_factory, slot, expression):
    outcome = check_outcome(model_text(slot, expression))
    if isinstance(outcome, ModelgenError):
        return
    try:
        modelgen.load(outcome, tmp_path_factory.mktemp("fuzz"))
    except BuildError as exc:   # the C compiler must never be the one to refuse
        pytest.fail(f"{expression!r} validated but did not compile: {exc}")
    except ModelgenError:       # e.g. refused before the compiler, or a singular A after it
        pass
