"""Printer stage: sympy expressions to C99 source text.

One printer, a subclass of sympy's C99 printer, that maps every symbol to the
C expression holding it (``q[0]``, ``p[3]``, a local ``w12`` or a work-array
slot ``w[7]``).  Templates never format numbers or expressions themselves.
"""
from __future__ import annotations

import math

import sympy
from sympy.printing.c import C99CodePrinter
from sympy.printing.codeprinter import PrintMethodNotImplementedError
from sympy.printing.precedence import precedence

from modelgen.derive.spatial import negative_number
from modelgen.errors import DerivationError


#: Integers at least this large are printed as double literals (a C integer
#: constant of 2**63 or more does not compile; beyond 2**53 a double is inexact anyway).
EXACT_INTEGER_LIMIT = 2**53


#: Precedences of the fast printer's output: a sum, a product or quotient, a
#: negated product, an atom (name, call, parenthesised group, unsigned number).
_ADD, _MUL, _NEG, _ATOM = 1, 2, 3, 4
_ONE, _MINUS_ONE = sympy.S.One, sympy.S.NegativeOne
#: sympy functions printed as a C call of the same arity.  sin and cos are the
#: model C's inline ``mg_sin``/``mg_cos`` (templates/model.c.j2: inline, so that
#: gcc shares one argument reduction between a sin and a cos of one angle;
#: ``-DMG_LIBM_TRIG`` makes them libm's).
_C_FUNCTIONS = {sympy.sin: "mg_sin", sympy.cos: "mg_cos", sympy.tan: "tan", sympy.asin: "asin",
                sympy.acos: "acos", sympy.atan: "atan", sympy.atan2: "atan2",
                sympy.sinh: "sinh", sympy.cosh: "cosh", sympy.tanh: "tanh",
                sympy.exp: "exp", sympy.log: "log", sympy.Abs: "fabs"}


class ModelPrinter(C99CodePrinter):
    """C99 printer with symbol -> slot mapping and cheap integer powers.

    ``doprint`` walks the expression directly (:meth:`_fast`: the node types the
    derivation produces) and hands any other node to sympy's C99 printer
    (:meth:`_slow`), which at n = 30 links took a fifth of the whole generation;
    ``tests/test_printer.py`` checks the two against each other on real models.

    The printer is strict: an expression it cannot print as C (an unevaluated
    ``Derivative``, ``re``...) raises :class:`DerivationError` naming
    ``routine``, never leaves text in the C.

    >>> x, y = sympy.symbols("x y")
    >>> ModelPrinter({x: "q[0]", y: "p[1]"}).doprint(x**2 * y + sympy.pi)
    '3.1415926535897931 + p[1]*(q[0]*q[0])'
    >>> ModelPrinter({x: "q[0]"}).doprint(10**19 * x + sympy.Rational(1, 3))
    '1.0/3.0 + 1e+19*q[0]'
    """

    def __init__(self, slots: dict, routine: str = ""):
        super().__init__({"order": "none", "strict": True,
                          "user_functions": {"sin": "mg_sin", "cos": "mg_cos"}})
        self.slots = slots
        self.routine = routine

    def doprint(self, expr, assign_to=None):
        if assign_to is None:
            return self._fast(expr)[0]
        return self._slow(expr, assign_to)

    def _slow(self, expr, assign_to=None):
        """sympy's C99 printer (with this class's methods): every node it knows."""
        try:
            return super().doprint(expr, assign_to)
        except PrintMethodNotImplementedError as exc:
            where = f" in routine {self.routine}" if self.routine else ""
            first = str(exc).splitlines()[0]
            raise DerivationError(f"cannot print {_shorten(str(expr))} as C{where} "
                                  f"({first})") from None

    def _handle_UnevaluatedExpr(self, expr):
        """No rewrite pass: modelgen never builds ``UnevaluatedExpr`` (sympy's pass
        walks every expression with ``replace``, a sixth of the printing time),
        and an ``re`` left in would still be refused by the strict printer."""
        return expr

    def _fast(self, e) -> tuple:
        """``(C text, precedence)`` of ``e`` by a direct walk over the node types the
        derivation produces (sums, products, integer and half powers, rationals,
        floats, symbols, the elementary functions): the same C as sympy's printer up to
        spacing and the order of a product's factors, at a fraction of its cost (it
        builds no sympy objects); any other node is printed by sympy's printer, in
        parentheses, so nothing is lost and strictness is kept."""
        if e.is_Symbol:
            return self._print_Symbol(e), _ATOM
        if e.is_Number or e is sympy.pi or e is sympy.E:
            printed = self._fast_number(e)
            if printed is not None:
                return printed
        if e.is_Add:
            return self._fast_add(e)
        if e.is_Mul:
            return self._fast_mul(e)
        if e.is_Pow:
            return self._fast_pow(e)
        if e.func in _C_FUNCTIONS:
            return f"{_C_FUNCTIONS[e.func]}({', '.join(self._fast(a)[0] for a in e.args)})", _ATOM
        return f"({self._slow(e)})", _ATOM

    def _fast_number(self, e):
        """``(text, precedence)`` of a number or constant, None for one that is not
        finite (printed by sympy's printer, which refuses it)."""
        if e.is_Integer:
            if abs(e.p) >= EXACT_INTEGER_LIMIT:
                text = self._double(e)
            else:
                text = f"{e.p}.0"
            return text, (_NEG if text.startswith("-") else _ATOM)
        if e.is_Rational:
            if max(abs(e.p), e.q) >= EXACT_INTEGER_LIMIT:
                text = self._double(e)
                return text, (_NEG if text.startswith("-") else _ATOM)
            return f"{e.p}.0/{e.q}.0", (_NEG if e.p < 0 else _MUL)
        if e.is_Float and math.isfinite(float(e)):
            text = repr(float(e))
            return text, (_NEG if text.startswith("-") else _ATOM)
        if e is sympy.pi:
            return "3.1415926535897931", _ATOM
        if e is sympy.E:
            return "2.7182818284590451", _ATOM
        return None

    def _fast_add(self, e) -> tuple:
        printed = [self._fast(term) for term in e.args]
        if len(printed) > 1 and printed[0][1] == _NEG and printed[1][1] != _NEG:
            # -a + b is printed b - a: the same rounding (a sum of two is
            # commutative), one operation fewer
            printed[0], printed[1] = printed[1], printed[0]
        parts = []
        for i, (text, prec) in enumerate(printed):
            if i and prec == _NEG:
                parts.append(" - " + text[1:])
            else:
                parts.append((" + " if i else "") + text)
        return "".join(parts), _ADD

    def _fast_mul(self, e) -> tuple:
        # numbers are compared by their fields or by identity (S.One, S.NegativeOne
        # and S.Half are singletons): sympy's rich comparisons sympify their
        # other operand, which took a fifth of the printing
        coeff, factors = _coeff_and_factors(e)
        negative = negative_number(coeff)
        sign = "-" if negative else ""
        coeff = -coeff if negative else coeff
        num, den = [], []
        for factor in factors:
            exp = factor.exp if factor.is_Pow else None
            if exp is not None and exp.is_Rational and exp.p < 0:
                den.append(factor.base if exp is _MINUS_ONE else
                           sympy.Pow(factor.base, -exp, evaluate=False))
            else:
                num.append(factor)
        texts = [] if coeff is _ONE else [self._fast(coeff)[0]]
        for factor in num:
            text, prec = self._fast(factor)
            texts.append(text if prec >= _MUL and not (prec == _MUL and factor.is_Rational)
                         else f"({text})")
        text = "*".join(texts) or "1.0"
        if den:
            printed = [self._fast(d) for d in den]
            if len(printed) == 1:
                d, prec = printed[0]
                text += "/" + (d if prec == _ATOM else f"({d})")
            else:
                text += "/(" + "*".join(d if prec >= _MUL else f"({d})"
                                        for d, prec in printed) + ")"
        return sign + text, (_NEG if sign else _MUL)

    def _fast_pow(self, e) -> tuple:
        base, exp = e.args
        b, prec = self._fast(base)
        group = b if prec == _ATOM else f"({b})"
        if exp.is_Integer and 1 < abs(exp.p) <= 4:
            prod = "(" + "*".join([group] * abs(exp.p)) + ")"
            return (prod, _ATOM) if exp.p > 0 else (f"1.0/{prod}", _MUL)
        if exp is _MINUS_ONE:
            return f"1.0/{group}", _MUL
        if exp.is_Rational and exp.q == 2 and abs(exp.p) == 1:
            return (f"sqrt({b})", _ATOM) if exp.p > 0 else (f"1.0/sqrt({b})", _MUL)
        return f"pow({b}, {self._fast(exp)[0]})", _ATOM

    def _print_Integer(self, expr):
        if abs(expr.p) >= EXACT_INTEGER_LIMIT:
            return self._double(expr)
        return super()._print_Integer(expr)

    def _print_Rational(self, expr):
        if max(abs(expr.p), expr.q) >= EXACT_INTEGER_LIMIT:
            return self._double(expr)
        return super()._print_Rational(expr)

    def _double(self, expr) -> str:
        """A number as the nearest double literal (validation keeps it in range)."""
        try:
            value = expr.p / expr.q
        except OverflowError:
            value = math.inf
        if not math.isfinite(value):
            magnitude = round(math.log10(abs(expr.p)) - math.log10(expr.q))
            where = f" in routine {self.routine}" if self.routine else ""
            raise DerivationError(
                f"a constant of about 1e{magnitude}{where} is beyond the range of a double: "
                "the model's constants are in range but their products (e.g. a mass times "
                "a length squared) are not; use units that keep constants near 1")
        return repr(value)

    def _print_Symbol(self, expr):
        try:
            return self.slots[expr]
        except KeyError:
            raise DerivationError(f"symbol {expr} has no storage in the generated C") from None

    def _print_Pi(self, expr):
        return "3.1415926535897931"

    def _print_Exp1(self, expr):
        return "2.7182818284590451"

    def _print_Pow(self, expr):
        base, exp = expr.args
        if exp.is_Integer and 1 < abs(int(exp)) <= 4:
            b = self.parenthesize(base, precedence(sympy.Mul(base, base, evaluate=False)))
            prod = "(" + "*".join([b] * abs(int(exp))) + ")"
            return prod if exp > 0 else f"1.0/{prod}"
        if exp == -1:
            return f"1.0/{self.parenthesize(base, precedence(expr))}"
        if exp == sympy.S.Half:
            return f"sqrt({self._print(base)})"
        if exp == -sympy.S.Half:
            return f"1.0/sqrt({self._print(base)})"
        return f"pow({self._print(base)}, {self._print(exp)})"

    def _print_Float(self, expr):
        return repr(float(expr))

    def _print_sign(self, expr):
        a = self._print(expr.args[0])
        return f"((double)(({a}) > 0) - (double)(({a}) < 0))"




def _coeff_and_factors(e) -> tuple:
    """``(coeff, factors)`` of a Mul: ``as_coeff_Mul`` and ``make_args`` of the
    rest, without building the rest (a Mul's number, if any, is its first
    argument)."""
    args = e.args
    if not args[0].is_Number:
        return _ONE, args
    factors = args[1:]
    if len(factors) == 1 and factors[0].is_Mul:     # an unevaluated 2*(x*y)
        factors = factors[0].args
    return args[0], factors


def c_operations(e) -> int:
    """Floating-point operations of ``e`` as :class:`ModelPrinter` prints it in C.

    Each binary ``+ - * /`` and each function call costs 1, a unary minus 1;
    a constant (``1.0/3.0``, ``-2.0``) costs nothing, and a term's sign inside a
    sum is its ``-`` (``a - b*c`` is 2).  Mirrors :meth:`ModelPrinter._fast`
    node for node; ``tests/test_printer.py`` checks it against the operators
    in the printed text of real models.

    >>> x, y, z = sympy.symbols("x y z")
    >>> c_operations(z - x*y), c_operations(-x*y), c_operations(-x + y), c_operations(x/3)
    (2, 2, 1, 1)
    """
    return sum(_c_ops(e))


def _c_ops(e) -> tuple:
    """(operations but a leading minus, 1 if printed with a leading minus that is
    an operation else 0)."""
    if e.is_Atom:
        return 0, 0
    if e.is_Add:
        terms = [_c_ops(t) for t in e.args]
        swapped = len(terms) > 1 and _negative_text(e.args[0]) and not _negative_text(e.args[1])
        first = terms[1] if swapped else terms[0]
        # a sign after the first term is its '-'; only the first one's can cost
        return sum(n for n, _ in terms) + len(terms) - 1 + first[1], 0
    if e.is_Mul:
        coeff, rest = _coeff_and_factors(e)
        negative = negative_number(coeff)
        coeff = -coeff if negative else coeff
        count, factors, den = 0, (0 if coeff is _ONE else 1), 0
        for factor in rest:
            exp = factor.exp if factor.is_Pow else None
            if exp is not None and exp.is_Rational and exp.p < 0:
                den += 1
                count += sum(_c_ops(factor.base if exp is _MINUS_ONE else
                                    sympy.Pow(factor.base, -exp, evaluate=False)))
            else:
                factors += 1
                count += sum(_c_ops(factor))
        count += max(factors - 1, 0) + den
        # a minus on a coefficient or a lone 1.0 is part of the literal (-2.0*x, -1.0/x)
        return count, int(negative and coeff is _ONE and factors > 0)
    if e.is_Pow:
        base, exp = e.args
        inner = sum(_c_ops(base))
        if exp.is_Integer and 1 < abs(exp.p) <= 4:
            return inner + abs(exp.p) - 1 + (1 if exp.p < 0 else 0), 0
        if exp is _MINUS_ONE:
            return inner + 1, 0
        if exp.is_Rational and exp.q == 2 and abs(exp.p) == 1:
            return inner + (1 if exp.p > 0 else 2), 0
        return inner + sum(_c_ops(exp)) + 1, 0
    return sum(sum(_c_ops(a)) for a in e.args) + 1, 0


def _negative_text(e) -> bool:
    """True if the printer prints ``e`` with a leading minus (precedence _NEG)."""
    if e.is_Number:
        return negative_number(e)
    if e.is_Mul:
        return e.args[0].is_Number and negative_number(e.args[0])
    return False


def _shorten(text: str) -> str:
    return text if len(text) <= 80 else text[:60] + "..." + text[-15:]
