"""The Python API checks its arguments where they enter, as scipy's solve_ivp does.

Each case is a misuse from issue 24 (item 8) that used to run silently, wrongly,
or end in a raw exception; the references are the same call written the
documented way (bit for bit), the pendulum's closed form and scipy's solve_ivp.
"""
from __future__ import annotations

import re
import threading
import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.integrate

from modelgen.codegen import capi
from modelgen.errors import ArgumentTypeError, ArgumentValueError, SimulationError
from modelgen.sim import integrate
from modelgen.sim.result import Result

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "models" / "scenes"
INPUT_ERROR = capi.STATUS_BY_NAME["INPUT_ERROR"].code


@pytest.fixture(scope="module")
def sp(compiled):
    return compiled("simple_pendulum")


@pytest.fixture(scope="module")
def cp(compiled):
    """The cart-pole: one input, F."""
    return compiled("cart_pole")


def _event(terminal=None, direction=None):
    def q_zero(t, x):
        return x[0]
    if terminal is not None:
        q_zero.terminal = terminal
    if direction is not None:
        q_zero.direction = direction
    return q_zero


# -- events ----------------------------------------------------------------------------

@pytest.mark.parametrize("terminal, error", [
    ("yes", ArgumentTypeError), ([1], ArgumentTypeError), (-1, ArgumentValueError),
    (2.5, ArgumentValueError), (float("nan"), ArgumentValueError)])
def test_an_event_terminal_that_is_no_bool_or_count_names_the_event(sp, terminal, error):
    with pytest.raises(error, match=r"event 0 \(q_zero\): terminal must be a bool or a "
                                    r"positive int count") as info:
        sp.simulate([1.0, 0.0], (0, 3), events=_event(terminal=terminal))
    # caught as scipy's users catch it, and as modelgen's
    assert isinstance(info.value, (TypeError if error is ArgumentTypeError else ValueError))
    assert isinstance(info.value, SimulationError)


def test_a_whole_float_terminal_counts_like_the_int(sp):
    """solve_ivp accepts an integral terminal (since scipy 1.11): 2.0 stops at the
    second zero, as 2 does; False and 0 never stop."""
    two = sp.simulate([1.0, 0.0], (0, 5), events=_event(terminal=2))
    two_f = sp.simulate([1.0, 0.0], (0, 5), events=_event(terminal=2.0))
    never = sp.simulate([1.0, 0.0], (0, 5), events=_event(terminal=0))
    assert two.status == 1 and len(two.t_events[0]) == 2
    assert np.array_equal(two.y, two_f.y)
    assert never.status == 0 and len(never.t_events[0]) > 2


@pytest.mark.parametrize("events", [42, "q_zero", 1.5, {"e": 1}])
def test_events_that_are_not_callables_raise_a_type_error(sp, events):
    with pytest.raises(TypeError, match="events must be a callable g\\(t, x\\) or a "
                                        "sequence of callables"):
        sp.simulate([1.0, 0.0], (0, 1), events=events)


def test_a_non_callable_in_the_event_list_is_named_by_its_index(sp):
    with pytest.raises(ArgumentTypeError, match=r"events\[1\] is 42"):
        sp.simulate([1.0, 0.0], (0, 1), events=[_event(), 42])


def test_event_direction_uses_the_sign_as_solve_ivp_does(sp):
    """direction = 5 selects the rising zeros, like 1 and like solve_ivp's (which uses
    the sign); the pendulum from q = 1 at rest has q rising through 0 at 3/4 of a period."""
    five = sp.simulate([1.0, 0.0], (0, 5), events=_event(direction=5))
    one = sp.simulate([1.0, 0.0], (0, 5), events=_event(direction=1))
    ref = scipy.integrate.solve_ivp(sp.rhs, (0, 5), [1.0, 0.0], method="DOP853", rtol=1e-12,
                                    atol=1e-12, events=_event(direction=5))
    assert np.array_equal(five.t_events[0], one.t_events[0])
    assert len(five.t_events[0]) == len(ref.t_events[0]) >= 2
    assert np.allclose(five.t_events[0], ref.t_events[0], atol=1e-7)
    assert np.all(five.y_events[0][:, 1] > 0)          # rising: q_dot > 0


@pytest.mark.parametrize("direction, error", [
    ("up", ArgumentTypeError), (1j, ArgumentTypeError), (True, ArgumentTypeError),
    (float("nan"), ArgumentValueError)])
def test_an_event_direction_that_is_no_real_number_names_the_event(sp, direction, error):
    with pytest.raises(error, match=r"event 0 \(q_zero\): direction must be a real number"):
        sp.simulate([1.0, 0.0], (0, 1), events=_event(direction=direction))


# -- tolerances --------------------------------------------------------------------------

def test_tolerances_too_small_are_raised_with_a_warning_and_the_run_succeeds(sp):
    """rtol = atol = 1e-300 used to end at once with status -4 "NaN or Inf in the
    state" and a finite state (the error norm overflowed).  Now both are raised to
    the floors, with a warning, and the run is the run at the floors."""
    with pytest.warns(RuntimeWarning) as caught:
        tiny = sp.simulate([1.0, 0.0], (0, 2), rtol=1e-300, atol=1e-300)
    text = " ".join(str(w.message) for w in caught)
    assert "rtol below" in text and "atol below" in text
    assert tiny.success, tiny.message
    floors = sp.simulate([1.0, 0.0], (0, 2), rtol=integrate.MIN_RTOL, atol=integrate.MIN_ATOL)
    assert np.array_equal(tiny.y, floors.y)
    # and it is as accurate as double precision allows: the closed form (Jacobi sn, cn)
    from scipy.special import ellipj, ellipk
    k, w = np.sin(0.5), np.sqrt(9.81)
    sn, cn, _, _ = ellipj(ellipk(k * k) - w * 2.0, k * k)
    exact = [2 * np.arcsin(k * sn), -2 * k * w * cn]
    assert np.max(np.abs(tiny.y[:, -1] - exact)) < 1e-12


@pytest.mark.parametrize("method", ["dopri5", "dop853", "rodas"])
def test_atol_zero_from_rest_is_not_reported_as_a_non_finite_state(sp, method):
    """At rest at the bottom every state component stays exactly 0: with atol = 0 the
    error ratios were 0 / 0 (status -4).  The state stays at rest."""
    with pytest.warns(RuntimeWarning, match="atol below"):
        res = sp.simulate([0.0, 0.0], (0, 1), method=method, rtol=1e-8, atol=0.0)
    assert res.success, res.message
    assert np.array_equal(res.y[:, -1], [0.0, 0.0])


def test_fixed_steps_ignore_the_tolerances_and_do_not_warn(sp, recwarn):
    sp.simulate([1.0, 0.0], (0, 1), method="rk4", step=1e-2, rtol=0.0, atol=1e-300)
    assert not [w for w in recwarn if "below" in str(w.message)]


# -- max_steps -----------------------------------------------------------------------------

def test_max_steps_must_be_a_whole_number(sp):
    with pytest.raises(ArgumentValueError, match="max_steps must be a whole number, got 2.5"):
        sp.simulate([1.0, 0.0], (0, 1), max_steps=2.5)
    with pytest.raises(ArgumentTypeError, match="max_steps must be an integer"):
        sp.simulate([1.0, 0.0], (0, 1), max_steps="100")
    with pytest.raises(ArgumentTypeError, match="max_steps must be an integer"):
        sp.simulate([1.0, 0.0], (0, 1), max_steps=True)
    with pytest.raises(ArgumentValueError, match="max_steps must be a whole number"):
        sp.simulate_batch([[1.0, 0.0]], (0, 1), max_steps=2.5)
    # 1e3 is a whole number: the same run as 1000, which it stops
    with pytest.warns(RuntimeWarning, match=r"Maximum number of steps \(10\)"):
        a = sp.simulate([1.0, 0.0], (0, 1), max_steps=10.0)
    with pytest.warns(RuntimeWarning):
        b = sp.simulate([1.0, 0.0], (0, 1), max_steps=np.int64(10))
    assert a.naccept + a.nreject == 10 and np.array_equal(a.y, b.y)


# -- out= ------------------------------------------------------------------------------------

@pytest.mark.parametrize("out, error", [
    (np.zeros(2, dtype=int), ArgumentTypeError), (np.zeros(2, dtype=np.float32),
                                                   ArgumentTypeError),
    ([0.0, 0.0], ArgumentTypeError), (np.zeros(3), ArgumentValueError),
    (np.zeros((2, 1)), ArgumentValueError)])
def test_rhs_function_refuses_an_out_array_it_would_round_or_broadcast_into(sp, out, error):
    f = sp.rhs_function()
    before = np.array(out, copy=True)
    with pytest.raises(error, match="out must"):
        f(0.0, np.array([1.0, 0.5]), out)
    assert np.array_equal(np.asarray(out), before)       # nothing written


def test_rhs_function_refuses_a_read_only_out_and_writes_a_strided_one(sp):
    f = sp.rhs_function()
    x = np.array([1.0, 0.5])
    frozen = np.zeros(2)
    frozen.flags.writeable = False
    with pytest.raises(ArgumentValueError, match="out is read-only"):
        f(0.0, x, frozen)
    wide = np.zeros(4)
    assert f(0.0, x, wide[::2]) is not None
    assert np.array_equal(wide[::2], sp.rhs(0.0, x)) and np.all(wide[1::2] == 0)


# -- inputs -----------------------------------------------------------------------------------

def test_a_one_input_model_takes_a_plain_number_as_u(cp):
    x0 = [0.0, 0.1, 0.0, 0.0]
    listed = cp.simulate(x0, (0, 1), u=[0.5])
    assert np.array_equal(cp.simulate(x0, (0, 1), u=0.5).y, listed.y)
    assert np.array_equal(cp.simulate(x0, (0, 1), u=np.float64(0.5)).y, listed.y)
    assert np.array_equal(cp.simulate(x0, (0, 1), u=lambda t, x: 0.5).y, listed.y)
    assert np.array_equal(cp.rhs(0.0, x0, u=0.5), cp.rhs(0.0, x0, u=[0.5]))


def test_a_plain_number_is_no_input_vector_for_other_models(sp, compiled):
    with pytest.raises(SimulationError, match=r"u must have shape \(0,\)"):
        sp.simulate([1.0, 0.0], (0, 1), u=0.5)


def test_a_feedback_u_returning_none_is_an_error_not_zero_force(cp):
    with pytest.raises(ArgumentTypeError, match=r"returned None at t=0.0; it must return "
                                                r"the inputs \(F\)") as info:
        cp.simulate([0.0, 0.1, 0.0, 0.0], (0, 1), u=lambda t, x: None)
    assert info.value.partial_result.status == INPUT_ERROR


def test_a_raising_feedback_u_re_raises_with_the_run_so_far(cp):
    """A typo in u(t, x) used to return a one-sample result with status -9 and no
    exception; solve_ivp would raise.  The run up to it rides on the exception."""
    def typo(t, x):
        if t > 0.5:
            return -2.0 * speed      # noqa: F821  (the typo under test)
        return [-2.0 * x[2]]
    with pytest.raises(NameError, match="speed") as info:
        cp.simulate([0.0, 0.1, 0.0, 0.0], (0, 2), u=typo)
    partial = info.value.partial_result
    assert isinstance(partial, Result) and partial.status == INPUT_ERROR
    assert partial.t[0] == 0.0 and 0.3 < partial.t[-1] <= 0.55
    if hasattr(info.value, "add_note"):          # Python 3.11+
        assert any(".partial_result" in note for note in info.value.__notes__)
    # what it computed before the typo is the run with the same feedback that has none
    good = cp.simulate([0.0, 0.1, 0.0, 0.0], (0, 2), t_eval=partial.t,
                       u=lambda t, x: [-2.0 * x[2]])
    assert np.allclose(partial.y, good.y[:, :partial.y.shape[1]], atol=1e-8)


def test_a_raising_feedback_u_in_a_batch_re_raises(cp):
    def broken(t, x):
        raise RuntimeError("controller offline")
    with pytest.raises(RuntimeError, match="controller offline") as info:
        cp.simulate_batch(np.zeros((2, 4)), (0, 1), u=broken)
    assert info.value.partial_result.y.shape == (2, 4, 1)
    assert np.all(info.value.partial_result.status == INPUT_ERROR)


def test_a_raising_event_function_re_raises_with_the_run_so_far(sp):
    """An exception in g(t, x) used to end the run with status -6 and no exception;
    solve_ivp propagates it.  It is re-raised like a raising u(t, x), the run up to
    it attached, and that run is the one without the event up to there."""
    class Broken(Exception):
        pass

    def broken(t, x):
        if t > 0.5:
            raise Broken("event function broke")
        return 1.0
    with pytest.raises(Broken, match="event function broke") as info:
        sp.simulate([1.0, 0.0], (0, 2), events=broken)
    partial = info.value.partial_result
    assert isinstance(partial, Result) and not partial.success
    assert partial.status == capi.STATUS_BY_NAME["EVENT_ERROR"].code
    assert "Broken: event function broke" in partial.message and "t=" in partial.message
    assert partial.info["exception"] is info.value
    assert partial.t[0] == 0.0 and 0.3 < partial.t[-1] <= 0.6 and np.all(np.isfinite(partial.y))
    if hasattr(info.value, "add_note"):          # Python 3.11+
        assert any("event function" in note and ".partial_result" in note
                   for note in info.value.__notes__)
    plain = sp.simulate([1.0, 0.0], (0, 2), t_eval=partial.t)
    assert np.allclose(partial.y, plain.y, atol=1e-8)


def test_an_event_function_returning_no_number_is_a_type_error(sp):
    def q_none(t, x):
        return None
    with pytest.raises(ArgumentTypeError, match=r"event function 0 \(q_none\) returned "
                                                r"None at t=0.0; it must return a number"):
        sp.simulate([1.0, 0.0], (0, 2), events=q_none)


def test_ctrl_c_inside_a_feedback_u_is_an_interrupt(cp):
    """KeyboardInterrupt keeps the behaviour of any Ctrl-C during a run: the result so
    far with status INTERRUPTED, not an exception (here from a thread, where the C
    call is a plain call and the callable is what sees the interrupt)."""
    def pressed(t, x):
        if t > 0.2:
            raise KeyboardInterrupt
        return 0.0
    box = []
    worker = threading.Thread(target=lambda: box.append(
        cp.simulate([0.0, 0.1, 0.0, 0.0], (0, 1), u=pressed)))
    worker.start()
    worker.join(60)
    res = box[0]
    assert res.status == capi.STATUS_BY_NAME["INTERRUPTED"].code
    assert res.message.startswith("Interrupted at t=") and 0.1 < res.t[-1] <= 0.25


# -- x0 by name ----------------------------------------------------------------------------------

def test_x0_by_name_everywhere_a_state_is_taken(sp, compiled):
    dp = compiled("double_pendulum")
    array = dp.simulate([1.0, 0.0, 0.0, 0.3], (0, 1))
    named = dp.simulate({"q1": 1.0, "q2_dot": 0.3}, (0, 1))     # the others 0
    assert np.array_equal(named.y, array.y)
    batch = dp.simulate_batch([{"q1": 1.0, "q2_dot": 0.3}, [0.5, 0.0, 0.0, 0.0]], (0, 1))
    assert np.array_equal(batch.y[0][:, -1], array.y[:, -1])
    with pytest.raises(SimulationError, match="x0 names unknown state 'q3'"):
        dp.simulate({"q3": 1.0}, (0, 1))
    with pytest.raises(SimulationError, match=re.escape("X0[1] names unknown state 'w'")):
        dp.simulate_batch([{"q1": 1.0}, {"w": 1.0}], (0, 1))
    with pytest.raises(SimulationError, match="must be numbers"):
        dp.simulate({"q1": "one"}, (0, 1))


def test_scene_run_takes_x0_by_name_over_its_initial_state(build_root):
    import modelgen
    scene = modelgen.load_scene(SCENES / "simple_pendulum_swing.yaml", build_root / "sps_api")
    named = scene.run(x0={"q_dot": 0.5})
    x = np.array(scene.spec.initial)
    x[1] = 0.5
    assert np.array_equal(named.y, scene.run(x0=x).y)
    with pytest.raises(SimulationError, match="x0 names unknown state 'q1'"):
        scene.run(x0={"q1": 0.0})
    with pytest.raises(SimulationError, match=r"x0 must have shape \(2,\)"):
        scene.run(x0=[1.0, 0.0, 0.0])


# -- the energy change of a run from rest (issue 24, item 9) ------------------------------------

def test_energy_change_is_measured_against_the_run_not_a_zero_initial_energy():
    """A body released from rest at zero potential has E(0) = 0 exactly; the change
    was divided by max(|E(0)|, 1e-300) and printed as -2.4e+288."""
    energy = np.array([[0.0, 0.0], [0.5, -1.0], [1.0, -2.0]])      # T, V
    res = Result(np.arange(3.0), np.zeros((2, 3)), energy=energy)
    change = res.energy_change()
    assert change.change == -1.0 and change.scale == 3.0 and change.relative == -1.0 / 3.0
    assert "against the largest |T| + |V| of the run, 3 J" in change.describe()
    still = Result(np.arange(2.0), np.zeros((2, 2)), energy=np.zeros((2, 2)))
    assert still.energy_change().relative is None
    assert still.energy_change().describe() == "energy change 0.000e+00 J (the energies stayed zero)"


def test_an_overflowed_energy_is_described_without_a_numpy_warning():
    energy = np.array([[1e308, 1e308], [np.inf, 1.0], [np.inf, -np.inf]])
    res = Result(np.arange(3.0), np.zeros((2, 3)), energy=energy)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        change = res.energy_change()
    assert change.describe() == "energy change nan J (the energies overflowed)"


def test_a_run_that_blew_up_is_plotted(tmp_path):
    # matplotlib's tick formatter overflowed on a range near 1e308 ("internal error")
    y = np.array([[1.0, 1e308, np.inf], [0.0, 1.0, 2.0]])
    energy = np.array([[0.0, 0.0], [1e308, 1.0], [np.inf, 1.0]])
    res = Result(np.arange(3.0), y, state_names=("q", "q_dot"), energy=energy, status=-4)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res.plot(tmp_path / "blown.png")
    assert (tmp_path / "blown.png").stat().st_size > 0


def test_cli_prints_a_bounded_energy_change_for_a_block_released_from_rest(tmp_path, capsys):
    """The block on the incline from rest (E(0) = 0: at the origin, at rest) creeps
    down under regularised friction: the change is about -1 of the run's scale
    (what was there was lost), computed here from the CSV's energies."""
    from modelgen.cli import main
    out = tmp_path / "out"
    assert main(["simulate", str(SCENES / "block_friction.yaml"), "--build-dir",
                 str(tmp_path / "b"), "-o", str(out), "--no-plot", "--init", "s_dot=0",
                 "--t-end", "0.2"]) == 0
    text = capsys.readouterr().out
    printed = float(re.search(r"relative energy change (\S+) \(against the largest", text)[1])
    data = np.genfromtxt(out / "block_friction.csv", delimiter=",", names=True)
    T, V = data["kinetic"], data["potential"]
    assert T[0] == 0.0 and V[0] == 0.0
    expected = ((T[-1] + V[-1]) - (T[0] + V[0])) / np.max(np.abs(T) + np.abs(V))
    assert abs(printed) <= 2.0 and printed == pytest.approx(expected, rel=1e-3)
    assert "relative" in text.split("energy balance")[1]
