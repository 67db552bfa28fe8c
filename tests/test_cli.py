"""The command line, called in-process through ``main(argv)``."""
from __future__ import annotations

import csv

import numpy as np
import pytest

import modelgen
from modelgen.cli import main

from conftest import MODELS


def test_generate_prints_sizes_operation_counts_and_stage_times(tmp_path, capsys):
    assert main(["generate", str(MODELS / "double_pendulum.yaml"), "-o", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "n          2 coordinates, 5 parameters, 1 inputs, 2 bodies" in out
    assert "ops before CSE" in out and "rhs" in out
    for stage in ("derive", "cse", "emit", "compile", "total"):
        assert f"\n{stage}" in out
    assert (tmp_path / "double_pendulum.c").is_file()
    assert (tmp_path / "double_pendulum.h").is_file()
    # a second run reuses the build
    assert main(["generate", str(MODELS / "double_pendulum.yaml"), "-o", str(tmp_path)]) == 0
    assert "reused the cached build" in capsys.readouterr().out


def test_simulate_writes_csv_and_png_with_small_energy_error(tmp_path, capsys):
    out_dir = tmp_path / "out"
    argv = ["simulate", str(MODELS / "double_pendulum.yaml"), "--build-dir", str(tmp_path / "b"),
            "-o", str(out_dir), "--init", "q1=1.0", "--t-end", "2", "--dt", "1e-3"]
    assert main(argv) == 0
    with open(out_dir / "double_pendulum.csv") as fh:
        rows = list(csv.reader(fh))
    assert rows[0][:5] == ["t", "q1", "q2", "q1_dot", "q2_dot"]
    data = np.array(rows[1:], dtype=float)
    assert data.shape[0] == 2001 and data[0, 1] == 1.0 and data[-1, 0] == 2.0
    total = data[:, -1]
    assert abs(total[-1] - total[0]) < 1e-8 * np.abs(data[:, -3:-1]).max()
    assert (out_dir / "double_pendulum.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_bad_model_exits_2_with_file_line_and_fix(tmp_path, capsys):
    bad = tmp_path / "bad.yaml"
    bad.write_text((MODELS / "double_pendulum.yaml").read_text().replace(
        "B2: {parent: B1, axis: 3", "B2: {parent: B1, axis: 7"))
    assert main(["generate", str(bad), "-o", str(tmp_path / "g")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("modelgen: error: ") and f"{bad}:" in err and "axis" in err


def test_unknown_initial_state_name_is_an_error(tmp_path, capsys):
    argv = ["simulate", str(MODELS / "simple_pendulum.yaml"), "--build-dir", str(tmp_path),
            "-o", str(tmp_path), "--init", "q9=1", "--no-plot"]
    assert main(argv) == 2
    assert "--init q9: unknown state" in capsys.readouterr().err


def test_help_lists_subcommands(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert "generate" in out and "simulate" in out


def _modelgen(*argv, cwd=None):
    """The real entry point, in a subprocess (``python -m modelgen``)."""
    import subprocess
    import sys
    return subprocess.run([sys.executable, "-m", "modelgen", *map(str, argv)], cwd=cwd,
                          capture_output=True, text=True, timeout=300)


def test_the_console_script_and_python_dash_m_run_the_same_entry_point():
    import tomllib
    from pathlib import Path
    root = Path(__file__).resolve().parent.parent
    scripts = tomllib.loads((root / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts["modelgen"] == "modelgen.cli:run"
    assert "from modelgen.cli import run" in (root / "modelgen" / "__main__.py").read_text()


def test_the_entry_point_exits_with_the_commands_status(tmp_path):
    proc = _modelgen("generate", tmp_path / "missing.yaml")
    assert proc.returncode == 2 and "modelgen: error:" in proc.stderr


def test_python_dash_m_modelgen_prints_the_version():
    from modelgen.version import __version__
    proc = _modelgen("--version")
    assert proc.returncode == 0 and proc.stdout.strip() == f"modelgen {__version__}"


@pytest.mark.parametrize("flags, message", [
    (["--set", "gg=1"], "--set gg: unknown parameter"),
    (["--set", "g=abc"], "'abc' is not a number or an expression of numbers (undefined "
                         "name 'abc'"),
    (["--init", "q1=pi/"], "'pi/' is not a number or an expression of numbers"),
    (["--dt", "-1"], "--dt must be a positive number"),
    (["--init", "q9=1"], "--init q9: unknown state"),
    (["--method", "rk44"], "unknown method 'rk44'"),
])
def test_scene_overrides_are_checked_with_exit_status_2(tmp_path, flags, message):
    from conftest import SCENES
    proc = _modelgen("simulate", SCENES / "dp_free.yaml", "-o", tmp_path / "out",
                     "--build-dir", tmp_path / "b", "--no-plot", *flags)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.startswith("modelgen: error: ") and message in proc.stderr
    assert "Traceback" not in proc.stderr


def test_scene_overrides_change_the_run(tmp_path):
    from conftest import SCENES
    out = tmp_path / "out"
    argv = ["simulate", str(SCENES / "dp_free.yaml"), "-o", str(out), "--build-dir",
            str(tmp_path / "b"), "--no-plot", "--t-end", "2", "--init", "q1=0.25",
            "--set", "g=1.62"]
    assert main(argv) == 0
    with np.load(out / "dp_free.npz") as npz:
        data = dict(npz)
    assert data["t"][-1] == 2.0 and data["y"][0, 0] == 0.25
    # the lunar gravity is used: the same run with the scene's own g differs
    assert main(argv[:-2]) == 0
    assert not np.allclose(np.load(out / "dp_free.npz")["y"][:, -1], data["y"][:, -1])


def test_failed_simulation_exits_4_and_keeps_its_partial_results(tmp_path):
    proc = _modelgen("simulate", MODELS / "double_pendulum.yaml", "--init", "q1=1.5",
                     "--init", "q2=0.5", "--dt", "0.5", "--t-end", "100", "--no-plot",
                     "--build-dir", tmp_path / "b", "-o", tmp_path / "out")
    assert proc.returncode == 4, proc.stderr
    assert "simulation stopped" in proc.stderr and "np.float64" not in proc.stderr
    assert (tmp_path / "out" / "double_pendulum.csv").stat().st_size > 0


def test_builds_go_to_the_user_cache_not_the_current_directory(tmp_path):
    import os
    import subprocess
    import sys
    cache, cwd = tmp_path / "cache", tmp_path / "work"
    cwd.mkdir()
    env = dict(os.environ, MODELGEN_CACHE_DIR=str(cache))
    proc = subprocess.run([sys.executable, "-m", "modelgen", "generate",
                           str(MODELS / "simple_pendulum.yaml")], cwd=cwd, env=env,
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert list(cwd.iterdir()) == []
    assert (cache / "models" / "simple_pendulum" / "simple_pendulum.c").is_file()
    assert str(cache / "models" / "simple_pendulum") in proc.stdout


@pytest.mark.parametrize("argv, message", [
    (["generate", "models/scenes/dp_free.yaml"], "is a scene file, not a model; fix: run it with"),
    (["bench", "models/double_pendulum.yaml"], "is a model file, not a scene"),
    (["bench", "models/nonexistent.yaml"], "no such file"),
])
def test_the_wrong_kind_of_file_says_which_command_to_use(argv, message, capsys):
    from conftest import ROOT
    argv = [argv[0], str(ROOT / argv[1])]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and "building" not in err


@pytest.mark.parametrize("argv, command", [
    (["simulate", "--bogus", "x.yaml"], "simulate"),
    (["generate", "--dt", "x", "m.yaml"], "generate"),
    (["simulate", "m.yaml", "--t-end", "abc"], "simulate"),
    (["bench", "s.yaml", "--quick", "--nope"], "bench"),
    (["import"], "import"),
])
def test_bad_subcommand_flags_print_that_subcommands_usage_and_exit_2(argv, command):
    proc = _modelgen(*argv)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.startswith(f"usage: modelgen {command} "), proc.stderr
    assert f"modelgen {command}: error: " in proc.stderr
    assert f"fix: see `modelgen {command} --help`" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_max_steps_truncation_is_printed_with_the_flag_that_raises_it(tmp_path):
    args = ("simulate", MODELS / "double_pendulum.yaml", "--init", "q1=1.5", "--method",
            "dop853", "--t-end", "20", "--no-plot", "--build-dir", tmp_path / "b",
            "-o", tmp_path / "out")
    proc = _modelgen(*args, "--max-steps", "50")
    assert proc.returncode == 4, proc.stderr
    assert "simulation stopped: Maximum number of steps (50) reached" in proc.stderr
    assert "--max-steps" in proc.stderr and "RuntimeWarning" not in proc.stderr
    assert _modelgen(*args, "--max-steps", "0").returncode == 2
    assert _modelgen(*args).returncode == 0


def _in_a_terminal(argv, env, timeout=300) -> str:
    """Run the real entry point with stdout and stderr on a pseudo-terminal; its output."""
    import fcntl
    import os
    import pty
    import struct
    import subprocess
    import sys
    import termios
    import time
    master, slave = pty.openpty()
    # a terminal of 30 rows and 120 columns (a fresh pty has 0 columns: no room for a bar)
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 30, 120, 0, 0))
    proc = subprocess.Popen([sys.executable, "-m", "modelgen", *map(str, argv)],
                            stdin=subprocess.DEVNULL, stdout=slave, stderr=slave, env=env)
    os.close(slave)
    chunks, deadline = [], time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            data = os.read(master, 65536)
        except OSError:              # EIO: the child closed the terminal
            break
        if not data:
            break
        chunks.append(data)
    os.close(master)
    assert proc.wait(timeout=60) == 0, b"".join(chunks).decode(errors="replace")
    return b"".join(chunks).decode(errors="replace")


def test_progress_bars_on_a_terminal_and_not_in_a_pipe_or_with_quiet(tmp_path):
    """On a terminal a build shows its stages and a run its simulated time as tqdm bars
    (here from the first moment: MODELGEN_PROGRESS_DELAY=0 instead of 2 s); through a
    pipe, or with --quiet, nothing of the kind is written."""
    import os
    import subprocess
    import sys
    from conftest import SCENES
    pytest.importorskip("tqdm")
    env = dict(os.environ, MODELGEN_PROGRESS_DELAY="0")
    argv = ["simulate", SCENES / "dp_damped.yaml", "--no-plot", "-o", tmp_path / "out",
            "--t-end", "2"]
    tty = _in_a_terminal([*argv, "--build-dir", tmp_path / "b1"], env)
    assert "stages |" in tty and "dp_damped: derive" in tty, tty
    assert "dp_damped: integrating |" in tty and "% of 0..2 s" in tty, tty
    quiet = _in_a_terminal([*argv, "--build-dir", tmp_path / "b2", "--quiet"], env)
    assert "stages |" not in quiet and "integrating |" not in quiet, quiet
    piped = subprocess.run([sys.executable, "-m", "modelgen", *map(str, argv),
                            "--build-dir", str(tmp_path / "b3")], env=env,
                           capture_output=True, text=True, timeout=300)
    assert piped.returncode == 0, piped.stderr
    assert "stages |" not in piped.stderr and "integrating |" not in piped.stderr, piped.stderr
    assert "work done: hinge_damping" in piped.stdout        # the run itself is the same


def test_an_output_path_that_is_a_file_is_refused_before_anything_runs(tmp_path):
    taken = tmp_path / "taken"
    taken.write_text("a file")
    for source in (MODELS / "double_pendulum.yaml", MODELS / "scenes" / "dp_free.yaml"):
        proc = _modelgen("simulate", source, "-o", taken / "sub", "--t-end", "0.1", cwd=tmp_path)
        assert proc.returncode == 2, proc.stderr
        assert "is a file, not a directory; fix:" in proc.stderr
        assert "integrating" not in proc.stderr and "generating" not in proc.stderr


def test_generate_prints_the_dependent_coordinates_and_speeds(tmp_path, capsys):
    """Declared in the model (the four-bar's q2, q3), and chosen by modelgen when the
    model declares none: then the names printed are the manifest's and their
    columns of the constraint Jacobian are regular at an assembled configuration."""
    assert main(["generate", str(MODELS / "four_bar.yaml"), "-o", str(tmp_path / "a")]) == 0
    out = capsys.readouterr().out
    assert "constraints 2 equations (2 on positions), dependent coordinates and speeds " \
        "declared in the model" in out
    assert "dependent  coordinates q2, q3; speeds q2_dot, q3_dot\n" in out
    assert "independent speeds q1_dot\n" in out
    # the same from a reused build
    assert main(["generate", str(MODELS / "four_bar.yaml"), "-o", str(tmp_path / "a")]) == 0
    again = capsys.readouterr().out
    assert "reused the cached build" in again
    assert "dependent  coordinates q2, q3; speeds q2_dot, q3_dot\n" in again

    text = (MODELS / "four_bar.yaml").read_text()
    free = tmp_path / "four_bar.yaml"
    free.write_text("\n".join(line for line in text.splitlines()
                              if not line.startswith("dependent:")) + "\n")
    assert main(["generate", str(free), "-o", str(tmp_path / "b")]) == 0
    out = capsys.readouterr().out
    assert "dependent coordinates and speeds chosen by modelgen" in out
    line = next(x for x in out.splitlines() if x.startswith("dependent  coordinates "))
    coords, speeds = line[len("dependent  coordinates "):].split("; speeds ")
    coords, speeds = coords.split(", "), speeds.split(", ")
    cm = modelgen.load(free, out_dir=tmp_path / "b")
    c = cm.manifest["constraints"]
    assert coords == [cm.coordinates[k] for k in c["dependent_coordinates"]]
    assert speeds == [cm.speeds[k] for k in c["dependent_speeds"]] and len(speeds) == 2
    q = cm.assemble([0.3, 1.0, 2.0], keep=["q1"])
    G = cm.constraint_jacobian(q)
    assert abs(np.linalg.det(G[:, c["dependent_speeds"]])) > 1e-3
    independent = [s for s in cm.speeds if s not in speeds]
    assert f"independent speeds {', '.join(independent)}\n" in out
