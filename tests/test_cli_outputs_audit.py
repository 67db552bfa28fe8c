"""What ``modelgen simulate`` writes, read back as a user would (an audit of the command
line's files): the NPZ names its model, scene, columns and their units and says where
a run stopped; the CSV is the Python API's run bit for bit; a failed run's plot says
it stopped; an -o that cannot be written is refused before the build; a rerun leaves
no plot of an earlier run; ``--help`` lists the exit statuses."""
from __future__ import annotations

import contextlib
import csv
import os
import shutil
import subprocess

import numpy as np
import pytest

import modelgen
from modelgen.cli import EXIT, main
from modelgen.cli.output_paths import column_units
from modelgen.model.spec import OutputSpec
from modelgen.sim.result import Result

from conftest import MODELS, SCENES

PENDULUM = MODELS / "simple_pendulum.yaml"


def test_the_npz_names_its_run_and_the_csv_is_the_python_run_bit_for_bit(tmp_path, build_root,
                                                                          capsys):
    """Before the audit the NPZ held the numbers, status and message only: no model or
    scene name, no column names (an output's layout), no units, no t_fail."""
    out = tmp_path / "a dir with spaces" / "résultats"        # created, any characters
    build = build_root / "cli_outputs_audit"
    assert main(["simulate", str(SCENES / "dp_damped.yaml"), "-o", str(out), "--build-dir",
                 str(build), "--no-plot", "-q"]) == 0
    assert f"wrote {out / 'dp_damped.csv'}" in capsys.readouterr().out
    res = modelgen.load_scene(SCENES / "dp_damped.yaml", build).run()
    with open(out / "dp_damped.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == res.columns() and len(rows) == len(res.t) + 1
    np.testing.assert_array_equal(np.array(rows[1:], dtype=float), res.table())
    np.testing.assert_array_equal(
        np.loadtxt(out / "dp_damped.csv", delimiter=",", skiprows=1), res.table())
    with np.load(out / "dp_damped.npz", allow_pickle=False) as npz:
        data = {key: npz[key] for key in npz.files}
    assert data["columns"].tolist() == rows[0]
    assert (str(data["model"]), str(data["scene"]), str(data["method"])) == \
        ("double_pendulum", "dp_damped", "rk4")
    units = dict(zip(rows[0], data["units"].tolist()))
    assert [units[c] for c in ("t", "q1", "q2_dot", "elbow.x", "energy", "kinetic",
                               "work.hinge_damping", "damping.q1")] == \
        ["s", "rad", "rad/s", "m", "J", "J", "J", "N.m"]
    assert float(data["t_reached"]) == 10.0 and np.isnan(data["t_fail"])
    assert not data["partial"] and data["status"] == 0
    assert all(value.dtype.kind in "biufU" for value in data.values())


def test_a_failed_run_says_where_it_stopped_in_its_files(tmp_path, build_root, capsys):
    """RK4 at 0.5 s steps blows the double pendulum up: exit 4; the CSV keeps the finite
    rows, the NPZ says why and when (t_fail), and the plot's title says it stopped
    (before the audit the title was the command's alone: nothing in the PNG said so)."""
    out = tmp_path / "out"
    status = main(["simulate", str(MODELS / "double_pendulum.yaml"), "--init", "q1=1.5",
                   "--init", "q2=0.5", "--dt", "0.5", "--t-end", "100", "-q",
                   "--build-dir", str(build_root / "cli_outputs_audit"), "-o", str(out)])
    assert status == EXIT["simulation"]
    assert "modelgen: simulation stopped: NaN or Inf" in capsys.readouterr().err
    table = np.loadtxt(out / "double_pendulum.csv", delimiter=",", skiprows=1)
    with np.load(out / "double_pendulum.npz", allow_pickle=False) as npz:
        assert npz["partial"] and npz["status"] == -4 and "NaN or Inf" in str(npz["message"])
        assert float(npz["t_fail"]) == float(npz["t_reached"]) == 2.0
        np.testing.assert_array_equal(table[:, 0], npz["t"])
    assert np.isfinite(table).all() and table[-1, 0] == 1.5
    res = Result(np.array([0.0, 1.5]), np.ones((2, 2)), state_names=("q", "q_dot"),
                 status=-4, t_fail=2.0, message="NaN or Inf in the state at t=2.0; last "
                 "finite state at t=1.5: x=[1e+300, 2e+300].")
    title = res.plot(title="pendulum: rk4, step 0.5 s").get_suptitle()
    assert title == "pendulum: rk4, step 0.5 s\nstopped at t = 2 s (status -4): NaN or Inf " \
        "in the state at t=2.0"


def test_output_panels_are_labelled_with_their_unit():
    res = Result(np.linspace(0, 1, 5), np.zeros((2, 5)), state_names=("q", "q_dot"),
                 outputs={"tip": np.zeros((5, 3)), "w": np.zeros((5, 3)),
                          "gf": np.zeros((5, 1))},
                 output_columns={"tip": ["tip.x", "tip.y", "tip.z"],
                                 "w": ["w.x", "w.y", "w.z"], "gf": ["gf.q"]})
    outputs = (OutputSpec("tip", "position", ()), OutputSpec("w", "angular_velocity", ()),
               OutputSpec("gf", "generalized_force", ()))
    res.info["units"] = column_units(res, outputs, {"q": "rad", "q_dot": "rad/s"})
    assert res.info["units"] == ["s", "rad", "rad/s", "m", "m", "m", "rad/s", "rad/s",
                                 "rad/s", "N.m"]
    labels = [ax.get_ylabel() for ax in res.plot().axes]
    assert labels[1:] == ["tip [m]", "w [rad/s]", "gf [N.m]"]
    res.info["units"] = column_units(res, outputs)            # a model without units:
    assert res.info["units"][1:3] == ["", ""] and res.info["units"][-1] == ""
    assert [ax.get_ylabel() for ax in res.plot().axes][-1] == "gf"


@contextlib.contextmanager
def _read_only_directory(path):
    """A directory this process cannot write into, or a skip: mode 555, and for root
    (whom modes do not stop) the immutable attribute."""
    path.mkdir()
    path.chmod(0o555)
    immutable = False
    if os.access(path, os.W_OK):
        if shutil.which("chattr") is None or subprocess.run(
                ["chattr", "+i", str(path)], capture_output=True).returncode != 0:
            path.chmod(0o755)
            pytest.skip("no way to make a directory read-only for this user")
        immutable = True
    try:
        yield path
    finally:
        if immutable:
            subprocess.run(["chattr", "-i", str(path)], check=True)
        path.chmod(0o755)


@pytest.mark.parametrize("where", ["ro", "ro/new/sub"])
def test_an_unwritable_output_directory_is_refused_before_the_build(tmp_path, capsys, where):
    """Before the audit the model was built and run, and only writing the NPZ failed
    (exit 2, "Operation not permitted", the run lost)."""
    never = tmp_path / "never"
    with _read_only_directory(tmp_path / "ro"):
        out = tmp_path / where
        assert main(["simulate", str(PENDULUM), "-o", str(out), "--build-dir", str(never),
                     "--t-end", "0.1", "-q"]) == EXIT["input"]
        err = capsys.readouterr().err
        assert f"modelgen: error: -o {out}: the directory {tmp_path / 'ro'} is not writable; " \
            f"fix: give -o a directory you can write to" in err, err
        assert not never.exists()
        assert main(["linearize", str(PENDULUM), "-o", str(out / "lin.npz"), "--build-dir",
                     str(never)]) == EXIT["input"]
        assert "is not writable" in capsys.readouterr().err and not never.exists()


def test_a_rerun_of_a_model_removes_the_plot_of_the_earlier_run(tmp_path, build_root):
    """A scene's rerun did; a model file's left the earlier PNG beside the new tables."""
    argv = ["simulate", str(PENDULUM), "-o", str(tmp_path), "--t-end", "0.2", "-q",
            "--build-dir", str(build_root / "cli_outputs_audit_pendulum")]
    assert main(argv) == 0 and (tmp_path / "simple_pendulum.png").is_file()
    assert main([*argv, "--no-plot"]) == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["simple_pendulum.csv",
                                                          "simple_pendulum.npz"]


def test_help_lists_the_exit_statuses_and_the_max_steps_default(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "exit status: 0 success; 2 bad input" in text
    assert "4 a simulation that failed (its partial results are written)" in text
    with pytest.raises(SystemExit):
        main(["simulate", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "(default: 100000, or the steps a fixed-step method needs for the span)" in text
    assert "errors, warnings and a failed run's reason are still printed" in text


def test_dt_with_an_adaptive_method_is_refused_for_a_model_as_for_a_scene(tmp_path, capsys):
    """--dt is "step of a fixed-step method": a model file's run with dop853 took it as
    the sample interval without a word, where a scene's run refuses it."""
    never = tmp_path / "never"
    for source in (PENDULUM, SCENES / "simple_pendulum_swing.yaml"):
        assert main(["simulate", str(source), "--method", "dop853", "--dt", "0.05", "-q",
                     "-o", str(tmp_path / "out"), "--build-dir", str(never)]) == EXIT["input"]
        err = capsys.readouterr().err
        assert "method dop853 adapts its steps to rtol and atol, so a step would be " \
            "ignored; fix: leave out --dt" in err, err
    assert not never.exists() and not (tmp_path / "out").exists()


def test_hard_cases_leaves_no_cut_figure_on_a_full_disk(tmp_path, monkeypatch, capsys):
    """Its table and figure were written in place: a full disk midway left a cut PNG
    under the final name, where every other result file is written whole or not at all."""
    import errno

    import modelgen.bench.hard_cases as hc

    class HalfFigure:
        def savefig(self, target, **options):
            with open(target, "wb") as fh:
                fh.write(b"\x89PNG half a figure")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    monkeypatch.setattr(hc, "run_cases", lambda *args, **kwargs: [])
    monkeypatch.setattr(hc, "figure", lambda results: HalfFigure())
    (tmp_path / "hard_cases.png").write_bytes(b"the previous figure")
    assert main(["hard-cases", "-o", str(tmp_path)]) == EXIT["input"]
    assert f"{tmp_path / 'hard_cases.png'} (the disk is full)" in capsys.readouterr().err
    assert (tmp_path / "hard_cases.png").read_bytes() == b"the previous figure"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hard_cases.md", "hard_cases.png"]
