"""The CSE stage and the program it works on, against plain sympy and symengine.

On the programs of real models (captured from the pipeline before CSE, nothing
compiled): the fast free-symbol walk gives sympy's ``free_symbols``, the memoised
sympy -> symengine conversion gives ``symengine.sympify``, the routines after CSE
compute the values of the routines before it (evaluated in exact order with
random inputs), and the operation counts equal a direct count.  The vector
helpers that skip zeros and ones build the expressions sympy's arithmetic builds.
"""
from __future__ import annotations

import itertools
import random

import pytest
import sympy
import symengine

import modelgen
from modelgen.codegen import cse, pipeline
from modelgen.codegen.cse import count_ops, make_routines
from modelgen.derive import graph as graph_module
from modelgen.derive import spatial
from modelgen.derive.graph import Graph, free_symbols
from modelgen.model.chains import spatial_chain

from conftest import MODELS, SCENES

CASES = {
    "chain 6 (aba)": (lambda: spatial_chain(6).spec(), {}),
    "double pendulum (crba, jacobian)": (
        lambda: modelgen.as_spec(MODELS / "double_pendulum.yaml"),
        {"formulation": "crba", "jacobian": True}),
    "heavy top (linearize)": (lambda: modelgen.as_spec(MODELS / "heavy_top.yaml"),
                              {"linearize": True}),
    "block friction scene (sign, abs, tanh)": ("block_friction.yaml", {}),
}


class _Captured(Exception):
    pass


def _program(make, options):
    """(graph, routine specs) that the pipeline hands to make_routines, for one model."""
    captured = {}

    def capture(graph, routines, **kwargs):
        captured["args"] = (graph, list(routines))
        raise _Captured
    if isinstance(make, str):
        from modelgen.model.scene import load_scene
        scene = load_scene(SCENES / make)
        spec, options = scene.model, dict(options, outputs=scene.outputs)
    else:
        spec = make()
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(pipeline, "make_routines", capture)
        with pytest.raises(_Captured):
            pipeline.generate(spec, "/nonexistent/never-written", force=True, **options)
    return captured["args"]


@pytest.fixture(scope="module", params=sorted(CASES))
def program(request):
    make, options = CASES[request.param]
    return _program(make, options)


def _evaluate(assignments, values):
    """Evaluate a straight-line program in order; ``values`` (symbol -> Float) grows."""
    for sym, expr in assignments:
        values[sym] = sympy.Float(expr.xreplace(values))
    return values


def _inputs(graph, outputs, rng):
    defined = {s for s, _ in graph.assignments}
    free = set().union(*(e.free_symbols for _, e in graph.assignments),
                       *(sympy.sympify(e).free_symbols for e in outputs)) - defined
    return {s: sympy.Float(rng.uniform(0.3, 1.7)) for s in sorted(free, key=str)}


def test_free_symbols_walk_agrees_with_sympy(program):
    graph, routines = program
    outputs = [e for _, _, outs in routines for _, items in outs for e in items]
    exprs = [e for _, e in graph.assignments] + [sympy.sympify(e) for e in outputs]
    assert len(exprs) > 50
    for e in exprs:
        assert free_symbols(e) == e.free_symbols, e


def test_free_symbols_walk_leaves_bound_symbols_to_sympy():
    x, y, t = sympy.symbols("x y t")
    f = sympy.Function("f")
    for e in (sympy.Derivative(f(t, y), t) + x,
              sympy.Integral(x * t, (t, 0, 1)) * y,
              sympy.Piecewise((x, y > 0), (2 * x, True)),
              sympy.sin(x) ** 2 + sympy.pi * sympy.Abs(y) - 3):
        assert free_symbols(e) == e.free_symbols, e


def test_symengine_conversion_matches_sympify(program):
    graph, _ = program
    convert = cse._converters(symengine)[0]
    for _, e in graph.assignments:
        converted = convert(e)
        assert converted == symengine.sympify(e), e
        assert str(converted) == str(symengine.sympify(e))


def test_routines_after_cse_compute_the_same_values(program):
    graph, routines = program
    outputs = [e for _, _, outs in routines for _, items in outs for e in items]
    rng = random.Random(7)
    inputs = _inputs(graph, outputs, rng)
    before = _evaluate(graph.assignments, dict(inputs))
    result = make_routines(graph, routines)
    assert [r.name for r in result] == [name for name, _, _ in routines]
    for routine, (_, _, outs) in zip(result, routines):
        after = _evaluate(routine.statements, dict(inputs))
        for (array, items), (array0, items0) in zip(routine.outputs, outs):
            assert array == array0 and len(items) == len(items0)
            for new, old in zip(items, items0):
                a = complex(sympy.sympify(new).xreplace(after))
                b = complex(sympy.sympify(old).xreplace(before))
                assert abs(a - b) <= 1e-12 * max(1.0, abs(b)), (routine.name, array)


def test_operation_counts_equal_a_direct_count(program):
    graph, routines = program
    result = make_routines(graph, routines)
    for routine, (_, _, outs) in zip(result, routines):
        flat0 = [e for _, items in outs for e in items]
        flat = [e for _, items in routine.outputs for e in items]
        assert routine.ops_before == (count_ops([e for _, e in graph.closure(flat0)])
                                      + count_ops(flat0))
        assert routine.ops_after == (count_ops([e for _, e in routine.statements])
                                     + count_ops(flat))
    assert sum(r.ops_after for r in result) < sum(r.ops_before for r in result)


def test_make_routines_without_cse_keeps_the_program():
    x, y = sympy.symbols("x y")
    g = graph_module.GraphBuilder()
    a = g.name(x * y + x)
    b = g.name((x * y + 1) ** 2)
    (r,) = make_routines(g.freeze(), [("f", (("in", (x, y)),), (("out", (a, b)),))], cse=False)
    assert r.statements == g.freeze().assignments
    assert r.ops_before == r.ops_after == 5


def test_plain_routine_keeps_its_program_beside_eliminated_ones():
    x, y = sympy.symbols("x y")
    g = graph_module.GraphBuilder()
    a = g.name(x * y + x)
    b = g.name((x * y + 1) ** 2)
    graph = g.freeze()
    routines = [(name, (("in", (x, y)),), (("out", (a, b)),)) for name in ("f", "g")]
    seen = []
    f, h = make_routines(graph, routines, alone=("g", "f"), plain=("f",),
                         ready=lambda built: seen.append(sorted(built)))
    assert f.statements == graph.assignments and f.ops_before == f.ops_after == 5
    assert h.ops_after == 4 < h.ops_before       # x*y named once in "g" alone
    assert seen == [["g"], ["f", "g"]]


def _pool():
    x, y = sympy.symbols("x y")
    # names whose string order is not their creation order, assumptions (which
    # sympy's ordering compares first), a noncommutative symbol and a Dummy
    mg9, mg10, mg_c2 = sympy.symbols("mg_9 mg_10 mg_c2")
    r, pos = sympy.Symbol("r", real=True), sympy.Symbol("a", positive=True)
    nc, d = sympy.Symbol("N", commutative=False), sympy.Dummy("d")
    return [0, 1, 2, -1, 0.0, 1.0, 2.5, sympy.S.Zero, sympy.S.One, sympy.S.NegativeOne,
            sympy.S.Half, sympy.Integer(3), sympy.Rational(-3, 7), sympy.Float(1.0),
            sympy.Float(0.0), sympy.Float(-2.0), x, -x, y, x * y, sympy.sin(x), x + 1,
            mg9, mg10, mg_c2, r, pos, nc, d, 2 * mg9]


def test_vector_helpers_build_what_sympy_builds():
    """Each helper against the plain arithmetic it replaces (same value, same type)."""
    rng = random.Random(3)
    pool = _pool()
    for _ in range(500):
        a = tuple(rng.choice(pool) for _ in range(3))
        b = tuple(rng.choice(pool) for _ in range(3))
        s = rng.choice(pool)
        m = tuple(tuple(rng.choice(pool) for _ in range(3)) for _ in range(3))
        expected = {
            "add": tuple(x + y for x, y in zip(a, b)),
            "sub": tuple(x - y for x, y in zip(a, b)),
            "scale": tuple(s * x for x in a),
            "dot": (sympy.Add(*[x * y for x, y in zip(a, b)]),),
            "cross": (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                      a[0] * b[1] - a[1] * b[0]),
            "matvec": tuple(sympy.Add(*[x * y for x, y in zip(row, a)]) for row in m),
        }
        got = {"add": spatial.add(a, b), "sub": spatial.sub(a, b),
               "scale": spatial.scale(s, a), "dot": (spatial.dot(a, b),),
               "cross": spatial.cross(a, b), "matvec": spatial.matvec(m, a)}
        for name, value in expected.items():
            assert got[name] == value, (name, a, b, s)
            assert [type(v) for v in got[name]] == [type(v) for v in value], (name, a, b, s)


def test_product_is_sympys_product_on_every_pair():
    sympy_pool = [sympy.sympify(v) for v in _pool()]
    for x, y in itertools.product(sympy_pool, repeat=2):
        got, expected = spatial.product(x, y), x * y
        assert got == expected and type(got) is type(expected), (x, y)
        assert got.args == expected.args, (x, y)


def _term_pool():
    """Terms of a program's sums and products: symbols in an order that is not
    their names' order, rationals, products of rationals and symbols, powers,
    functions, sums; floats and noncommutative ones too (which must be left to
    sympy)."""
    x, y, z = sympy.symbols("x y z")
    mg9, mg10 = sympy.symbols("mg_9 mg_10")
    r, nc = sympy.Symbol("r", real=True), sympy.Symbol("N", commutative=False)
    half, third = sympy.Rational(1, 2), sympy.Rational(-1, 3)
    return [x, y, z, mg9, mg10, r, -x, 2 * y, half * z, x * y, -x * y, 3 * x * mg9,
            third * mg10 * z, x * y * z, -mg9 * mg10, x ** 2, y ** -1, 2 * x ** 2,
            sympy.sin(x), -sympy.cos(y), x * sympy.sin(y), x + 1, x - y, mg9 * mg10 + z,
            half - z * x, sympy.S(3), sympy.S.NegativeOne, half, third,
            sympy.Float(2.5), sympy.Float(2.5) * x, x + sympy.Float(1.0), nc, 2 * nc,
            sympy.Dummy("d"), x * (y + z)]


def test_canonical_sum_and_product_are_sympys():
    """The direct constructors give sympy's own Add and Mul, argument for
    argument, or decline (None); and they do not decline a program's sums."""
    rng = random.Random(5)
    pool = _term_pool()
    built = {"sum": 0, "product": 0}
    for _ in range(3000):
        terms = [rng.choice(pool) for _ in range(rng.randint(2, 6))]
        for kind, fast, slow in (("sum", spatial.canonical_sum, sympy.Add),
                                 ("product", spatial.canonical_product, sympy.Mul)):
            got, expected = fast(terms), slow(*terms)
            if got is None:
                continue
            built[kind] += 1
            assert type(got) is type(expected), (kind, terms)
            assert got == expected and got.args == expected.args, (kind, terms)
            assert str(got) == str(expected) and got.is_commutative == expected.is_commutative
    assert built["sum"] > 1000 and built["product"] > 50, built


def test_total_and_times_are_sympys_on_a_program():
    """Every sum and product of the 4-link chain's derivation (with its derivatives),
    rebuilt by sympy."""
    spec = spatial_chain(4).spec()
    calls = []
    total, product = spatial.total, spatial.product

    def spy_total(terms):
        terms = list(terms)
        calls.append(("sum", terms, total(terms)))
        return calls[-1][2]

    def spy_product(x, y):
        calls.append(("product", [x, y], product(x, y)))
        return calls[-1][2]

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(spatial, "total", spy_total)
        mp.setattr(spatial, "product", spy_product)
        pipeline._derive(spec, pipeline.BuildOptions(derivatives=True, formulation="aba"),
                         pipeline.choose_formulation(spec, "aba")[1])
    assert len(calls) > 500
    for kind, args, got in calls:
        args = [a for a in args if not spatial.is_zero(a)]
        expected = (sympy.Add if kind == "sum" else sympy.Mul)(*args)
        assert got == expected and got.args == expected.args, (kind, args)


def test_closure_is_the_needed_statements_in_program_order():
    x, y = sympy.symbols("x y")
    g = graph_module.GraphBuilder()
    a = g.name(x * y + 1)
    b = g.name(sympy.sin(x) * y)      # not needed below
    c = g.name(a * x + y)
    graph = g.freeze()
    assert graph.closure([c + 1]) == ((a, x * y + 1), (c, a * x + y))
    assert graph.closure([b]) == ((b, sympy.sin(x) * y),)
    assert graph.closure([x, 2]) == ()
    assert isinstance(graph, Graph)
