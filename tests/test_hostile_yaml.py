"""Broken and hostile YAML: every failure is a ModelError with the file and the line.

Regression tests for the raw exceptions that escaped the loader (the
hostile-input issue, item 7): ReaderError for control characters, RecursionError
for deep nesting, ValueError/KeyError/OverflowError from YAML's own tagged
scalars, and a non-UTF-8 file without a line.
"""
from __future__ import annotations

import pytest

from modelgen.errors import ModelError
from modelgen.model import load_model, parse_model, parse_scene

BASE = "name: m\ncoordinates: [q]\nparameters: {m: 1.0}\n"


@pytest.mark.parametrize("text, line, message", [
    (BASE + 'description: "red \x1b[31m text"\n', 4, r"U\+001B"),
    (BASE + "description: a\x00b\n", 4, r"U\+0000"),
    (BASE + "description: a\ufffeb\n", 4, r"U\+FFFE"),
    (BASE.replace("1.0", "!!int abc"), 3, "cannot read the value 'abc' as int"),
    (BASE.replace("1.0", "!!int " + "9" * 5000), 3, "as int"),
    (BASE.replace("1.0", "!!float abc"), 3, "as float"),
    (BASE.replace("1.0", "!!bool maybe"), 3, "'maybe' as bool"),
    (BASE.replace("1.0", "1" + "0" * 400), 3, "beyond the range of a double"),
])
def test_bad_scalars_and_characters_are_model_errors_with_a_line(text, line, message):
    with pytest.raises(ModelError, match=message) as exc:
        parse_model(text, "m.yaml")
    assert exc.value.file == "m.yaml" and exc.value.line == line and exc.value.fix


@pytest.mark.parametrize("depth", [70, 400, 5000])
def test_deep_nesting_is_refused_not_a_recursion_error(depth):
    text = "name: m\nx: " + "[" * depth + "]" * depth + "\n"
    with pytest.raises(ModelError, match="nested"):
        parse_model(text, "m.yaml")
    with pytest.raises(ModelError, match="nested"):
        parse_scene("scene: s\nmodel: m.yaml\nx: " + "{a: " * depth + "1" + "}" * depth, "s.yaml")


def test_file_that_is_not_utf8_names_the_line(tmp_path):
    path = tmp_path / "latin1.yaml"
    path.write_bytes(b"name: m\ncoordinates: [q]\ndescription: caf\xe9\n")
    with pytest.raises(ModelError, match="not UTF-8") as exc:
        load_model(path)
    assert exc.value.line == 3 and exc.value.file == str(path)


def _body_with_inertia(inertia, parameters=None):
    from modelgen.model import Model
    m = Model("b")
    m.add_coordinate("q")
    if parameters:
        m.add_parameters(parameters)
    m.add_base("B", parent="E", axis=3, angle="q")
    m.add_point("G", parent="O", base="B", coordinates=[1, 0, 0])
    m.add_body("body", mass=1, G="G", base="B", inertia=inertia)
    return m


def test_inertia_tensors_computed_in_floating_point_are_accepted():
    """R diag(d) R^T differs by an ulp across the diagonal; 943 of 1,000 were refused."""
    import numpy as np
    rng = np.random.default_rng(0)
    for _ in range(200):
        R, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        d = np.sort(rng.uniform(0.1, 1.0, 3))
        d[2] = min(d[2], d[0] + d[1])
        inertia = R @ np.diag(d) @ R.T
        spec = _body_with_inertia(inertia.tolist()).spec()
        stored = np.array([[float(v) for v in row] for row in spec.bodies[0].inertia])
        assert np.array_equal(stored, stored.T)
        assert np.allclose(stored, inertia, rtol=0, atol=1e-15)


def test_asymmetric_symbolic_inertia_is_refused_quickly_without_expansion():
    """Entries that agree at the defaults but not elsewhere; the symbolic expansion of
    (a + b)**30 - (a + c)**30 took minutes and hundreds of MB."""
    import time
    start = time.perf_counter()
    with pytest.raises(ModelError, match=r"not symmetric: entry \[0\]\[1\]"):
        _body_with_inertia([[10, "(a+b)**30*1e-12", 0], ["(a+c)**30*1e-12", 10, 0],
                            [0, 0, 10]], {"a": 1.0, "b": 2.0, "c": 2.0}).spec()
    assert time.perf_counter() - start < 2.0
