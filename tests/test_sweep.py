"""Sweeps (modelgen.sweep): in-process and through a 2-worker Dask LocalCluster.

The references are independent runs of the same compiled model: single
``cm.simulate`` calls (which record the scene outputs in C, not through the
sweep's per-sample evaluation) and a bare ``simulate_batch``; the cluster
must reproduce the in-process sweep bit for bit, failures included.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys

import numpy as np
import pytest

xr = pytest.importorskip("xarray")
distributed = pytest.importorskip("distributed")

import modelgen                                          # noqa: E402
from modelgen.errors import ModelgenError                # noqa: E402
from modelgen.sim import sweep as sw                     # noqa: E402
from modelgen.sim.sweep_results import crossings        # noqa: E402

from conftest import MODELS, ROOT, SCENES                 # noqa: E402

T = np.linspace(0.0, 2.0, 21)


def bits(a):
    """The raw bits of a float array (NaN == NaN, -0.0 != 0.0)."""
    return np.ascontiguousarray(a, dtype=float).view(np.int64)


@pytest.fixture(scope="module")
def scene(build_root):
    """dp_damped (outputs: a 3-column position, a scalar energy, a 2-column force)."""
    return modelgen.load_scene(SCENES / "dp_damped.yaml", build_root / "sweep_dp_damped")


@pytest.fixture(scope="module")
def study(scene):
    """Eleven runs, the middle one (fast, high energy) stopped by max_steps mid-run."""
    cm = scene.model
    q1_dot = np.array([0.0, 0.3, 0.6, 0.9, 1.2, 14.0, 1.5, 1.8, 2.1, 2.4, 2.7])
    c = np.linspace(0.0, 0.2, q1_dot.size)
    X0 = np.tile(scene.initial_state(), (q1_dot.size, 1))
    X0[:, 2] = q1_dot
    free = cm.simulate_batch(X0, (0.0, 2.0), t_eval=T, P={"c": c}, rtol=1e-9)
    steps = free.naccept + free.nreject
    others = np.delete(steps, 5)
    assert steps[5] > 1.5 * others.max()        # the middle run needs far more steps
    max_steps = int((steps[5] + others.max()) // 2)
    return dict(parameters={"c": c}, initial={"q1_dot": q1_dot}, t_eval=T, method="dop853",
                rtol=1e-9, max_steps=max_steps, X0=X0)


def _sweep(source, study, **options):
    return modelgen.sweep(source, study["parameters"], study["initial"], t_eval=study["t_eval"],
                          method=study["method"], rtol=study["rtol"],
                          max_steps=study["max_steps"], x0=study["X0"][0], **options)


@pytest.fixture(scope="module")
def in_process(scene, study):
    return _sweep(scene.model, study)


def test_sweep_equals_single_runs_and_keeps_a_failed_runs_partial_data(scene, study, in_process):
    cm, ds = scene.model, in_process
    assert ds.sizes == {"run": 11, "time": 21, "elbow_column": 3, "damping_column": 2}
    status = ds["status"].values
    assert status[5] == -1 and np.all(np.delete(status, 5) == 0)
    assert "max_steps" in str(ds["message"].values[5]) or "steps" in str(ds["message"].values[5])
    for r in range(11):
        res = cm.simulate(study["X0"][r], (0.0, 2.0), t_eval=T, method="dop853", rtol=1e-9,
                          p={"c": study["parameters"]["c"][r]}, max_steps=study["max_steps"])
        assert res.status == status[r]
        k = len(res.t)                                 # rows the single run reached
        for i, name in enumerate(cm.state_names):
            assert np.array_equal(bits(ds[name].values[r, :k]), bits(res.y[i]))
            assert np.all(np.isnan(ds[name].values[r, k:]))
        # outputs: the sweep evaluates them per sample, the single run records them in C
        assert np.array_equal(bits(ds["elbow"].values[r, :k]), bits(res["elbow"]))
        assert np.array_equal(bits(ds["energy"].values[r, :k]), bits(res["energy"][:, 0]))
        assert np.array_equal(bits(ds["damping"].values[r, :k]), bits(res["damping"]))
        assert np.all(np.isnan(ds["energy"].values[r, k:]))
    k5 = int(np.sum(np.isfinite(ds["q1"].values[5])))
    assert 1 < k5 < 21                                # partial: started, stopped mid-run
    assert np.allclose(ds["c"].values, study["parameters"]["c"])
    assert np.array_equal(ds["initial_q1_dot"].values, study["initial"]["q1_dot"])


@pytest.mark.parametrize("engine", ["scipy", "netcdf4"])
def test_netcdf_round_trip_keeps_nan_status_and_coordinates(in_process, tmp_path, engine):
    if engine == "netcdf4":
        pytest.importorskip("netCDF4")
    path = tmp_path / "s.nc"
    in_process.to_netcdf(path, engine=engine)
    with xr.open_dataset(path, engine=engine) as back:
        assert np.array_equal(bits(back["q2"].values), bits(in_process["q2"].values))
        assert back["status"].values.tolist() == in_process["status"].values.tolist()
        assert list(back["message"].values) == list(in_process["message"].values)
        assert np.array_equal(back["c"].values, in_process["c"].values)


def test_outputs_under_sampled_inputs_equal_those_recorded_in_c(build_root):
    """cart_pole_push: a linearly interpolated input force enters the outputs."""
    scene = modelgen.load_scene(SCENES / "cart_pole_push.yaml", build_root / "sweep_cart_pole")
    theta = np.array([0.05, 0.1, 0.2])
    times = np.linspace(0.0, 2.5, 26)
    ds = modelgen.sweep(scene, initial={"theta": theta}, t_eval=times, t_span=(0.0, 2.5))
    assert ds.attrs["method"] == "rk4" and ds.attrs["step"] == 1e-3
    for r, th in enumerate(theta):
        res = scene.model.simulate(scene.initial_state({"theta": th}), (0.0, 2.5),
                                   t_eval=times, method="rk4", step=1e-3,
                                   u=scene.input_signal())
        assert np.array_equal(bits(ds["theta"].values[r]), bits(res["theta"]))
        for name in ("push", "tip_v", "energy"):
            got = ds[name].values[r].reshape(len(times), -1)
            assert np.array_equal(bits(got), bits(res[name].reshape(len(times), -1))), name
    assert np.any(ds["push"].values != 0.0)          # the pulses reached the outputs


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    """Two single-threaded worker processes with their own build cache."""
    cache = tmp_path_factory.mktemp("worker_cache")
    env = {"MODELGEN_CACHE_DIR": str(cache),
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None, env=env) as c, \
            distributed.Client(c) as client:
        yield client


def test_two_worker_cluster_equals_in_process_bit_for_bit(scene, study, in_process, cluster):
    ds = _sweep(scene.model, study, client=cluster, chunk=3)
    assert ds.attrs["chunks"] == 4 and ds.attrs["workers"] == 2
    for name, var in in_process.data_vars.items():
        if var.dtype.kind == "f":
            assert np.array_equal(bits(ds[name].values), bits(var.values)), name
        else:
            assert ds[name].values.tolist() == var.values.tolist(), name
    for name in ("c", "initial_q1_dot", "time"):
        assert np.array_equal(ds[name].values, in_process[name].values)


def test_worker_compiles_a_model_missing_from_its_file_system_once(tmp_path, cluster):
    """Without the driver's build on the workers' file system, each worker compiles
    the shipped sources at most once, whatever the number of chunks."""
    cm = modelgen.load(MODELS / "double_pendulum.yaml", tmp_path / "driver_only")
    payload = sw.payload_of(cm)
    cm.path.unlink()                    # the workers cannot load the driver's module
    X0 = np.column_stack([np.linspace(0.1, 2.0, 16), np.zeros(16), np.zeros(16), np.zeros(16)])
    before = cluster.run(sw.builds_in_this_process)
    ds = modelgen.sweep(cm, initial={"q1": X0[:, 0]}, t_eval=T, client=cluster, chunk=2)
    builds = {w: n - before[w] for w, n in cluster.run(sw.builds_in_this_process).items()}
    assert ds.attrs["chunks"] == 8
    assert all(n <= 1 for n in builds.values()) and 1 <= sum(builds.values()) <= 2, builds
    assert payload.sources[f"{cm.name}.c"] and payload.build_hash == cm.manifest["build_hash"]
    ref = cm.simulate_batch(X0, (0.0, 2.0), t_eval=T)
    assert np.array_equal(bits(ds["q2"].values), bits(ref.y[:, 1, :]))


def test_model_file_and_compiled_model_sources_equal_a_bare_batch(compiled, build_root):
    cm = compiled("double_pendulum")
    g = modelgen.grid(m2=[0.5, 1.0, 2.0], q2=[0.1, 0.2])
    assert g["m2"].tolist() == [0.5, 0.5, 1.0, 1.0, 2.0, 2.0]
    a = modelgen.sweep(cm, {"m2": g["m2"]}, {"q2": g["q2"]}, t_eval=T, x0=[1.0, 0, 0, 0])
    b = modelgen.sweep(MODELS / "double_pendulum.yaml", {"m2": g["m2"]}, {"q2": g["q2"]},
                       t_eval=T, x0=[1.0, 0, 0, 0], build_dir=build_root / "double_pendulum")
    X0 = np.column_stack([np.ones(6), g["q2"], np.zeros(6), np.zeros(6)])
    ref = cm.simulate_batch(X0, (0.0, 2.0), t_eval=T, P={"m2": g["m2"]})
    for ds in (a, b):
        for i, name in enumerate(cm.state_names):
            assert np.array_equal(bits(ds[name].values), bits(ref.y[:, i, :]))
        assert ds.attrs["scene"] == "" and ds.attrs["method"] == "dop853"
    assert sw.scalar(a, "final", "q1").tolist() == ref.y[:, 0, -1].tolist()


def test_bad_sweeps_say_what_to_fix(compiled, monkeypatch):
    cm = compiled("double_pendulum")
    with pytest.raises(modelgen.SimulationError, match="unknown parameter 'mass'"):
        modelgen.sweep(cm, {"mass": [1.0, 2.0]}, t_eval=T)
    with pytest.raises(modelgen.SimulationError, match="modelgen.grid"):
        modelgen.sweep(cm, {"m2": [1.0, 2.0]}, {"q1": [0.1, 0.2, 0.3]}, t_eval=T)
    with pytest.raises(modelgen.SimulationError, match="give t_eval"):
        modelgen.sweep(cm, {"m2": [1.0, 2.0]})
    monkeypatch.setitem(sys.modules, "xarray", None)
    with pytest.raises(ModelgenError, match=r"modelgen\[sweep\]"):
        modelgen.sweep(cm, {"m2": [1.0, 2.0]}, t_eval=T)


def test_cli_sweep_writes_the_dataset_the_summary_and_the_plot(scene, build_root, tmp_path):
    out = tmp_path / "study.nc"
    env = dict(os.environ, MODELGEN_CACHE_DIR=str(tmp_path / "cache"))
    proc = subprocess.run(
        [sys.executable, "-m", "modelgen", "sweep", str(SCENES / "dp_damped.yaml"),
         "--param", "c=0.0:0.2:3", "--init", "q1=0.5:1.5:2", "--method", "dop853",
         "--rtol", "1e-6", "-o", str(out), "--plot", "max:q2",
         "--build-dir", str(build_root / "sweep_dp_damped")],
        cwd=ROOT, capture_output=True, text=True, timeout=300, env=env)
    assert proc.returncode == 0, proc.stderr
    assert re.search(r"^runs +6$", proc.stdout, re.M), proc.stdout
    assert "runs per second" in proc.stdout and "failed" not in proc.stdout
    with xr.open_dataset(out) as ds:
        assert ds.sizes["run"] == 6 and ds.attrs["method"] == "dop853"
        assert ds["c"].values.tolist() == [0.0, 0.0, 0.1, 0.1, 0.2, 0.2]
        assert ds["initial_q1"].values.tolist() == [0.5, 1.5] * 3
        assert np.all(ds["q1"].values[:, 0] == ds["initial_q1"].values)
    assert out.with_suffix(".png").stat().st_size > 1000
    bad = subprocess.run([sys.executable, "-m", "modelgen", "sweep",
                          str(SCENES / "dp_damped.yaml"), "--param", "c=0:1"],
                         cwd=ROOT, capture_output=True, text=True, timeout=300, env=env)
    assert bad.returncode == 2 and "START:STOP:COUNT" in bad.stderr
    capped = subprocess.run(
        [sys.executable, "-m", "modelgen", "sweep", str(SCENES / "dp_damped.yaml"),
         "--param", "c=0.0:0.2:2", "--method", "dop853", "--max-steps", "5", "--strict",
         "-o", str(tmp_path / "capped.nc"), "--build-dir", str(build_root / "sweep_dp_damped")],
        cwd=ROOT, capture_output=True, text=True, timeout=300, env=env)
    assert capped.returncode == 4 and "MAX_STEPS" in capped.stdout, capped.stdout


def test_period_of_a_swept_pendulum_equals_the_elliptic_closed_form(compiled):
    """period:q over the release angle: upward crossings on the cubic Hermite
    interpolant of the sampled q and q_dot, against 4 sqrt(L/g) K(sin^2(q0/2))."""
    from scipy.special import ellipk
    cm = compiled("simple_pendulum")
    q0 = np.array([0.2, 1.0, 2.0, 2.8])
    t = np.linspace(0.0, 12.0, 241)                       # sampled every 0.05 s
    ds = modelgen.sweep(cm, initial={"q": q0}, t_eval=t, rtol=1e-12, atol=1e-12)
    period = sw.scalar(ds, "period", "q")
    L, g = cm.parameters["L"], cm.parameters["g"]
    exact = 4 * np.sqrt(L / g) * ellipk(np.sin(q0 / 2) ** 2)
    assert np.max(np.abs(period / exact - 1)) < 1e-7, period / exact - 1
    linear = np.array([np.diff(crossings(t, ds["q"].values[r])).mean() for r in range(4)])
    assert np.max(np.abs(linear / exact - 1)) > 10 * np.max(np.abs(period / exact - 1))
