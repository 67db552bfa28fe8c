"""The vector and spatial algebra of derive/: one copy, used by every stage.

Vectors are tuples of sympy expressions (3-vectors; spatial 6-vectors as
motion ``(w, v)`` or force ``(n, f)``, angular part first), 3x3 matrices are
tuples of rows, spatial inertias are blocks ``(A, B, C)`` of
``[[A, B], [B^T, C]]`` (Featherstone, *Rigid Body Dynamics Algorithms*, 2008,
ch. 2).  Transforms are Plücker ``X = rot(E) xlt(r)``.

**The zero rule.**  An *exact* zero or one (sympy's ``S.Zero``/``S.One`` or a
Python ``int``) is skipped before sympy sees it: axis vectors, motion
subspaces, joint rotations and offsets are mostly zeros and ones, and
building ``0*x`` or ``x + 0`` through sympy (sympify, flatten) costs as much
as a real product.  Anything else is sympy's own arithmetic: a sum or
product of symbols, rationals and such simple terms is built directly in the
form sympy's flatten would give it (:func:`canonical_sum`,
:func:`canonical_product`), the rest by ``Add`` and ``Mul``, and two numbers
are combined by sympy, so every helper returns the expression sympy's
arithmetic builds (``tests/test_cse.py`` checks it, float zeros
included: ``Float(0.0)`` is not skipped, sympy absorbs it in ``0.0*x`` and
``x + 0.0``).  No derive/ call site meets a float zero: every number of a
``ModelSpec`` is exact (the expression reader makes ``0.1`` a ``Rational``)
and derive/ writes no float literals; the articulated-body code once also
skipped ``Float(0.0)`` (``x.is_Number and x.is_zero``), which the generated C
of every shipped model shows made no difference.

Helpers whose first argument is ``builder`` (a
:class:`~modelgen.derive.graph.GraphBuilder`) name their results, so the
straight-line program shares them.
"""
from __future__ import annotations

import functools

import sympy

ZERO = sympy.S.Zero
ONE = sympy.S.One
ZERO3 = (ZERO, ZERO, ZERO)
IDENTITY3 = ((ONE, ZERO, ZERO), (ZERO, ONE, ZERO), (ZERO, ZERO, ONE))
#: the (row, column) of the 6 entries (xx, yy, zz, xy, xz, yz) of a symmetric 3x3 matrix
PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


# -- the zero rule and scalar arithmetic -------------------------------------------

def is_zero(x) -> bool:
    """An exact zero: sympy's ``S.Zero`` or the ``int`` 0 (not ``Float(0.0)``)."""
    return x is ZERO or (type(x) is int and x == 0)


def is_one(x) -> bool:
    """An exact one: sympy's ``S.One`` or the ``int`` 1."""
    return x is ONE or (type(x) is int and x == 1)


def _is_number(x) -> bool:
    return isinstance(x, (int, float)) or x.is_Number


#: sympy's order of the arguments of a sum or product (``Basic.compare``)
_ORDER = functools.cmp_to_key(sympy.Basic.compare)


def _symbol_key(s) -> tuple:
    """A sort key of sympy Symbols in ``Basic.compare``'s order (one class: the
    length of the hashable content, name and assumptions, then the content),
    which ``sort`` compares without calling back into Python as ``cmp_to_key``
    does at every comparison."""
    content = s._hashable_content()
    return len(content), content


def _sort_terms(seq) -> None:
    """Sort ``seq`` in place in ``Basic.compare``'s order; two terms (most sums of a
    program) by one ``compare``, without ``cmp_to_key``'s wrappers."""
    if len(seq) == 2:
        if seq[0].compare(seq[1]) > 0:
            seq.reverse()
    else:
        seq.sort(key=_ORDER)


def _factors(e):
    """``(number, symbols)`` of a symbol, a rational or a product of a rational
    and symbols (in sympy's form, the number first), else None."""
    kind = type(e)
    if kind is sympy.Symbol:
        return ONE, (e,)
    if kind is sympy.Mul:
        args = e.args
        number = args[0]
        if isinstance(number, sympy.Rational):
            args = args[1:]
        else:
            number = ONE
        for a in args:
            if type(a) is not sympy.Symbol:
                return None
        return number, args
    if isinstance(e, sympy.Rational):
        return e, ()
    return None


def canonical_product(factors):
    """The product of ``factors`` built directly in sympy's canonical form when
    each is a symbol, a rational or a product of a rational and symbols and no
    symbol repeats (the rationals multiplied, the symbols sorted by
    ``Basic.compare``: what ``Mul``'s flatten returns, at a tenth of its cost);
    None otherwise, for ``Mul`` to build.

    >>> x, y, z = sympy.symbols("x y z")
    >>> canonical_product((2 * z, x, sympy.Rational(1, 2) * y)) == x * y * z
    True
    """
    number = ONE
    symbols = []
    for f in factors:
        parts = _factors(f)
        if parts is None:
            return None
        if parts[0] is not ONE:
            number = number * parts[0]
        symbols.extend(parts[1])
    if len(set(symbols)) != len(symbols) or number is ZERO:
        return None
    for s in symbols:
        if not s.is_commutative:
            return None
    if not symbols:
        return number
    symbols.sort(key=_symbol_key)    # all Symbols of one class: compare's order
    if number is ONE:
        return symbols[0] if len(symbols) == 1 else sympy.Mul._from_args(symbols, True)
    return sympy.Mul._from_args([number] + symbols, True)


def canonical_sum(terms):
    """The sum of the sympy expressions ``terms`` built directly in sympy's
    canonical form when no two terms are alike (no two share their non-numeric
    part) and each is a rational, a symbol, a power of a symbol, a function, a
    commutative product whose number (if any) is a rational, or a sum of
    those: the rationals added, the other terms sorted by ``Basic.compare``,
    what ``Add``'s flatten returns without its dictionary of like terms; None
    otherwise, for ``Add`` to build.

    >>> x, y = sympy.symbols("x y")
    >>> canonical_sum((2 * x * y, x + 1, sympy.S(3))) == 2*x*y + x + 4
    True
    """
    flat = []
    for t in terms:
        if type(t) is sympy.Add:
            flat.extend(t.args)
        else:
            flat.append(t)
    number = ZERO
    seq = []
    seen = set()
    for t in flat:
        kind = type(t)
        if kind is sympy.Symbol:
            if not t.is_commutative:
                return None
            key = (t,)
        elif kind is sympy.Mul:
            args = t.args
            if args[0].is_Number:
                if not isinstance(args[0], sympy.Rational):
                    return None
                args = args[1:]
            if not t.is_commutative:
                return None
            key = args
        elif isinstance(t, sympy.Rational):
            number = number + t
            continue
        elif (kind is sympy.Pow and type(t.args[0]) is sympy.Symbol) or t.is_Function:
            if not t.is_commutative:
                return None
            key = (t,)
        else:
            return None
        if key in seen:
            return None
        seen.add(key)
        seq.append(t)
    _sort_terms(seq)
    if number is not ZERO:
        seq.insert(0, number)
    if len(seq) < 2:
        return seq[0] if seq else ZERO
    return sympy.Add._from_args(seq, True)


def product(x, y):
    """``x*y`` of two sympy expressions: :func:`canonical_product` where it
    applies (products of symbols and rationals, most of a program's), else
    ``Mul``.

    >>> x, y = sympy.symbols("x y")
    >>> product(y, x).args == (x * y).args, product(x, sympy.Rational(1, 2)) == x / 2
    (True, True)
    """
    r = canonical_product((x, y))
    return x * y if r is None else r


def times(x, y):
    """``x*y``, without building a product when either is an exact 0 or 1."""
    if _is_number(x) and _is_number(y):
        return x * y
    if is_zero(x) or is_zero(y):
        return ZERO
    if is_one(x):
        return y
    if is_one(y):
        return x
    return product(x, y)


def total(terms):
    """``sympy.Add(*terms)``, with the exact zeros dropped first."""
    terms = [t for t in terms if not is_zero(t)]
    if len(terms) == 1:
        return terms[0] if isinstance(terms[0], sympy.Basic) else sympy.sympify(terms[0])
    if not terms:
        return ZERO
    if all(isinstance(t, sympy.Basic) for t in terms):
        r = canonical_sum(terms)
        if r is not None:
            return r
    return sympy.Add(*terms)


def neg(x):
    """``-x``, an exact zero kept as ``ZERO``; a sum negated term by term and
    summed by :func:`canonical_sum` (what sympy's ``-x`` builds by ``Add``).

    >>> x, y = sympy.symbols("x y")
    >>> neg(x - 2 * y).args == (2 * y - x).args
    True
    """
    if is_zero(x):
        return ZERO
    if type(x) is sympy.Add:
        r = canonical_sum([-t for t in x.args])
        if r is not None:
            return r
    return -x


def _plus(x, y):
    """``x + y``."""
    return x + y if _is_number(x) and _is_number(y) else total((x, y))


def _minus(x, y):
    """``x - y``."""
    if _is_number(x) and _is_number(y):
        return x - y
    return total((x, neg(y)))


# -- 3-vectors ---------------------------------------------------------------------

def add(a, b):
    return tuple(_plus(x, y) for x, y in zip(a, b, strict=True))


def sub(a, b):
    return tuple(_minus(x, y) for x, y in zip(a, b, strict=True))


def scale(s, a):
    return tuple(times(s, x) for x in a)


def dot(a, b):
    return total([times(x, y) for x, y in zip(a, b, strict=True)])


def cross(a, b):
    return (_minus(times(a[1], b[2]), times(a[2], b[1])),
            _minus(times(a[2], b[0]), times(a[0], b[2])),
            _minus(times(a[0], b[1]), times(a[1], b[0])))


def matvec(m, v):
    """``m @ v`` for a 3x3 tuple-of-rows ``m``."""
    return tuple(dot(row, v) for row in m)


def is_zero_vec(v) -> bool:
    return all(x == 0 for x in v)


# -- naming with the sign left outside -----------------------------------------------
# The operation count charges a negation (``a - b*c`` is three operations), so a
# quantity is named by its positive form and its sign stays in the expression
# that uses it, where two signs can cancel (``(-x)*(-y)``) before they are ever
# printed.

def named(builder, e):
    """``builder.name(e)``, with a negative numeric factor, or a sum of mostly negative
    terms, kept outside the name."""
    if isinstance(e, sympy.Mul) and negative_number(e.args[0]):
        return -builder.name(-e)
    if isinstance(e, sympy.Add):
        negative = sum(1 for t in e.args if _leading_minus(t))
        if 2 * negative > len(e.args):
            return -builder.name(neg(e))
    return builder.name(e)


def negative_number(c) -> bool:
    """``c.is_Number and c.is_extended_negative``, read from the value for the
    numbers of a model (rationals and finite floats): sympy's assumptions
    system deduces every fact of each new number first, the largest cost of
    deriving and printing a model with many constants (a URDF's)."""
    if isinstance(c, sympy.Rational):
        return c.p < 0
    if isinstance(c, sympy.Float) and c._mpf_[1]:     # (sign, mantissa, ...): nonzero
        return c._mpf_[0] == 1
    return bool(c.is_Number and c.is_extended_negative)


def _leading_minus(term) -> bool:
    """``term.could_extract_minus_sign()`` for a term of a sum (a number, or a product
    whose leading factor is its number), without building ``-term`` as sympy's
    test does."""
    return negative_number(term.args[0] if term.is_Mul else term)


def signed(namer, e):
    """``namer(e)`` with the sign sympy would extract kept outside, so that e
    and -e share one name."""
    return -namer(neg(e)) if e.could_extract_minus_sign() else namer(e)


def name_vec(builder, xs) -> tuple:
    return tuple(named(builder, x) for x in xs)


# -- 3x3 matrices: tuples of rows; symmetric ones from their 6 entries ---------------

def symmetric(entries) -> tuple:
    """Full rows from the 6 entries (xx, yy, zz, xy, xz, yz)."""
    xx, yy, zz, xy, xz, yz = entries
    return ((xx, xy, xz), (xy, yy, yz), (xz, yz, zz))


def name_symmetric(builder, M) -> tuple:
    return symmetric(name_vec(builder, [M[i][j] for i, j in PAIRS]))


def name_matrix(builder, M) -> tuple:
    return tuple(name_vec(builder, row) for row in M)


def matmul(a, b) -> tuple:
    return tuple(tuple(total(times(a[i][l], b[l][j]) for l in range(3)) for j in range(3))
                 for i in range(3))


def transpose(a) -> tuple:
    return tuple(tuple(a[j][i] for j in range(3)) for i in range(3))


def skew(r) -> tuple:
    return ((ZERO, -r[2], r[1]), (r[2], ZERO, -r[0]), (-r[1], r[0], ZERO))


def is_identity(E) -> bool:
    return all(E[i][j] == (1 if i == j else 0) for i in range(3) for j in range(3))


def rotation(axis, c, s) -> tuple:
    """E of a rotation by (c, s) = (cos, sin) of an angle about base axis 1, 2 or 3:
    parent -> child components.  Its rows are the child's unit vectors in parent
    components (the columns of R = E^T)."""
    if axis == 1:
        return ((ONE, ZERO, ZERO), (ZERO, c, s), (ZERO, -s, c))
    if axis == 2:
        return ((c, ZERO, -s), (ZERO, ONE, ZERO), (s, ZERO, c))
    return ((c, s, ZERO), (-s, c, ZERO), (ZERO, ZERO, ONE))


# -- spatial algebra: motion (w, v), force (n, f), inertia (A, B, C) -----------------

def motion_rot(builder, E, m):
    return name_vec(builder, matvec(E, m[:3])) + name_vec(builder, matvec(E, m[3:]))


def motion_xlt(builder, r, m):
    return m[:3] + name_vec(builder, sub(m[3:], cross(r, m[:3])))


def force_rot_T(builder, E, f):
    Et = transpose(E)
    return name_vec(builder, matvec(Et, f[:3])) + name_vec(builder, matvec(Et, f[3:]))


def force_xlt_T(builder, r, f):
    return name_vec(builder, add(f[:3], cross(r, f[3:]))) + f[3:]


def inertia_rot_T(builder, E, I):
    """X^T I X for X = rot(E): each block B -> E^T B E."""
    Et = transpose(E)
    A, B, C = I
    return (name_symmetric(builder, matmul(Et, name_matrix(builder, matmul(A, E)))),
            name_matrix(builder, matmul(Et, name_matrix(builder, matmul(B, E)))),
            name_symmetric(builder, matmul(Et, name_matrix(builder, matmul(C, E)))))


def inertia_xlt_T(builder, r, I):
    """X^T I X for X = xlt(r): A + rx B^T - B rx - rx C rx, B + rx C, C."""
    A, B, C = I
    rx = skew(r)
    M = name_matrix(builder, matmul(rx, C))       # rx C
    N = name_matrix(builder, matmul(B, rx))       # B rx
    P = matmul(M, rx)                             # rx C rx (symmetric)
    # on the diagonal N_ii + N_ii = B (2 rx) _ii: one product by the parameter 2 r
    # (computed once per parameter set), where 2 * (B rx)_ii would be two
    rx2 = skew(tuple(ZERO if is_zero(x) else signed(builder.factor, 2 * x) for x in r))
    A2 = tuple(tuple(total((A[i][j], neg(dot(B[i], (rx2[0][i], rx2[1][i], rx2[2][i]))),
                             neg(P[i][j]))) if i == j else
                     total((A[i][j], neg(N[i][j]), neg(N[j][i]), neg(P[i][j])))
                     for j in range(3)) for i in range(3))
    B2 = tuple(tuple(total((B[i][j], M[i][j])) for j in range(3)) for i in range(3))
    return (name_symmetric(builder, A2), name_matrix(builder, B2), C)


def inertia_times(I, m):
    A, B, C = I
    w, v = m[:3], m[3:]
    return add(matvec(A, w), matvec(B, v)) + add(matvec(transpose(B), w), matvec(C, v))


def cross_motion(a, b):
    """a x b for motion vectors (Featherstone's crm)."""
    return cross(a[:3], b[:3]) + add(cross(a[:3], b[3:]), cross(a[3:], b[:3]))


# -- an inertia turned about one base axis, in closed form ----------------------------

#: the plane (k1, k2) of a rotation about axis 1, 2, 3 in which E = [[c, s], [-s, c]]
_PLANE = {1: (1, 2), 2: (2, 0), 3: (0, 1)}


def _plane_rot_T(c, s, k1, k2, x1, x2):
    """(E^T x)[k1], (E^T x)[k2] for the plane rotation."""
    return (total((times(c, x1), neg(times(s, x2)))),
            total((times(s, x1), times(c, x2))))


def _sym_axis_rot_T(builder, M, k1, k2, c, s, trig):
    """E^T M E for a symmetric M and a rotation about one axis.

    With a, b, d the in-plane entries and ``t = s^2 (a - d) + 2cs b``:
    ``a' = a - t``, ``d' = d + t``, ``b' = cs (a - d) + (c^2 - s^2) b``
    (expand ``E^T M E`` and use ``c^2 + s^2 = 1``); the out-of-plane column
    turns like a vector.
    """
    ss, cs, C2, S2 = trig
    j = 3 - k1 - k2
    a, b, d = M[k1][k1], M[k1][k2], M[k2][k2]
    out = [[None] * 3 for _ in range(3)]
    diff = named(builder, _minus(a, d))
    t = named(builder, _plus(times(ss, diff), times(S2, b)))
    out[k1][k1], out[k2][k2] = _minus(a, t), _plus(d, t)
    out[k1][k2] = _plus(times(cs, diff), times(C2, b))
    out[j][k1], out[j][k2] = _plane_rot_T(c, s, k1, k2, M[j][k1], M[j][k2])
    out[j][j] = M[j][j]
    return name_symmetric(builder, _sym_rows(out))


def _sym_rows(out):
    return tuple(tuple(out[i][j] if out[i][j] is not None else out[j][i] for j in range(3))
                 for i in range(3))


def _full_axis_rot_T(builder, M, k1, k2, c, s, trig):
    """E^T M E for a general M and a rotation about one axis.

    The in-plane 2x2 block changes by its symmetric, trace-free part only:
    with ``d = m11 - m22``, ``e = m12 + m21``, ``t = s^2 d + cs e`` and
    ``w = cs d - s^2 e``: ``m11' = m11 - t``, ``m22' = m22 + t``,
    ``m12' = m12 + w``, ``m21' = m21 + w`` (8 operations, not 24); the
    out-of-plane row and column turn like vectors.
    """
    ss, cs = trig[0], trig[1]
    j = 3 - k1 - k2
    out = [[None] * 3 for _ in range(3)]
    d = named(builder, _minus(M[k1][k1], M[k2][k2]))
    e = named(builder, _plus(M[k1][k2], M[k2][k1]))
    t = named(builder, total((times(ss, d), times(cs, e))))
    w = named(builder, total((times(cs, d), neg(times(ss, e)))))
    out[k1][k1], out[k2][k2] = total((M[k1][k1], neg(t))), total((M[k2][k2], t))
    out[k1][k2], out[k2][k1] = total((M[k1][k2], w)), total((M[k2][k1], w))
    out[j][k1], out[j][k2] = _plane_rot_T(c, s, k1, k2, M[j][k1], M[j][k2])
    out[k1][j], out[k2][j] = _plane_rot_T(c, s, k1, k2, M[k1][j], M[k2][j])
    out[j][j] = M[j][j]
    return name_matrix(builder, out)


def axis_rot_T(builder, I, axis, c, s):
    """X^T I X for X = rot(E), E a rotation by (c, s) about one base axis."""
    ss, cs = builder.name(s * s), builder.name(c * s)
    trig = (ss, cs, builder.name(1 - 2 * ss), builder.name(2 * cs))
    k1, k2 = _PLANE[axis]
    A, B, C = I
    return (_sym_axis_rot_T(builder, A, k1, k2, c, s, trig),
            _full_axis_rot_T(builder, B, k1, k2, c, s, trig),
            _sym_axis_rot_T(builder, C, k1, k2, c, s, trig))


def elementary(E):
    """(axis, c, s) if the constant E is a rotation about one base axis (as
    :func:`rotation` writes it), else None."""
    for axis, (k1, k2) in _PLANE.items():
        j = axis - 1
        if E[j][j] == 1 and all(E[j][k] == 0 and E[k][j] == 0 for k in (k1, k2)) \
                and E[k2][k2] == E[k1][k1] and E[k2][k1] == -E[k1][k2]:
            return axis, E[k1][k1], E[k1][k2]
    return None
