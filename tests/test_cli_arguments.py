"""Arguments checked before anything is built or run, each message naming the flag or
argument at fault and the fix (a probe of the CLI, the sweep API and scene files):
a bad --scheduler, --chunk, --rtol or --method of a sweep; an -o that cannot be
written; a --trace point the model lacks; the Python sweep's arguments; a scene's
step longer than its span; and --step of an FMU with an adaptive method."""
from __future__ import annotations

import importlib.util

import numpy as np
import pytest

import modelgen
from modelgen.cli import EXIT, main
from modelgen.errors import ArgumentTypeError, ArgumentValueError, ModelError
from modelgen.model.scene import parse_scene

from conftest import MODELS, ROOT, SCENES

DP_DAMPED = SCENES / "dp_damped.yaml"
HAS_SWEEP = all(importlib.util.find_spec(m) for m in ("xarray", "distributed"))
needs_sweep = pytest.mark.skipif(not HAS_SWEEP, reason="needs xarray and distributed")


def _refused(argv, never, capsys) -> str:
    """Run ``argv``; it must exit 2 with one error line and no build in ``never``."""
    assert main([str(a) for a in argv]) == EXIT["input"]
    err = capsys.readouterr().err
    assert "modelgen: error: " in err and "internal error" not in err, err
    assert "<model>" not in err, err
    assert not never.exists(), "the model was built before the argument was checked"
    return err


# -- sweep flags ---------------------------------------------------------------------------

@needs_sweep
@pytest.mark.parametrize("flags, phrase", [
    (["--scheduler", "garbage"], "--scheduler 'garbage' is not a Dask scheduler address"),
    (["--scheduler", "tcp://host"], "tcp://HOST:PORT"),
    (["--chunk", "-1"], "--chunk must be a positive number"),
    (["--chunk", "0"], "--chunk must be a positive number"),
    (["--rtol", "-1"], "--rtol must be a positive number"),
    (["--rtol", "nan"], "--rtol must be a positive number"),
    (["--method", "bogus"], "--method: unknown method 'bogus'"),
    (["--method", "gauss4", "--param", "c=0:1:2"], "--method gauss4 has a fixed step; fix: give --dt"),
    (["--param", "bogus=1:2:3"], "--param: unknown parameter 'bogus'"),
    (["--init", "q9=1"], "--init: unknown state 'q9'"),
    # the scene file's time rules, as simulate applies them
    (["--method", "rk4", "--dt", "0.003", "--param", "c=0:1:2"],
     "the sample interval 0.01 is not a whole multiple of the step 0.003"),
    (["--method", "rk4", "--dt", "1e-12", "--param", "c=0:1:2"], "more than the 1e+09"),
])
def test_bad_sweep_flags_are_usage_errors_before_the_build(flags, phrase, tmp_path, capsys):
    never = tmp_path / "never"
    scene = SCENES / "four_bar_swing.yaml"         # dop853: a fixed-step --method needs --dt
    err = _refused(["sweep", scene, *flags, "--build-dir", never, "-o", tmp_path / "s.nc",
                    "--quiet"], never, capsys)
    assert phrase in err, err


# -- -o that cannot be written ---------------------------------------------------------------

def _output_cases(tmp_path):
    afile = tmp_path / "afile"
    afile.write_text("a file")
    adir = tmp_path / "adir.npz"
    adir.mkdir()
    urdf = ROOT / "tests" / "data" / "urdf" / "double_pendulum.urdf"
    model = MODELS / "simple_pendulum.yaml"
    cases = [
        (["import", urdf, "-o", afile / "x.yaml"], f"{afile} is a file, not a directory"),
        (["import", urdf, "-o", adir], f"{adir} is a directory, not a file"),
        (["fmu", model, "-o", afile / "x"], f"{afile} is a file, not a directory"),
        (["fmu", model, "-o", afile / "x.fmu"], f"{afile} is a file, not a directory"),
        (["linearize", model, "-o", afile / "x.npz"], f"{afile} is a file, not a directory"),
        (["linearize", model, "-o", adir], f"{adir} is a directory, not a file"),
    ]
    if HAS_SWEEP:
        cases += [(["sweep", DP_DAMPED, "--param", "g=1:2:3", "-o", afile / "x.nc"],
                   f"{afile} is a file, not a directory"),
                  (["sweep", DP_DAMPED, "--param", "g=1:2:3", "-o", adir],
                   f"{adir} is a directory, not a file")]
    return cases


def test_an_output_that_cannot_be_written_is_refused_naming_o_before_the_work(tmp_path,
                                                                               capsys):
    for k, (argv, phrase) in enumerate(_output_cases(tmp_path)):
        never = tmp_path / f"never{k}"
        build = [] if argv[0] == "import" else ["--build-dir", never]
        err = _refused([*argv, *build], never, capsys)
        assert f"-o {argv[argv.index('-o') + 1]}: {phrase}; fix:" in err, (argv, err)
    assert "modes" not in capsys.readouterr().out      # linearize printed no result


def test_bench_of_a_directory_says_it_is_a_directory(tmp_path, capsys):
    err = _refused(["bench", tmp_path, "--build-dir", tmp_path / "never"], tmp_path / "never",
                   capsys)
    assert f"{tmp_path} is a directory, not a scene file; fix:" in err


# -- simulate and generate -----------------------------------------------------------------

@pytest.mark.parametrize("source", [SCENES / "simple_pendulum_swing.yaml",
                                    MODELS / "simple_pendulum.yaml"])
def test_an_unknown_trace_point_is_refused_before_the_run(source, tmp_path, capsys):
    never, out = tmp_path / "never", tmp_path / "out"
    err = _refused(["simulate", source, "--trace", "ZZ", "--animate", "-o", out,
                    "--build-dir", never, "--t-end", "0.1", "-q"], never, capsys)
    assert "--trace ZZ: unknown point of model" in err and str(source) in err
    assert "fix: trace one of O, P" in err
    assert not out.exists()                         # no CSV written before the refusal
    # without --animate, --trace would do nothing: refused, not ignored
    err = _refused(["simulate", source, "--trace", "P", "-o", out, "--build-dir", never,
                    "--t-end", "0.1", "-q"], never, capsys)
    assert "--trace draws a point's path in the animation; fix: add --animate" in err
    assert not out.exists()


@pytest.mark.parametrize("command", ["generate", "simulate"])
def test_a_negative_max_operations_names_the_flag_not_a_placeholder(command, tmp_path,
                                                                    capsys):
    never = tmp_path / "never"
    build = ["-o", never] if command == "generate" else ["--build-dir", never, "-o",
                                                         tmp_path / "out"]
    err = _refused([command, MODELS / "simple_pendulum.yaml", "--max-operations", "-1",
                    *build], never, capsys)
    assert "--max-operations must be a positive number of operations, got -1; fix:" in err


# -- the Python API of sweeps ------------------------------------------------------------------

@needs_sweep
@pytest.mark.parametrize("kwargs, error, phrase", [
    (dict(parameters={"g": "abc"}), ArgumentTypeError, "parameter 'g' must be a real number"),
    (dict(parameters={"g": 1 + 2j}), ArgumentTypeError, "parameter 'g' must be a real number"),
    (dict(parameters={"g": []}), ArgumentValueError, "parameter 'g' must be one value or a "
                                                     "non-empty"),
    (dict(parameters=[1.0, 2.0]), ArgumentTypeError, "parameters must map parameter names"),
    (dict(initial={"q1": "abc"}), ArgumentTypeError, "state 'q1' must be a real number"),
    (dict(t_eval="abc"), ArgumentTypeError, "t_eval must be a real number"),
    (dict(x0="abc"), ArgumentTypeError, "x0 must be a real number"),
    (dict(chunk="a"), ArgumentTypeError, "chunk must be an integer"),
    (dict(chunk=0), ArgumentValueError, "chunk must be >= 1"),
    (dict(max_steps="a"), ArgumentTypeError, "max_steps must be an integer"),
    (dict(client="garbage"), ArgumentValueError, "client 'garbage' is not a Dask scheduler"),
    (dict(client=3), ArgumentTypeError, "client must be a string or a Client, got 3; fix"),
    (dict(progress=3), ArgumentTypeError, "progress must be None or a callable"),
])
def test_bad_sweep_arguments_name_the_argument_and_the_fix_before_loading(kwargs, error,
                                                                          phrase, tmp_path):
    never = tmp_path / "never"
    with pytest.raises(error, match="; fix: ") as info:
        modelgen.sweep(DP_DAMPED, build_dir=never, **kwargs)
    assert phrase in str(info.value)
    assert not never.exists()


@pytest.mark.parametrize("axis, error", [("abc", ArgumentTypeError), (1j, ArgumentTypeError),
                                         ([], ArgumentValueError),
                                         ([[1.0, 2.0]], ArgumentValueError)])
def test_bad_grid_axes_name_the_axis_and_the_fix(axis, error):
    with pytest.raises(error, match=r"grid axis 'g' must .*; fix: give"):
        modelgen.grid(g=axis)


def test_grid_still_takes_lists_of_numbers_and_objects_that_are_numbers():
    from fractions import Fraction
    g = modelgen.grid(a=[1, 2], b=np.array([Fraction(1, 2)], dtype=object))
    assert g["a"].tolist() == [1.0, 2.0] and g["b"].tolist() == [0.5, 0.5]


# -- scenes: the step ----------------------------------------------------------------------------

_SCENE = """scene: s
model: {model}
effects: [gravity]
initial: {{q: 0.5, q_dot: 0.0}}
time: {{end: 0.2, sample: 0.01}}
integrator: {{method: {method}, step: {step}}}
"""


def _scene(method, step):
    return _SCENE.format(model=MODELS / "simple_pendulum.yaml", method=method, step=step)


def test_a_step_longer_than_the_span_suggests_a_shorter_step_not_a_huge_sample():
    with pytest.raises(ModelError) as info:
        parse_scene(_scene("rk4", "1e300"), "s.yaml")
    text = str(info.value)
    assert text.startswith("s.yaml:6: integrator.step: the step 1e+300 is longer than the "
                           "time span 0.2 s; fix: give a step that divides time.sample, e.g. "
                           "step: 0.002"), text
    assert "1e+300" not in text.split("fix:")[1]
    # the suggestion itself is accepted
    assert parse_scene(_scene("rk4", "0.002"), "s.yaml").step == 0.002
