"""FMI 2.0 at the edges of the standard, driven call by call.

What a master may rely on besides the ordinary run of tests/test_fmu.py: a
step the integrator cannot finish is fmi2Discard with the last successful time
and the slave's wish to terminate (and FMPy ends such a run there), the status
functions answer each fmi2StatusKind as the standard says, a defined stop time
is not stepped past, each step ends at the master's time, and the calls on the
edges of the state machine (NULL arrays of length 0, fmi2Reset, two instances
at once, fmi2FreeInstance(NULL)) behave.  Under Model Exchange, derivatives
that cannot be evaluated at the importer's states are fmi2Discard.
"""
from __future__ import annotations

import ctypes

import numpy as np
import pytest

from conftest import MODELS

fmpy = pytest.importorskip("fmpy")
from fmpy import extract, read_model_description, simulate_fmu  # noqa: E402
from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi2 import (FMU2Slave, fmi2DoStepStatus, fmi2LastSuccessfulTime,  # noqa: E402
                       fmi2PendingStatus, fmi2Terminated)

from modelgen.codegen.fmu import build_fmu  # noqa: E402
from test_fmu import _Log, rocker_fmu  # noqa: E402

OK, DISCARD, ERROR = 0, 2, 3


@pytest.fixture(scope="module")
def cart_pole(build_root, tmp_path_factory):
    out = tmp_path_factory.mktemp("fmu_edges")
    return build_fmu(MODELS / "cart_pole.yaml", out / "cart_pole.fmu",
                     out_dir=build_root / "cart_pole")


@pytest.fixture(scope="module")
def rocker(build_root, tmp_path_factory):
    """The rocker-driven four-bar and a start that reaches its dead point at t = 0.31 s:
    mg_integrate stops there with MG_STATUS_DEAD_POINT."""
    return rocker_fmu(build_root, tmp_path_factory.mktemp("fmu_rocker"))


def _slave(fmu, tmp_path, name="probe"):
    """An instantiated FMU2Slave with a logger that keeps the messages."""
    md = read_model_description(str(fmu.path))
    directory = extract(str(fmu.path), unzipdir=str(tmp_path / name))
    log = _Log()
    slave = FMU2Slave(guid=md.guid, unzipDirectory=directory,
                      modelIdentifier=fmu.model_identifier, instanceName=name)
    slave.instantiate(callbacks=log.callbacks)
    return slave, log, {v.name: v.valueReference for v in md.modelVariables}


def _status(call, *args):
    """The fmi2Status of a call through FMPy (which raises above fmi2Warning)."""
    try:
        call(*args)
    except FMICallException as e:
        return e.status
    return OK


def _initialized(slave, start=None, **setup):
    slave.setupExperiment(startTime=0.0, **setup)
    slave.enterInitializationMode()
    for vr, value in (start or {}).items():
        slave.setReal([vr], [value])
    slave.exitInitializationMode()


def _raw(slave, name, restype, *argtypes):
    function = getattr(slave.dll, name)
    function.argtypes, function.restype = [ctypes.c_void_p, *argtypes], restype
    return function


# -- a step the integrator cannot finish ---------------------------------------------

def test_a_step_that_stops_short_is_discarded_with_the_last_successful_time(rocker, tmp_path):
    """fmi2Discard, not fmi2Error: the slave computed part of the step.  The master
    then reads fmi2LastSuccessfulTime (where the integrator stopped, inside the
    step), fmi2Terminated (true: nothing lets the slave go on from there) and the
    values there; the step-failed state refuses another step or a set, and allows
    fmi2Terminate and fmi2Reset."""
    fmu, start = rocker
    slave, log, vr = _slave(fmu, tmp_path)
    try:
        _initialized(slave, {vr[k]: v for k, v in start.items()})
        t, h, status = 0.0, 0.05, OK
        while status == OK and t < 1.0:
            status = _status(slave.doStep, t, h)
            t = t + h if status == OK else t
        assert status == DISCARD
        level, category, message = log.messages[-1]
        assert (level, category) == (DISCARD, "logStatusDiscard")
        assert "MG_STATUS_DEAD_POINT" in message
        last = slave.getRealStatus(fmi2LastSuccessfulTime)
        assert t <= last < t + h and 0.25 < last < 0.35
        assert slave.getBooleanStatus(fmi2Terminated) is True
        states = [vr[k] for k in start]
        derivatives = [vr[f"der({k})"] for k in start]
        values = slave.getReal(states + derivatives)
        assert np.all(np.isfinite(values))
        count = len(log.messages)
        assert _status(slave.doStep, last, h) == ERROR
        assert "may not be called in the step-failed state" in log.messages[-1][2]
        assert _status(slave.setReal, [vr["q3"]], [0.0]) == ERROR
        assert len(log.messages) == count + 2
        assert slave.getReal(states) == values[:len(states)]      # nothing changed
        slave.terminate()
        slave.reset()                                             # and reusable
        _initialized(slave, {vr[k]: v for k, v in start.items()})
        slave.doStep(0.0, 0.1)
        assert slave.getRealStatus(fmi2LastSuccessfulTime) == 0.1
        assert slave.getBooleanStatus(fmi2Terminated) is False
    finally:
        slave.freeInstance()


def test_fmpy_ends_a_run_the_fmu_cannot_finish_where_it_stopped(rocker):
    """FMPy reads fmi2Terminated after fmi2Discard and ends the run at
    fmi2LastSuccessfulTime: the result up to the dead point, the reason logged."""
    fmu, start = rocker
    messages, calls = [], []
    result = simulate_fmu(str(fmu.path), fmi_type="CoSimulation", start_time=0.0,
                          stop_time=5.0, output_interval=0.01, start_values=start,
                          logger=lambda *args: messages.append(args[-2:]),
                          fmi_call_logger=calls.append)
    assert 0.25 < result["time"][-1] < 0.35
    assert np.all(np.isfinite(result["q3"]))
    assert any(category == b"logStatusDiscard" and b"MG_STATUS_DEAD_POINT" in text
               for category, text in messages), messages
    assert any(c.startswith("fmi2DoStep(") and c.endswith("-> DISCARD") for c in calls)
    assert calls[-2].startswith("fmi2Terminate(") and calls[-2].endswith("-> OK")


def test_a_step_that_cannot_start_is_an_error(cart_pole, tmp_path):
    """A tunable parameter set between steps that leaves the mass matrix indefinite:
    nothing of the step can be computed, fmi2Error and the error state."""
    slave, log, vr = _slave(cart_pole, tmp_path)
    try:
        _initialized(slave)
        slave.doStep(0.0, 0.1)
        slave.setReal([vr["M"]], [-5.0])
        assert _status(slave.doStep, 0.1, 0.1) == ERROR
        assert log.messages[-1][:2] == (ERROR, "logStatusError")
        assert "mass matrix is not positive definite" in log.messages[-1][2]
        assert _status(slave.doStep, 0.1, 0.1) == ERROR
        assert "may not be called in the error state" in log.messages[-1][2]
        assert slave.getRealStatus(fmi2LastSuccessfulTime) == 0.1
        slave.reset()
    finally:
        slave.freeInstance()


# -- the status functions ----------------------------------------------------------

def test_each_status_kind_is_answered_as_the_standard_says(cart_pole, tmp_path):
    """fmi2LastSuccessfulTime and fmi2Terminated are given; a status the slave
    cannot give (fmi2DoStepStatus and fmi2PendingStatus: no step is ever pending;
    no Integer status exists) is fmi2Discard; a kind that is none is fmi2Error."""
    slave, log, vr = _slave(cart_pole, tmp_path)
    try:
        _initialized(slave)
        slave.doStep(0.0, 0.25)
        assert slave.getRealStatus(fmi2LastSuccessfulTime) == 0.25
        assert slave.getBooleanStatus(fmi2Terminated) is False
        for call, kind in ((slave.getStatus, fmi2DoStepStatus),
                           (slave.getStringStatus, fmi2PendingStatus),
                           (slave.getIntegerStatus, fmi2LastSuccessfulTime),
                           (slave.getRealStatus, fmi2Terminated),
                           (slave.getBooleanStatus, fmi2DoStepStatus)):
            assert _status(call, kind) == DISCARD, call
            assert log.messages[-1][:2] == (DISCARD, "logStatusDiscard")
        assert _status(slave.getRealStatus, 7) == ERROR
        get = _raw(slave, "fmi2GetRealStatus", ctypes.c_int, ctypes.c_int, ctypes.c_void_p)
        assert get(slave.component, fmi2LastSuccessfulTime, None) == ERROR
        slave.doStep(0.25, 0.25)                  # none of it changed the slave
        assert slave.getRealStatus(fmi2LastSuccessfulTime) == 0.5
    finally:
        slave.freeInstance()


# -- time ----------------------------------------------------------------------------

def test_a_step_past_a_defined_stop_time_is_an_error(cart_pole, tmp_path):
    """fmi2SetupExperiment's stopTime: computing past it is fmi2Error (rounding
    of the master's last point excepted), and nothing changes."""
    slave, log, vr = _slave(cart_pole, tmp_path)
    try:
        _initialized(slave, stopTime=0.3)
        slave.doStep(0.0, 0.1)
        slave.doStep(0.1, 0.2 * (1 + 1e-15))           # ends a few ulps past 0.3
        x = slave.getReal([vr["x"]])
        assert _status(slave.doStep, 0.3, 0.1) == ERROR
        assert "past stopTime" in log.messages[-1][2]
        assert slave.getReal([vr["x"]]) == x
    finally:
        slave.freeInstance()
    slave, log, vr = _slave(cart_pole, tmp_path, "free")   # stopTime not defined
    try:
        _initialized(slave)
        slave.doStep(0.0, 5.0)
    finally:
        slave.freeInstance()


def test_each_step_ends_at_the_masters_time(cart_pole, tmp_path):
    """The slave integrates to currentCommunicationPoint + communicationStepSize,
    not to its own time plus the step, so a master whose points are k * h (while
    the slave would sum h) finds the slave at its points."""
    slave, log, vr = _slave(cart_pole, tmp_path)
    try:
        _initialized(slave)
        h = 0.1
        for k in range(30):
            slave.doStep(k * h, h)
            assert slave.getRealStatus(fmi2LastSuccessfulTime) == k * h + h
    finally:
        slave.freeInstance()


def test_a_step_of_zero_or_less_or_from_elsewhere_is_an_error(cart_pole, tmp_path):
    slave, log, vr = _slave(cart_pole, tmp_path)
    try:
        assert _status(slave.doStep, 0.0, 0.1) == ERROR          # before initialization
        _initialized(slave)
        for t, h in ((0.0, 0.0), (0.0, -0.1), (0.0, float("nan")), (0.5, 0.1)):
            assert _status(slave.doStep, t, h) == ERROR
            assert log.messages[-1][:2] == (ERROR, "logStatusError")
        slave.doStep(0.0, 0.1)                                    # and still usable
    finally:
        slave.freeInstance()


# -- the state machine's edges -------------------------------------------------------

def test_arrays_of_length_zero_may_be_null(cart_pole, tmp_path):
    slave, log, vr = _slave(cart_pole, tmp_path)
    try:
        _initialized(slave)
        for name in ("fmi2GetReal", "fmi2SetReal", "fmi2GetInteger", "fmi2SetInteger",
                     "fmi2GetBoolean", "fmi2SetBoolean", "fmi2GetString", "fmi2SetString"):
            call = _raw(slave, name, ctypes.c_int, ctypes.c_void_p, ctypes.c_size_t,
                        ctypes.c_void_p)
            assert call(slave.component, None, 0, None) == OK, name
        logging = _raw(slave, "fmi2SetDebugLogging", ctypes.c_int, ctypes.c_int,
                       ctypes.c_size_t, ctypes.c_void_p)
        assert logging(slave.component, 1, 0, None) == OK
        assert _status(slave.getReal, [10_000]) == ERROR
        assert "unknown value reference 10000" in log.messages[-1][2]
        free = _raw(slave, "fmi2FreeInstance", None)
        free(None)                                                # nothing happens
    finally:
        slave.freeInstance()


def test_reset_gives_a_fresh_instance_and_two_instances_are_independent(cart_pole, tmp_path):
    """Two instances stepped in turn with different parameters and tolerances give
    what each gives alone; fmi2Reset brings back the start values, the exported
    tolerance and no stop time."""
    def run(slave, vr, steps=5):
        out = []
        for k in range(steps):
            slave.doStep(0.1 * k, 0.1)
            out.append(slave.getReal([vr["x"], vr["theta"]]))
        return out

    a, _, vr = _slave(cart_pole, tmp_path, "a")
    b, _, _ = _slave(cart_pole, tmp_path, "b")
    try:
        alone = []
        for slave, m in ((a, 0.2), (b, 0.5)):
            _initialized(slave, {vr["theta"]: 0.3, vr["m"]: m})
            alone.append(run(slave, vr))
            slave.reset()
        _initialized(a, {vr["theta"]: 0.3, vr["m"]: 0.2}, stopTime=0.2, tolerance=1e-4)
        a.reset()                          # drops the stop time and the tolerance
        _initialized(a, {vr["theta"]: 0.3, vr["m"]: 0.2})
        _initialized(b, {vr["theta"]: 0.3, vr["m"]: 0.5})
        together = [[], []]
        for k in range(5):
            for i, slave in enumerate((a, b)):
                slave.doStep(0.1 * k, 0.1)
                together[i].append(slave.getReal([vr["x"], vr["theta"]]))
        assert together == alone
        assert alone[0] != alone[1]
    finally:
        a.freeInstance()
        b.freeInstance()


def test_a_start_off_a_constrained_models_constraints_is_named(build_root, tmp_path):
    """The four-bar's default start (all zero) is not on its loop: FMPy's default
    run fails at fmi2ExitInitializationMode, and the message says what is wrong
    (the constraint Jacobian, a dependent coordinate) rather than a mass matrix
    pivot of coordinate '?'."""
    fmu = build_fmu(MODELS / "four_bar.yaml", tmp_path / "four_bar.fmu",
                    out_dir=build_root / "four_bar")
    messages = []
    with pytest.raises(FMICallException, match="fmi2ExitInitializationMode"):
        simulate_fmu(str(fmu.path), fmi_type="CoSimulation",
                     logger=lambda *args: messages.append(args[-1].decode()))
    assert "the constraint Jacobian is singular" in messages[-1]
    assert "start values must satisfy them" in messages[-1]
    assert "(coordinate q2)" in messages[-1] or "(coordinate q3)" in messages[-1]


def test_setup_experiment_ignores_what_it_is_told_is_undefined(cart_pole, tmp_path):
    """toleranceDefined and stopTimeDefined false: tolerance and stopTime are not
    looked at (here nonsense), and the run is the default one; a defined stop
    time before the start time is refused."""
    runs = []
    for arguments in ((0, -5.0, 0.0, 0, -1.0), (0, 0.0, 0.0, 0, 0.0)):
        slave, log, vr = _slave(cart_pole, tmp_path, f"s{len(runs)}")
        try:
            setup = _raw(slave, "fmi2SetupExperiment", ctypes.c_int, ctypes.c_int,
                         ctypes.c_double, ctypes.c_double, ctypes.c_int, ctypes.c_double)
            assert setup(slave.component, *arguments) == OK
            slave.enterInitializationMode()
            slave.setReal([vr["theta"]], [0.3])
            slave.exitInitializationMode()
            slave.doStep(0.0, 0.5)
            runs.append(slave.getReal([vr["x"], vr["theta"]]))
            slave.reset()
            assert setup(slave.component, 0, 0.0, 1.0, 1, 0.5) == ERROR
            assert "stopTime = 0.5 is before startTime = 1" in log.messages[-1][2]
        finally:
            slave.freeInstance()
    assert runs[0] == runs[1]


def test_model_exchange_discards_derivatives_at_a_state_it_cannot_evaluate(build_root,
                                                                          tmp_path):
    """Under Model Exchange the importer's solver chooses the states: at one where
    the mass matrix is singular (the heavy top's Euler angles at theta = 0) the
    derivatives are fmi2Discard, the standard's hint to retry with a shorter step,
    with NaN for the values and the reason logged; the instance stays in
    continuous-time mode and evaluates the next state it is given.  At
    initialization nothing lets the importer retry: the same state is fmi2Error."""
    from fmpy.fmi2 import FMU2Model
    fmu = build_fmu(MODELS / "heavy_top.yaml", tmp_path / "heavy_top.fmu",
                    out_dir=build_root / "heavy_top")
    md = read_model_description(str(fmu.path))
    directory = extract(str(fmu.path), unzipdir=str(tmp_path / "me"))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    log = _Log()
    model = FMU2Model(guid=md.guid, unzipDirectory=directory,
                      modelIdentifier=fmu.model_identifier, instanceName="me")
    model.instantiate(callbacks=log.callbacks)
    get_derivatives = _raw(model, "fmi2GetDerivatives", ctypes.c_int,
                           ctypes.POINTER(ctypes.c_double), ctypes.c_size_t)
    get_real = _raw(model, "fmi2GetReal", ctypes.c_int, ctypes.POINTER(ctypes.c_uint),
                    ctypes.c_size_t, ctypes.POINTER(ctypes.c_double))
    try:
        model.setupExperiment(startTime=0.0)
        model.enterInitializationMode()
        model.setReal([vr["theta"]], [0.5])
        model.exitInitializationMode()
        model.enterContinuousTimeMode()
        good = [0.0, 0.5, 0.0, 0.1, 0.0, 20.0]
        singular = [0.0, 0.0, 0.0, 0.1, 0.0, 20.0]
        out = (ctypes.c_double * 6)()
        for x, expected in ((good, OK), (singular, DISCARD), (good, OK)):
            model.setContinuousStates((ctypes.c_double * 6)(*x), 6)
            assert get_derivatives(model.component, out, 6) == expected
            assert np.all(np.isfinite(out)) == (expected == OK)
            refs = [vr["theta"], vr["der(phi_dot)"], vr["der(psi_dot)"]]
            values = (ctypes.c_double * 3)()
            assert get_real(model.component, (ctypes.c_uint * 3)(*refs), 3, values) \
                == expected
            assert values[0] == x[1] and np.all(np.isfinite(values[1:])) == (expected == OK)
            if expected == DISCARD:
                level, category, message = log.messages[-1]
                assert (level, category) == (DISCARD, "logStatusDiscard")
                assert "mass matrix is not positive definite" in message
                assert "(coordinate phi)" in message
        model.reset()
        model.setupExperiment(startTime=0.0)
        model.enterInitializationMode()
        with pytest.raises(FMICallException):
            model.exitInitializationMode()
        assert log.messages[-1][:2] == (ERROR, "logStatusError")
    finally:
        model.freeInstance()
