"""The crba rhs's solve of A q_ddot = b: a sparse LDL^T of the mass matrix.

:func:`elimination` finds the order that eliminates a tree's mass matrix
without fill-in (the symbolic factorization); :func:`unrolled_ldlt` writes
that factorization and solve as straight-line C; :func:`solve_code` decides
between it and a loop over the non-zeros, for the model template.
"""
from __future__ import annotations

import functools
from typing import NamedTuple

#: Up to this many coordinates the solve is emitted as straight-line LDL^T
#: (no sqrt, independent chains the compiler can interleave); above it, a
#: right-looking Cholesky loop (for an A with structural zeros see
#: :data:`SPARSE_UNROLL_SIZE`).
UNROLL_SOLVE = 12

#: A mass matrix with structural zeros (a branched tree's) is unrolled while its
#: factorization and solve take at most the products of the dense one of 30
#: coordinates (5,830); beyond, a loop over its non-zeros.  Measured with the
#: crba rhs, callgrind instructions and time a call:
#:
#: * floating solo12 (18 speeds, 690 products): unrolled sparse 13,730 and
#:   1.29 us; the dense loop 22,322 and 1.56 us (a dense unrolled one 14,622
#:   and 1.50 us);
#: * floating G1 humanoid (35 speeds, 2,695 products): unrolled sparse 40,632
#:   and 4.09 us; the sparse loop 74,379 and 5.33 us; the dense loop 91,539
#:   and 6.08 us.
SPARSE_UNROLL_SIZE = 30

#: Up to this many coordinates the unrolled solve of the derivatives' 2n + nu
#: columns runs one column at a time through straight-line code; above, every
#: update of it is a whole row of the columns side by side (vectorized).
#: Callgrind instructions a call of ``<name>_derivatives``, one column at a time
#: against by rows (each row updated once forwards and once backwards,
#: ``<name>_derivatives_rows``): the 7-link chain 14,463 against 14,231, the
#: 7-joint arm 20,045 against 19,316 (with the loop over the pairs of dofs).
BY_COLUMN_SOLVE = 6


class Elimination(NamedTuple):
    """The symbolic LDL^T of a mass matrix's structure: the order in which the
    coordinates are eliminated, and for each its neighbours when eliminated
    (the rows of its column of L, in elimination order)."""
    order: tuple
    below: dict         # v -> the coordinates w with L[w][v] structurally non-zero
    fill: frozenset     # the pairs {w, v} where A is zero but L is not

    def earlier(self) -> dict:
        """v -> the pivots eliminated before ``v`` whose column of L has a row ``v``,
        in elimination order."""
        out = {v: [] for v in self.order}
        for k in self.order:
            for w in self.below[k]:
                out[w].append(k)
        return {v: tuple(ks) for v, ks in out.items()}

    def products(self) -> int:
        """Multiplications of the unrolled factorization and solve (the cost that
        decides whether it is unrolled)."""
        earlier = {v: set(ks) for v, ks in self.earlier().items()}
        return sum(2 * len(earlier[v]) + 2 * len(self.below[v]) + 1
                   + sum(len(earlier[v] & earlier[w]) for w in self.below[v])
                   for v in self.order)


def elimination(pattern) -> Elimination:
    """The elimination of a symmetric structure ``pattern`` (n x n booleans: which
    entries of A can be non-zero) that exploits the tree's sparsity.

    The mass matrix of a tree couples a coordinate exactly with its ancestors
    and descendants, a chordal structure, which some order eliminates without
    fill-in: each coordinate, when eliminated, has only neighbours that are
    all coupled with each other (a leaf of what is left; Featherstone, *Rigid
    Body Dynamics Algorithms*, §6.5, numbers parents first and eliminates
    from the last coordinate).  Such an order is the reverse of a maximum
    cardinality search (Tarjan and Yannakakis, 1984), found here from the
    structure itself, so it does not depend on how the coordinates are
    numbered; ties go to the highest index, so a dense A is eliminated in
    index order, the plain LDL^T.  A structure that is not chordal gets the
    fill-in that order causes, recorded in ``fill``.  O(n^2 + the products).

    >>> plan = elimination([[1, 1, 1], [1, 1, 0], [1, 0, 1]])    # a root, two leaves
    >>> plan.order, plan.fill                                   # a leaf first: no fill-in
    ((1, 0, 2), frozenset())
    """
    n = len(pattern)
    adj = {i: {j for j in range(n) if j != i and (pattern[i][j] or pattern[j][i])}
           for i in range(n)}
    weight, unvisited, visited = [0] * n, set(range(n)), []
    while unvisited:
        v = max(unvisited, key=lambda v: (weight[v], v))
        unvisited.remove(v)
        visited.append(v)
        for w in adj[v] & unvisited:
            weight[w] += 1
    order = visited[::-1]
    below, fill = {}, set()
    for v in order:                        # the symbolic factorization: L's structure
        nbrs = adj.pop(v)
        for a in nbrs:
            adj[a].discard(v)
            fill |= {frozenset((a, b)) for b in nbrs - adj[a] - {a}}
            adj[a] |= nbrs - {a}
        below[v] = nbrs
    position = {v: i for i, v in enumerate(order)}
    return Elimination(tuple(order), {v: tuple(sorted(w, key=position.get))
                                      for v, w in below.items()}, frozenset(fill))


def unrolled_ldlt(n: int, tol: str, plan: Elimination | None = None) -> list:
    """Straight-line C that solves ``A y = b`` by LDL^T for a fixed ``n``.

    No square roots: each pivot costs one division, which shortens the
    dependency chain from pivot to pivot.  Reads the lower triangle of the
    row-major ``A``; overwrites ``b`` with y.  Returns the 1-based failing
    pivot (d_j <= tol * A_jj, or A_jj <= 0) like the loop version: A_jj / d_j
    estimates the condition number of the diagonally scaled A, so extreme but
    well-defined mass ratios pass (see ``modelgen.sim.conditioning``).
    ``plan`` (:func:`elimination`) gives the order and the structural zeros
    to skip; without it, A is dense and eliminated in index order.
    """
    plan = plan or elimination([[True] * n for _ in range(n)])
    return unrolled_factor(n, tol, plan) + _substitutions(plan, lambda i: f"b[{i}]", "")


def _substitutions(plan: Elimination, entry, sign: str) -> list:
    """Straight-line forward (``y_i = b_i - sum L_ik y_k``) and backward
    (``b_i = sign y_i / d_i - sum L_ki b_k``) substitution in place on the
    entries ``entry(i)``, with the locals of :func:`unrolled_factor`."""
    earlier = plan.earlier()
    lines = []
    for i in plan.order:
        terms = "".join(f" - L{i}_{k} * y{k}" for k in earlier[i])
        lines.append(f"const double y{i} = {entry(i)}{terms};")
    for i in reversed(plan.order):
        terms = "".join(f" - L{k}_{i} * {entry(k)}" for k in plan.below[i])
        lines.append(f"{entry(i)} = {sign}y{i} * inv{i}{terms};")
    return lines


def unrolled_factor(n: int, tol: str, plan: Elimination, stored: bool = False) -> list:
    """The factorization half of :func:`unrolled_ldlt`: locals ``d{j}``, ``inv{j}``
    (1 / d) and ``L{i}_{j}`` from the lower triangle of ``A``; a failing pivot
    returns its 1-based index.

    With ``stored``, each entry of L and each ``u[j][k] = L[j][k] d[k]`` goes to
    the arrays ``Lf`` and ``Uf`` at :func:`factor_offsets`' places (L also to
    ``Lb``, which :func:`unrolled_apply` reads with ``Lf``), 1 / d to ``inv``,
    and every later use reads it back from there, after a compiler barrier
    (``MG_BARRIER``) before each pivot: as locals, gcc keeps every entry of L in
    a register from its column to its last use, and allocating those registers
    was most of the compile time of the derivatives' solve."""
    earlier = plan.earlier()
    earlier_sets = {v: set(ks) for v, ks in earlier.items()}

    def a(i, j):
        return f"A[{max(i, j) * n + min(i, j)}]"

    if stored:
        forward, backward = factor_offsets(plan)
        place = {(v, k): forward[v] + x for v in plan.order for x, k in enumerate(earlier[v])}

        def L(i, k):
            return f"Lf[{place[i, k]}]"

        def u(j, k):
            return f"Uf[{place[j, k]}]"
        define = ""
    else:
        def L(i, k):
            return f"L{i}_{k}"

        def u(j, k):
            return f"u{j}_{k}"
        define = "const double "
    lines = []
    for p, j in enumerate(plan.order):
        if stored and p:
            lines.append("MG_BARRIER;")
        # u[j][k] = L[j][k] * d[k]: reused by every row below j
        for k in earlier[j]:
            lines.append(f"{define}{u(j, k)} = {L(j, k)} * d{k};")
        terms = "".join(f" - {u(j, k)} * {L(j, k)}" for k in earlier[j])
        lines.append(f"const double d{j} = {a(j, j)}{terms};")
        lines.append(f"if (!(d{j} > {tol} * {a(j, j)}) || !({a(j, j)} > 0.0)) return {j + 1};")
        if not stored:
            lines.append(f"const double inv{j} = 1.0 / d{j};")
        elif plan.below[j]:
            lines.append(f"const double inv{j} = inv[{j}] = 1.0 / d{j};")
        else:
            lines.append(f"inv[{j}] = 1.0 / d{j};")
        for i in plan.below[j]:
            common = [k for k in earlier[j] if k in earlier_sets[i]]
            terms = "".join(f" - {L(i, k)} * {u(j, k)}" for k in common)
            # a fill-in entry: A is zero there, only the updates remain
            first = "" if frozenset((i, j)) in plan.fill else a(i, j)
            lines.append(f"{define}{L(i, j)} = ({first}{terms}) * inv{j};")
            if stored:
                lines.append(f"Lb[{backward[j] + plan.below[j].index(i)}] = {L(i, j)};")
    return lines


def factor_offsets(plan: Elimination) -> tuple:
    """``(forward, backward)``: where each row's and each column's entries of L
    start in the arrays ``Lf`` (row ``i``: ``L[i][k]`` for ``k`` in ``earlier()[i]``)
    and ``Lb`` (column ``j``: ``L[i][j]`` for ``i`` in ``below[j]``), each packed in
    elimination order, ``nonzeros(plan)`` long.

    >>> factor_offsets(elimination([[1, 1, 1], [1, 1, 1], [1, 1, 1]]))
    ({0: 0, 1: 0, 2: 1}, {0: 0, 1: 2, 2: 3})
    """
    earlier = plan.earlier()
    forward, backward, f, b = {}, {}, 0, 0
    for v in plan.order:
        forward[v], backward[v] = f, b
        f += len(earlier[v])
        b += len(plan.below[v])
    return forward, backward


def nonzeros(plan: Elimination) -> int:
    """The entries of L below its diagonal that are not structurally zero."""
    return sum(len(w) for w in plan.below.values())


@functools.lru_cache(maxsize=None)
def _dense_products(n: int) -> int:
    """The products of the straight-line LDL^T of a dense n x n A."""
    return elimination([[True] * n] * n).products()


def solve_code(n: int, tol: str, pattern=None) -> dict:
    """How the crba rhs solves A q_ddot = b, for the template: ``solve_lines``, a
    straight-line LDL^T (:func:`unrolled_ldlt`), or ``solve_loop``, the tables of
    a loop over the non-zeros of a sparse A; neither for the dense loop.

    A dense A is unrolled up to :data:`UNROLL_SOLVE` coordinates; one with
    structural zeros (``pattern``) in the order of :func:`elimination` up to
    the products of a dense one of :data:`SPARSE_UNROLL_SIZE`, and looped beyond.
    """
    if pattern is None or all(map(all, pattern)):
        return {"solve_lines": unrolled_ldlt(n, tol) if n <= UNROLL_SOLVE else [],
                "solve_loop": None}
    plan = elimination(pattern)
    products = plan.products()
    if n <= UNROLL_SOLVE or products <= _dense_products(SPARSE_UNROLL_SIZE):
        return {"solve_lines": [f"/* eliminated in the order "
                                f"{', '.join(str(v + 1) for v in plan.order)}, the structural "
                                f"zeros of A skipped: {products} products, "
                                f"{len(plan.fill)} fill-ins */"] + unrolled_ldlt(n, tol, plan),
                "solve_loop": None}
    return {"solve_lines": [], "solve_loop": loop_tables(plan)}


def loop_tables(plan: Elimination) -> dict:
    """The tables of a loop over the non-zeros of L (for the template): the
    elimination order, and per pivot the rows below it (``below[start[p]:start[p + 1]]``),
    as C initialiser lists.

    >>> loop_tables(elimination([[1, 1, 1], [1, 1, 0], [1, 0, 1]]))["below"]
    '0, 2'
    """
    below = [w for v in plan.order for w in plan.below[v]]
    start = [0]
    for v in plan.order:
        start.append(start[-1] + len(plan.below[v]))
    return {"order": ", ".join(map(str, plan.order)),
            "start": ", ".join(map(str, start)),
            "below": ", ".join(map(str, below)) or "0",
            "nbelow": max(len(below), 1), "products": plan.products(),
            "fill": len(plan.fill)}


def unrolled_columns(plan: Elimination, array: str, stride: str) -> list:
    """Straight-line C that overwrites column ``c`` of the row-major ``array`` (rows
    ``stride`` apart, entry ``array[i * stride + c]``) with ``-A^-1`` times it,
    using the factor of :func:`unrolled_factor`: one block of a loop over the
    columns of many right-hand sides."""
    return _substitutions(plan, lambda i: f"{array}[{i} * {stride} + c]", "-")


def unrolled_apply(plan: Elimination, name: str) -> list:
    """Straight-line C that overwrites the rows of ``B`` (all the columns at once,
    rows ``<NAME>_DS`` apart) with ``-A^-1 B``, from the factor of
    :func:`unrolled_factor` stored in ``Lf`` and ``Lb``: one call of
    ``<name>_derivatives_rows`` per row forwards (``y_i = b_i - sum L_ik y_k``) and
    backwards (``x_i = -y_i / d_i - sum L_ki x_k``), each a fused update that reads
    row i once and every row it subtracts once, keeping row i in registers.

    Each call reads its coefficients where the factorization stored them, so
    none of L has to live in a register (or a spill slot) from the
    factorization to its last use: with the coefficients as locals the
    compiler's register allocation of this function grew with the square of
    their number.

    >>> unrolled_apply(elimination([[1, 1], [1, 1]]), "m")[0]
    '{ static const int r[1] = {0 * M_DS}; m_derivatives_rows(B + 1 * M_DS, B, r, Lf + 0, 1, 1.0); }'
    """
    stride = f"{name.upper()}_DS"
    earlier = plan.earlier()
    forward, backward = factor_offsets(plan)

    def call(i, rows, coefs, scale):
        if not rows:
            return f"{name}_derivatives_rows(B + {i} * {stride}, B, NULL, NULL, 0, {scale});"
        offsets = ", ".join(f"{k} * {stride}" for k in rows)
        return (f"{{ static const int r[{len(rows)}] = {{{offsets}}}; "
                f"{name}_derivatives_rows(B + {i} * {stride}, B, r, {coefs}, {len(rows)}, "
                f"{scale}); }}")
    lines = [call(i, earlier[i], f"Lf + {forward[i]}", "1.0")
             for i in plan.order if earlier[i]]
    lines += [call(i, plan.below[i], f"Lb + {backward[i]}", f"-inv[{i}]")
              for i in reversed(plan.order)]
    return lines


def row_blocks(stride: int, most: int = 12) -> list:
    """``[(first, count), ...]``: the vectors of 4 doubles of a row of ``stride``
    doubles in blocks of at most ``most``, the accumulators
    ``<name>_derivatives_rows`` keeps in registers (16 vector registers on x86-64).

    >>> row_blocks(40), row_blocks(60)
    ([(0, 10)], [(0, 8), (8, 7)])
    """
    vectors = stride // 4
    blocks = -(-vectors // most)
    out, first = [], 0
    for b in range(blocks):
        count = vectors // blocks + (1 if b < vectors % blocks else 0)
        out.append((first, count))
        first += count
    return out


def derivative_solve(n: int, tol: str, pattern, nu: int, name: str = "model") -> dict:
    """How ``<name>_derivatives`` applies -M^-1 to its 2n + nu columns, for the
    template: ``loop``, the tables of a loop over the non-zeros of L
    (:func:`loop_tables`), and while the factorization is small enough to
    unroll (as :func:`solve_code` decides for the rhs) ``unrolled``: the
    straight-line factorization and its application to one column at a time
    (``X``, ``Y``, ``U``: :func:`unrolled_columns`) up to :data:`BY_COLUMN_SOLVE`
    coordinates, to every column at once above (``apply``:
    :func:`unrolled_apply`, calling the functions of the model ``name``);
    ``stride``: the row length of the array of all the columns side by side.
    """
    plan = elimination(pattern)
    unrolled = None
    if n <= UNROLL_SOLVE or plan.products() <= _dense_products(SPARSE_UNROLL_SIZE):
        by_column = n <= BY_COLUMN_SOLVE
        unrolled = {"factor": unrolled_factor(n, tol, plan, stored=not by_column),
                    "by_column": by_column, "nonzeros": max(nonzeros(plan), 1)}
        if by_column:
            unrolled |= {"X": unrolled_columns(plan, "X", "N"),
                         "Y": unrolled_columns(plan, "Y", "N"),
                         "U": unrolled_columns(plan, "U", str(nu)) if nu else []}
        else:
            unrolled["apply"] = unrolled_apply(plan, name)
    # the loop's array of all columns: rows padded to a multiple of 4 (a vector)
    stride = -(-(2 * n + nu) // 4) * 4
    return {"loop": loop_tables(plan), "unrolled": unrolled, "stride": stride,
            "blocks": [[4 * v for v in range(f, f + c)] for f, c in row_blocks(stride)]}
