"""Fuzzing the runtime's arguments: whatever a caller passes, only modelgen's errors escape.

Hypothesis (derandomized, bounded) throws shapes, dtypes, NaN/Inf, complex
numbers, strings and odd spans at ``rhs``, the fast path, the model functions
and ``simulate``.  Every call either returns finite-shaped results or raises a
:class:`~modelgen.errors.ModelgenError`; nothing else escapes and nothing
crashes the process (a crash would take pytest down with it).
"""
from __future__ import annotations

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from modelgen.errors import ModelgenError  # noqa: E402

SETTINGS = settings(max_examples=150, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture,
                                           HealthCheck.too_slow])

scalars = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=64),
    st.integers(min_value=-10**30, max_value=10**30),
    st.complex_numbers(max_magnitude=1e3),
    st.just("abc"), st.just(None), st.booleans(),
)
arrays = st.one_of(
    scalars,
    st.lists(scalars, min_size=0, max_size=6),
    st.lists(st.lists(st.floats(width=64), min_size=0, max_size=4), max_size=3),
    st.builds(lambda n, v: np.full(n, v), st.integers(0, 6), st.floats(width=64)),
)


@pytest.fixture(scope="module")
def dp(compiled):
    return compiled("double_pendulum")


def _only_modelgen_errors(call):
    try:
        out = call()
    except ModelgenError:
        return None
    return out


@SETTINGS
@given(t=scalars, x=arrays, u=st.one_of(st.none(), arrays,
                                        st.dictionaries(st.sampled_from(["T1", "T9"]), scalars,
                                                        max_size=2)),
       p=st.one_of(st.none(), arrays, st.dictionaries(st.sampled_from(["g", "m1", "zz"]),
                                                      scalars, max_size=2)))
def test_model_functions_raise_only_modelgen_errors(dp, t, x, u, p):
    out = _only_modelgen_errors(lambda: dp.rhs(t, x, u=u, p=p))
    if out is not None:
        assert out.shape == (4,)
    _only_modelgen_errors(lambda: dp.mass_matrix(x, p))
    _only_modelgen_errors(lambda: dp.generalized_forces(t, x, x, u=u, p=p))
    _only_modelgen_errors(lambda: dp.rhs_function(u=u, p=p)(0.0, x))


@SETTINGS
@given(x0=arrays,
       span=st.one_of(st.tuples(scalars, scalars), st.just((0.0, 1.0)), st.just((1.0, 0.0)),
                      st.just((0.0, 1e300)), st.lists(scalars, max_size=3)),
       method=st.sampled_from(["dop853", "rk4", "gauss4", "rodas", "RK45", "", "dopri5"]),
       step=st.one_of(st.none(), st.floats(width=64), st.just(1e-19), st.just(0.1)),
       rtol=st.one_of(st.just(1e-6), st.floats(width=64), arrays),
       t_eval=st.one_of(st.none(), arrays, st.just([0.0, 0.5, 1.0])),
       max_steps=st.one_of(st.none(), st.integers(-5, 50)))
def test_simulate_raises_only_modelgen_errors_or_reports_a_status(dp, x0, span, method, step,
                                                                 rtol, t_eval, max_steps):
    res = _only_modelgen_errors(lambda: dp.simulate(x0, span, t_eval=t_eval, method=method,
                                                    step=step, rtol=rtol,
                                                    max_steps=max_steps))
    if res is not None:
        assert res.y.shape == (4, len(res.t)) and isinstance(res.message, str)
        assert res.success or res.message
