"""The constrained shipped models written again by hand with sympy.physics.mechanics'
``KanesMethod`` (dependent coordinates and speeds, configuration and velocity
constraints), sharing nothing with modelgen but the parameter values: the
independent references of ``tests/test_constraints.py`` (the rhs) and
``tests/test_constrained_linearize.py`` (the linearization).
"""
from __future__ import annotations

import sympy
from sympy.physics.mechanics import (
    KanesMethod,
    Point,
    ReferenceFrame,
    RigidBody,
    dynamicsymbols,
    inertia,
)

t = dynamicsymbols._t

#: A disc rolling without slip, written with the ``rolling`` constraint kind (its
#: centre's three coordinates, the height dependent).
WHEEL_DISC = """\
name: wheel_disc
coordinates: [q1, q2, q3, x, y, z]
parameters: {m: 1.0, r: 0.5, g: 9.81}
bases:
  Y: {parent: E, axis: 3, angle: q1}
  L: {parent: Y, axis: 1, angle: q2}
  R: {parent: L, axis: 2, angle: q3}
points:
  Gd: {coordinates: [x, y, z]}
bodies:
  disc: {mass: m, G: Gd, base: R, inertia: [m*r**2/4, m*r**2/2, m*r**2/4]}
gravity: [0, 0, -g]
constraints:
  wheel: {type: rolling, body: disc, axle: 2, radius: r}
dependent: {coordinates: [z], speeds: [x_dot, y_dot, z_dot]}
"""


def rolling_disc_kane():
    """models/rolling_disc.yaml: yaw q1, lean q2, spin q3, contact (x, y); the two
    no-slip constraints make x', y' dependent.  (kane, q, u, parameter symbols,
    velocity constraints)."""
    q1, q2, q3, x, y = q = list(dynamicsymbols("q1:4 x y"))
    u = list(dynamicsymbols("u1:6"))
    m, r, g = syms = sympy.symbols("m r g")
    N = ReferenceFrame("N")
    Y = N.orientnew("Y", "Axis", (q1, N.z))
    L = Y.orientnew("L", "Axis", (q2, Y.x))
    R = L.orientnew("R", "Axis", (q3, L.y))
    qd_to_u = {qk.diff(t): uk for qk, uk in zip(q, u)}
    for fr in (Y, L, R):
        fr.set_ang_vel(N, fr.ang_vel_in(N).subs(qd_to_u))
    O = Point("O")
    O.set_vel(N, 0)
    C = O.locatenew("C", x * N.x + y * N.y)
    Dm = C.locatenew("Dm", r * L.z)
    Dm.set_vel(N, Dm.pos_from(O).dt(N).subs(qd_to_u))
    contact = Dm.vel(N) + R.ang_vel_in(N).cross(C.pos_from(Dm))
    vc = [contact.dot(N.x), contact.dot(N.y)]
    disc = RigidBody("disc", Dm, R, m, (inertia(R, m * r**2 / 4, m * r**2 / 2, m * r**2 / 4),
                                        Dm))
    kd = [qk.diff(t) - uk for qk, uk in zip(q, u)]
    kane = KanesMethod(N, q_ind=q, u_ind=u[:3], kd_eqs=kd, u_dependent=u[3:],
                       velocity_constraints=vc)
    kane.kanes_equations([disc], [(Dm, -m * g * N.z)])
    return kane, q, u, syms, vc


def four_bar_kane():
    """models/four_bar.yaml: the crank q1 independent, q2 and q3 (and their speeds)
    dependent through the loop's two position constraints.  (kane, q, u,
    parameter symbols, velocity constraints)."""
    q = list(dynamicsymbols("q1:4"))
    u = list(dynamicsymbols("u1:4"))
    a, b, c, d, m1, m2, m3, g = syms = sympy.symbols("a b c d m1 m2 m3 g")
    N = ReferenceFrame("N")
    frames = [N.orientnew(f"B{k}", "Axis", (qk, N.z)) for k, qk in enumerate(q, 1)]
    for f, uk in zip(frames, u):
        f.set_ang_vel(N, uk * N.z)
    O = Point("O")
    O.set_vel(N, 0)
    D = O.locatenew("D", d * N.x)
    P1 = O.locatenew("P1", a * frames[0].x)
    P2 = P1.locatenew("P2", b * frames[1].x)
    P3 = D.locatenew("P3", c * frames[2].x)
    centres = [O.locatenew("G1", a / 2 * frames[0].x), P1.locatenew("G2", b / 2 * frames[1].x),
               D.locatenew("G3", c / 2 * frames[2].x)]
    qd_to_u = {qk.diff(t): uk for qk, uk in zip(q, u)}
    for P in centres:
        P.set_vel(N, P.pos_from(O).dt(N).subs(qd_to_u))
    bodies = [RigidBody(f"rod{k}", G, f, m, (inertia(f, 0, m * L**2 / 12, m * L**2 / 12), G))
              for k, (G, f, m, L) in enumerate(zip(centres, frames, (m1, m2, m3), (a, b, c)))]
    loads = [(G, -body.mass * g * N.y) for G, body in zip(centres, bodies)]
    loop = P2.pos_from(O) - P3.pos_from(O)
    f = [loop.dot(N.x), loop.dot(N.y)]
    vc = [sympy.diff(fi, t).subs(qd_to_u) for fi in f]
    kane = KanesMethod(N, q_ind=q[:1], u_ind=u[:1], kd_eqs=[qk.diff(t) - uk for qk, uk in
                                                             zip(q, u)],
                       q_dependent=q[1:], configuration_constraints=f, u_dependent=u[1:],
                       velocity_constraints=vc)
    kane.kanes_equations(bodies, loads)
    return kane, q, u, syms, vc
