"""FMI 2.0 export, checked by a real importer (FMPy).

The FMUs of the double pendulum (its scene dp_free, with outputs), the
cart-pole (with its input force) and the 7-joint arm are validated by FMPy,
simulated by FMPy as Model Exchange (its CVode drives our derivatives) and as
Co-Simulation (our fmi2DoStep and mg_integrate), and compared with modelgen's
own ``simulate`` of the same model: a parameter and the state start values set
from FMPy, inputs given to FMPy as signals.  Misuse through FMPy's low-level
classes returns fmi2Error with a logged message and never crashes.
"""
from __future__ import annotations

import ctypes
import math
import subprocess
import zipfile

import numpy as np
import pytest

from conftest import MODELS, SCENES, SUMMARY

fmpy = pytest.importorskip("fmpy")
from fmpy import read_model_description, simulate_fmu  # noqa: E402
from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.fmi2 import (FMU2Model, FMU2Slave, fmi2CallbackAllocateMemoryTYPE,  # noqa: E402
                       fmi2CallbackFreeMemoryTYPE, fmi2CallbackFunctions,
                       fmi2CallbackLoggerTYPE)
from fmpy.validation import validate_fmu  # noqa: E402

import modelgen  # noqa: E402
from modelgen.codegen.build import compiler  # noqa: E402
from modelgen.codegen.emit import integrator_files  # noqa: E402
from modelgen.codegen.fmu import build_fmu  # noqa: E402
from modelgen.errors import ModelgenError  # noqa: E402

#: the Co-Simulation integrator of the model FMUs (chosen at export)
CS_RTOL, CS_ATOL = 1e-10, 1e-12
#: FMPy's CVode tolerance for Model Exchange (its atol is rtol times the nominal, 1)
ME_RTOL = 1e-12


@pytest.fixture(scope="module")
def fmus(build_root, tmp_path_factory):
    """name -> (Fmu, path); built once, into the session's shared model builds."""
    out = tmp_path_factory.mktemp("fmu")
    cache = {}

    def get(name):
        if name not in cache:
            if name == "dp_free":
                src, options = SCENES / "dp_free.yaml", {}
            else:
                src, options = MODELS / f"{name}.yaml", {"rtol": CS_RTOL, "atol": CS_ATOL}
            cache[name] = build_fmu(src, out / f"{name}.fmu", out_dir=build_root / name,
                                    **options)
        return cache[name]
    return get


def _steps(times, values):
    """An FMPy input signal that is piecewise constant: ``values[k]`` from ``times[k]``
    on (repeated rows at the jumps, which FMPy treats as input events)."""
    rows = []
    for k, t in enumerate(times):
        if k:
            rows.append((t, *values[k - 1]))
        rows.append((t, *values[k]))
    return rows


# -- the archive and its model description ---------------------------------------------

@pytest.mark.parametrize("name", ["dp_free", "cart_pole", "arm7", "four_bar"])
def test_fmpy_validates_the_fmu_with_no_problem(fmus, name, capsys):
    fmu = fmus(name)
    problems = validate_fmu(str(fmu.path))
    assert problems == []
    md = read_model_description(str(fmu.path), validate=True, validate_variable_names=True,
                                validate_model_structure=True)
    assert md.fmiVersion == "2.0" and md.modelExchange and md.coSimulation
    assert md.modelExchange.modelIdentifier == md.coSimulation.modelIdentifier == fmu.model_identifier
    names = [v.name for v in md.modelVariables]
    assert names == [v.name for v in fmu.variables]
    states = [d.variable.derivative.name for d in md.derivatives]
    n = len(states) // 2
    assert states[n:] == [f"{q}_dot" for q in states[:n]]
    assert [d.variable.name for d in md.derivatives] == [f"der({s})" for s in states]
    assert md.numberOfContinuousStates == 2 * n
    fmpy.dump(str(fmu.path))                        # FMPy's summary reads it too
    assert "Model Exchange, Co-Simulation" in capsys.readouterr().out
    SUMMARY.append(f"fmu {name}: FMPy validate_fmu problems: {len(problems)}; "
                   f"{len(names)} variables, {2 * n} states")


def test_the_description_names_every_variable_by_its_model_name(fmus, compiled):
    fmu = fmus("cart_pole")
    md = read_model_description(str(fmu.path))
    by_name = {v.name: v for v in md.modelVariables}
    for q in ("x", "theta", "x_dot", "theta_dot"):
        assert by_name[q].causality == "local" and by_name[q].initial == "exact"
    assert by_name["der(theta_dot)"].derivative is by_name["theta_dot"]
    cm = compiled("cart_pole")
    params = {v.name: float(v.start) for v in md.modelVariables if v.causality == "parameter"}
    assert params == cm.parameters
    assert all(by_name[p].variability == "tunable" for p in params)
    assert [v.name for v in md.modelVariables if v.causality == "input"] == ["F"]
    assert by_name["F"].variability == "continuous"
    # the Co-Simulation integrator is recorded
    assert "dop853, rtol 1e-10, atol 1e-12" in md.description
    with zipfile.ZipFile(fmu.path) as z:
        names = set(z.namelist())
        xml = z.read("modelDescription.xml").decode()
    assert '<CoSimulationIntegrator method="dop853"' in xml
    library = [n for n in names if n.startswith(f"binaries/{fmu.platform}/cart_pole.")]
    assert len(library) == 1
    assert {"sources/cart_pole.c", "sources/cart_pole.h",
            "sources/mg_integrate.c", "sources/mg_integrate.h", "sources/cart_pole_fmi2.c",
            "sources/fmi2Functions.h", "sources/fmi2FunctionTypes.h",
            "sources/fmi2TypesPlatform.h", "sources/fmi2-headers-LICENSE.txt"} <= names
    # and the files mg_integrate.c includes
    assert {f"sources/{f}" for f in integrator_files()} <= names


def test_a_scene_exports_its_outputs_initial_state_and_experiment(fmus, build_root):
    fmu = fmus("dp_free")
    md = read_model_description(str(fmu.path))
    scene = modelgen.load_scene(SCENES / "dp_free.yaml", build_root / "dp_free")
    outputs = [v.name for v in md.modelVariables if v.causality == "output"]
    assert outputs == list(scene.model.output_columns)
    assert "elbow.x" in outputs and "pose2[3,3]" in outputs
    assert [u.variable.name for u in md.outputs] == outputs
    starts = {v.name: float(v.start) for v in md.modelVariables if v.causality == "local"
              and v.start is not None}
    assert starts == dict(zip(scene.model.state_names, scene.spec.initial))
    assert (md.defaultExperiment.startTime, md.defaultExperiment.stopTime,
            md.defaultExperiment.stepSize) == ("0.0", "10.0", "0.01")
    assert "rk4, fixed steps of 0.001 s" in md.description


# -- simulation by FMPy against modelgen's own ---------------------------------------

CASES = {
    # name: (start values set from FMPy, input signal: jump times and values, t_end)
    "dp_free": ({"q1": 1.2, "g": 9.5}, None, 2.0),
    "cart_pole": ({"theta": 0.3, "x_dot": 0.2, "m": 0.25},
                  ([0.0, 0.4, 1.1], [[0.0], [2.0], [-1.5]]), 2.0),
    "arm7": ({"q2": 0.5, "q4": -1.0, "q6": 0.5, "g": 1.62},
             ([0.0, 0.5], [[0.5, 0.0, 0.2, 0.0, 0.1, 0.0, 0.02],
                           [0.0, 1.0, 0.0, -0.5, 0.0, 0.1, 0.0]]), 1.0),
}


def _reference(build_root, name, start, signal, times, **options):
    """modelgen's own simulate of the same model, start values and inputs."""
    if name == "dp_free":
        scene = modelgen.load_scene(SCENES / "dp_free.yaml", build_root / name)
        cm, x0 = scene.model, dict(zip(scene.model.state_names, scene.spec.initial))
    else:
        cm = modelgen.load(MODELS / f"{name}.yaml", build_root / name)
        x0 = dict.fromkeys(cm.state_names, 0.0)
    x0.update({k: v for k, v in start.items() if k in cm.state_names})
    p = _parameters(cm, start)
    u = None if signal is None else (np.array(signal[0]), np.array(signal[1]), "hold")
    res = cm.simulate([x0[s] for s in cm.state_names], (0.0, times[-1]), t_eval=times,
                      p=p, u=u, **options)
    assert res.success, res.message
    return cm, res


def _parameters(cm, start):
    return {k: v for k, v in start.items() if k in cm.parameters}


def _fmpy_input(fmu, signal):
    if signal is None:
        return None
    names = fmu.names("input")
    dtype = [("time", np.float64)] + [(n, np.float64) for n in names]
    return np.array(_steps(*signal), dtype=dtype)


def _deviation(cm, result, res, outputs=False, p=None):
    dev = max(float(np.max(np.abs(result[s] - res[s]))) for s in cm.state_names)
    if outputs:
        for c in cm.output_columns:
            col = list(cm.output_columns).index(c)
            ref = np.array([cm.output_values(t, res.y[:, k], p=p)[col] for k, t in enumerate(res.t)])
            dev = max(dev, float(np.max(np.abs(result[c] - ref))))
    return dev


@pytest.mark.parametrize("name", list(CASES))
def test_model_exchange_under_fmpy_cvode_matches_simulate(fmus, build_root, name):
    fmu = fmus(name)
    start, signal, t_end = CASES[name]
    record = [v.name for v in fmu.variables if v.causality == "local"
              and not v.name.startswith("der(")] + fmu.names("output")
    result = simulate_fmu(str(fmu.path), fmi_type="ModelExchange", solver="CVode",
                          relative_tolerance=ME_RTOL, start_time=0.0, stop_time=t_end,
                          output_interval=0.01, start_values=start,
                          input=_fmpy_input(fmu, signal), output=record)
    cm, res = _reference(build_root, name, start, signal, result["time"], rtol=1e-13, atol=1e-13)
    dev = _deviation(cm, result, res, outputs=name == "dp_free", p=_parameters(cm, start))
    SUMMARY.append(f"fmu {name}: Model Exchange (FMPy CVode, rtol {ME_RTOL:g}) against "
                   f"simulate: max |deviation| {dev:.2e} over {t_end:g} s")
    assert dev < 1e-6


@pytest.mark.parametrize("name", ["cart_pole", "arm7"])
def test_co_simulation_with_modelgens_integrator_matches_simulate(fmus, build_root, name):
    """Each fmi2DoStep starts dop853 afresh over one communication interval at the
    exported tolerances; the trajectory stays within those tolerances of one run."""
    fmu = fmus(name)
    start, signal, t_end = CASES[name]
    result = simulate_fmu(str(fmu.path), fmi_type="CoSimulation", start_time=0.0,
                          stop_time=t_end, output_interval=0.01, start_values=start,
                          input=_fmpy_input(fmu, signal), output=list(fmu.names("local")))
    cm, res = _reference(build_root, name, start, signal, result["time"], rtol=1e-13, atol=1e-13)
    dev = _deviation(cm, result, res)
    scale = max(1.0, float(np.max(np.abs(res.y))))
    SUMMARY.append(f"fmu {name}: Co-Simulation (dop853 rtol {CS_RTOL:g}, atol {CS_ATOL:g}) "
                   f"against simulate: max |deviation| {dev:.2e} (max |x| {scale:.3g})")
    assert dev < 100 * CS_RTOL * scale
    if name == "arm7":
        # a tolerance the importer gives (fmi2SetupExperiment) replaces the exported one
        kwargs = dict(fmi_type="CoSimulation", start_time=0.0, stop_time=t_end,
                      output_interval=0.1, start_values=start, input=_fmpy_input(fmu, signal),
                      output=list(fmu.names("local")))
        exported = simulate_fmu(str(fmu.path), **kwargs)
        loose = simulate_fmu(str(fmu.path), relative_tolerance=1e-4, **kwargs)
        cm, res = _reference(build_root, name, start, signal, loose["time"], rtol=1e-13,
                             atol=1e-13)
        dev_exported, dev_loose = _deviation(cm, exported, res), _deviation(cm, loose, res)
        SUMMARY.append(f"fmu arm7: Co-Simulation, 0.1 s steps: max |deviation| {dev_exported:.2e} "
                       f"at the exported rtol, {dev_loose:.2e} at the importer's rtol 1e-4")
        assert dev_exported < 100 * CS_RTOL * scale < 1e-3 * dev_loose


def test_co_simulation_of_a_scene_repeats_its_fixed_steps_exactly(fmus, build_root):
    """dp_free integrates with RK4 at 1 ms: ten steps per 10 ms communication interval
    are the same steps as one run's, so the two agree to rounding, outputs included."""
    fmu = fmus("dp_free")
    start, _, t_end = CASES["dp_free"]
    result = simulate_fmu(str(fmu.path), fmi_type="CoSimulation", start_time=0.0,
                          stop_time=t_end, output_interval=0.01, start_values=start,
                          output=list(fmu.names("local")) + fmu.names("output"))
    cm, res = _reference(build_root, "dp_free", start, None, result["time"], method="rk4",
                         step=1e-3)
    dev = _deviation(cm, result, res, outputs=True, p=_parameters(cm, start))
    SUMMARY.append(f"fmu dp_free: Co-Simulation (rk4, 1 ms) against simulate (rk4, 1 ms): "
                   f"max |deviation| {dev:.2e}")
    assert dev < 1e-11


# -- a constrained model under Model Exchange -------------------------------------------

def _four_bar_start(build_root, crank_speed=2.0):
    cm = modelgen.load(MODELS / "four_bar.yaml", build_root / "four_bar")
    q0 = cm.assemble([0.3, 1.0, 2.0], keep=["q1"])
    x0 = np.concatenate([q0, cm.consistent_speeds(q0, [crank_speed, 0.0, 0.0])])
    return cm, dict(zip(cm.state_names, x0))


def _violations(cm, result):
    """max |f(q)| and max |G qd| at each recorded row, computed by the model's own C."""
    X = np.array([result[s] for s in cm.state_names])
    f = np.array([np.max(np.abs(cm.constraint_residuals(x[:cm.nq]))) for x in X.T])
    g = np.array([np.max(np.abs(cm.constraint_jacobian(x[:cm.nq]) @ x[cm.nq:])) for x in X.T])
    return f, g


def test_model_exchange_projects_a_constrained_model_onto_its_constraints(fmus, build_root):
    """FMPy's CVode (rtol 1e-6) drives the four-bar for 100 s.  With
    fmi2CompletedIntegratorStep (the model description asks for it) the FMU asks
    for an event whenever the loop's residual or G qd exceeds the states'
    absolute tolerance and projects in fmi2NewDiscreteStates: every recorded row
    is within it.  The same run with the call switched off in the description
    (so no projection) drifts off, more at the end than after 10 s."""
    fmu = fmus("four_bar")
    md = read_model_description(str(fmu.path))
    assert md.modelExchange.needsCompletedIntegratorStep
    assert not read_model_description(str(fmus("cart_pole").path)) \
        .modelExchange.needsCompletedIntegratorStep
    cm, start = _four_bar_start(build_root)
    rtol = 1e-6
    tol = CS_ATOL * rtol / CS_RTOL      # fmi2SetupExperiment scales atol with the tolerance
    runs = {}
    for project in (True, False):
        md = read_model_description(str(fmu.path))
        md.modelExchange.needsCompletedIntegratorStep = project
        result = simulate_fmu(str(fmu.path), fmi_type="ModelExchange", solver="CVode",
                              relative_tolerance=rtol, start_time=0.0, stop_time=100.0,
                              output_interval=0.05, start_values=start, model_description=md,
                              output=list(cm.state_names), record_events=False)
        assert result["time"][-1] == pytest.approx(100.0)
        runs[project] = _violations(cm, result)
    (f, g), (f_off, g_off) = runs[True], runs[False]
    SUMMARY.append(f"fmu four_bar: Model Exchange (FMPy CVode, rtol {rtol:g}) over 100 s: "
                   f"max |f| {f.max():.1e}, |G qd| {g.max():.1e} with the projection "
                   f"(tolerance {tol:.0e}); {f_off.max():.1e}, {g_off.max():.1e} without")
    assert f.max() <= tol and g.max() <= tol
    assert f_off.max() > 100 * tol and g_off.max() > 100 * tol
    assert f_off[-200:].max() > 5 * f_off[:200].max()         # about linear in t


def rocker_fmu(build_root, out) -> tuple:
    """The FMU of the rocker-driven four-bar (crank and coupler dependent), written
    into ``out``, and a start (names -> values) that reaches its dead point at
    t = 0.31 s, where mg_integrate stops with MG_STATUS_DEAD_POINT."""
    from modelgen.bench import hard_case_models as hm
    path = out / "hc_four_bar_rocker.yaml"
    path.write_text(hm.FOUR_BAR_ROCKER)
    fmu = build_fmu(path, out / "rocker.fmu", out_dir=build_root / "hc_four_bar_rocker")
    cm = modelgen.load(path, build_root / "hc_four_bar_rocker")
    q0 = cm.assemble([0.0, 1.2, 2.0], keep=["q3"])
    return fmu, dict(zip(cm.state_names,
                         np.concatenate([q0, cm.consistent_speeds(q0, [0.0, 0.0, 3.0])])))


def test_a_dead_point_is_an_error_in_model_exchange_and_a_discard_in_cs(build_root, tmp_path):
    """The rocker-driven four-bar (crank and coupler dependent) reaches a dead point
    at t = 0.31 s: under Model Exchange fmi2CompletedIntegratorStep sees det G_d
    change sign and fails with the dead point named; under Co-Simulation
    fmi2DoStep returns fmi2Discard with mg_integrate's status, and FMPy ends the
    run at the last time reached; never a silent crossing or NaN."""
    fmu, start = rocker_fmu(build_root, tmp_path)
    messages = []
    with pytest.raises(FMICallException):
        simulate_fmu(str(fmu.path), fmi_type="ModelExchange", solver="CVode",
                     relative_tolerance=1e-6, start_time=0.0, stop_time=5.0,
                     output_interval=0.01, start_values=start,
                     logger=lambda *args: messages.append(args[-1].decode()))
    assert any("dead point" in m and "t = 0.3" in m for m in messages), messages
    # Co-Simulation: mg_integrate's own status, through fmi2DoStep's Discard
    messages.clear()
    result = simulate_fmu(str(fmu.path), fmi_type="CoSimulation", start_time=0.0,
                          stop_time=5.0, output_interval=0.01, start_values=start,
                          logger=lambda *args: messages.append(args[-1].decode()))
    assert 0.29 < result["time"][-1] < 0.31, result["time"][-1]
    assert np.all(np.isfinite(result["q3"]))
    assert any("MG_STATUS_DEAD_POINT" in m for m in messages), messages


def test_the_sources_rebuild_the_binary(fmus, tmp_path):
    """sources/ is complete: compiled alone (as an importer on another platform would),
    it gives a library that FMPy runs to the same result."""
    fmu = fmus("cart_pole")
    root = tmp_path / "unzipped"
    with zipfile.ZipFile(fmu.path) as z:
        z.extractall(root)
    (library,) = (root / "binaries" / fmu.platform).glob("cart_pole.*")
    library.unlink()
    sources = root / "sources"
    md = read_model_description(str(fmu.path))
    files = md.buildConfigurations[0].sourceFileSets[0].sourceFiles
    assert files == ["cart_pole.c", "mg_integrate.c", "cart_pole_fmi2.c"]
    subprocess.run([*compiler(), "-shared", "-fPIC", "-O2", "-std=c99", "-I.", *files, "-o",
                    str(library), "-lm"], cwd=sources, check=True, capture_output=True)
    start, signal, t_end = CASES["cart_pole"]
    kwargs = dict(fmi_type="CoSimulation", start_time=0.0, stop_time=0.5,
                  output_interval=0.05, start_values=start, input=_fmpy_input(fmu, signal),
                  output=["x", "theta"])
    rebuilt = simulate_fmu(str(root), **kwargs)
    original = simulate_fmu(str(fmu.path), **kwargs)
    assert np.max(np.abs(rebuilt["theta"] - original["theta"])) < 1e-12
    assert np.max(np.abs(original["theta"] - start["theta"])) > 0.01   # it did move


@pytest.mark.parametrize("name", ["dp_free", "four_bar"])
def test_the_wrapper_compiles_as_strict_c99_and_as_cpp(fmus, tmp_path, name):
    fmu = fmus(name)
    with zipfile.ZipFile(fmu.path) as z:
        z.extractall(tmp_path)
    sources = tmp_path / "sources"
    for command in ([*compiler(), "-std=c99", "-pedantic"],
                    ["c++", "-x", "c++", "-std=c++11"]):
        proc = subprocess.run([*command, "-Wall", "-Wextra", "-Werror", "-I.", "-c",
                               f"{name}_fmi2.c", "-o", "wrapper.o"], cwd=sources,
                              capture_output=True, text=True)
        assert proc.returncode == 0, proc.stdout + proc.stderr


def test_the_fmu_carries_the_c_of_its_own_variant(tmp_path):
    """A build directory keeps several variants of one model, and <name>.c is the
    newest one's: the export checks the model hash and regenerates when it differs."""
    build = tmp_path / "build"
    modelgen.load(MODELS / "simple_pendulum.yaml", build)
    modelgen.load(MODELS / "simple_pendulum.yaml", build, jacobian=True)
    assert "simple_pendulum_jacobian(" in (build / "simple_pendulum.c").read_text()
    fmu = build_fmu(MODELS / "simple_pendulum.yaml", tmp_path / "sp.fmu", out_dir=build)
    with zipfile.ZipFile(fmu.path) as z:
        c = z.read("sources/simple_pendulum.c").decode()
    assert "simple_pendulum_jacobian(" not in c      # dop853 needs no Jacobian
    assert validate_fmu(str(fmu.path)) == []


# -- misuse: fmi2Error and a logged message, never a crash -----------------------------

class _Log:
    """FMI callbacks whose logger keeps (status, category, message)."""

    def __init__(self):
        self.messages = []
        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(self._log)
        self.callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(self._calloc)
        self.callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(self._free)

    def _log(self, env, instance, status, category, message):
        self.messages.append((status, category.decode(), message.decode()))

    libc = ctypes.CDLL(None)
    libc.calloc.restype = ctypes.c_void_p
    libc.calloc.argtypes = [ctypes.c_size_t, ctypes.c_size_t]
    libc.free.argtypes = [ctypes.c_void_p]

    def _calloc(self, n, size):
        return self.libc.calloc(n, size)

    def _free(self, pointer):
        self.libc.free(pointer)

    def last(self, level=3):
        status, category, message = self.messages[-1]
        assert (status, category) == ((3, "logStatusError") if level == 3
                                      else (level, "logStatusDiscard"))
        return message


def _instance(fmu, kind, tmp_path):
    from fmpy import extract
    md = read_model_description(str(fmu.path))
    directory = extract(str(fmu.path), unzipdir=str(tmp_path / kind.__name__))
    log = _Log()
    instance = kind(guid=md.guid, unzipDirectory=directory,
                    modelIdentifier=fmu.model_identifier, instanceName="probe")
    instance.instantiate(callbacks=log.callbacks)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    return instance, log, vr


def _derivatives(me, n=4):
    dx = (ctypes.c_double * n)()
    me.getDerivatives(dx, n)
    return list(dx)


def _fails(log, call, *args, status=3):
    """Call, expect fmi2Error (or ``status``; FMPy raises), return the logged message."""
    before = len(log.messages)
    with pytest.raises(FMICallException) as info:
        call(*args)
    assert info.value.status == status
    assert len(log.messages) == before + 1
    return log.last(status)


def test_misuse_of_a_model_exchange_instance_is_an_error_with_a_reason(fmus, tmp_path):
    fmu = fmus("cart_pole")
    me, log, vr = _instance(fmu, FMU2Model, tmp_path)
    try:
        me.setupExperiment(startTime=0.0)
        assert "unknown value reference 999" in _fails(log, me.setReal, [999], [1.0])
        assert "may not be called in the instantiated state" in _fails(
            log, _derivatives, me)
        assert "not a finite number" in _fails(log, me.setReal, [vr["m"]], [float("nan")])
        me.setReal([vr["theta"], vr["m"]], [0.2, 0.3])       # before initialization: fine
        me.enterInitializationMode()
        me.exitInitializationMode()
        me.enterContinuousTimeMode()
        message = _fails(log, me.setReal, [vr["theta"]], [0.1])
        assert "theta (value reference 1) is a continuous state" in message
        assert "continuous-time mode" in message
        assert "tunable parameter" in _fails(log, me.setReal, [vr["g"]], [1.0])
        assert "calculated by the FMU" in _fails(log, me.setReal, [vr["der(x)"]], [1.0])
        assert "no Integer variables" in _fails(log, me.getInteger, [0])
        do_step = me.dll.fmi2DoStep            # FMPy's model does not bind it
        do_step.argtypes = [ctypes.c_void_p, ctypes.c_double, ctypes.c_double, ctypes.c_int]
        do_step.restype = ctypes.c_int
        assert do_step(me.component, 0.0, 0.1, 0) == 3
        assert "is a Co-Simulation function" in log.last()
        # NULL arguments
        assert "vr is NULL" in _fails(log, lambda: me.fmi2GetReal(me.component, None, 1, None))
        assert "nx = 3, but this FMU has 4" in _fails(
            log, lambda: me.fmi2GetDerivatives(me.component, (ctypes.c_double * 3)(), 3))
        # nothing changed: the instance still answers correctly
        assert me.getReal([vr["theta"], vr["m"]]) == [0.2, 0.3]
        assert np.all(np.isfinite(_derivatives(me)))
        me.enterEventMode()
        me.setReal([vr["g"]], [1.62])                          # in event mode: fine
        assert me.getReal([vr["g"]]) == [1.62]
        # a negative pole mass leaves the mass matrix not positive definite: in event
        # mode fmi2Discard (the importer may change what it set), nothing changed
        me.setReal([vr["M"], vr["m"]], [-1.0, 0.5])
        message = _fails(log, _derivatives, me, status=2)
        assert "mass matrix is not positive definite" in message and "coordinate" in message
        me.setReal([vr["M"]], [1.0])
        assert np.all(np.isfinite(_derivatives(me)))
        # at initialization nothing can be retried: fmi2Error and the error state,
        # diagnostics only, then reset
        me.reset()
        me.setupExperiment(startTime=0.0)
        me.setReal([vr["theta"], vr["M"], vr["m"]], [0.2, -1.0, 0.5])
        me.enterInitializationMode()
        assert "mass matrix is not positive definite" in _fails(log, me.exitInitializationMode)
        assert log.messages[-1][:2] == (3, "logStatusError")
        assert "may not be called in the error state" in _fails(log, me.enterEventMode)
        assert me.getReal([vr["M"]]) == [-1.0]
        # the whole state for diagnosis, derivatives included: NaN where the failure
        # leaves them undefined, without failing (or logging) a second time
        count = len(log.messages)
        values = me.getReal([vr["theta"], vr["der(x)"], vr["der(x_dot)"]])
        assert values[0] == 0.2 and math.isnan(values[1]) and math.isnan(values[2])
        assert len(log.messages) == count
        # the NULL instance: fmi2Error, nothing to log through
        count = len(log.messages)
        with pytest.raises(FMICallException):
            me.fmi2GetReal(None, None, 0, None)
        assert len(log.messages) == count
    finally:
        me.freeInstance()


def test_misuse_of_a_co_simulation_instance_is_an_error_with_a_reason(fmus, tmp_path):
    fmu = fmus("cart_pole")
    cs, log, vr = _instance(fmu, FMU2Slave, tmp_path)
    try:
        message = _fails(log, cs.doStep, 0.0, 0.1)
        assert message.startswith("fmi2DoStep may not be called in the instantiated state")
        cs.setupExperiment(startTime=0.0)
        cs.setReal([vr["M"]], [-5.0])
        cs.enterInitializationMode()
        assert "mass matrix is not positive definite" in _fails(log, cs.exitInitializationMode)
        cs.reset()                                             # back to the start values
        cs.setupExperiment(startTime=0.0)
        cs.enterInitializationMode()
        cs.exitInitializationMode()
        assert "currentCommunicationPoint = 1" in _fails(log, cs.doStep, 1.0, 0.1)
        assert "must be a positive number" in _fails(log, cs.doStep, 0.0, -0.1)
        set_time = cs.dll.fmi2SetTime        # FMPy's slave does not bind it
        set_time.argtypes, set_time.restype = [ctypes.c_void_p, ctypes.c_double], ctypes.c_int
        assert set_time(cs.component, 0.5) == 3
        assert "is a Model Exchange function" in log.last()
        assert "continuous state" in _fails(log, cs.setReal, [vr["x"]], [1.0])
        cs.setReal([vr["F"], vr["m"]], [1.0, 0.2])            # inputs and parameters: fine
        assert 'unknown log category "logAll"' in _fails(log, cs.setDebugLogging, True,
                                                         ["logAll"])
        cs.setDebugLogging(True, ["logDebug"])
        cs.doStep(0.0, 0.1)
        status, category, message = log.messages[-1]
        assert (status, category) == (0, "logDebug") and message.startswith("fmi2DoStep: t = 0.1")
        assert "rhs evaluations" in message
        assert cs.getReal([vr["x"]])[0] > 0
        assert "not supported" in _fails(log, cs.getFMUstate)
    finally:
        cs.freeInstance()


def test_a_last_step_of_a_few_ulps_is_taken_not_failed(fmus, tmp_path):
    """An importer that sums 0.1 s steps and then steps to stopTime ends with a step
    of 1.95e-14 s at t = 10, below the integrators' step control: it used to fail
    (STEP_UNDERFLOW, the instance in the error state); it is one Euler step now, and
    the run ends where one without the sliver does, to rounding."""
    fmu = fmus("cart_pole")
    runs = []
    for steps in ([0.1] * 10, [0.1] * 9 + [0.1 - 3e-15, 3e-15]):
        cs, log, vr = _instance(fmu, FMU2Slave, tmp_path / str(len(runs)))
        try:
            cs.setupExperiment(startTime=0.0)
            cs.enterInitializationMode()
            cs.setReal([vr["theta"]], [0.3])
            cs.exitInitializationMode()
            t = 0.0
            for h in steps:
                cs.doStep(t, h)
                t += h
            runs.append(np.array(cs.getReal([vr["x"], vr["theta"], vr["x_dot"],
                                             vr["theta_dot"]])))
        finally:
            cs.freeInstance()
    assert np.allclose(runs[1], runs[0], rtol=1e-12, atol=1e-12)
    cs, log, vr = _instance(fmu, FMU2Slave, tmp_path / "sum")
    try:
        cs.setupExperiment(startTime=0.0)
        cs.enterInitializationMode()
        cs.exitInitializationMode()
        t = 0.0
        while t < 10.0:
            h = min(0.1, 10.0 - t)
            cs.doStep(t, h)                    # the last h is 1.95e-14
            t += h
        assert cs.getReal([vr["x"]])[0] == cs.getReal([vr["x"]])[0]
        # a tolerance no integrator reaches is refused, not failed at every step
        cs.reset()
        assert "is below 2.22045e-15, which the integrators" in _fails(
            log, lambda: cs.setupExperiment(tolerance=1e-30, startTime=0.0))
    finally:
        cs.freeInstance()


def test_a_wrong_guid_is_refused_with_a_message(fmus, tmp_path):
    from fmpy import extract
    fmu = fmus("cart_pole")
    log = _Log()
    instance = FMU2Slave(guid="{00000000-0000-0000-0000-000000000000}",
                         unzipDirectory=extract(str(fmu.path), unzipdir=str(tmp_path / "g")),
                         modelIdentifier="cart_pole", instanceName="probe")
    with pytest.raises(Exception, match="Failed to instantiate"):
        instance.instantiate(callbacks=log.callbacks)
    assert "does not match this FMU's" in log.last()
    instance.freeLibrary()


# -- options and the command line ------------------------------------------------------

def test_export_options_are_checked_before_anything_is_built(tmp_path):
    with pytest.raises(ModelgenError, match="unknown integration method 'nope'"):
        build_fmu(MODELS / "cart_pole.yaml", tmp_path / "a.fmu", method="nope")
    with pytest.raises(ModelgenError, match="takes fixed steps; fix: give the step"):
        build_fmu(MODELS / "cart_pole.yaml", tmp_path / "a.fmu", method="rk4")
    with pytest.raises(ModelgenError, match="rtol must be a positive number"):
        build_fmu(MODELS / "cart_pole.yaml", tmp_path / "a.fmu", rtol=-1.0)
    assert not (tmp_path / "a.fmu").exists()


def test_the_fmu_command_writes_a_valid_fmu(build_root, tmp_path, capsys):
    from modelgen.cli import main
    out = tmp_path / "cp.fmu"
    code = main(["fmu", str(MODELS / "cart_pole.yaml"), "-o", str(out), "--method", "rk4",
                 "--step", "0.002", "--build-dir", str(build_root / "cart_pole")])
    assert code == 0
    text = capsys.readouterr().out
    assert str(out) in text and "rk4" in text
    assert validate_fmu(str(out)) == []
    assert "rk4, fixed steps of 0.002 s" in read_model_description(str(out)).description
    assert main(["fmu", str(MODELS / "cart_pole.yaml"), "-o", str(out), "--method",
                 "rk4"]) == 2
