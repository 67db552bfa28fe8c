"""The command line's outcomes on hostile input: the documented exit status for every
misuse found by an audit (issue 24), output budgets checked before anything runs,
results written whole or not at all, SIGTERM handled as Ctrl-C, and the messages."""
from __future__ import annotations

import errno
import importlib.util
import os
import re
import signal
import subprocess
import sys

import numpy as np
import pytest

from modelgen.cli import EXIT, main
from modelgen.sim.result import Result

from conftest import MODELS, ROOT, SCENES

DP = MODELS / "double_pendulum.yaml"
DP_FREE = SCENES / "dp_free.yaml"
HAS_XARRAY = importlib.util.find_spec("xarray") is not None

#: (argv after the build and output flags, the documented status, a phrase of the message);
#: each one exited 1 ("internal error") or 4 ("simulation failed") before issue 24
CASES = [
    (["simulate", DP_FREE, "--t-end", "1e300"], 2, "--max-output-mb"),
    (["simulate", DP_FREE, "--sample", "1e-300"], 2, "--max-output-mb"),
    (["simulate", DP_FREE, "--t-end", "10000", "--sample", "1e-4"], 2, "1e+08 samples"),
    (["simulate", DP, "--dt", "1e-300"], 2, "--max-output-mb"),
    (["simulate", DP_FREE, "--dt", "1e-300"], 2, "more than the C integrator can count"),
    (["simulate", DP_FREE, "--set", "g=nan"], 2, "must be a finite number"),
    (["simulate", DP_FREE, "--set", "g=inf"], 2, "must be a finite number"),
    (["simulate", DP_FREE, "--init", "q1=nan"], 2, "must be a finite number"),
    (["simulate", DP_FREE, "--floating-base"], 2, "--floating-base applies to a URDF"),
    (["generate", DP, "--floating-base"], 2, "--floating-base applies to a URDF"),
    (["linearize", DP, "--equilibrium", "--at", "q1=nan"], 2, "must be a finite number"),
    (["linearize", MODELS / "spring_chain.yaml", "--equilibrium", "--set", "k=0"], 2,
     "q_ddot is not finite"),
    (["linearize", DP, "--t", "nan"], 2, "--t must be a finite time"),
    pytest.param(["sweep", DP_FREE, "--param", "bogus=1:2:3"], 2, "unknown parameter 'bogus'",
                 marks=pytest.mark.skipif(not HAS_XARRAY, reason="needs xarray")),
    pytest.param(["sweep", DP_FREE, "--param", "g=1:2:100000000"], 2, "1e+08 runs",
                 marks=pytest.mark.skipif(not HAS_XARRAY, reason="needs xarray")),
    # --debug shows the traceback and keeps the status
    (["--debug", "simulate", DP_FREE, "--set", "g=nan"], 2, "must be a finite number"),
    (["--debug", "linearize", DP, "--t", "nan"], 2, "Traceback"),
]


def _argv(case, tmp_path, build):
    """``case`` with the build directory and an output beside it."""
    argv = [str(a) for a in case]
    command = next(a for a in argv if not a.startswith("--"))
    extra = {"simulate": ["--build-dir", str(build), "-o", str(tmp_path / "out"), "--no-plot"],
             "linearize": ["--build-dir", str(build)],
             "generate": ["-o", str(build)],
             "sweep": ["--build-dir", str(build), "-o", str(tmp_path / "sweep.nc"), "--quiet"]}
    return argv + extra[command]


@pytest.mark.parametrize("case, status, message", CASES)
def test_every_misuse_exits_with_its_documented_status(case, status, message, tmp_path,
                                                       build_root, capsys):
    assert main(_argv(case, tmp_path, build_root / "cli_outcomes")) == status
    err = capsys.readouterr().err
    assert "modelgen: error: " in err and message in err, err
    assert "internal error" not in err
    assert ("Traceback" in err) == ("--debug" in map(str, case))
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_mp4_without_ffmpeg_is_refused_before_the_run(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("PATH", str(tmp_path))          # no ffmpeg on it
    argv = ["simulate", str(DP_FREE), "--animate", "--animate-format", "mp4",
            "-o", str(tmp_path / "out"), "--build-dir", str(tmp_path / "never")]
    assert main(argv) == EXIT["input"]
    assert "needs ffmpeg" in capsys.readouterr().err
    assert not (tmp_path / "never").exists() and not (tmp_path / "out").exists()


def test_max_output_mb_raises_the_budget(tmp_path, build_root, capsys):
    argv = ["simulate", str(DP), "--t-end", "1", "--build-dir", str(build_root / "cli_outcomes"),
            "-o", str(tmp_path), "--no-plot"]
    # 1001 samples x 8 columns: 64 kB of doubles and 160 kB of CSV text
    assert main([*argv, "--max-output-mb", "0.1"]) == 2
    assert "0.2242 MB (1001 samples x 8 columns)" in capsys.readouterr().err
    assert main([*argv, "--max-output-mb", "0.3"]) == 0


# -- results written whole or not at all ------------------------------------------------

class _InterruptedFile:
    """A file whose third write is interrupted, as by a Ctrl-C between two blocks."""

    def __init__(self, fh):
        self.fh, self.writes = fh, 0

    def write(self, text):
        self.writes += 1
        if self.writes == 3:
            raise KeyboardInterrupt
        return self.fh.write(text)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return self.fh.__exit__(*exc)


def test_an_interrupted_csv_never_leaves_a_cut_file(tmp_path, monkeypatch):
    from pathlib import Path
    path = tmp_path / "run.csv"
    path.write_text("the previous complete file\n")
    res = Result(np.linspace(0, 1, 20000), np.zeros((2, 20000)), state_names=("q1", "q1_dot"))
    real_open = Path.open
    monkeypatch.setattr(Path, "open", lambda self, *a, **k: _InterruptedFile(real_open(self, *a,
                                                                                       **k)))
    with pytest.raises(KeyboardInterrupt):
        res.to_csv(path)
    monkeypatch.undo()
    assert path.read_text() == "the previous complete file\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.csv"]


def test_csv_formats_repeated_and_constant_columns_once_and_exactly(tmp_path, monkeypatch):
    """Formatting floats is the cost of a long run's CSV (170,001 samples x 43 columns
    of a scene took 3.7 s of CPU): columns equal to others or constant over a block
    are formatted once and reused.  The text is still every value's repr, with -0.0,
    NaN and Inf kept apart from their look-alikes."""
    import modelgen.sim.result as result_module
    calls = []

    def counting_repr(value):
        calls.append(value)
        return repr(value)
    monkeypatch.setattr(result_module, "repr", counting_repr, raising=False)
    rng = np.random.default_rng(7)
    y = rng.normal(size=(7, 9000))
    y[1] = y[0]                          # a repeated column
    y[2] = 0.0                           # constant
    y[3] = -0.0                          # constant, but not the same bits as 0.0
    y[4] = -y[0]                         # a negated one
    y[5, :4000] = np.nan                 # constant over a block only
    y[6] = np.where(np.arange(9000) % 2, np.inf, -np.inf)
    res = Result(np.linspace(0, 1, 9000), y, state_names=tuple(f"s{i}" for i in range(7)))
    lines = res.to_csv(tmp_path / "r.csv").read_bytes().decode().split("\r\n")
    assert lines[-1] == "" and len(lines) == 9002
    expected = [",".join(map(repr, row)) for row in res.table().tolist()]
    assert lines[1:-1] == expected
    # per block of rows: t, s0, s4, s5, s6 every value; s1 is s0; s2 and s3 one each
    blocks = -(-9000 // result_module.CSV_BLOCK)
    assert len(calls) == 5 * 9000 + 2 * blocks


def test_a_full_disk_names_the_file_and_leaves_no_cut_npz(tmp_path, monkeypatch, capsys):
    def savez_on_a_full_disk(file, **arrays):
        with open(file, "wb") as fh:
            fh.write(b"PK\x03\x04 half an archive")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    monkeypatch.setattr(np, "savez", savez_on_a_full_disk)
    out = tmp_path / "out"
    argv = ["simulate", str(MODELS / "simple_pendulum.yaml"), "--t-end", "0.1",
            "--build-dir", str(tmp_path / "b"), "-o", str(out), "--no-plot"]
    assert main(argv) == EXIT["input"]
    err = capsys.readouterr().err
    assert f"no space left on the device: {out / 'simple_pendulum.npz'} (the disk is full)" \
        in err, err
    assert "None" not in err
    assert sorted(p.name for p in out.iterdir()) == []     # the NPZ is written first


def test_an_import_that_fails_midway_leaves_the_previous_model_file(tmp_path, monkeypatch,
                                                                   capsys):
    """`modelgen import` writes the model file beside and renames it: a full disk
    midway leaves the earlier file as it was and no cut YAML under its name."""
    from pathlib import Path
    out = tmp_path / "robot.yaml"
    out.write_text("# the previous complete model\n")
    real = Path.write_text

    def half_then_full_disk(path, text, *args, **kwargs):
        real(path, text[:len(text) // 2], *args, **kwargs)
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    monkeypatch.setattr(Path, "write_text", half_then_full_disk)
    urdf = ROOT / "tests" / "data" / "urdf" / "double_pendulum.urdf"
    assert main(["import", str(urdf), "-o", str(out)]) == EXIT["input"]
    assert f"{out} (the disk is full)" in capsys.readouterr().err
    assert out.read_text() == "# the previous complete model\n"
    assert [p.name for p in tmp_path.iterdir()] == ["robot.yaml"]
    monkeypatch.setattr(Path, "write_text", real)
    assert main(["import", str(urdf), "-o", str(out)]) == 0
    assert "joint1" in out.read_text() and [p.name for p in tmp_path.iterdir()] == ["robot.yaml"]


def test_csv_round_trips_every_value_and_keeps_its_layout(tmp_path):
    rng = np.random.default_rng(24)
    y = rng.normal(size=(2, 500)) * 10.0 ** rng.integers(-300, 300, size=(2, 500))
    y[0, :3] = [np.nan, np.inf, -0.0]
    res = Result(np.linspace(0, 1, 500), y, state_names=("q1", "q1_dot"))
    text = res.to_csv(tmp_path / "r.csv").read_bytes()
    lines = text.split(b"\r\n")
    assert lines[0] == b"t,q1,q1_dot" and lines[-1] == b"" and len(lines) == 502
    back = np.array([[float(v) for v in line.split(b",")] for line in lines[1:-1]])
    np.testing.assert_array_equal(back, res.table())
    assert lines[1].split(b",")[1:] == [b"nan", repr(float(y[1, 0])).encode()]


def test_energies_of_a_run_match_the_per_sample_energy(compiled):
    cm = compiled("double_pendulum")
    res = cm.simulate([1.0, 0.5, 0.0, 0.0], (0, 1), t_eval=np.linspace(0, 1, 51))
    expected = [cm.energy(x[:cm.nq], x[cm.nq:], {"g": 3.0}) for x in res.y.T]
    np.testing.assert_array_equal(cm.energies(res, {"g": 3.0}), expected)


# -- signals -----------------------------------------------------------------------------

def test_sigterm_keeps_and_writes_the_partial_run_and_exits_143(tmp_path):
    out = tmp_path / "out"
    # 10^8 fixed steps: minutes of integration, stopped after a few seconds
    proc = subprocess.Popen(
        [sys.executable, "-m", "modelgen", "simulate", str(DP_FREE), "--t-end", "1000",
         "--dt", "1e-5", "--sample", "0.5", "--no-plot", "--build-dir", str(tmp_path / "b"),
         "-o", str(out)], stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
        env={**os.environ, "PYTHONPATH": str(ROOT)})
    for line in proc.stderr:
        if "integrating" in line:
            break
    import time
    # the line comes just before the C run starts; on a loaded machine the set-up
    # after it can take a while, and a signal then stops a run that has no samples
    time.sleep(3.0)
    proc.send_signal(signal.SIGTERM)
    stdout, stderr = proc.communicate(timeout=120)
    assert proc.returncode == EXIT["terminated"] == 143, stderr
    assert "simulation stopped" in stderr and "partial" in stdout
    with np.load(out / "dp_free.npz") as npz:
        assert bool(npz["partial"]) and 0 < npz["t"][-1] < 1000
        rows = len(npz["t"])
    assert len((out / "dp_free.csv").read_text().splitlines()) == rows + 1


# -- messages ----------------------------------------------------------------------------

def test_linearize_prints_no_negative_zeros_and_labels_d(tmp_path, build_root, capsys):
    assert main(["linearize", str(SCENES / "cart_pole_push.yaml"),
                 "--build-dir", str(build_root / "cli_outcomes")]) == 0
    out = capsys.readouterr().out
    assert not re.search(r"-0\.(\s|0*\s|0*\])", out), out
    assert "\nD:" not in out and "D (rows: the outputs of C; columns: " in out


@pytest.mark.skipif(importlib.util.find_spec("distributed") is None, reason="needs dask")
def test_an_unreachable_scheduler_is_named(tmp_path, build_root, monkeypatch, capsys):
    import distributed

    def refuse(address, *args, **kwargs):       # what distributed raises, without the wait
        raise OSError(f"Timed out trying to connect to {address} after 30 s")
    monkeypatch.setattr(distributed, "Client", refuse)
    argv = ["sweep", str(DP_FREE), "--param", "g=1:2:3", "--scheduler", "tcp://127.0.0.1:9",
            "--build-dir", str(build_root / "cli_outcomes"), "-o", str(tmp_path / "s.nc")]
    assert main(argv) == EXIT["input"]
    err = capsys.readouterr().err
    assert "could not reach the Dask scheduler at 'tcp://127.0.0.1:9'" in err
    assert "None" not in err


def test_results_too_large_for_memory_are_a_clear_error(compiled, monkeypatch):
    from modelgen.errors import ArgumentValueError
    cm = compiled("double_pendulum")

    def short_of_memory(real):                      # as numpy fails a huge allocation
        def allocate(shape, *args, **kwargs):
            if np.prod(shape) > 10**6:
                raise MemoryError
            return real(shape, *args, **kwargs)
        return allocate
    for name in ("empty", "full"):
        monkeypatch.setattr(np, name, short_of_memory(getattr(np, name)))
    t_eval = np.linspace(0.0, 1.0, 400_000)
    with pytest.raises(ArgumentValueError, match=r"the results of 400000 samples need "
                                                 r"0\.0\d+ GB.*fix: fewer samples"):
        cm.simulate([1.0, 0.0, 0.0, 0.0], (0.0, 1.0), t_eval=t_eval)
    with pytest.raises(ArgumentValueError, match=r"the results of 3 runs x 400000 samples"):
        cm.simulate_batch(np.zeros((3, 4)), (0.0, 1.0), t_eval=t_eval)


def test_generate_takes_build_dir_as_its_output_directory(tmp_path, capsys):
    assert main(["generate", str(MODELS / "simple_pendulum.yaml"), "--build-dir",
                 str(tmp_path / "b")]) == 0
    assert (tmp_path / "b" / "simple_pendulum.c").is_file()
    assert f"output     {tmp_path / 'b'}/simple_pendulum.c" in capsys.readouterr().out


@pytest.mark.parametrize("command", ["generate", "simulate", "linearize", "sweep", "fmu"])
def test_help_names_every_accepted_source(command, capsys):
    with pytest.raises(SystemExit):
        main([command, "--help"])
    assert "URDF" in " ".join(capsys.readouterr().out.split())
