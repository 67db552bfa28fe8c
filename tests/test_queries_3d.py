"""Every query kind on genuinely 3-D models, against sympy.physics.mechanics.

tests/test_queries.py checks the queries on the planar double pendulum, where
every rotation is about one axis and several sign and direction mistakes
cannot show.  Here the same quantities are checked on spatial models: the
heavy top (ZXZ Euler angles), the spherical pendulum (x then y), the 7-joint
arm (z y z y z y z, full inertia tensors), a heavy body on a ball joint and
the tennis racket on a free joint (unit quaternions).  Each reference is
built by hand from the YAML with sympy.physics.mechanics (frames by
``orient_axis`` / ``orient_body_fixed``, points by ``locatenew``, velocities
by ``dt`` in N, energies and partial velocities from those), never from
modelgen's own derivation, and compared at random states and parameters with

* the closed-form queries :class:`modelgen.derive.queries.Mechanism`;
* the compiled scene outputs (``cm.output_values``), ``cm.energy`` and
  ``cm.body_poses``.

Conventions checked (and stated in docs/model-format.md, ``Mechanism``):

* change of basis ``change_of_basis(A, B)`` and ``{orientation: A,
  relative_to: B}``: the matrix M with ``v_B = M v_A``; its column j is A's
  j-th unit vector in components of B;
* ``angular_velocity(A, B, C)`` and ``{angular_velocity: B, relative_to: A,
  components: C}``: the angular velocity of B relative to A (B moving, A
  fixed), in components of C;
* ``position(P, Q, C)`` and ``{position: Q, from: P, base: C}``: r_Q - r_P
  (the vector from P to Q) in components of C;
* a ball or free joint's quaternion (w, x, y, z), scalar first, turns the
  parent into the joint's base by the angle 2 atan2(|(x, y, z)|, w) about the
  axis (x, y, z) in the parent's components; its angular velocity and a free
  joint's linear velocity are in components of the joint's base.
"""
from __future__ import annotations

import numpy as np
import pytest
import sympy
import yaml
from sympy.physics.mechanics import (Point, ReferenceFrame, dynamicsymbols, inertia, msubs)

import modelgen
from modelgen.derive.queries import Mechanism
from modelgen.model.api import load_model

from conftest import MODELS, ROOT, SUMMARY

JOINTS = ROOT / "tests" / "data" / "joints"
TOL = 1e-12
t = dynamicsymbols._t
S = sympy.Symbol


# -- the references, by hand -----------------------------------------------------
class Ref:
    """A model built with sympy.physics.mechanics: frames and points by name."""

    def __init__(self, coordinates=(), joint_speeds=()):
        self.N = ReferenceFrame("N")
        self.O = Point("O")
        self.O.set_vel(self.N, 0)
        self.frames = {"E": self.N}
        self.points = {"O": self.O}
        self.bodies = {}                  # name -> (mass, G, frame, inertia dyadic about G)
        self.gravity = None               # a Vector in N
        self.coordinates = coordinates    # simple coordinates: q(t), q'(t), q''(t)
        self.joint_speeds = joint_speeds  # a joint's speeds: w(t), w'(t)
        self.extra_velocity = {}          # point -> velocity not in d/dt of its position
        self.dofs = {}                    # dof name -> the generalized speed (a function of t)
        self._energies = (None, None)     # (subs, (T, V)) of the last state asked for
        for c in coordinates:
            self.dofs[c] = dynamicsymbols(c, 1)
        for s in joint_speeds:
            self.dofs[s] = dynamicsymbols(s)

    def frame(self, name, parent, axis, angle):
        """A base turned by ``angle`` about the parent's unit vector ``axis`` (1, 2, 3)."""
        P = self.frames[parent]
        B = ReferenceFrame(name)
        B.orient_axis(P, axis=[P.x, P.y, P.z][axis - 1], angle=angle)
        self.frames[name] = B
        return B

    def point(self, name, origin, base, coordinates):
        B = self.frames[base]
        offset = sum((c * e for c, e in zip(coordinates, (B.x, B.y, B.z))), 0 * B.x)
        self.points[name] = self.points[origin].locatenew(name, offset)
        return self.points[name]

    def quaternion_frame(self, name, joint, parent="E"):
        """The joint's base: the parent turned by the quaternion's angle about its axis,
        turning at (wx, wy, wz) in its own components (set explicitly)."""
        P = self.frames[parent]
        w, x, y, z = (S(f"{joint}_q{c}") for c in "wxyz")
        s = sympy.sqrt(x**2 + y**2 + z**2)
        B = ReferenceFrame(name)
        B.orient_axis(P, axis=(x * P.x + y * P.y + z * P.z) / s, angle=2 * sympy.atan2(s, w))
        wx, wy, wz = dynamicsymbols(f"{joint}_wx {joint}_wy {joint}_wz")
        B.set_ang_vel(P, wx * B.x + wy * B.y + wz * B.z)
        self.frames[name] = B
        return B

    def velocity(self, point):
        return self.points[point].pos_from(self.O).dt(self.N) + \
            self.extra_velocity.get(point, 0 * self.N.x)

    def acceleration(self, point):
        return self.velocity(point).dt(self.N)

    def energies(self, subs):
        """(T, V) at one state: each body's vectors evaluated in its own base, summed
        as numbers (the symbolic sums of the 7-joint arm take seconds)."""
        if self._energies[0] is subs:     # T, V and H of one state: computed once
            return self._energies[1]
        T = V = 0.0
        for m, G, B, I in self.bodies.values():
            m = float(msubs(m, subs))
            v = _num(self.velocity(G).to_matrix(B), subs)
            w = _num(B.ang_vel_in(self.N).to_matrix(B), subs)
            T += m * v @ v / 2 + w @ _num(I.to_matrix(B), subs).reshape(3, 3) @ w / 2
            if self.gravity is not None:
                V -= m * _num(self.gravity.to_matrix(self.N), subs) @ \
                    _num(self.points[G].pos_from(self.O).to_matrix(self.N), subs)
        self._energies = (subs, (T, V))
        return T, V

    def substitutions(self, state):
        """mechanics' q(t), q'(t), q''(t), w(t), w'(t) and constants -> numbers."""
        subs = {}
        for c in self.coordinates:
            f = dynamicsymbols(c)
            subs[f.diff(t, 2)] = state[c + "_ddot"]
            subs[f.diff(t)] = state[c + "_dot"]
            subs[f] = state[c]
        for s in self.joint_speeds:
            f = dynamicsymbols(s)
            subs[f.diff(t)] = state[s + "_dot"]
            subs[f] = state[s]
        for name, value in state.items():
            subs.setdefault(S(name), value)
        return subs


def heavy_top():
    r = Ref(("phi", "theta", "psi"))
    phi, theta, psi = dynamicsymbols("phi theta psi")
    r.frame("B1", "E", 3, phi)
    r.frame("B2", "B1", 1, theta)
    # B3 straight from N by body-fixed ZXZ angles: a second route to the same base
    B3 = ReferenceFrame("B3")
    B3.orient_body_fixed(r.N, (phi, theta, psi), "ZXZ")
    r.frames["B3"] = B3
    r.point("G", "O", "B3", (0, 0, S("a")))
    A0, C = S("A0"), S("C")
    r.bodies["top"] = (S("m"), "G", B3, inertia(B3, A0, A0, C))
    r.gravity = -S("g") * r.N.z
    return r


def spherical_pendulum():
    r = Ref(("q1", "q2"))
    q1, q2 = dynamicsymbols("q1 q2")
    r.frame("B1", "E", 1, q1)
    B2 = r.frame("B2", "B1", 2, q2)
    r.point("P", "O", "B2", (0, 0, -S("L")))
    r.bodies["bob"] = (S("m"), "P", B2, inertia(B2, 0, 0, 0))
    r.gravity = -S("g") * r.N.z
    return r


def arm7():
    """The chain written out; only the numbers (inertias, centres of mass) are
    read from the YAML, with a plain YAML reader."""
    data = yaml.safe_load((MODELS / "arm7.yaml").read_text())
    names = [f"q{i}" for i in range(1, 8)]
    r = Ref(tuple(names))
    q = dynamicsymbols(" ".join(names))
    d = [S(f"d{i}") for i in range(8)]
    a3, a6 = S("a3"), S("a6")
    for i in range(1, 8):
        r.frame(f"B{i}", "E" if i == 1 else f"B{i - 1}", 3 if i % 2 else 2, q[i - 1])
    r.point("J1", "O", "E", (0, 0, d[0]))
    offsets = {2: (0, 0, d[1]), 3: (0, 0, d[2]), 4: (a3, 0, d[3]), 5: (-a3, 0, d[4]),
               6: (0, 0, d[5]), 7: (0, a6, d[6])}
    for i, c in offsets.items():
        r.point(f"J{i}", f"J{i - 1}", f"B{i - 1}", c)
    r.point("flange", "J7", "B7", (0, 0, d[7]))
    for i in range(1, 8):
        G = data["points"][f"G{i}"]
        r.point(f"G{i}", G["from"], G["base"], [sympy.Float(c, 17) for c in G["coordinates"]])
        I = [[sympy.Float(x, 17) for x in row] for row in data["bodies"][f"link{i}"]["inertia"]]
        B = r.frames[f"B{i}"]
        r.bodies[f"link{i}"] = (S(f"m{i}"), f"G{i}", B,
                                inertia(B, I[0][0], I[1][1], I[2][2], I[0][1], I[1][2], I[0][2]))
    r.gravity = -S("g") * r.N.z
    return r


def heavy_body_ball():
    r = Ref(joint_speeds=("J_wx", "J_wy", "J_wz"))
    B = r.quaternion_frame("B", "J")
    r.point("G", "O", "B", (S("a1"), S("a2"), S("a3")))
    I = [[S(f"I{min(i, j)}{max(i, j)}") for j in (1, 2, 3)] for i in (1, 2, 3)]
    r.bodies["body"] = (S("m"), "G", B,
                        inertia(B, I[0][0], I[1][1], I[2][2], I[0][1], I[1][2], I[0][2]))
    r.gravity = -S("g") * r.N.z
    return r


def tennis_racket():
    r = Ref(joint_speeds=("J_vx", "J_vy", "J_vz", "J_wx", "J_wy", "J_wz"))
    B = r.quaternion_frame("B", "J")
    # G at (J_x, J_y, J_z) from O in E, moving at (J_vx, J_vy, J_vz) in B
    r.point("G", "O", "E", (S("J_x"), S("J_y"), S("J_z")))
    vx, vy, vz = dynamicsymbols("J_vx J_vy J_vz")
    r.extra_velocity["G"] = vx * B.x + vy * B.y + vz * B.z
    r.bodies["racket"] = (S("m"), "G", B, inertia(B, S("I1"), S("I2"), S("I3")))
    return r


# -- the cases: model, reference, the outputs asked for ---------------------------
ENERGIES = [("T", {"energy": "kinetic"}), ("V", {"energy": "potential"}),
            ("H", {"energy": "total"})]
CASES = {
    "heavy_top": (MODELS / "heavy_top.yaml", heavy_top, ["gravity"], [
        ("rG", {"position": "G", "from": "O", "base": "B1"}),
        ("rGO", {"position": "O", "from": "G", "base": "B3"}),
        ("vG", {"velocity": "G", "base": "B2"}),
        ("R31", {"orientation": "B3", "relative_to": "B1"}),
        ("R13", {"orientation": "B1", "relative_to": "B3"}),
        ("w31", {"angular_velocity": "B3", "relative_to": "B1", "components": "B2"}),
        ("w13", {"angular_velocity": "B1", "relative_to": "B3", "components": "E"}),
        ("w3", {"angular_velocity": "B3", "components": "B3"}),
        *ENERGIES, ("pose", {"pose": "top"})]),
    "spherical_pendulum": (MODELS / "spherical_pendulum.yaml", spherical_pendulum, ["gravity"], [
        ("rP", {"position": "P", "base": "B1"}),
        ("vP", {"velocity": "P", "base": "B1"}),
        ("R2", {"orientation": "B2"}),
        ("R12", {"orientation": "B1", "relative_to": "B2"}),
        ("w21", {"angular_velocity": "B2", "relative_to": "B1", "components": "E"}),
        ("w2", {"angular_velocity": "B2", "components": "B2"}),
        *ENERGIES, ("pose", {"pose": "bob"})]),
    "arm7": (MODELS / "arm7.yaml", arm7, ["gravity"], [
        ("tool", {"position": "flange", "from": "J2", "base": "B3"}),
        ("back", {"position": "J2", "from": "flange", "base": "B6"}),
        ("v_tool", {"velocity": "flange", "base": "B4"}),
        ("R72", {"orientation": "B7", "relative_to": "B2"}),
        ("w72", {"angular_velocity": "B7", "relative_to": "B2", "components": "B5"}),
        ("w27", {"angular_velocity": "B2", "relative_to": "B7", "components": "B7"}),
        *ENERGIES, ("pose5", {"pose": "link5"})]),
    "heavy_body_ball": (JOINTS / "heavy_body_ball.yaml", heavy_body_ball, ["gravity"], [
        ("rG", {"position": "G", "base": "E"}),
        ("rOG", {"position": "O", "from": "G", "base": "B"}),
        ("vG", {"velocity": "G", "base": "E"}),
        ("RB", {"orientation": "B"}),
        ("RE", {"orientation": "E", "relative_to": "B"}),
        ("wB", {"angular_velocity": "B", "components": "E"}),
        ("wE", {"angular_velocity": "E", "relative_to": "B", "components": "B"}),
        *ENERGIES, ("pose", {"pose": "body"})]),
    "tennis_racket": (MODELS / "tennis_racket.yaml", tennis_racket, [], [
        ("rG", {"position": "G", "base": "B"}),
        ("vG", {"velocity": "G", "base": "E"}),
        ("vGB", {"velocity": "G", "base": "B"}),
        ("RB", {"orientation": "B"}),
        ("wB", {"angular_velocity": "B", "components": "E"}),
        ("wBB", {"angular_velocity": "B", "components": "B"}),
        ("T", {"energy": "kinetic"}), ("H", {"energy": "total"}),
        ("pose", {"pose": "racket"})]),
}
#: points whose accelerations and bodies whose partial velocities Mechanism is asked for
ACCELERATIONS = {"heavy_top": [("G", "B2")], "spherical_pendulum": [("P", "B1")],
                 "arm7": [("flange", "B3"), ("G4", "E")], "heavy_body_ball": [("G", "B")],
                 "tennis_racket": [("G", "E")]}
#: random states per model: fewer for the arm, whose reference takes seconds per state
STATES = {"arm7": 1}
PARTIALS = {"heavy_top": "top", "spherical_pendulum": "bob", "arm7": "link6",
            "heavy_body_ball": "body", "tennis_racket": "racket"}


def random_state(spec, rng) -> dict:
    """Coordinates, speeds, accelerations and parameters (defaults scaled by 0.5..1.5),
    by modelgen's names; each quaternion a random unit one."""
    state = {name: float(value) * rng.uniform(0.5, 1.5) for name, value in spec.parameters}
    for c in spec.simple_coordinates:
        state[c], state[c + "_dot"], state[c + "_ddot"] = rng.uniform(-np.pi, np.pi), \
            rng.uniform(-2, 2), rng.uniform(-3, 3)
    for j in spec.joints:
        for c in j.coordinates:
            state[c] = rng.uniform(-1, 1)
        quat = [c for c in j.coordinates if "_q" in c]
        u = rng.normal(size=4)
        u /= np.linalg.norm(u)
        state.update(zip(quat, map(float, u)))
        for s in j.speeds:
            state[s], state[s + "_dot"] = rng.uniform(-2, 2), rng.uniform(-3, 3)
    return state


# -- what the reference says each output is ----------------------------------------
def _num(expr, subs) -> np.ndarray:
    return np.array(sympy.Matrix(msubs(sympy.Matrix(expr), subs)).evalf(30), dtype=float).ravel()


def reference_output(ref, args, subs) -> np.ndarray:
    """One output, from the mechanics model: the meaning the docs give it."""
    kind = next(k for k in args if k in ("position", "velocity", "orientation",
                                         "angular_velocity", "energy", "pose"))
    F, P = ref.frames, ref.points
    if kind == "position":
        vec = P[args[kind]].pos_from(P[args.get("from", "O")])
        return _num(vec.to_matrix(F[args.get("base", "E")]), subs)
    if kind == "velocity":
        return _num(ref.velocity(args[kind]).to_matrix(F[args.get("base", "E")]), subs)
    if kind == "orientation":
        # column j: the j-th unit vector of `base` in components of `relative_to`
        A, B = F[args[kind]], F[args.get("relative_to", "E")]
        return _num(sympy.Matrix.hstack(*[e.to_matrix(B) for e in (A.x, A.y, A.z)]), subs)
    if kind == "angular_velocity":
        w = F[args[kind]].ang_vel_in(F[args.get("relative_to", "E")])
        return _num(w.to_matrix(F[args.get("components", "E")]), subs)
    if kind == "energy":
        T, V = ref.energies(subs)
        return np.array([{"kinetic": T, "potential": V, "total": T + V}[args[kind]]])
    m, G, B, _ = ref.bodies[args[kind]]
    R = sympy.Matrix.hstack(*[e.to_matrix(ref.N) for e in (B.x, B.y, B.z)])
    T = sympy.Matrix.hstack(R, P[G].pos_from(ref.O).to_matrix(ref.N))
    return _num(sympy.Matrix.vstack(T, sympy.Matrix([[0, 0, 0, 1]])), subs)


def mechanism_output(mech, args):
    """The same output from the closed-form queries (Mechanism's argument order)."""
    if "position" in args:
        return mech.position(args.get("from", "O"), args["position"], args.get("base", "E"))
    if "velocity" in args:
        return mech.velocity(args["velocity"], args.get("base", "E"))
    if "orientation" in args:
        return mech.change_of_basis(args["orientation"], args.get("relative_to", "E"))
    if "angular_velocity" in args:
        return mech.angular_velocity(args.get("relative_to", "E"), args["angular_velocity"],
                                     args.get("components", "E"))
    if "energy" in args:
        T, V = mech.kinetic_energy(), mech.potential_energy()
        return sympy.Matrix([{"kinetic": T, "potential": V, "total": T + V}[args["energy"]]])
    return mech.pose(args["pose"])


def _evaluate(expr, state) -> np.ndarray:
    values = {S(k): v for k, v in state.items()}
    return np.array(sympy.Matrix(expr).xreplace(values).evalf(30), dtype=float).ravel()


def relative(got, want) -> float:
    """max |got - want| over max(|want|, 1e-3): relative, and absolute near zero."""
    got, want = np.asarray(got, float), np.asarray(want, float)
    return float(np.abs(got - want).max() / max(np.abs(want).max(), 1e-3))


WORST: dict = {}


def _record(model, what, err):
    key = (model, what)
    WORST[key] = max(WORST.get(key, 0.0), err)


@pytest.fixture(scope="module", autouse=True)
def _summary():
    yield
    if WORST:
        by_source: dict = {}
        for (model, what), err in WORST.items():
            key = (model, what.split(".")[0])
            by_source[key] = max(by_source.get(key, 0.0), err)
        SUMMARY.append("test_queries_3d, worst relative disagreement with mechanics: " + ", ".join(
            f"{m} {w} {e:.1e}" for (m, w), e in sorted(by_source.items())))


# -- the closed-form queries ---------------------------------------------------------
@pytest.fixture(scope="module")
def mechanisms():
    cache = {}

    def get(model):
        if model not in cache:
            path, build, _, _ = CASES[model]
            cache[model] = (Mechanism(load_model(path), simplify=False), build())
        return cache[model]
    return get


@pytest.mark.parametrize("model", list(CASES))
def test_mechanism_queries_match_mechanics(model, mechanisms):
    mech, ref = mechanisms(model)
    _, _, _, outputs = CASES[model]
    closed = [(name, args, mechanism_output(mech, args)) for name, args in outputs]
    closed += [(f"a_{p}_{b}", (p, b), mech.acceleration(p, b)) for p, b in ACCELERATIONS[model]]
    rng = np.random.default_rng(abs(hash(model)) % 2**32)
    for _ in range(STATES.get(model, 3)):
        state = random_state(mech.spec, rng)
        subs = ref.substitutions(state)
        for name, args, expr in closed:
            if isinstance(args, tuple):   # an acceleration: (point, base)
                want = _num(ref.acceleration(args[0]).to_matrix(ref.frames[args[1]]), subs)
            else:
                want = reference_output(ref, args, subs)
            err = relative(_evaluate(expr, state), want)
            _record(model, f"Mechanism.{name}", err)
            assert err < TOL, (model, name, err)


@pytest.mark.parametrize("model", list(CASES))
def test_partial_velocities_match_mechanics(model, mechanisms):
    """The seed's virtual velocities (c_k, b_k): d omega / d u_k and d v_G / d u_k in E,
    u_k the k-th generalized speed (q_dot of a coordinate, a joint's own speed)."""
    mech, ref = mechanisms(model)
    body = PARTIALS[model]
    _, G, B, _ = ref.bodies[body]
    got = mech.partial_velocities(body)
    assert list(got) == list(mech.spec.dof_names)
    rng = np.random.default_rng(3)
    state = random_state(mech.spec, rng)
    subs = ref.substitutions(state)
    for dof, u in ref.dofs.items():
        c, b = got[dof]
        want_c = _num(B.ang_vel_in(ref.N).diff(u, ref.N).to_matrix(ref.N), subs)
        want_b = _num(ref.velocity(G).diff(u, ref.N).to_matrix(ref.N), subs)
        err = max(relative(_evaluate(c, state), want_c), relative(_evaluate(b, state), want_b))
        _record(model, "Mechanism.partial_velocities", err)
        assert err < TOL, (model, dof, err)


# -- the compiled outputs -----------------------------------------------------------
def scene_text(model, path, effects, outputs) -> str:
    lines = [f"scene: q3d_{model}", f"model: {path}", f"effects: [{', '.join(effects)}]",
             "time: {end: 0.01, sample: 0.01}", "outputs:"]
    lines += [f"  {name}: {{{', '.join(f'{k}: {v}' for k, v in args.items())}}}"
              for name, args in outputs]
    return "\n".join(lines) + "\n"


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    root = tmp_path_factory.mktemp("q3d")
    cache = {}

    def get(model):
        if model not in cache:
            path, build, effects, outputs = CASES[model]
            spec = load_model(path)
            state0 = random_state(spec, np.random.default_rng(0))
            initial = {k: state0[k] for k in (*spec.coordinates, *spec.speeds)}
            text = scene_text(model, path, effects, outputs) + "initial: {" + ", ".join(
                f"{k}: {v!r}" for k, v in initial.items()) + "}\n"
            file = root / f"q3d_{model}.yaml"
            file.write_text(text)
            cache[model] = (modelgen.load_scene(file).model, build(), spec)
        return cache[model]
    return get


@pytest.mark.parametrize("model", list(CASES))
def test_compiled_outputs_energy_and_poses_match_mechanics(model, scenes):
    cm, ref, spec = scenes(model)
    _, _, _, outputs = CASES[model]
    assert cm.outputs == {name: cm.outputs[name] for name, _ in outputs}
    rng = np.random.default_rng(11)
    for _ in range(STATES.get(model, 3)):
        state = random_state(spec, rng)
        subs = ref.substitutions(state)
        x = [state[k] for k in (*cm.coordinates, *cm.speeds)]
        p = {k: state[k] for k in cm.parameters}
        y = cm.output_values(0.0, x, p=p)
        k = 0
        for name, args in outputs:
            want = reference_output(ref, args, subs)
            err = relative(y[k:k + len(want)], want)
            _record(model, f"output.{name}", err)
            assert err < TOL, (model, name, y[k:k + len(want)], want)
            k += len(want)
        q, qd = x[:cm.nq], x[cm.nq:]
        T, V = cm.energy(q, qd, p=p)
        err = relative([T, V], [reference_output(ref, {"energy": e}, subs)[0]
                                for e in ("kinetic", "potential")])
        _record(model, "cm.energy", err)
        assert err < TOL, (model, "energy", err)
        poses = cm.body_poses(q, p=p)
        for i, body in enumerate(cm.bodies):
            err = relative(poses[i].ravel(), reference_output(ref, {"pose": body}, subs))
            _record(model, "cm.body_poses", err)
            assert err < TOL, (model, body, err)


# -- directions, stated once more in numbers ---------------------------------------------
def test_directions_reverse_as_they_should(mechanisms):
    """Swapping the two bases or points of a query reverses it: omega of A in B is
    minus omega of B in A (any components), the vector from P to Q is minus the
    one from Q to P, and the change of basis B -> A is the inverse (the transpose)
    of A -> B.  A test that confuses the two orders would fail here, since the
    reference comparisons above use both orders on every model."""
    mech, _ = mechanisms("heavy_top")
    state = random_state(mech.spec, np.random.default_rng(5))
    w = [_evaluate(mech.angular_velocity(a, b, "B2"), state) for a, b in (("B1", "B3"), ("B3", "B1"))]
    assert np.abs(w[0] + w[1]).max() < 1e-14 and np.abs(w[0]).max() > 0.1
    r = [_evaluate(mech.position(a, b, "B1"), state) for a, b in (("O", "G"), ("G", "O"))]
    assert np.abs(r[0] + r[1]).max() < 1e-15 and np.abs(r[0]).max() > 0.01
    M = _evaluate(mech.change_of_basis("B1", "B3"), state).reshape(3, 3)
    Minv = _evaluate(mech.change_of_basis("B3", "B1"), state).reshape(3, 3)
    assert np.abs(M @ Minv - np.eye(3)).max() < 1e-14 and np.abs(M - Minv.T).max() < 1e-15
    assert np.abs(M - np.eye(3)).max() > 0.1


def test_simple_rotation_and_quaternion_conventions(mechanisms):
    """A base turned by q about x of its parent has y = (0, cos q, sin q) in the
    parent (right-handed) and turns at q_dot about x; a quaternion
    (cos(a/2), sin(a/2) n) is the same turn by a about n, at the speeds
    (wx, wy, wz) given in the joint's base."""
    mech, _ = mechanisms("spherical_pendulum")
    q1, q1d = 0.7, 1.3
    state = {"q1": q1, "q2": 0.0, "q1_dot": q1d, "q2_dot": 0.0}
    M = _evaluate(mech.change_of_basis("B1", "E"), state).reshape(3, 3)
    assert np.abs(M[:, 1] - [0, np.cos(q1), np.sin(q1)]).max() < 1e-15
    assert np.abs(_evaluate(mech.angular_velocity("E", "B1", "B1"), state) - [q1d, 0, 0]).max() == 0

    mech, _ = mechanisms("heavy_body_ball")
    a = 0.7
    state = dict(zip(("J_qw", "J_qx", "J_qy", "J_qz"), (np.cos(a / 2), np.sin(a / 2), 0, 0)))
    state.update({"J_wx": 0.3, "J_wy": -0.4, "J_wz": 0.5})
    M = _evaluate(mech.change_of_basis("B", "E"), state).reshape(3, 3)
    assert np.abs(M - [[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]]).max() < 1e-15
    w = _evaluate(mech.angular_velocity("E", "B", "B"), state)
    assert np.abs(w - [0.3, -0.4, 0.5]).max() < 1e-15
