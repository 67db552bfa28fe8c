"""Fuzzing scene texts: only ModelErrors escape the scene loader, with file and line.

Scenes are drawn from a grammar of plausible and broken values for every
section (effects, added effects and parameters, initial state, time,
integrator, inputs, outputs of every kind), derandomized and bounded.
"""
from __future__ import annotations

import time

import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from conftest import MODELS  # noqa: E402
from modelgen.errors import ModelError, ModelgenError  # noqa: E402
from modelgen.model import parse_scene  # noqa: E402

names = st.sampled_from(["q1", "q2", "q1_dot", "P1", "G2", "B1", "B2", "E", "O", "rod1", "rod2",
                         "gravity", "motor", "c", "k", "zz", "", "1x", "a b", "é", "T1"])
numbers = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64).map(repr),
                    st.integers(-10**6, 10**6).map(str), st.just("1e400"), st.just("-0.0"),
                    st.just('"2*c"'), st.just('"sin("'), st.just("[1, 2]"), st.just("{}"))
values = st.one_of(names, numbers, st.just("null"), st.just("true"),
                   st.lists(st.one_of(names, numbers), max_size=3).map(lambda v: f"[{', '.join(v)}]"))
outputs = st.sampled_from([
    "{position: P1}", "{position: P1, from: O, base: E}", "{velocity: G2, base: B2}",
    "{orientation: B2, relative_to: E}", "{angular_velocity: B2, relative_to: B1, components: B2}",
    "{energy: total}", "{energy: totl}", "{pose: rod2}", "{generalized_force: damp}",
    "{position: ZZ}", "{velocity: P1, base: [1]}", "{}", "[]", "7", "{pose: rod2, extra: 1}"])


def mostly(valid, broken):
    """``valid`` about eight times in nine, else something from ``broken``."""
    return st.one_of(*([st.just(valid)] * 8), broken)


@st.composite
def scene_texts(draw):
    lines = ["scene: fuzz", "model: double_pendulum.yaml"]
    if draw(st.booleans()):
        lines.append(f"add_parameters: {{c: {draw(mostly('0.1', numbers))}}}")
    if draw(st.booleans()):
        lines.append("add_effects:\n  damp: {type: " + draw(mostly("joint_damping", st.sampled_from(
            ["spring", "damper", "friction", "drag", "nope"])))
            + f", coordinates: {draw(mostly('[q1, q2]', values))}, "
            f"damping: {draw(mostly('0.2', values))}}}")
    effects = draw(mostly(["gravity"], st.lists(names, max_size=3)))
    lines.append(f"effects: [{', '.join(effects)}]")
    lines.append(f"initial: {{q1: {draw(mostly('0.5', numbers))}, "
                 f"q2: {draw(mostly('0.1', values))}, q1_dot: 0.0, q2_dot: 0.0}}")
    lines.append(f"time: {{start: {draw(mostly('0.0', numbers))}, "
                 f"end: {draw(mostly('1.0', numbers))}, sample: {draw(mostly('0.01', numbers))}}}")
    lines.append("integrator: {method: " + draw(st.sampled_from(
        ["rk4", "dop853", "rodas", "gauss4", "euler", "", "1"])) + ", step: "
        + draw(mostly("0.001", numbers)) + ", rtol: " + draw(mostly("1e-6", numbers)) + "}")
    if draw(st.booleans()):
        lines.append(f"inputs: {{T1: {draw(values)}}}")
    lines.append("outputs:")
    for i, out in enumerate(draw(st.lists(outputs, max_size=4))):
        lines.append(f"  o{i}: {out}")
    return "\n".join(lines) + "\n"


@settings(max_examples=300, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(text=scene_texts())
def test_scene_loader_raises_only_model_errors_with_a_line(text):
    start = time.perf_counter()
    try:
        parse_scene(text, "fuzz.yaml", base_dir=MODELS)
    except ModelError as exc:
        assert exc.file is not None and exc.line is not None, str(exc)
    except ModelgenError as exc:          # pragma: no cover - would be a defect
        pytest.fail(f"{type(exc).__name__} instead of a ModelError: {exc}")
    assert time.perf_counter() - start < 2.0
