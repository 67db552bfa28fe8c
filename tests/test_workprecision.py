"""Work-precision machinery (modelgen/bench/) on small problems.

References are independent of the code under test: the pendulum's closed
form (mpmath and scipy's ellipj), scipy's expm for a linear chain, the
compiled rhs for the long-double equations.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.special import ellipj, ellipk

import modelgen.bench as wp
from modelgen.bench import standard
from modelgen.cli import main
from modelgen.errors import SimulationError
from modelgen.model.scene import load_scene
from modelgen.sim.integrate import METHODS

from conftest import MODELS

PERIOD_90 = 2.367841947576237          # L = 1, g = 9.81, released from horizontal


@pytest.fixture(scope="module")
def pendulum(build_root):
    return wp.pendulum_problem(build_root / "wp")


def _methods():
    return [wp.scipy_method("RK45"), wp.scipy_method("DOP853"),
            wp.scipy_method("Radau", jac=True), wp.c_method("dopri5"), wp.c_method("dop853"),
            wp.c_method("rodas"), wp.c_method("rk4")]


@pytest.fixture(scope="module")
def sweep(pendulum):
    spacing = pendulum.t_eval[1] - pendulum.t_eval[0]
    return wp.run_sweep(pendulum, _methods(), tolerances=[1e-4, 1e-6, 1e-8],
                        steps=[spacing, spacing / 4, spacing / 16], repeats=2, time_budget=0.05)


def test_pendulum_reference_is_the_closed_form(pendulum):
    ref = pendulum.reference
    theta0 = math.pi / 2
    assert pendulum.t_span[1] == pytest.approx(4 * PERIOD_90, rel=1e-15)
    assert ref.q[-1, 0] == theta0 and ref.q[0, 0] == pytest.approx(theta0, abs=1e-15)
    k = math.sin(theta0 / 2)
    sn = ellipj(ellipk(k * k) - math.sqrt(9.81) * ref.t, k * k)[0]
    assert np.max(np.abs(2 * np.arcsin(k * sn) - ref.q[:, 0])) < 1e-13
    # the bob swings through the bottom at T/4 and reaches -theta0 at T/2
    assert np.interp(PERIOD_90 / 2, ref.t, ref.q[:, 0]) == pytest.approx(-theta0, abs=1e-3)
    assert ref.floor("final") < 1e-12


def test_errors_fall_with_tolerance_and_step_for_every_method(sweep):
    labels = list(dict.fromkeys(p.method for p in sweep))
    assert len(labels) >= 4
    for label in labels:
        mine = sorted((p for p in sweep if p.method == label), key=lambda p: -p.setting)
        assert len(mine) == 3 and all(p.ok for p in mine), [p.message for p in mine]
        l2 = [p.l2_error for p in mine]
        assert l2[0] > l2[1] > l2[2], (label, l2)
        assert l2[2] < l2[0] / 100, (label, l2)        # four decades of tolerance or 16x steps
        assert mine[0].nfev < mine[2].nfev
        assert all(p.seconds > 0 and 1 <= p.repeats <= 2 for p in mine)
        assert all(p.final_error < 1e-2 for p in mine)


def test_c_and_scipy_dop853_take_about_the_same_steps(sweep):
    for rtol in (1e-4, 1e-6, 1e-8):
        c = wp.point_at(sweep, "C dop853", rtol)
        s = wp.point_at(sweep, "solve_ivp DOP853", rtol)
        assert c.ok and s.ok
        # the same method on the same rhs: evaluations and errors agree roughly
        assert 0.7 < c.nfev / s.nfev < 1.4, (rtol, c.nfev, s.nfev)
        assert 0.1 < c.l2_error / s.l2_error < 10, (rtol, c.l2_error, s.l2_error)


def test_failures_are_recorded_not_dropped(pendulum):
    def broken(problem, setting, budget):
        raise FloatingPointError("deliberately broken")
    broken.label = "broken"
    methods = [wp.scipy_method("RK45"), broken, wp.c_method("dop853")]
    points = wp.run_sweep(pendulum, methods, tolerances=[1e-3, 1e-6, 1e-9], repeats=1,
                          budget=wp.Budget(max_nfev=400, max_steps=40), warmup=False)
    assert len(points) == 3 * len(methods)
    rk45 = sorted((p for p in points if p.method == "solve_ivp RK45"), key=lambda p: -p.setting)
    assert rk45[0].ok                                 # 1e-3 needs fewer than 400 evaluations
    assert rk45[1].failed and "budget" in rk45[1].message and rk45[1].nfev == 400
    assert not rk45[2].ran and "not run" in rk45[2].message   # tighter: not run, but listed
    bad = [p for p in points if p.method == "broken"]
    assert all(p.failed and "deliberately broken" in p.message for p in bad)
    c = [p for p in points if p.method == "C dop853"]
    assert any(p.failed and p.status == -1 for p in c)        # MAX_STEPS from the C
    table = wp.markdown_table(points)
    assert table.count("**FAILED**") == sum(p.failed for p in points)


def test_table_csv_and_png_are_written(sweep, pendulum, tmp_path):
    md, csv_path = wp.write_tables(sweep, tmp_path / "pendulum", pendulum)
    text = md.read_text()
    assert text.startswith("# Work-precision: simple pendulum")
    assert "closed form" in text and text.count("\n| ") == len(sweep) + 1
    with csv_path.open() as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(sweep)
    assert {r["method"] for r in rows} == {p.method for p in sweep}
    assert float(rows[0]["final_error"]) == sweep[0].final_error
    png = wp.plot_work_precision(sweep, pendulum, tmp_path / "pendulum.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cost_at_error_interpolates_on_the_log_log_curve():
    def point(setting, error, seconds):
        return wp.Point("p", "m", "C", False, setting, error, error, seconds, 1, 100, 0, 0,
                        "", 1e-14, 1e-14)
    points = [point(1e-4, 1e-3, 1e-3), point(1e-6, 1e-5, 1e-2), point(1e-8, 1e-7, 1e-1)]
    # error 1e-6 lies half-way (in logs) between 1e-5 and 1e-7: time 10^-1.5
    assert wp.cost_at_error(points, "m", 1e-6) == pytest.approx(10 ** -1.5, rel=1e-12)
    assert wp.cost_at_error(points, "m", 1e-9) is None          # never reached
    assert wp.cost_at_error(points, "m", 1e-15) is None         # below the reference
    assert wp.cost_at_error(points, "m", 1e-6, cost="nfev") == pytest.approx(100)


def test_linear_reference_matches_scipy_expm(build_root, compiled):
    import modelgen
    cm = modelgen.load(MODELS / "spring_chain.yaml", build_root / "wp_chain", jacobian=True)
    x0 = np.array([0.8, 2.0, 3.0, 0.0, 0.0, 0.0])
    t = np.linspace(0.0, 5.0, 51)
    ref = wp.linear_reference(cm, x0, t)
    with pytest.raises(SimulationError, match="symbolic Jacobian"):
        wp.linear_reference(compiled("spring_chain"), x0, t)     # differences: not exact
    # independent: m x'' = -K (x - x_rest) - C x' with the tridiagonal K and C of the model
    m, k, c, L = (cm.parameters[name] for name in ("m", "k", "c", "L"))
    T = np.array([[2.0, -1.0, 0.0], [-1.0, 2.0, -1.0], [0.0, -1.0, 1.0]])
    A = np.block([[np.zeros((3, 3)), np.eye(3)], [-k / m * T, -c / m * T]])
    rest = np.array([L, 2 * L, 3 * L, 0.0, 0.0, 0.0])
    want = np.array([rest + expm(A * ti) @ (x0 - rest) for ti in t])[:, :3]
    assert np.max(np.abs(ref.q - want)) < 1e-12


def test_long_double_equations_and_integrators_match_the_model(compiled, pendulum):
    dp = compiled("double_pendulum")
    f = wp.extended_rhs(_spec("double_pendulum"), dp.params(), dp.input_vector([0.3]))
    rng = np.random.default_rng(11)
    for _ in range(5):
        x = rng.normal(size=4)
        want = dp.rhs(0.0, x, u=[0.3])
        got = f(0.0, x.astype(np.longdouble)).astype(float)
        assert np.max(np.abs(got - want)) <= 1e-13 * np.max(np.abs(want))
    # both long-double integrators reproduce the pendulum's closed form over one period
    sp = pendulum.model
    g = wp.extended_rhs(_spec("simple_pendulum"), sp.params(), sp.input_vector())
    grid = pendulum.t_eval[:51]
    for integrate in (wp.dop853_extended, wp.gbs_extended):
        x, nfev = integrate(g, pendulum.x0, grid, tol=1e-16)
        assert np.max(np.abs(x[:, 0].astype(float) - pendulum.reference.q[:51, 0])) < 1e-14
        assert nfev > 100


def _spec(name):
    from modelgen.model.api import load_model
    return load_model(MODELS / f"{name}.yaml")


def test_bench_command_writes_diagram_and_table(tmp_path, capsys):
    scene = tmp_path / "swing.yaml"
    scene.write_text(f"""\
scene: swing_short
model: {MODELS / 'simple_pendulum.yaml'}
effects: [gravity]
initial: {{q: 1.0, q_dot: 0.0}}
time: {{end: 1.0, sample: 0.01}}
integrator: {{method: rk4, step: 0.01}}
""")
    argv = ["bench", str(scene), "-o", str(tmp_path / "out"), "--quick",
            "--build-dir", str(tmp_path / "build")]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "Reference:" in out and "| method | setting |" in out
    for suffix in (".png", ".md", ".csv"):
        assert (tmp_path / "out" / f"swing_short_work_precision{suffix}").is_file()
    assert "solve_ivp DOP853" in out and "rtol=1e-08" in out


def test_standard_scenes_and_models_ship_inside_the_package(tmp_path, monkeypatch):
    package = Path(wp.__file__).resolve().parent
    scenes = sorted(standard.SCENES.glob("*.yaml"))
    assert len(scenes) == len(wp.STANDARD)
    monkeypatch.chdir(tmp_path)                        # nothing is found through the cwd
    for path in scenes:
        assert package in path.resolve().parents
        spec = load_scene(path)
        assert spec.model.source is not None
        assert package in Path(spec.model.source).resolve().parents, spec.model.source


def test_default_c_methods_are_the_method_table():
    c = [m for m in wp.default_methods() if m.family == "C"]
    assert [m.name for m in c] == list(METHODS)
    assert [m.fixed_step for m in c] == [not m.adaptive for m in METHODS.values()]
    with pytest.raises(SimulationError, match="unknown method 'gauss2'"):
        wp.c_method("gauss2")
