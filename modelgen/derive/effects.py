"""Effect physics: one effect spec -> its generalized forces and potential energy.

Input: a :class:`~modelgen.derive.graph.GraphBuilder` (new named expressions
go into it), the model's :class:`~modelgen.derive.kinematics.Kinematics` and
one effect dataclass of :mod:`modelgen.model.spec` (or an ActionSpec).
Output: an :class:`EffectTerms`: either spatial forces on bodies, which
:func:`modelgen.derive.dynamics.derive_equations` projects with the shared
partial velocities of the composite-body groups (gravity, drag, actions), or
the n generalized forces computed directly from the points' or coordinates'
own partial velocities (springs, dampers, coordinate effects); plus the
effect's potential energy (zero for non-conservative effects).

One function per effect kind, and one table, :data:`DERIVATIONS`, from the
effect class to its function; adding a kind adds a dataclass in
``modelgen/model/spec.py`` and one function here (see ``README.md``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import sympy

from modelgen.derive.calculus import norm_of_square
from modelgen.derive.graph import GraphBuilder
from modelgen.derive.spatial import ZERO, add, cross, dot, matvec, scale, sub
from modelgen.derive.kinematics import Kinematics
from modelgen.model.spec import (ActionSpec, DamperEffect, DragEffect,
                                 FrictionEffect, GravityEffect, JointDampingEffect, SpringEffect,
                                 TorsionSpringEffect)

__all__ = ["EffectTerms", "DERIVATIONS", "derive_effect", "action_forces"]


@dataclass(frozen=True)
class EffectTerms:
    """What one effect contributes to the equations of motion.

    Exactly one of ``body_forces`` (``{body index: 6-tuple}``, the spatial
    force at O in E, moment first) and ``generalized`` (the n generalized
    forces) is set.  ``potential`` is the effect's potential energy.
    """
    body_forces: Optional[dict] = None
    generalized: Optional[tuple] = None
    potential: sympy.Expr = ZERO


def derive_effect(builder: GraphBuilder, kin: Kinematics, effect) -> EffectTerms:
    """The terms of one effect, by its class in :data:`DERIVATIONS`.

    >>> from modelgen.model import parse_model
    >>> from modelgen.derive.graph import GraphBuilder
    >>> from modelgen.derive.kinematics import derive_kinematics
    >>> spec = parse_model("{name: m, coordinates: [q], parameters: {c: 0.5}, "
    ...     "effects: {d: {type: joint_damping, coordinates: [q], damping: c}}}")
    >>> kin = derive_kinematics(spec)
    >>> builder = GraphBuilder(kin.graph)
    >>> terms = derive_effect(builder, kin, spec.effects[0])
    >>> [builder.freeze().expand(x) for x in terms.generalized], terms.potential
    ([-c*q_dot], 0)
    """
    return DERIVATIONS[type(effect)](builder, kin, effect)


def _body_index(kin: Kinematics, body: str) -> int:
    return next(i for i, b in enumerate(kin.spec.bodies) if b.name == body)


def action_forces(builder: GraphBuilder, kin: Kinematics, act) -> dict:
    """The seed's Action as a spatial force at O on its body: (T + r_P x F, F)."""
    Rb = kin.bases[act.base].R
    F = builder.vec(matvec(Rb, act.force))
    T = builder.vec(matvec(Rb, act.torque))
    rP = kin.points[act.point].r
    return {_body_index(kin, act.body): builder.vec(add(T, cross(rP, F))) + F}


def _action(builder: GraphBuilder, kin: Kinematics, eff: ActionSpec) -> EffectTerms:
    return EffectTerms(body_forces=action_forces(builder, kin, eff))


def _gravity(builder: GraphBuilder, kin: Kinematics, eff: GravityEffect) -> EffectTerms:
    """m * vector at every G; potential -m vector . r_G, counted only for a field
    constant in E (a field fixed in a moving base, or one that varies in time,
    has none)."""
    vec = builder.vec(matvec(kin.bases[eff.base].R, eff.vector))
    forces = {}
    potential = ZERO
    for i, body in enumerate(kin.spec.bodies):
        r = kin.points[body.G].r
        Fg = builder.vec(scale(body.mass, vec))
        forces[i] = builder.vec(cross(r, Fg)) + Fg
        if eff.in_energy:
            potential -= dot(Fg, r)
    return EffectTerms(body_forces=forces, potential=potential)


def _drag(builder: GraphBuilder, kin: Kinematics, eff: DragEffect) -> EffectTerms:
    """-1/2 rho Cd A |v| v at the body-fixed point, v its velocity."""
    i = _body_index(kin, eff.body)
    body = kin.spec.bodies[i]
    B, G = kin.bases[body.base], kin.points[body.G]
    rP = kin.points[eff.point].r
    vP = builder.vec(add(G.v, cross(B.omega, sub(rP, G.r))))
    # |v|, whose derivative is 0 at rest (sqrt's is 0/0 there: NaN Jacobians from rest)
    speed = builder.name(norm_of_square(dot(vP, vP)))
    coef = builder.name(-eff.density * eff.drag_coefficient * eff.area * speed / 2)
    F = builder.vec(scale(coef, vP))
    return EffectTerms(body_forces={i: builder.vec(cross(rP, F)) + F})


def _point_force_power(builder: GraphBuilder, kin: Kinematics, point: str, F, n: int) -> list:
    """Generalized force of a force F applied at a model point (its own kinematics).

    b_k = beta_k + w_k x r, so F . b_k = F . beta_k + w_k . (r x F).
    """
    P = kin.points[point]
    if not P.partials:
        return [ZERO] * n
    M = builder.vec(cross(P.r, F))
    out = [ZERO] * n
    for k, (w, beta) in P.partials.items():
        out[k] = dot(F, beta) + dot(w, M)
    return out


def _between_points(builder: GraphBuilder, kin: Kinematics, eff, tension_of) -> EffectTerms:
    """A tension along the line from point_a to point_b (pulling them together if > 0).

    ``tension_of(length, unit, A, B)`` returns ``(tension, potential)``.
    """
    n = kin.spec.n
    A, B = kin.points[eff.point_a], kin.points[eff.point_b]
    d = builder.vec(sub(B.r, A.r))
    length = builder.name(sympy.sqrt(dot(d, d)))
    unit = builder.vec(scale(1 / length, d))
    tension, potential = tension_of(length, unit, A, B)
    F_b = builder.vec(scale(-tension, unit))            # on B; -F_b on A
    on_b = _point_force_power(builder, kin, eff.point_b, F_b, n)
    on_a = _point_force_power(builder, kin, eff.point_a, F_b, n)
    tau = [b - a for a, b in zip(on_a, on_b, strict=True)]
    return EffectTerms(generalized=tuple(builder.name(x) for x in tau), potential=potential)


def _spring(builder: GraphBuilder, kin: Kinematics, eff: SpringEffect) -> EffectTerms:
    """Tension k (l - rest_length) + preload; potential k/2 (l - rest)^2 + preload l."""
    def tension_of(length, unit, A, B):
        stretch = builder.name(length - eff.rest_length)
        tension = builder.name(eff.stiffness * stretch + eff.preload)
        return tension, eff.stiffness * stretch ** 2 / 2 + eff.preload * length
    return _between_points(builder, kin, eff, tension_of)


def _damper(builder: GraphBuilder, kin: Kinematics, eff: DamperEffect) -> EffectTerms:
    """Tension c dl/dt, dl/dt the rate of change of the distance."""
    def tension_of(length, unit, A, B):
        rate = builder.name(dot(unit, sub(B.v, A.v)))
        return builder.name(eff.damping * rate), ZERO
    return _between_points(builder, kin, eff, tension_of)


def _on_coordinates(builder: GraphBuilder, kin: Kinematics, forces: dict,
                    potential=ZERO) -> EffectTerms:
    """Generalized forces ``{dof name: force}`` (others zero) as EffectTerms; a dof is a
    simple coordinate or a ball/free joint's speed."""
    coord = {name: k for k, name in enumerate(kin.spec.dof_names)}
    tau = [ZERO] * kin.spec.n
    for name, force in forces.items():
        tau[coord[name]] = force
    return EffectTerms(generalized=tuple(builder.name(x) for x in tau), potential=potential)


def _torsion_spring(builder: GraphBuilder, kin: Kinematics,
                    eff: TorsionSpringEffect) -> EffectTerms:
    """-k (q - rest_angle) on the coordinate; potential k/2 (q - rest_angle)^2."""
    q = kin.q[kin.spec.coordinates.index(eff.coordinate)]
    stretch = q - eff.rest_angle
    return _on_coordinates(builder, kin, {eff.coordinate: -eff.stiffness * stretch},
                           eff.stiffness * stretch ** 2 / 2)


def _joint_damping(builder: GraphBuilder, kin: Kinematics, eff: JointDampingEffect) -> EffectTerms:
    """-c q_dot on each listed coordinate, -c v on each listed ball/free joint speed."""
    qd = {name: kin.qd[k] for k, name in enumerate(kin.spec.dof_names)}
    return _on_coordinates(builder, kin,
                           {name: -eff.damping * qd[name] for name in eff.coordinates})


def _friction(builder: GraphBuilder, kin: Kinematics, eff: FrictionEffect) -> EffectTerms:
    """Regularised Coulomb + Stribeck + viscous friction (see FrictionEffect)."""
    v = kin.qd[kin.spec.coordinates.index(eff.coordinate)]
    static = eff.coulomb if eff.static is None else eff.static
    level = eff.coulomb
    if static != eff.coulomb:
        level = level + (static - eff.coulomb) * sympy.exp(-(v / eff.stribeck_speed) ** 2)
    tau = -level * sympy.tanh(v / eff.smoothing_speed) - eff.viscous * v
    return _on_coordinates(builder, kin, {eff.coordinate: tau})


#: Effect class -> the function deriving its terms: the one place an effect's physics goes.
DERIVATIONS = {
    ActionSpec: _action,
    GravityEffect: _gravity,
    SpringEffect: _spring,
    TorsionSpringEffect: _torsion_spring,
    DamperEffect: _damper,
    JointDampingEffect: _joint_damping,
    FrictionEffect: _friction,
    DragEffect: _drag,
}
