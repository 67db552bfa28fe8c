"""Quaternions of hinge chains as polynomials in half-angle cosines and sines.

A body's orientation quaternion (MuJoCo's ``xquat``: the product along the
tree of constant quaternions and each hinge's ``(cos(a/2), sin(a/2) axis)``)
is, per component, a polynomial in ``c_j = cos(a_j/2)`` and ``s_j =
sin(a_j/2)``, each hinge to the first power: at most ``2^k`` terms for ``k``
hinges.  Multiplying in this form keeps an orientation residual (a MuJoCo
weld's) a flat sum that can be written as one expression of the coordinates
(:mod:`modelgen.model.mjcf`).  A polynomial is a dict: monomial (a sorted tuple
of ``(joint, "c" or "s")``) -> float coefficient; a quaternion is four of them.

>>> turn = ({((7, "c"),): 1.0}, {((7, "s"),): 1.0}, {}, {})     # hinge 7 about x
>>> back = quat_mul(turn, quat_conj(turn))                          # c^2 + s^2, 0, 0, 0
>>> back[0], {k: v for k, v in back[1].items() if v}
({((7, 'c'), (7, 'c')): 1.0, ((7, 's'), (7, 's')): 1.0}, {})
"""
from __future__ import annotations

__all__ = ["POLY_NOISE", "poly_add", "poly_mul", "quat_conj", "quat_const", "quat_mul"]

#: coefficients below this fraction of a row's largest are the rounding of
#: terms that cancel (a turn and its inverse), and are left out
POLY_NOISE = 1e-15


def poly_mul(a: dict, b: dict) -> dict:
    """Product of two polynomials."""
    out: dict = {}
    for ma, ca in a.items():
        for mb, cb in b.items():
            key = tuple(sorted(ma + mb))
            out[key] = out.get(key, 0.0) + ca * cb
    return out


def poly_add(*terms) -> dict:
    """Sum of (sign, polynomial) pairs."""
    out: dict = {}
    for sign, poly in terms:
        for mono, c in poly.items():
            out[mono] = out.get(mono, 0.0) + sign * c
    return out


def quat_mul(p, q) -> tuple:
    """Hamilton product of quaternions of polynomials (w, x, y, z)."""
    m = lambda i, j: poly_mul(p[i], q[j])
    return (poly_add((1, m(0, 0)), (-1, m(1, 1)), (-1, m(2, 2)), (-1, m(3, 3))),
            poly_add((1, m(0, 1)), (1, m(1, 0)), (1, m(2, 3)), (-1, m(3, 2))),
            poly_add((1, m(0, 2)), (-1, m(1, 3)), (1, m(2, 0)), (1, m(3, 1))),
            poly_add((1, m(0, 3)), (1, m(1, 2)), (-1, m(2, 1)), (1, m(3, 0))))


def quat_const(q) -> tuple:
    """A constant quaternion (w, x, y, z) of numbers."""
    return tuple({(): float(x)} if x else {} for x in q)


def quat_conj(q) -> tuple:
    """The conjugate (w, -x, -y, -z)."""
    return (q[0],) + tuple({k: -c for k, c in part.items()} for part in q[1:])
