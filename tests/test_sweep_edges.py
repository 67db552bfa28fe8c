"""Sweeps at their edges, as a parameter study uses them: failed rows, names that clash
with the dataset's own, fixed steps, sizes beyond memory, interrupts, reproducibility,
netCDF, and what a Dask worker imports.

Each reference is an independent ``cm.simulate`` (or ``simulate_batch``) of the same
compiled model; each test failed before the fix it guards (see the report of the
sweep audit).
"""
from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

xr = pytest.importorskip("xarray")
distributed = pytest.importorskip("distributed")

import modelgen                                          # noqa: E402
from modelgen.sim import sweep as sw                     # noqa: E402

from conftest import ROOT                                 # noqa: E402

T = np.linspace(0.0, 2.0, 21)
#: the attrs that time the sweep or describe where it ran: all else must repeat exactly
TIMING = ("seconds", "load_seconds", "compute_seconds", "workers", "chunks", "chunk",
          "scheduler")

CLASH = """\
name: clash_pendulum
coordinates: [q]
parameters: {L: 1.0, m: 1.0, g: 9.81, time: 0.0, run: 0.0, initial_q: 0.0, status: 0.0}
bases:
  B1: {parent: E, axis: 3, angle: q}
points:
  P: {from: O, base: B1, coordinates: [0, -L - 0*time - 0*run - 0*initial_q - 0*status, 0]}
bodies:
  bob: {mass: m, G: P, base: B1}
gravity: [0, -g, 0]
"""


def bits(a):
    return np.ascontiguousarray(a, dtype=float).view(np.int64)


def same_up_to_timing(a, b):
    """Data, coordinates, dims, dtypes and every attr but the timing ones equal."""
    assert a.equals(b)
    assert set(a.variables) == set(b.variables)
    for name in a.variables:
        assert a[name].dtype == b[name].dtype and a[name].attrs == b[name].attrs, name
        if a[name].dtype.kind == "f":
            assert np.array_equal(bits(a[name].values), bits(b[name].values)), name
    strip = lambda d: {k: v for k, v in d.attrs.items() if k not in TIMING}   # noqa: E731
    assert strip(a) == strip(b)


@pytest.fixture(scope="module")
def dp(compiled):
    return compiled("double_pendulum")


@pytest.fixture(scope="module")
def failing(dp):
    """Three runs: fine, an indefinite mass matrix (m2 < 0), stopped by max_steps."""
    with pytest.warns(RuntimeWarning, match="max_steps"):
        return sw.sweep(dp, {"m2": [1.0, -3.0, 1.0]}, {"q1_dot": [0.0, 0.0, 30.0]}, t_eval=T,
                        x0=[1.0, 0, 0, 0], max_steps=300)


def test_a_failed_row_keeps_the_others_and_says_status_message_and_time_reached(dp, failing):
    ds = failing
    assert ds["status"].values.tolist() == [0, -3, -1]
    assert "Mass matrix" in str(ds["message"].values[1])
    assert "Maximum number of steps" in str(ds["message"].values[2])
    for r, (m2, qd) in enumerate([(1.0, 0.0), (-3.0, 0.0), (1.0, 30.0)]):
        res = dp.simulate([1.0, 0, qd, 0], (0.0, 2.0), t_eval=T, p={"m2": m2}, max_steps=300)
        k = len(res.t)
        assert res.status == ds["status"].values[r]
        for i, name in enumerate(dp.state_names):
            assert np.array_equal(bits(ds[name].values[r, :k]), bits(res.y[i]))
            assert np.all(np.isnan(ds[name].values[r, k:]))
    # where each run stopped: t_end for a success, else the time it reached
    ref = dp.simulate_batch(np.array([[1.0, 0, 0, 0], [1.0, 0, 0, 0], [1.0, 0, 30.0, 0]]),
                            (0.0, 2.0), t_eval=T, P={"m2": [1.0, -3.0, 1.0]}, max_steps=300)
    assert ds["t_reached"].dims == ("run",)
    assert ds["t_reached"].values.tolist() == ref.info["t_reached"].tolist()
    assert ds["t_reached"].values[0] == 2.0 and ds["t_reached"].values[1] == 0.0
    assert 0.0 < ds["t_reached"].values[2] < 2.0
    assert ds.attrs["failed"] == 2


def test_the_dataset_documents_its_variables(failing):
    ds = failing
    assert ds["time"].attrs.get("units") == "s"
    assert ds["t_reached"].attrs.get("units") == "s"
    assert "0" in ds["status"].attrs.get("description", "")
    for name in ("q1", "q1_dot", "m2", "initial_q1_dot", "message"):
        assert ds[name].attrs.get("description"), name


def test_a_non_finite_swept_value_fails_its_run_only(dp):
    ds = sw.sweep(dp, {"m2": [1.0, np.nan, 2.0]}, {"q1": [0.5, 0.5, np.inf]}, t_eval=T)
    assert ds["status"].values.tolist() == [0, -7, -7]
    assert "m2" in str(ds["message"].values[1]) and "q1" in str(ds["message"].values[2])
    assert np.all(np.isnan(ds["q1"].values[1:])) and ds.attrs["failed"] == 2
    ref = dp.simulate([0.5, 0, 0, 0], (0.0, 2.0), t_eval=T)
    assert np.array_equal(bits(ds["q2"].values[0]), bits(ref.y[1]))


def test_a_fixed_step_gets_the_steps_its_span_needs_as_simulate_does(dp):
    """simulate's default budget covers a fixed step's span; the sweep's did not
    (every run stopped at 100,000 steps)."""
    t = np.linspace(0.0, 1.2, 7)
    ds = sw.sweep(dp, initial={"q1": [0.5, 1.0]}, t_eval=t, method="rk4", step=1e-5)
    assert ds["status"].values.tolist() == [0, 0]
    ref = dp.simulate([1.0, 0, 0, 0], (0.0, 1.2), t_eval=t, method="rk4", step=1e-5)
    assert np.array_equal(bits(ds["q2"].values[1]), bits(ref.y[1]))


def test_swept_names_never_overwrite_the_datasets_own(build_root, tmp_path):
    path = tmp_path / "clash.yaml"
    path.write_text(CLASH)
    cm = modelgen.load(path, build_root / "clash_pendulum")
    t = np.linspace(0.0, 1.0, 5)
    ds = sw.sweep(cm, {"time": [1.0, 2.0], "run": [3.0, 4.0], "initial_q": [5.0, 6.0],
                       "status": [7.0, 8.0]}, {"q": [0.1, 0.2]}, t_eval=t)
    assert ds["time"].values.tolist() == t.tolist() and ds["run"].values.tolist() == [0, 1]
    assert ds["status"].values.tolist() == [0, 0]
    assert ds["initial_q"].values.tolist() == [0.1, 0.2]
    for name, values in (("time", [1.0, 2.0]), ("run", [3.0, 4.0]),
                         ("initial_q", [5.0, 6.0]), ("status", [7.0, 8.0])):
        assert ds[f"parameter_{name}"].values.tolist() == values
    assert ds.attrs["swept"].split() == ["parameter_time", "parameter_run",
                                         "parameter_initial_q", "parameter_status",
                                         "initial_q"]


def test_an_unknown_name_says_where_it_belongs_and_the_valid_ones(dp):
    with pytest.raises(modelgen.SimulationError, match=r"'q1' is a state.*initial=.*m1, m2"):
        sw.sweep(dp, {"q1": [0.1, 0.2]}, t_eval=T)
    with pytest.raises(modelgen.SimulationError, match=r"'m2' is a parameter.*parameters="):
        sw.sweep(dp, initial={"m2": [0.1, 0.2]}, t_eval=T)
    with pytest.raises(modelgen.SimulationError, match=r"unknown state 'x'.*q1, q2, q1_dot"):
        sw.sweep(dp, initial={"x": [0.1, 0.2]}, t_eval=T)


def test_a_sweep_beyond_memory_is_refused_before_any_run(dp, monkeypatch):
    monkeypatch.setattr(sw, "physical_memory", lambda: 1e5)     # a 100 kB machine
    ran = []
    with pytest.raises(modelgen.SimulationError, match=r"GB.*fewer"):
        sw.sweep(dp, initial={"q1": np.linspace(0.1, 1.0, 400)}, t_eval=T, chunk=10,
                 progress=lambda done, total: ran.append(done))
    assert ran == []
    # the real machine's memory is used without the patch, and a real study passes
    monkeypatch.undo()
    assert sw.physical_memory() > 1e8
    with pytest.raises(modelgen.SimulationError, match=r"TB|GB"):
        sw.sweep(dp, initial={"q1": np.linspace(0.1, 1.0, 100_000)},
                 t_eval=np.linspace(0.0, 10.0, 1_000_001), chunk=10,
                 progress=lambda done, total: ran.append(done))
    assert ran == []


def test_chunks_workers_and_repeats_give_the_same_dataset(dp):
    g = sw.grid(m2=np.linspace(0.5, 2.0, 4), q1=np.linspace(0.1, 2.0, 5))
    args = ({"m2": g["m2"]}, {"q1": g["q1"]})
    a = sw.sweep(dp, *args, t_eval=T)
    same_up_to_timing(a, sw.sweep(dp, *args, t_eval=T))
    same_up_to_timing(a, sw.sweep(dp, *args, t_eval=T, chunk=3))
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as c, distributed.Client(c) as client:
        same_up_to_timing(a, sw.sweep(dp, *args, t_eval=T, client=client, chunk=7))


def test_netcdf_with_the_default_writer_reads_back_equal(failing, tmp_path):
    """netCDF4 or, without it, scipy's netCDF3 writer: everything reads back."""
    path = tmp_path / "s.nc"
    failing.to_netcdf(path)
    with xr.open_dataset(path) as back:
        back = back.load()
    assert back.equals(failing)
    for name in failing.variables:
        if failing[name].dtype.kind == "f":
            assert np.array_equal(bits(back[name].values), bits(failing[name].values)), name
        assert back[name].attrs == failing[name].attrs, name
    assert list(back["message"].values) == list(failing["message"].values)
    assert {k: np.asarray(v).tolist() for k, v in back.attrs.items()} == \
        {k: np.asarray(v).tolist() for k, v in failing.attrs.items()}


def test_an_interrupt_cancels_the_chunks_on_a_users_client(dp):
    """Ctrl-C (here raised by the progress callback) must not leave a user's cluster
    running the rest of the study."""
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as c, distributed.Client(c) as client:
        def stop(done, total):
            raise KeyboardInterrupt
        # the traceback kept (as an interactive session keeps the last one) keeps the
        # sweep's futures referenced: only cancelling them stops the cluster
        with pytest.raises(KeyboardInterrupt) as kept:
            sw.sweep(dp, initial={"q1": np.linspace(0.1, 2.0, 400)},
                     t_eval=np.linspace(0, 10, 11), client=client, chunk=1, progress=stop)
        deadline = time.monotonic() + 10
        while client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks)) and \
                time.monotonic() < deadline:
            time.sleep(0.05)
        assert client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks)) == 0
        assert kept.traceback


@pytest.mark.skipif(threading.current_thread() is not threading.main_thread(),
                    reason="Ctrl-C reaches the main thread only")
def test_ctrl_c_stops_an_in_process_sweep_soon(dp):
    """Ctrl-C lands between the in-process chunks, not after the whole study."""
    args = dict(initial={"q1": np.linspace(0.1, 3.0, 1500)}, t_eval=np.linspace(0, 10, 11))
    start = time.perf_counter()
    sw.sweep(dp, **args)
    full = time.perf_counter() - start
    timer = threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGINT))
    start = time.perf_counter()
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            sw.sweep(dp, **args)
            time.sleep(5)         # the sweep ended first: the signal must not escape
    finally:
        timer.cancel()
    assert time.perf_counter() - start < 0.5 * full, full


def test_a_worker_loads_the_model_without_the_code_generator(dp, tmp_path):
    """sympy costs a worker process about 0.6 s and 40 MB: importing the sweep and
    loading a shipped model from its build must not import it."""
    payload = sw.payload_of(dp)
    assert payload.runtime == (dp.lib.runtime[0], str(dp.lib.runtime[1]))
    study = sw._study(dp, {}, {}, {"q1": np.array([0.3, 0.6])}, None, T, None, None, None,
                      None, None, 1000, None, True)[0]
    (tmp_path / "job.pkl").write_bytes(pickle.dumps((payload, study)))
    code = ("import pickle, sys; from modelgen.sim import sweep as sw\n"
            "assert 'sympy' not in sys.modules, 'import'\n"
            f"payload, study = pickle.loads(open({str(tmp_path / 'job.pkl')!r}, 'rb').read())\n"
            "out = sw.run_chunk(payload, study, 0, 2)\n"
            "assert 'sympy' not in sys.modules, 'load'\n"
            "print(out['y'][1, 0, -1].hex(), out['status'].tolist())\n")
    proc = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True,
                          text=True, timeout=120, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert proc.returncode == 0, proc.stderr
    ref = dp.simulate([0.6, 0, 0, 0], (0.0, 2.0), t_eval=T)
    assert proc.stdout.split() == [float(ref.y[0, -1]).hex(), "[0,", "0]"]
