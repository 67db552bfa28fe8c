"""FMUs of models with ball and free joints: quaternion states under FMI 2.0.

The state is the coordinates (a free joint's position and unit quaternion:
7) and the speeds (6), so it has more coordinates than speeds, and only a
simple coordinate's derivative is a state.  Co-Simulation keeps each
quaternion at unit length inside mg_integrate; under Model Exchange the
importer's integrator lets it drift, and the FMU asks for an event when the
drift exceeds the tolerance and normalises it there.  A start quaternion need
not have unit length (as in ``simulate``); zero is refused with its name.
"""
from __future__ import annotations

import ctypes

import numpy as np
import pytest

from conftest import MODELS, SCENES, SUMMARY

fmpy = pytest.importorskip("fmpy")
from fmpy import read_model_description, simulate_fmu  # noqa: E402
from fmpy.fmi1 import FMICallException  # noqa: E402
from fmpy.validation import validate_fmu  # noqa: E402

import modelgen  # noqa: E402
from modelgen.codegen.fmu import build_fmu  # noqa: E402

QUATERNION = ["J_qw", "J_qx", "J_qy", "J_qz"]


@pytest.fixture(scope="module")
def racket_scene(build_root, tmp_path_factory):
    out = tmp_path_factory.mktemp("fmu_joints")
    return build_fmu(SCENES / "tennis_racket_flip.yaml", out / "flip.fmu",
                     out_dir=build_root / "tennis_racket_flip")


def _deviation(result, reference, names) -> float:
    t = result["time"]
    return max(float(np.max(np.abs(np.interp(t, reference.t, reference[n]) - result[n])))
               for n in names)


def test_a_free_body_fmu_is_valid_and_its_derivatives_say_what_they_depend_on(racket_scene):
    """13 states (7 coordinates, 6 speeds) and their 13 derivatives; a joint
    coordinate's derivative is calculated from the whole state (no
    ``dependencies`` claiming it is one speed, as a simple coordinate's is)."""
    assert validate_fmu(str(racket_scene.path)) == []
    md = read_model_description(str(racket_scene.path), validate=True,
                                validate_variable_names=True)
    states = [v.name for v in md.modelVariables if v.causality == "local"
              and not v.name.startswith("der(")]
    assert states == ["J_x", "J_y", "J_z", *QUATERNION, "J_vx", "J_vy", "J_vz",
                      "J_wx", "J_wy", "J_wz"]
    assert len(md.derivatives) == 13
    assert all(not d.dependencies for d in md.derivatives)
    assert not md.modelExchange.completedIntegratorStepNotNeeded


def test_a_free_body_fmu_runs_both_ways_as_simulate(racket_scene):
    """The tennis racket's flip over 10 s: Co-Simulation (its own dop853 at
    rtol 1e-11) agrees with ``simulate`` to integration error, the quaternion at
    unit length to rounding; Model Exchange under FMPy's CVode (rtol 1e-10)
    agrees to CVode's error, the quaternion kept within the tolerance by
    projection events the FMU asks for (logged with logDebug)."""
    reference = modelgen.load_scene(SCENES / "tennis_racket_flip.yaml").run()
    names = QUATERNION + ["J_wx", "J_wy", "J_wz"]
    figures = {}
    for kind, options in (("CoSimulation", {}),
                          ("ModelExchange", {"solver": "CVode", "relative_tolerance": 1e-10})):
        messages = []
        result = simulate_fmu(str(racket_scene.path), fmi_type=kind, stop_time=10.0,
                              output_interval=0.01, output=names, debug_logging=True,
                              logger=lambda *args, kept=messages: kept.append(args[-1].decode()),
                              **options)
        norm = np.sqrt(sum(result[n] ** 2 for n in QUATERNION))
        projections = sum("projected onto the state's manifold" in m for m in messages)
        figures[kind] = (_deviation(result, reference, names), float(np.abs(norm - 1).max()),
                         projections)
    SUMMARY.append("fmu tennis_racket_flip over 10 s: max |deviation| from simulate, "
                   "max ||q| - 1|, projections: " + "; ".join(
                       f"{k} {d:.1e}, {n:.1e}, {p}" for k, (d, n, p) in figures.items()))
    deviation, drift, projections = figures["CoSimulation"]
    assert deviation < 1e-9 and drift < 1e-15 and projections == 0
    deviation, drift, projections = figures["ModelExchange"]
    assert deviation < 1e-4 and drift < 1e-8 and projections > 0


def test_a_model_fmu_starts_at_no_rotation_and_normalises_its_start(build_root, tmp_path):
    """A model's FMU starts at the identity quaternion (zeros would be no
    orientation at all); a start quaternion (2, 0, 0, 0) is normalised at
    fmi2ExitInitializationMode, so spinning at 2 rad/s about y for 1 s ends at
    q_w = cos(1) both ways; a zero quaternion is refused, named."""
    fmu = build_fmu(MODELS / "tennis_racket.yaml", tmp_path / "racket.fmu",
                    out_dir=build_root / "tennis_racket")
    md = read_model_description(str(fmu.path))
    start = {v.name: v.start for v in md.modelVariables if v.causality == "local"}
    assert [start[n] for n in QUATERNION] == ["1.0", "0.0", "0.0", "0.0"]
    for kind in ("CoSimulation", "ModelExchange"):
        result = simulate_fmu(str(fmu.path), fmi_type=kind, stop_time=1.0, output=QUATERNION,
                              start_values={"J_qw": 2.0, "J_wy": 2.0})
        assert result["J_qw"][0] == 1.0
        assert abs(result["J_qw"][-1] - np.cos(1.0)) < 1e-6
        assert abs(result["J_qy"][-1] - np.sin(1.0)) < 1e-6
    messages = []
    with pytest.raises(FMICallException, match="fmi2ExitInitializationMode"):
        simulate_fmu(str(fmu.path), fmi_type="CoSimulation", start_values={"J_qw": 0.0},
                     logger=lambda *args: messages.append(args[-1].decode()))
    assert "the quaternion (J_qw, J_qx, J_qy, J_qz) = (0, 0, 0, 0) cannot be normalised" \
        in messages[-1]


def test_a_floating_base_robot_fmu_steps_as_simulate(build_root, tmp_path):
    """Solo-12 thrown tumbling (a free joint and 12 revolute ones, 19 coordinates
    and 18 speeds), Co-Simulation in 0.05 s steps over the scene's 1 s against its
    own run (dop853 at rtol 1e-10 both)."""
    fmu = build_fmu(SCENES / "solo12_falling.yaml", tmp_path / "solo12.fmu",
                    out_dir=build_root / "solo12_falling")
    scene = modelgen.load_scene(SCENES / "solo12_falling.yaml")
    reference = scene.run()
    names = [*scene.model.coordinates, *scene.model.speeds]
    result = simulate_fmu(str(fmu.path), fmi_type="CoSimulation", stop_time=1.0,
                          output_interval=0.05, output=names)
    deviation = _deviation(result, reference, names)
    SUMMARY.append(f"fmu solo12_falling (Co-Simulation, 1 s): max |deviation| from "
                   f"simulate {deviation:.1e}")
    assert deviation < 1e-8
    assert len(names) == 37


def test_reading_a_free_body_fmus_derivatives_through_the_c(racket_scene, tmp_path):
    """fmi2GetDerivatives fills all 13 rates; the quaternion's is half the
    quaternion times the angular velocity (in the body's base)."""
    from fmpy import extract
    from fmpy.fmi2 import FMU2Model
    md = read_model_description(str(racket_scene.path))
    model = FMU2Model(guid=md.guid, unzipDirectory=extract(str(racket_scene.path),
                                                           unzipdir=str(tmp_path / "me")),
                      modelIdentifier=racket_scene.model_identifier, instanceName="me")
    model.instantiate()
    try:
        model.setupExperiment(startTime=0.0)
        model.enterInitializationMode()
        model.exitInitializationMode()
        model.enterContinuousTimeMode()
        x = (ctypes.c_double * 13)()
        model.getContinuousStates(x, 13)
        dx = (ctypes.c_double * 13)()
        model.getDerivatives(dx, 13)
        q, w = np.array(x[3:7]), np.array(x[10:13])
        expected = 0.5 * np.array([-q[1:] @ w, *(q[0] * w + np.cross(q[1:], w))])
        assert np.allclose(dx[3:7], expected, rtol=0, atol=1e-15)
        assert np.allclose(dx[0:3], 0.0) and np.allclose(dx[7:10], 0.0)
    finally:
        model.terminate()
        model.freeInstance()
