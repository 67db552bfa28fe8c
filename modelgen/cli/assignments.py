"""The NAME=VALUE flags (``--init``, ``--set``, ``--at``, ``--u``): each value a number
or, as in a model file, an expression of numbers (``--at al=pi``: the upright
pendulum is where a user types pi), checked finite, each name checked against
what it may name before anything is built."""
from __future__ import annotations

import math

from modelgen.errors import ModelgenError


def parse_assignments(items, what: str) -> dict:
    """The NAME=VALUE items of ``--<what>`` as name -> finite float."""
    out = {}
    for item in items or ():
        name, sep, value = item.partition("=")
        if not sep:
            raise ModelgenError(f"--{what} takes NAME=VALUE, got {item!r}")
        out[name.strip()] = _value(value, f"--{what} {item!r}")
        if not math.isfinite(out[name.strip()]):
            raise ModelgenError(f"--{what} {item!r}: the value must be a finite number")
    return out


def _value(text: str, where: str) -> float:
    """A number, or an expression of numbers (``pi - 0.1``) as a model file takes them."""
    try:
        return float(text)
    except ValueError:
        pass
    from modelgen.model.expr import ExpressionParseError, parse_expression
    try:
        return float(parse_expression(text, {}))    # a finite real, or refused
    except ExpressionParseError as exc:
        raise ModelgenError(f"{where}: {text!r} is not a number or an expression of numbers "
                            f"({exc}); fix: e.g. 1.5 or pi/2") from None


def state_overrides(names, items) -> dict:
    """``--init`` over the state ``names``: each name one of them."""
    init = parse_assignments(items, "init")
    for key in init:
        if key not in names:
            raise ModelgenError(f"--init {key}: unknown state; the state is {', '.join(names)}")
    return init


def parameter_overrides(parameters, items) -> dict:
    """``--set`` over ``parameters``: each name one of them."""
    values = parse_assignments(items, "set")
    for key in values:
        if key not in parameters:
            raise ModelgenError(f"--set {key}: unknown parameter; parameters are "
                                f"{', '.join(parameters) or 'none'}")
    return values
