"""The hard-case suite: named hard cases, each against a reference modelgen does not compute.

Each case simulates only through ``CompiledModel.simulate`` and returns a
:class:`CaseResult`: what was tried, the reference (closed form, 30-digit
mpmath, scipy's ``expm``, MuJoCo), the tolerance, the measured figure, and a
verdict (``passed`` True / False, or None when a peer is not installed), plus
the curves worth plotting.  ``bench/hard_cases.py`` runs them all and writes
``docs/hard_cases.md`` and its figure; ``modelgen hard-cases`` does the same.
The models and closed forms are in :mod:`modelgen.bench.hard_case_models`.

>>> sorted(CASES)[:3]
['bicycle_capsize', 'chain_conditioning', 'energy_long_run']
"""
from __future__ import annotations

import importlib.util
import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
from matplotlib.figure import Figure
from scipy.linalg import expm

from modelgen.bench import hard_case_models as hm
from modelgen.bench.peers import chain_mjcf
from modelgen.codegen.pipeline import default_output
from modelgen.errors import DerivationError, ModelgenError
from modelgen.model.api import parse_model
from modelgen.model.chains import spatial_chain
from modelgen.sim.load import load


@dataclass(frozen=True)
class Curve:
    """One panel of the figure: named series of (x, y) on shared axes."""
    title: str
    xlabel: str
    ylabel: str
    series: tuple            # ((label, x array, y array), ...)
    logx: bool = False
    logy: bool = True


@dataclass(frozen=True)
class CaseResult:
    """The outcome of one hard case."""
    name: str
    tried: str               # what was run
    reference: str           # what it is compared against (never modelgen itself)
    tolerance: str
    figure: str              # the measured figure
    passed: bool | None      # None: skipped (a peer is not installed)
    note: str = ""
    curves: tuple = field(default=())

    @property
    def verdict(self) -> str:
        return {True: "pass", False: "FAIL", None: "skipped"}[self.passed]


@dataclass(frozen=True)
class Context:
    """Where the cases build their models, and whether to run the short version."""
    build_root: Path
    quick: bool = False

    def model(self, text: str, **options):
        spec = parse_model(text)
        return load(spec, self.build_root / spec.name, **options)


def _event(g: Callable, direction: float = 0.0, terminal=False):
    g.direction, g.terminal = direction, terminal
    return g


def _rel(a, b) -> float:
    return float(abs(a - b) / abs(b))


# -- the cases -------------------------------------------------------------------------

def pendulum_near_top(ctx: Context) -> CaseResult:
    """Released 0.1 deg below the top: the half period by event against 4 sqrt(L/g) K(k)."""
    cm = ctx.model(hm.PENDULUM)
    theta0 = math.pi - math.radians(0.1)
    T = hm.pendulum_period(theta0)
    rtols = (1e-7, 1e-9, 1e-11, 1e-13)
    errors = []
    for rtol in rtols:
        ev = _event(lambda t, x: x[1], direction=1.0, terminal=True)
        res = cm.simulate([theta0, 0.0], (0.0, T), method="dop853", rtol=rtol,
                          atol=rtol * 1e-2, events=ev)
        got = 2 * res.t_events[0][0] if res.status == 1 else math.nan
        errors.append(_rel(got, T))
    worst = errors[-1]
    return CaseResult(
        "pendulum_near_top", "simple pendulum released at 179.9 deg, dop853, half period "
        "by event (q' = 0), rtol 1e-7 .. 1e-13",
        f"T = 4 sqrt(L/g) K(sin^2(theta0/2)) = {T:.12g} s", "rel. error <= 1e-8 at rtol 1e-13",
        f"rel. error {errors[0]:.1e} .. {worst:.1e}", bool(worst <= 1e-8),
        curves=(Curve("pendulum at 179.9 deg: period error", "rtol", "relative error",
                      (("dop853", np.array(rtols), np.array(errors)),), logx=True),))


def lagrange_top_separatrix(ctx: Context) -> CaseResult:
    """The heavy top on its separatrix, cos theta = 1/(1 + sech gamma t), over gamma t <= 18."""
    cm = ctx.model(hm.HEAVY_TOP)
    gamma, x0 = hm.separatrix_start()
    t1 = 18.0 / gamma
    t = np.linspace(0.0, t1, 201)
    res = cm.simulate(x0, (0.0, t1), t_eval=t, method="dop853", rtol=1e-13, atol=1e-13)
    err = np.abs(np.cos(res.y[1]) - hm.separatrix_cos_theta(res.t, gamma))
    worst = float(np.max(err)) if res.success else math.nan
    return CaseResult(
        "lagrange_top_separatrix", f"heavy top from theta = pi/3 on the separatrix to "
        f"gamma t = 18 (t = {t1:.2f} s), dop853 rtol 1e-13",
        "cos theta(t) = 1/(1 + sech(gamma t))", "max |cos theta error| <= 1e-10",
        f"max error {worst:.1e}", bool(worst <= 1e-10),
        curves=(Curve("Lagrange top on the separatrix", "gamma t", "|cos theta error|",
                      (("dop853 rtol 1e-13", gamma * res.t, np.maximum(err, 1e-17)),)),))


def sleeping_top(ctx: Context) -> CaseResult:
    """Spin 20% above and below C^2 w^2 = 4 A m g a, from theta = 0.01: bounded or not."""
    cm = ctx.model(hm.HEAVY_TOP)
    w_c = hm.sleeping_top_threshold()
    theta0, span = 0.01, (0.0, 3.0)
    rows = []
    for ratio in (1.2, 0.8):
        res = cm.simulate([0.0, theta0, 0.0, 0.0, 0.0, ratio * w_c], span, method="dop853",
                          rtol=1e-10, atol=1e-12)
        rows.append((ratio, float(np.max(res.y[1])), res.success))
    stable, unstable = rows
    ok = stable[2] and unstable[2] and stable[1] < 5 * theta0 and unstable[1] > 0.5
    return CaseResult(
        "sleeping_top", "heavy top spinning about the vertical from theta = 0.01 at 1.2 and "
        "0.8 times the threshold spin, 3 s",
        f"stable exactly when C^2 w^2 > 4 A m g a (w_c = {w_c:.4g} rad/s)",
        "max theta < 0.05 above, > 0.5 below",
        f"max theta {stable[1]:.3g} (1.2 w_c), {unstable[1]:.3g} (0.8 w_c)", bool(ok))


def stiff_springs(ctx: Context) -> CaseResult:
    """A stiff, damped spring k = 1e2 .. 1e8: rodas' cost stays flat, dopri5's grows as
    sqrt(k); both solutions against the matrix exponential."""
    cm = ctx.model(hm.STIFF_PAIR, jacobian=True)
    ks = (1e2, 1e4, 1e6) if ctx.quick else (1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8)
    t1, dx0 = 2.0, np.array([0.1, 0.1, 0.0, 0.0])   # the stiff spring starts relaxed
    t = np.linspace(0.0, t1, 41)
    cost = {"rodas": [], "dopri5": []}
    worst = 0.0
    for k in ks:
        p = {"k": k, "c": math.sqrt(2.0 * k)}          # critically damped: reduced mass 1/2
        S = hm.stiff_pair_matrix(1.0, 1.0, 1.0, k, p["c"])
        ref = np.array([expm(S * ti) @ dx0 for ti in t]).T + np.array([[1.0], [2.0], [0], [0]])
        for method in cost:
            res = cm.simulate(ref[:, 0], (0.0, t1), t_eval=t, method=method, rtol=1e-8,
                              atol=1e-10, p=p, max_steps=10 ** 7)
            if not res.success:
                cost[method].append(math.nan)
                worst = math.inf
                continue
            cost[method].append(res.nfev)
            worst = max(worst, float(np.max(np.abs(res.y - ref))))
    growth = cost["rodas"][-1] / cost["rodas"][0]
    ok = worst <= 1e-6 and growth <= 3.0
    return CaseResult(
        "stiff_springs", f"two masses, a stiff spring k = {ks[0]:.0e} .. {ks[-1]:.0e} with "
        "critical damping sqrt(2k), rodas and dopri5 at rtol 1e-8 over 2 s",
        "expm of the linear state matrix (scipy)",
        "max |x error| <= 1e-6; rodas rhs calls grow <= 3x",
        f"max error {worst:.1e}; rhs calls rodas {cost['rodas'][0]} -> {cost['rodas'][-1]}, "
        f"dopri5 {cost['dopri5'][0]} -> {cost['dopri5'][-1]}", bool(ok),
        curves=(Curve("cost versus stiffness", "spring stiffness k (N/m)",
                      "rhs evaluations", tuple((m, np.array(ks), np.array(c, dtype=float))
                                               for m, c in cost.items()), logx=True),))


def mass_ratios(ctx: Context) -> CaseResult:
    """q'' of the double pendulum for m2/m1 and J2/J1 = 1e-12 .. 1e12 against mpmath.

    Mass ratios leave A well conditioned (error at round-off); a large inertia
    ratio makes A ill-conditioned (the rods then barely turn relative to each
    other), and the bound of a backward-stable solve is 10 eps cond(A)."""
    cm = ctx.model(hm.DOUBLE_PENDULUM)
    rng = np.random.default_rng(8)
    ratios = 10.0 ** np.arange(-12, 13, 4 if ctx.quick else 2)
    base = {name: cm.parameters[name] for name in ("m1", "m2", "l1", "l2", "J1", "J2")}
    errs = {"m2/m1": [], "J2/J1": []}
    bound = {"m2/m1": [], "J2/J1": []}
    for r in ratios:
        for label, p in (("m2/m1", {"m2": r}), ("J2/J1", {"J2": r * base["J1"]})):
            worst, cond = 0.0, 0.0
            for _ in range(3):
                q, qd = rng.uniform(-3, 3, 2), rng.uniform(-2, 2, 2)
                ref = hm.double_pendulum_qdd(q, qd, **{**base, **p})
                got = cm.rhs(0.0, np.concatenate([q, qd]), p=p)[2:]
                worst = max(worst, float(np.max(np.abs(got - ref)) / np.max(np.abs(ref))))
                cond = max(cond, float(np.linalg.cond(cm.mass_matrix(q, p=p))))
            errs[label].append(worst)
            bound[label].append(max(1e-12, 10 * 2.2e-16 * cond))
    ok = all(e <= b for k in errs for e, b in zip(errs[k], bound[k]))
    return CaseResult(
        "mass_ratios", "double pendulum q'' at 3 random states for m2/m1 and J2/J1 = "
        "1e-12 .. 1e12", "A q'' = tau - h written by hand, solved with 30-digit mpmath",
        "rel. error <= max(1e-12, 10 eps cond(A))",
        f"max rel. error {max(errs['m2/m1']):.1e} (mass), {max(errs['J2/J1']):.1e} at "
        f"cond(A) {max(bound['J2/J1']) / 2.2e-15:.1e} (inertia, within 10 eps cond(A))", bool(ok),
        curves=(Curve("q'' error versus mass and inertia ratio", "ratio", "relative error",
                      tuple((k, ratios, np.maximum(np.array(v), 1e-17))
                            for k, v in errs.items())
                      + (("10 eps cond(A), J2/J1", ratios, np.array(bound["J2/J1"])),),
                      logx=True),))


def singular_at_start(ctx: Context) -> CaseResult:
    """The heavy top started upright (theta = 0): A is singular; a status, never NaN."""
    cm = ctx.model(hm.HEAVY_TOP)
    res = cm.simulate([0.0, 0.0, 0.0, 0.0, 0.0, 50.0], (0.0, 1.0), method="dop853")
    ok = res.status == -3 and res.t_fail == 0.0 and np.all(np.isfinite(res.y))
    return CaseResult(
        "singular_at_start", "heavy top started at theta = 0 (ZXZ gimbal lock)",
        "rank A = 2 at theta = 0: the phi and psi axes coincide",
        "mass-matrix status -3 at t = 0, no NaN",
        f"status {res.status} at t = {res.t_fail}: {res.message[:60]}...", bool(ok))


def singular_reached(ctx: Context) -> CaseResult:
    """The separatrix top creeping toward theta = 0 (dop853, rtol 1e-12): each run must stop
    with a status whose message names the singular configuration, the long one after
    following the closed form down to theta = 1e-5.  The crba rhs: the case is about
    A's condition number (the aba rhs has no A and integrates through)."""
    cm = ctx.model(hm.HEAVY_TOP, formulation="crba")
    gamma, x0 = hm.separatrix_start()
    t_ref = hm.separatrix_time_to(1e-5, gamma)
    figures, ok = [], True
    for max_steps in (10 ** 5,) if ctx.quick else (10 ** 5, 10 ** 6):
        res = cm.simulate(x0, (0.0, 6.0), method="dop853", rtol=1e-12, atol=1e-12,
                          t_eval=np.linspace(0.0, 6.0, 601), max_steps=max_steps)
        named = "singular" in res.message
        t_stop = res.t_fail or float(res.t[-1])      # max steps: the last sample
        figures.append(f"max_steps {max_steps:.0e}: status {res.status} at t = {t_stop:.3f} s "
                       f"({res.nfev} rhs calls), cause named: {named}")
        ok &= bool(res.status < 0 and named and np.all(np.isfinite(res.y)))
        if max_steps > 10 ** 5:
            ok &= bool(t_stop >= t_ref)
    return CaseResult(
        "singular_reached", "separatrix top (dop853 rtol 1e-12) creeping toward theta = 0 "
        "over 6 s, max_steps 1e5 and 1e6",
        f"closed form: theta = 1e-5 at t = {t_ref:.3f} s, theta -> 0 as t -> infinity",
        "a failure status whose message names the singular configuration; the 1e6 run "
        "stops after t(theta = 1e-5)", "; ".join(figures), ok, note=res.message)


def singular_everywhere(ctx: Context) -> CaseResult:
    """A coordinate that moves no mass: refused on a fresh build and again from the cache."""
    with tempfile.TemporaryDirectory() as tmp:
        spec = parse_model(hm.SINGULAR_EVERYWHERE)
        seen = []
        for attempt in ("fresh", "cached"):
            try:
                load(spec, Path(tmp) / spec.name)
                seen.append(f"{attempt}: loaded")
            except DerivationError as exc:
                seen.append(f"{attempt}: refused" if "'q2'" in str(exc) else f"{attempt}: ?")
    ok = seen == ["fresh: refused", "cached: refused"]
    return CaseResult(
        "singular_everywhere", "pendulum whose particle bob also turns about the rod (q2)",
        "A_22 = 0 for every q: q2 moves no mass", "DerivationError naming q2, fresh and cached",
        "; ".join(seen), bool(ok))


def energy_long_run(ctx: Context) -> CaseResult:
    """Energy of the double pendulum over 1e4 s: bounded for gauss4 and midpoint, secular
    for dopri5."""
    cm = ctx.model(hm.DOUBLE_PENDULUM)
    t1 = 1e3 if ctx.quick else 1e4
    x0 = np.array([-1.07, 0.3, 0.0, 0.0])    # 0.5 rad from hanging: regular motion
    E0 = float(np.sum(cm.energy(x0[:2], x0[2:])))
    t = np.linspace(0.0, t1, 401)
    series, figures, ok = [], [], True
    for method, opts in (("gauss4", {"step": 0.01}), ("midpoint", {"step": 0.005}),
                         ("dopri5", {"rtol": 1e-6, "atol": 1e-8})):
        res = cm.simulate(x0, (0.0, t1), t_eval=t, method=method, max_steps=10 ** 7, **opts)
        dE = np.abs(np.sum(cm.energies(res), axis=1) - E0) / abs(E0)
        # mean |dE| late in the run against early: about 1 when bounded, about
        # 0.95 / 0.15 = 6 for a drift linear in t
        early = np.mean(dE[(res.t >= t1 / 10) & (res.t <= t1 / 5)])
        late = np.mean(dE[res.t >= 0.9 * t1])
        ratio = float(late / early)
        figures.append(f"{method}: max {np.max(dE):.1e}, late/early {ratio:.2f}")
        series.append((method, res.t[1:], np.maximum(dE[1:], 1e-17)))
        if method == "dopri5":
            ok &= bool(res.success and ratio > 3.0)
        else:
            ok &= bool(res.success and ratio < 2.0 and np.max(dE) < 1e-2)
    return CaseResult(
        "energy_long_run", f"double pendulum 0.5 rad from hanging (q = (-1.07, 0.3)) over "
        f"{t1:.0e} s: gauss4 "
        "h = 0.01, midpoint h = 0.005, dopri5 rtol 1e-6",
        f"energy conservation (E0 = {E0:.6g} J)",
        "mean |dE| over [0.9, 1] T / over [0.1, 0.2] T: gauss4, midpoint < 2 (bounded) "
        "and |dE| < 1e-2; dopri5 > 3 (secular)",
        "; ".join(figures), ok,
        curves=(Curve("energy error over a long run", "t (s)", "|E - E0| / |E0|",
                      tuple(series)),))


def friction_stop(ctx: Context) -> CaseResult:
    """Stop time of a block on an incline against v0 / (g (mu cos a - sin a)): the error is
    first order in the smoothing speed."""
    cm = ctx.model(hm.INCLINE_BLOCK, jacobian=True)
    p0 = cm.parameters
    alpha, mu, g, v0 = p0["alpha"], p0["mu"], p0["g"], 1.0
    t_star = v0 / (g * (mu * math.cos(alpha) - math.sin(alpha)))
    speeds = (1e-2, 1e-3, 1e-4) if ctx.quick else (1e-2, 3e-3, 1e-3, 3e-4, 1e-4, 3e-5, 1e-5)
    errors = []
    for v_s in speeds:
        creep = v_s * math.atanh(math.tan(alpha) / mu)
        ev = _event(lambda t, x, c=creep: x[1] - 2 * c, direction=-1.0, terminal=True)
        res = cm.simulate([0.0, v0], (0.0, 2 * t_star), method="rodas", rtol=1e-10,
                          atol=1e-12, p={"v_s": v_s}, events=ev)
        errors.append(abs(res.t_events[0][0] - t_star) if res.status == 1 else math.nan)
    slope = float(np.polyfit(np.log(speeds), np.log(errors), 1)[0])
    return CaseResult(
        "friction_stop", f"block on an incline (v0 = 1 m/s), regularised Coulomb friction, "
        f"smoothing speed {speeds[0]:g} .. {speeds[-1]:g} m/s, rodas rtol 1e-10; stop = "
        "speed down to twice the creep",
        f"t* = v0 / (g (mu cos a - sin a)) = {t_star:.6g} s", "error ~ v_s: fitted slope 1 +- 0.1",
        f"slope {slope:.3f}; error {errors[0]:.2e} .. {errors[-1]:.2e} s",
        bool(abs(slope - 1.0) <= 0.1),
        curves=(Curve("friction: stop time error", "smoothing speed v_s (m/s)",
                      "|t_stop - t*| (s)", (("rodas", np.array(speeds), np.array(errors)),),
                      logx=True),))


def chain_conditioning(ctx: Context) -> CaseResult:
    """q'' of spatial chains up to n = 100 against MuJoCo, and cond(A)."""
    if importlib.util.find_spec("mujoco") is None:
        return CaseResult("chain_conditioning", "spatial chains", "MuJoCo", "-", "-", None,
                          note="mujoco is not installed")
    import mujoco
    ns = (5, 20) if ctx.quick else (5, 10, 20, 50, 100)
    rng = np.random.default_rng(100)
    errs, conds = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for n in ns:
            cm = load(spatial_chain(n), ctx.build_root / f"spatial_chain_{n}")
            xml = Path(tmp) / f"chain{n}.xml"
            xml.write_text(chain_mjcf(n, cm.parameters))
            model = mujoco.MjModel.from_xml_path(str(xml))
            data = mujoco.MjData(model)
            worst, cond = 0.0, 0.0
            for _ in range(3):
                x = np.concatenate([rng.uniform(-1, 1, n), rng.uniform(-1, 1, n)])
                data.qpos[:], data.qvel[:] = x[:n], x[n:]
                mujoco.mj_forward(model, data)
                qdd = cm.rhs(0.0, x)[n:]
                worst = max(worst, float(np.max(np.abs(data.qacc - qdd)) / np.max(np.abs(qdd))))
                cond = max(cond, float(np.linalg.cond(cm.mass_matrix(x[:n]))))
            errs.append(worst)
            conds.append(cond)
    return CaseResult(
        "chain_conditioning", f"spatial chains n = {', '.join(map(str, ns))}, 3 random states",
        f"MuJoCo {mujoco.__version__} mj_forward qacc (MJCF built from the chain's definition)",
        "max rel. difference <= 1e-9", f"max rel. diff {max(errs):.1e}; cond(A) up to "
        f"{max(conds):.1e} (n = {ns[-1]})", bool(max(errs) <= 1e-9),
        curves=(Curve("chains: q'' against MuJoCo", "links n", "rel. difference / cond(A)",
                      (("|qdd - MuJoCo| / |qdd|", np.array(ns), np.array(errs)),
                       ("cond(A)", np.array(ns), np.array(conds))), logx=True),))


def tennis_racket(ctx: Context) -> CaseResult:
    """Ten flips of a body spinning near its intermediate axis: the flip times against the
    closed-form flip period 2 K(k) / lambda."""
    cm = ctx.model(hm.TORQUE_FREE)
    I1, I2, I3 = 1.0, 2.0, 3.0
    w0 = np.array([0.05, 0.0, 1.0])       # body x (I1), y (I3), z (I2)
    T = hm.flip_period(I1, I2, I3, [w0[0], w0[2], w0[1]])

    def w_mid(t, x):                       # body z component of the angular velocity
        _, pitch, roll, yaw_d, pitch_d, _ = x
        return -pitch_d * math.sin(roll) + yaw_d * math.cos(pitch) * math.cos(roll)
    flips = 10
    res = cm.simulate([0.0, 0.0, 0.0, w0[2], 0.0, w0[0]], (0.0, (flips + 1) * T),
                      method="dop853", rtol=1e-12, atol=1e-12, events=_event(w_mid))
    times = np.asarray(res.t_events[0]) if res.t_events else np.zeros(0)
    if not res.success or len(times) < flips:
        return CaseResult("tennis_racket", "torque-free body", "2 K(k)/lambda", "-",
                          f"status {res.status}, {len(times)} flips", False, note=res.message)
    times = times[:flips]
    drift = np.abs(times - times[0] - T * np.arange(flips)) / T
    worst = float(np.max(drift[1:]))
    return CaseResult(
        "tennis_racket", "torque-free body (I = 1, 2, 3) spun about its intermediate axis "
        "with 5% on the smallest, ten flips, dop853 rtol 1e-12",
        f"flip period 2 K(k) / lambda = {T:.10g} s (Landau-Lifshitz 37)",
        "flip-time drift <= 1e-8 periods over ten flips",
        f"drift {drift[1]:.1e} (flip 2) .. {drift[-1]:.1e} (flip {flips}) periods",
        bool(worst <= 1e-8),
        curves=(Curve("tennis racket: flip-time drift", "flip", "|drift| (periods)",
                      (("dop853 rtol 1e-12", np.arange(2, flips + 1),
                        np.maximum(drift[1:], 1e-17)),)),))


def fixed_step_implicit(ctx: Context) -> CaseResult:
    """gauss4 and midpoint on the double pendulum at steps their Newton iteration can
    solve: no failure over the run, and the error at t = 0.6 s (a grid point of every
    step) against dop853 at rtol 1e-13."""
    cm = ctx.model(hm.DOUBLE_PENDULUM)
    x0 = np.array([2.0, 1.0, 0.0, 0.0])
    t1, t_chk = (30.0 if ctx.quick else 150.0), 0.6
    ref = cm.simulate(x0, (0.0, t_chk), method="dop853", rtol=1e-13, atol=1e-13).y[:, -1]
    figures, ok = [], True
    for method, step in (("gauss4", 0.05), ("gauss4", 0.03), ("gauss4", 0.02),
                         ("gauss4", 0.015), ("midpoint", 0.01)):
        res = cm.simulate(x0, (0.0, t1), method=method, step=step, t_eval=[t1],
                          max_steps=10 ** 7)
        short = cm.simulate(x0, (0.0, t_chk), method=method, step=step)
        err = float(np.max(np.abs(short.y[:2, -1] - ref[:2]))) if short.success else math.nan
        figures.append(f"{method} h={step}: " + ("ok" if res.success else
                                                  f"status {res.status} at {res.t_fail:.4g}")
                       + f", error {err:.1e}")
        ok &= bool(res.success and short.success and err < 1e-3)
    return CaseResult(
        "fixed_step_implicit", f"double pendulum from (2, 1) rad over {t1:g} s, gauss4 h = "
        "0.05 .. 0.015, midpoint h = 0.01 (the steps that stopped with status -5)",
        "dop853 rtol 1e-13 at t = 0.6 s; the run must reach the end",
        "every run reaches the end; angle error at 0.6 s < 1e-3 rad", "; ".join(figures), ok)


def rk4_beyond_stability(ctx: Context) -> CaseResult:
    """RK4 on the friction block with a step beyond its stability limit: warned, not silent."""
    cm = ctx.model(hm.INCLINE_BLOCK, jacobian=True)
    p = {"v_s": 1e-4}
    alpha, mu = cm.parameters["alpha"], cm.parameters["mu"]
    creep = 1e-4 * math.atanh(math.tan(alpha) / mu)
    x0 = [0.0, 0.5 * creep]                 # near the creep, where the friction is stiff
    res = cm.simulate(x0, (0.0, 0.05), method="rk4", step=1e-4, p=p, t_eval=[0.05])
    warned = "stability" in res.message
    return CaseResult(
        "rk4_beyond_stability", "friction block at v_s = 1e-4 m/s near its creep speed, rk4 "
        "h = 1e-4 s", f"creep speed v_s atanh(tan a / mu) = {creep:.3g} m/s; RK4's stability "
        "limit h |lambda| <= 2.79", "the result's message carries the stability warning",
        f"end speed {res.y[1, -1]:.3g} m/s; warned: {warned}", bool(warned),
        note=res.message)


def four_bar_dead_point(ctx: Context) -> CaseResult:
    """A crank-rocker driven by its rocker's speed into a dead point (crank and coupler
    in line): every run either stops there with a status naming the singular
    constraint Jacobian, at the closed-form rocker angle, or goes on conserving the
    energy; never NaN."""
    cm = ctx.model(hm.FOUR_BAR_ROCKER)
    dead = hm.rocker_dead_points()
    q0 = cm.assemble([0.0, 1.2, 2.0], keep=["q1"])
    x0 = np.concatenate([q0, cm.consistent_speeds(q0, [0.0, 0.0, 3.0])])
    E0 = float(cm.energy(x0[:3], x0[3:]).sum())
    scale = float(cm.energy(x0[:3], x0[3:])[0])          # the kinetic energy
    rows, series, ok = [], [], True
    for rtol in (1e-6, 1e-9, 1e-12):
        t = np.linspace(0.0, 5.0, 501)
        res = cm.simulate(x0, (0.0, 5.0), t_eval=t, method="dop853", rtol=rtol,
                          atol=rtol * 1e-2)
        finite = bool(np.all(np.isfinite(res.y)))
        E = np.array([cm.energy(y[:3], y[3:]).sum() for y in res.y.T])
        drift = float(np.max(np.abs(E - E0))) / scale
        series.append((f"rtol {rtol:g}", res.t, np.maximum(np.abs(E - E0) / scale, 1e-17)))
        if res.status != 0:
            named = "constraint Jacobian" in res.message and "dead point" in res.message
            q = res.y[:3, -1]
            off = min(abs(q[2] - r) for r in dead)
            ok &= finite and named and off < 1e-3
            rows.append(f"rtol {rtol:g}: status {res.status} at t = {res.t[-1]:.3f} s, "
                        f"q3 {off:.1e} from the dead point, named: {named}")
        else:
            ok &= finite and drift <= 1e3 * rtol
            rows.append(f"rtol {rtol:g}: went on to t = 5 s, energy drift {drift:.1e} "
                        "of the kinetic energy")
    return CaseResult(
        "four_bar_dead_point", "crank-rocker four-bar (a, b, c, d = 1, 2, 2, 2.5) with the "
        "rocker's speed independent, started at 3 rad/s, dop853 rtol 1e-6, 1e-9, 1e-12 "
        "over 5 s", f"dead points at rocker angles {dead[0]:.10f}, {dead[1]:.10f} rad "
        "(law of cosines: crank and coupler in line)",
        "each run stops with a status naming the singular constraint Jacobian within 1e-3 "
        "rad of a dead point, or conserves the energy to 1e3 rtol; no NaN",
        "; ".join(rows), bool(ok),
        note="a run that goes on has stepped over the dead point: its step crossed the fold "
             "of the constraint manifold and the projection moved q onto it",
        curves=(Curve("four-bar driven into its dead point", "t [s]",
                      "|E - E0| / kinetic energy", tuple(series)),))


def bicycle_capsize(ctx: Context) -> CaseResult:
    """The Whipple bicycle at 8 m/s, beyond its capsize speed, nudged sideways: the
    lean grows as e^(lambda t) with lambda the capsize eigenvalue of cm.linearize."""
    path = Path(__file__).resolve().parents[2] / "models" / "whipple_bicycle.yaml"
    if not path.is_file():
        return CaseResult("bicycle_capsize", "-", "-", "-", "models/ not shipped", None)
    from modelgen.bench.bicycle import TABLE_2, lean_steer_eigenvalues, upright_state
    cm = load(path, ctx.build_root / "whipple_bicycle", linearize=True)
    v = 8.0
    lam = float(np.max(lean_steer_eigenvalues(cm, v).real))
    x0 = upright_state(cm, v)
    qd = x0[cm.nq:].copy()
    qd[cm.speeds.index("roll_dot")] = 1e-6
    x0 = np.concatenate([x0[:cm.nq], cm.consistent_speeds(x0[:cm.nq], qd)])
    t1 = 20.0 if ctx.quick else 30.0
    t = np.linspace(0.0, t1, 601)
    res = cm.simulate(x0, (0.0, t1), t_eval=t, method="dop853", rtol=1e-12, atol=1e-15)
    lean = np.abs(res.y[cm.coordinates.index("roll")])
    late = res.t >= 10.0          # the weave (-2.69) and castering (-20.3) modes died out
    rate = float(np.polyfit(res.t[late], np.log(lean[late]), 1)[0]) if res.success \
        else math.nan
    err = abs(rate - lam) / lam
    paper = TABLE_2[8][2]
    return CaseResult(
        "bicycle_capsize", f"Whipple bicycle upright at {v:g} m/s, roll rate nudged by 1e-6 "
        f"rad/s, dop853 rtol 1e-12 over {t1:g} s; growth rate of |lean| fitted on t >= 10 s",
        f"capsize eigenvalue of cm.linearize {lam:.10f} /s (the paper's Table 2: "
        f"{paper:.10f})", "relative difference <= 1e-5",
        f"fitted {rate:.10f} /s, relative difference {err:.1e}; lean grew "
        f"{lean[-1] / lean[late][0]:.1f}x from t = 10 s", bool(err <= 1e-5),
        curves=(Curve("bicycle at 8 m/s: capsize", "t [s]", "|lean| [rad]",
                      (("run", res.t[1:], np.maximum(lean[1:], 1e-17)),
                       ("e^(lambda t) fit", res.t[late],
                        lean[late][0] * np.exp(lam * (res.t[late] - res.t[late][0]))))),))


#: every case, by name, in the table's order
CASES = {f.__name__: f for f in (
    pendulum_near_top, lagrange_top_separatrix, sleeping_top, stiff_springs, mass_ratios,
    singular_at_start, singular_reached, singular_everywhere, energy_long_run,
    friction_stop, chain_conditioning, tennis_racket, fixed_step_implicit,
    rk4_beyond_stability, four_bar_dead_point, bicycle_capsize)}


def run_cases(names=None, *, quick=False, build_root=None, progress=None) -> list:
    """Run the named cases (default: all); returns their :class:`CaseResult`s.

    A case that raises is reported as failed with the exception, never dropped.
    """
    unknown = [name for name in names or () if name not in CASES]
    if unknown:
        raise ModelgenError(f"unknown hard case(s) {', '.join(unknown)}; the cases are "
                            f"{', '.join(CASES)}")
    ctx = Context(Path(build_root) if build_root else default_output("hard_cases"), quick)
    results = []
    for name in names or CASES:
        if progress:
            progress(name)
        try:
            results.append(CASES[name](ctx))
        except Exception as exc:   # noqa: BLE001 - a crashing case is a failed case
            results.append(CaseResult(name, "-", "-", "-", f"raised {type(exc).__name__}",
                                      False, note=str(exc)))
    return results


def markdown(results) -> str:
    """The results as a markdown table: case, tried, reference, tolerance, figure, verdict."""
    lines = ["| case | what is tried | reference | tolerance | measured | verdict |",
             "|---|---|---|---|---|---|"]
    for r in results:
        cells = (f"`{r.name}`", r.tried, r.reference, r.tolerance, r.figure,
                 f"**{r.verdict}**")
        lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
    return "\n".join(lines) + "\n"


def figure(results):
    """A one-page matplotlib Figure of every case's curves (no pyplot)."""
    curves = [c for r in results for c in r.curves]
    cols = 3
    rows = max(1, -(-len(curves) // cols))
    fig = Figure(figsize=(15, 4 * rows), layout="constrained")
    for i, c in enumerate(curves):
        ax = fig.add_subplot(rows, cols, i + 1)
        for label, x, y in c.series:
            ax.plot(x, y, "o-", ms=3, label=label)
        ax.set_xscale("log" if c.logx else "linear")
        ax.set_yscale("log" if c.logy else "linear")
        ax.set(title=c.title, xlabel=c.xlabel, ylabel=c.ylabel)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    return fig
