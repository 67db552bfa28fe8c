"""Units of a model's names: read, checked, written back, carried into the compiled
model (``cm.units``), a sweep's dataset and an FMU's modelDescription; never part
of the equations (the generated C does not change)."""
from __future__ import annotations

import numpy as np
import pytest

import modelgen
from modelgen.codegen.pipeline import model_hash
from modelgen.errors import ModelError
from modelgen.model import parse_model
from modelgen.model.writer import spec_to_yaml

BASE = ("{name: m, coordinates: [q], parameters: {L: 1.0, g: 9.81}, inputs: [T], "
        "bases: {B: {parent: E, axis: 3, angle: q}}, points: {P: {from: O, base: B, "
        "coordinates: [0, -L, 0]}}, bodies: {b: {mass: 1, G: P, base: B}}, gravity: [0, -g, 0]")


def model(units: str):
    return parse_model(BASE + (f", units: {units}" if units else "") + "}")


def test_units_are_read_written_back_and_leave_the_equations_alone():
    spec = model("{q: rad, L: m, g: m/s^2, T: N*m}")
    assert dict(spec.units) == {"q": "rad", "L": "m", "g": "m/s^2", "T": "N*m"}
    again = parse_model(spec_to_yaml(spec))
    assert again.units == spec.units
    assert model_hash(spec) == model_hash(model("{L: m, q: rad, T: N*m, g: m/s^2}"))


def test_units_reach_the_compiled_model_and_change_no_line_of_c(tmp_path):
    """``cm.units`` (a speed: its coordinate's per second) from the manifest.  The C
    is the same with and without units, but the build is another: a cached build
    must not answer a model whose units changed with the old ones."""
    with_units = modelgen.load(model("{q: rad, L: m, T: N*m}"), tmp_path / "a")
    assert with_units.units == {"q": "rad", "q_dot": "rad/s", "L": "m", "T": "N*m"}
    changed = modelgen.load(model("{q: deg, L: cm}"), tmp_path / "a")
    assert changed.units == {"q": "deg", "q_dot": "deg/s", "L": "cm"}
    bare = modelgen.load(model(""), tmp_path / "b")
    assert bare.units == {}
    code = [[line for line in (tmp_path / d / "m.c").read_text().splitlines()
             if not line.startswith(" * Model hash: ")] for d in "ab"]
    assert code[0] == code[1] and len(code[0]) > 100
    x = [0.3, -0.2]
    assert np.array_equal(changed.rhs(0.0, x), bare.rhs(0.0, x))


def test_a_sweep_gives_each_state_and_swept_value_its_unit(tmp_path):
    pytest.importorskip("xarray")
    from conftest import MODELS
    ds = modelgen.sweep(MODELS / "cart_pole.yaml", parameters={"m": [0.1, 0.2]},
                        initial={"theta": 0.1}, t_eval=np.linspace(0.0, 0.1, 3),
                        build_dir=tmp_path)
    units = {name: ds[name].attrs.get("units") for name in
             ("x", "theta", "x_dot", "theta_dot", "m", "initial_theta", "time", "status")}
    assert units == {"x": "m", "theta": "rad", "x_dot": "m/s", "theta_dot": "rad/s",
                     "m": "kg", "initial_theta": "rad", "time": "s", "status": None}
    from modelgen.sim.sweep import plot_scalar
    fig = plot_scalar(ds, "final", "x")
    assert fig.axes[0].get_xlabel() == "m [kg]" and fig.axes[0].get_ylabel() == "final x [m]"


@pytest.mark.parametrize("units, message", [
    ("{q_dot: rad/s}", "'q_dot' is not a declared coordinate, parameter or input"),
    ("{B: rad}", "'B' is not a declared coordinate, parameter or input"),
    ("{L: 3}", "the unit of 'L' must be short plain text"),
    ("{L: 'm\\\" onload=\\\"x'}", "the unit of 'L' must be short plain text"),
    ("{L: '<b>m</b>'}", "the unit of 'L' must be short plain text"),
    ("[m, kg]", "expected a mapping of names to units"),
])
def test_bad_units_name_the_key_and_the_fix(units, message):
    with pytest.raises(ModelError, match=message) as info:
        model(units)
    assert "units" in str(info.value) and "fix" in str(info.value).lower()


def test_an_fmu_carries_the_units(tmp_path):
    pytest.importorskip("fmpy")
    from fmpy import read_model_description

    from modelgen.codegen.fmu import build_fmu
    from conftest import MODELS
    fmu = build_fmu(MODELS / "cart_pole.yaml", tmp_path / "cp.fmu", out_dir=tmp_path / "b")
    md = read_model_description(str(fmu.path), validate=True)
    unit = {v.name: (v.unit or "") for v in md.modelVariables}
    assert (unit["x"], unit["x_dot"], unit["der(x_dot)"]) == ("m", "m/s", "m/s2")
    assert (unit["theta"], unit["der(theta)"], unit["M"], unit["F"]) == ("rad", "rad/s", "kg", "N")
    assert {u.name for u in md.unitDefinitions} >= {"m", "m/s", "rad", "kg", "N"}
