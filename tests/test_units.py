"""Units of a model's names: read, checked, written back, and carried into an FMU's
modelDescription; never part of the equations (the generated C does not change)."""
from __future__ import annotations

import pytest

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
    assert model_hash(spec) == model_hash(model(""))


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
