"""Scenes: only the chosen effects are generated, and the physics adds up.

* switching an effect off removes its parameters and terms from the C and
  lowers the operation count, with results identical to the full model with
  that effect's parameters set to zero;
* conservative scenes conserve energy; with dampers, the energy lost equals
  the integrated damper power;
* closed forms: the block on an incline stops at t* = v0 / (g (mu cos a - sin a)).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import simpson

import modelgen
from modelgen.cli import main
from modelgen.model.scene import load_scene as load_scene_spec

from conftest import MODELS

SCENES = MODELS / "scenes"


@pytest.fixture(scope="module")
def scene(build_root):
    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = modelgen.load_scene(SCENES / f"{name}.yaml", build_root / f"scene_{name}")
        return cache[name]
    return get


@pytest.mark.parametrize("name", sorted(p.stem for p in SCENES.glob("*.yaml")))
def test_every_shipped_scene_runs(scene, name):
    res = scene(name).run()
    assert res.success, res.message
    assert res.t[-1] == pytest.approx(scene(name).spec.t_end)
    assert np.all(np.isfinite(res.y))


def test_switching_an_effect_off_removes_its_parameters_and_terms(scene):
    free, damped = scene("dp_free"), scene("dp_damped")
    assert "c" in damped.model.parameters and "c" not in free.model.parameters
    c_free = (free.generated.build.directory / "dp_free.c").read_text()
    c_damped = (damped.generated.build.directory / "dp_damped.c").read_text()
    assert "/* c */" in c_damped and "/* c */" not in c_free
    ops_free = free.generated.manifest["ops"]["rhs"]["after_cse"]
    ops_damped = damped.generated.manifest["ops"]["rhs"]["after_cse"]
    assert ops_free < ops_damped
    # the model's motor action is switched off in both: no input enters tau
    tau = free.model.generalized_forces(0.0, [0.3, 0.2], [0.0, 0.0], u=[5.0])
    assert np.array_equal(tau, free.model.generalized_forces(0.0, [0.3, 0.2], [0.0, 0.0]))


def test_effect_off_equals_effect_with_zero_parameters(scene):
    """The two scenes are two C programs: their rhs agree to rounding at every
    state of the run, and the runs agree to 1e-12 while the double pendulum's
    chaos has not yet grown a rounding difference (it reaches 2e-10 by t = 10 s,
    doubling about every 0.4 s)."""
    free, damped = scene("dp_free"), scene("dp_damped")
    a = free.run()
    b = damped.run(p={"c": 0.0})
    early = a.t <= 4.0
    assert np.allclose(a.y[:, early], b.y[:, early], rtol=0, atol=1e-12 * np.abs(a.y).max())
    for x in a.y.T[::50]:
        fa, fb = free.model.rhs(0.0, x), damped.model.rhs(0.0, x, p={"c": 0.0})
        assert np.allclose(fa, fb, rtol=1e-14, atol=1e-14 * np.abs(fa).max())


def test_conservative_scene_conserves_energy(scene):
    s = scene("dp_free")
    assert s.conservative
    res = s.run()
    total = res.energy.sum(axis=1)
    assert np.abs(total - total[0]).max() < 1e-6 * np.abs(res.energy).max()


def test_energy_lost_equals_integrated_damper_power(scene):
    s = scene("dp_damped")
    assert not s.conservative
    # sample every step so Simpson's rule is as accurate as the integration
    res = s.model.simulate(s.spec.initial, (0.0, 5.0), t_eval=np.linspace(0.0, 5.0, 2501),
                           method="rk4", step=1e-3)
    n = s.model.n
    power = np.einsum("ij,ij->i", res.outputs["damping"], res.y[n:].T)
    energy = res["energy"][:, 0]
    lost = energy[-1] - energy[0]
    assert lost < 0
    assert lost == pytest.approx(simpson(power, x=res.t), rel=1e-6)


def test_damped_scene_energy_balance_closes_to_the_integration_error(scene, build_root):
    """E(t) - E(0) - W(t) = 0 for the exact motion, W the integrated power of the
    damping (a ``power`` output on 5-point Lobatto nodes): at rtol 1e-10 the
    balance is below 1e-8 of the initial energies (measured 9e-10) while the energy
    itself drops by more than they are; it shrinks with the tolerance.  E comes
    from the energy function, W from tau . q_dot: a wrong sign or a missing factor
    in either leaves a balance of order 1."""
    from dataclasses import replace
    base = scene("dp_damped")
    balance = {}
    for rtol in (1e-8, 1e-10):
        s = modelgen.sim.scene.Scene(replace(base.spec, method="dop853", rtol=rtol, atol=rtol),
                                     build_root / "scene_dp_damped")
        res = s.run()
        scale = np.abs(res.energy[0]).sum()
        total = res.energy.sum(axis=1)
        balance[rtol] = np.abs(res.info["energy_balance"]).max() / scale
        assert list(res.work) == ["hinge_damping"] and "power_hinge_damping" not in res.outputs
        work = res.work["hinge_damping"]
        assert work.shape == res.t.shape and work[0] == 0.0
        assert np.all(np.diff(work) <= 0)                   # damping only dissipates
        assert np.allclose(res.info["energy_balance"], total - total[0] - work, rtol=0,
                           atol=1e-12 * scale)
    assert total[-1] - total[0] < -scale                    # the energy drops a lot
    assert balance[1e-10] < 1e-8, balance
    assert balance[1e-10] < balance[1e-8] / 10, balance
    assert res.info["work_quadrature_check"] < 1e-5 * scale

    fig = res.plot(conservative=False)
    labels = {ax.get_ylabel(): [line.get_label() for line in ax.get_lines()] for ax in fig.axes}
    assert "work of hinge_damping" in labels["energy, work [J]"]
    assert "total E" in labels["energy, work [J]"]
    (line,) = [ax for ax in fig.axes if "balance" in ax.get_ylabel()][0].get_lines()
    assert np.array_equal(line.get_ydata(), total - total[0] - work)
    assert not any("E scale" in ylabel for ylabel in labels)    # no 'relative error'
    # a conservative scene keeps its drift panel and records no work
    free = scene("dp_free").run()
    assert free.work == {} and "energy_balance" not in free.info
    assert any("E scale" in ax.get_ylabel() for ax in free.plot(conservative=True).axes)


def test_block_on_incline_stops_at_closed_form_time(scene):
    s = scene("block_friction")
    p = s.model.parameters
    v0 = s.spec.initial[1]
    a = p["g"] * (p["mu"] * np.cos(p["alpha"]) - np.sin(p["alpha"]))
    t_star = v0 / a
    res = s.run()
    speed = res.y[1]
    # sliding: speed falls linearly at rate a until the smoothing band |v| ~ v_s
    sliding = res.t < t_star - 0.05
    assert np.allclose(speed[sliding], v0 - a * res.t[sliding], atol=1e-6)
    # stuck afterwards: the regularised friction holds it within the band
    assert np.all(np.abs(speed[res.t > t_star + 0.05]) < 2 * p["v_s"])


def test_sampled_input_force_is_interpolated_linearly(scene):
    s = scene("cart_pole_push")
    sig = next(sig for sig in s.spec.inputs if sig.constant is None)
    t = np.linspace(s.spec.t_start, s.spec.t_end, 7)
    expected = np.interp(t, sig.times, sig.values)
    u_index = s.model.inputs.index(sig.name)
    times, values, interpolation = s._inputs()
    assert interpolation == "linear"
    assert np.allclose(np.interp(t, times, values[:, u_index]), expected, rtol=0, atol=1e-15)
    # the C integrator sees the same force: compare with a Python RK4 on cm.rhs
    cm, h = s.model, 1e-3
    x = np.array(s.spec.initial, dtype=float)
    u_at = lambda tt: np.interp(tt, sig.times, sig.values)   # noqa: E731
    for k in range(500):
        tk = k * h
        k1 = cm.rhs(tk, x, u=[u_at(tk)])
        k2 = cm.rhs(tk + h / 2, x + h / 2 * k1, u=[u_at(tk + h / 2)])
        k3 = cm.rhs(tk + h / 2, x + h / 2 * k2, u=[u_at(tk + h / 2)])
        k4 = cm.rhs(tk + h, x + h * k3, u=[u_at(tk + h)])
        x = x + h / 6 * (k1 + 2 * (k2 + k3) + k4)
    res = cm.simulate(s.spec.initial, (0.0, 0.5), method="rk4", step=h, u=s._inputs())
    assert np.allclose(res.y[:, -1], x, rtol=0, atol=1e-12 * max(1.0, np.abs(x).max()))


def test_stiff_and_non_smooth_effects_are_flagged(scene):
    assert "STIFF" in scene("spring_chain_stiff").summary()
    assert "friction" in scene("block_friction").spec.stiff_effects
    assert "STIFF" not in scene("dp_free").summary()


def test_failing_run_returns_what_it_computed(scene):
    s = scene("dp_free")
    res = s.run(p={"m1": 1.0, "m2": float("1e300"), "l2": 1e300})
    assert not res.success
    assert res.t.size >= 1 and res.t[-1] < s.spec.t_end
    assert "t=" in res.message


def test_simulate_cli_writes_csv_npz_png_for_a_scene(tmp_path, capsys):
    argv = ["simulate", str(SCENES / "dp_damped.yaml"), "-o", str(tmp_path / "out"),
            "--build-dir", str(tmp_path / "build")]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert "effects on: gravity, hinge_damping" in out
    assert "effects off (not generated): motor" in out
    for ext in ("csv", "npz", "png"):
        assert (tmp_path / "out" / f"dp_damped.{ext}").stat().st_size > 0
    data = np.load(tmp_path / "out" / "dp_damped.npz")
    assert data["x"].shape == (1001, 4) and data["output:elbow"].shape == (1001, 3)
    assert data["work:hinge_damping"].shape == (1001,)
    assert "work done: hinge_damping -30.3" in out and "energy balance E - E(0)" in out


def test_scene_spec_reduced_model_is_named_after_the_scene():
    spec = load_scene_spec(SCENES / "dp_free.yaml")
    assert spec.model.name == "dp_free" and spec.full_model.name == "double_pendulum"


def test_feedback_input_from_python_callable(compiled):
    """A PD controller u(t, x) holds the cart-pole's cart at x = 0.5."""
    cm = compiled("cart_pole")
    n = cm.n
    i_cart = cm.coordinates.index("x")

    def controller(t, x):
        return [-40.0 * (x[i_cart] - 0.5) - 12.0 * x[n + i_cart]]
    res = cm.simulate(np.zeros(2 * n), (0.0, 3.0), t_eval=np.linspace(0.0, 3.0, 31),
                      method="rk4", step=1e-3, u=controller)
    assert res.success and res.t.size == 31
    # the same feedback in a plain Python RK4 on cm.rhs gives the same final state
    x, h = np.zeros(2 * n), 1e-3
    f = lambda t, x: cm.rhs(t, x, u=controller(t, x))   # noqa: E731
    for k in range(3000):
        t = k * h
        k1 = f(t, x)
        k2 = f(t + h / 2, x + h / 2 * k1)
        k3 = f(t + h / 2, x + h / 2 * k2)
        k4 = f(t + h, x + h * k3)
        x = x + h / 6 * (k1 + 2 * (k2 + k3) + k4)
    assert np.allclose(res.y[:, -1], x, rtol=0, atol=1e-12)
    assert abs(res["x"][-1] - 0.5) < 0.05


def test_stiff_scene_with_rodas_matches_scipy_radau_and_beats_dopri5(scene):
    """The stiff chain (stiffness ratio 2e7): rodas with the symbolic Jacobian.

    Reference: scipy's Radau at rtol 1e-10 driving the same compiled rhs and
    Jacobian.  dopri5 is throttled by stability: it needs over 100x the rhs
    evaluations, or stops at its step limit.
    """
    from scipy.integrate import solve_ivp
    s = scene("spring_chain_stiff")
    cm = s.model
    assert s.spec.method == "rodas" and cm.manifest["jacobian"]
    res = s.run()
    assert res.success, res.message
    ref = solve_ivp(cm.rhs, (s.spec.t_start, s.spec.t_end), s.spec.initial, method="Radau",
                    jac=cm.jac, rtol=1e-10, atol=1e-12, t_eval=res.t)
    assert ref.success
    assert np.allclose(res.y, ref.y, rtol=0, atol=1e-5)
    stiff = cm.simulate(s.spec.initial, (0.0, 2.0), method="rodas", rtol=1e-6, atol=1e-9)
    with pytest.warns(RuntimeWarning, match="max_steps"):     # it does not get far
        explicit = cm.simulate(s.spec.initial, (0.0, 2.0), method="dopri5", rtol=1e-6,
                               atol=1e-9, max_steps=200_000)
    assert stiff.success and stiff.nfev < 2000
    assert explicit.nfev > 100 * stiff.nfev


def test_stiffness_verdict_comes_from_the_jacobian_not_the_effect_kind(scene):
    """Springs and friction are only stiff-prone: the summary says what |lambda|max implies
    for the scene's method (the stiff chain is handled by rodas; the soft chain is not
    stiff; RK4 beyond its stability limit is warned about)."""
    from dataclasses import replace
    stiff = scene("spring_chain_stiff")
    assert stiff.stiffness() > 1e7
    assert "handled by rodas" in stiff.summary()
    soft = scene("spring_chain_release")
    assert "not stiff for rk4" in soft.summary()
    block = scene("block_friction")
    lam, card = block.stiffness(), block.card
    try:
        block.card = replace(card, step=4.0 / lam)
        summary = block.summary()
    finally:
        block.card = card
    assert "WARNING the step" in summary and "beyond rk4's stability limit" in summary


def test_rk4_beyond_its_stability_limit_is_warned_not_silent(scene, tmp_path):
    """The friction block with a step 2x beyond RK4's limit at rest: the run 'succeeds'
    but its message, and the CLI, say the result is unreliable; within it, no warning."""
    block = scene("block_friction")
    lam = block.stiffness()
    x0 = block.initial_state()
    x0[block.model.n:] = 0.0          # at rest, where the smoothed friction is steepest
    bad = block.model.simulate(x0, (0.0, 0.5), method="rk4", step=2 * 2.785 / lam)
    assert "WARNING: the step" in bad.message and "stability limit" in bad.message
    good = block.model.simulate(x0, (0.0, 0.5), method="rk4", step=0.5 * 2.785 / lam)
    assert "WARNING" not in good.message and good.success
    import subprocess
    import sys
    proc = subprocess.run([sys.executable, "-m", "modelgen", "simulate",
                           str(SCENES / "block_friction.yaml"), "--dt", str(2 * 2.785 / lam),
                           "--sample", str(2 * 2.785 / lam),
                           "--init", f"{block.model.state_names[-1]}=0",
                           "--t-end", "0.5", "--no-plot", "-o", str(tmp_path / "o"),
                           "--build-dir", str(tmp_path / "b")], capture_output=True, text=True)
    assert "modelgen: warning: the step" in proc.stderr, proc.stderr


def test_a_field_that_varies_in_time_has_its_work_recorded(tmp_path):
    """Gravity whose strength varies in time (the top-level field) and a second
    field along x: neither has a potential, so the scene records their power and
    the balance E(t) - E(0) - W(t) closes to the integration error (measured
    5e-9 J) while the energy changes by joules."""
    (tmp_path / "pend.yaml").write_text(
        "name: pend_gt\ncoordinates: [q]\nparameters: {l: 1.0, m: 1.0, g: 9.81}\n"
        "gravity: [0, -g*(1 + sin(3*t)/5), 0]\n"
        "bases: {B: {parent: E, axis: 3, angle: q}}\n"
        "points: {P: {from: O, base: B, coordinates: [l, 0, 0]}}\n"
        "bodies: {bob: {mass: m, G: P, base: B}}\n"
        "effects:\n  pull: {type: gravity, vector: [g*cos(2*t)/4, 0, 0]}\n")
    (tmp_path / "scene.yaml").write_text(
        "scene: pend_gt_swing\nmodel: pend.yaml\neffects: [gravity, pull]\n"
        "initial: {q: 0.5, q_dot: 0.0}\ntime: {end: 5.0, sample: 0.01}\n"
        "integrator: {method: dop853, rtol: 1e-10, atol: 1e-10}\n"
        "outputs:\n  energy: {energy: total}\n")
    s = modelgen.load_scene(tmp_path / "scene.yaml", tmp_path / "build")
    assert not s.conservative
    res = s.run()
    assert sorted(res.work) == ["gravity", "pull"]
    total = res.energy.sum(axis=1)
    assert np.all(res.energy[:, 1] == 0.0)              # no potential is counted
    assert np.ptp(total) > 1.0
    assert np.abs(res.info["energy_balance"]).max() < 1e-7


def test_stiffness_is_taken_at_the_state_the_run_starts_from(build_root, tmp_path):
    """simulate normalises x0's quaternion, so the scene's |lambda|max must be taken
    there too: on the heavy body on a ball joint, x0's quaternion scaled by 10 moved
    it from 5.7 to 56.1 1/s."""
    model = Path(__file__).parent / "data" / "joints" / "heavy_body_ball.yaml"
    path = tmp_path / "ball_swing.yaml"
    path.write_text(f"scene: ball_swing\nmodel: {model}\neffects: [gravity]\n"
                    "initial: {J_qw: 0.8, J_qx: 0.4, J_qy: 0.2, J_qz: 0.4,\n"
                    "          J_wx: 0.5, J_wy: -0.3, J_wz: 0.2}\n"
                    "time: {end: 1.0, sample: 0.1}\nintegrator: {method: rk4, step: 0.01}\n")
    swing = modelgen.load_scene(path, build_root / "scene_ball_swing")
    x0 = swing.initial_state()
    scaled = x0.copy()
    scaled[list(swing.model.quaternions[0])] *= 10.0
    assert swing.stiffness(scaled) == pytest.approx(swing.stiffness(x0), rel=1e-12)
