"""Evaluate RS274/NGC expressions (LinuxCNC's interp_read.cc / interp_execute.cc semantics).

The parser gives an expression as nested tuples (see :mod:`nurbscnc.program.parse`). Real
programs nest them a few levels deep, hostile ones thousands (``ABS[ABS[...`` or ``####1``),
so evaluation is ITERATIVE: an explicit stack of pending operations instead of Python
recursion, and the depth is unbounded by anything but memory. Every intermediate result is
checked to be finite, so SIN, ROUND or a parameter index never sees inf or nan.

Angles are in degrees, as in RS274/NGC. Comparisons and logic give 1.0 or 0.0.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Callable

import numpy as np

from nurbscnc.errors import ProgramError

#: The highest parameter number (LinuxCNC: RS274NGC_MAX_PARAMETERS − 1).
MAX_PARAMETER = 5602
#: LinuxCNC's TOLERANCE_EQUAL: EQ and NE compare within it ([0.1 + 0.2] EQ 0.3 is 1, and
#: a loop counting in steps of 0.1 meets its NE bound).
TOLERANCE_EQUAL = 0.0001


class ExpressionError(ProgramError):
    """An expression cannot be evaluated (division by zero, domain, overflow)."""


def _divide(a: float, b: float) -> float:
    if b == 0.0:
        raise ExpressionError("division by zero")
    return a / b


def _mod(a: float, b: float) -> float:
    if b == 0.0:
        raise ExpressionError("MOD by zero")
    r = math.fmod(a, b)
    return r + abs(b) if r < 0.0 else r  # LinuxCNC: result in [0, |b|)


def _power(a: float, b: float) -> float:
    if a < 0.0 and b != int(b):
        raise ExpressionError("negative number raised to a non-integer power")
    if a == 0.0 and b < 0.0:
        raise ExpressionError("zero raised to a negative power")
    return float(a**b)


#: The binary operators. Comparisons and logic give 1.0 or 0.0; EQ and NE compare within
#: TOLERANCE_EQUAL (LinuxCNC 2.9, execute_binary2), LE and GE exactly.
_BINARY = {
    "+": operator.add,
    "-": operator.sub,
    "*": operator.mul,
    "/": _divide,
    "MOD": _mod,
    "**": _power,
    "EQ": lambda a, b: float(abs(a - b) < TOLERANCE_EQUAL),
    "NE": lambda a, b: float(abs(a - b) >= TOLERANCE_EQUAL),
    "GT": lambda a, b: float(a > b),
    "GE": lambda a, b: float(a >= b),
    "LT": lambda a, b: float(a < b),
    "LE": lambda a, b: float(a <= b),
    "AND": lambda a, b: float(a != 0.0 and b != 0.0),
    "OR": lambda a, b: float(a != 0.0 or b != 0.0),
    "XOR": lambda a, b: float((a != 0.0) != (b != 0.0)),
}


def _binop(op: str, a: float, b: float) -> float:
    """``a op b`` (:data:`_BINARY`)."""
    function = _BINARY.get(op)
    if function is None:  # pragma: no cover
        raise AssertionError(op)
    return function(a, b)


#: π in the C ``long double`` LinuxCNC's execute_unary and execute_binary use (M_PIl): its
#: degree conversions run in that precision (80-bit on x86-64; where numpy's longdouble is
#: a double, the results are a double's). SIN[30] is 0.5 there, 0.49999999999999994 in
#: doubles, and FIX[2*SIN[30]] 1, not 0.
_PI_L = np.longdouble("3.14159265358979323846264338327950288")
_TRIG_L = {"SIN": np.sin, "COS": np.cos, "TAN": np.tan}


def degrees_as_linuxcnc(radians: float) -> float:
    """``(radians * 180.0) / M_PIl`` rounded to a double (ASIN, ACOS, ATAN)."""
    return float(np.longdouble(radians * 180.0) / _PI_L)


def _func(name: str, x: float) -> float:
    if name in _TRIG_L:  # sin((x * M_PIl) / 180.0), in long double
        return float(_TRIG_L[name](np.longdouble(x) * _PI_L / 180))
    if name in ("ASIN", "ACOS"):
        if not -1.0 <= x <= 1.0:
            raise ExpressionError(f"{name} argument {x:g} outside [-1, 1]")
        return degrees_as_linuxcnc(math.asin(x) if name == "ASIN" else math.acos(x))
    if name == "SQRT":
        if x < 0.0:
            raise ExpressionError(f"SQRT of a negative number ({x:g})")
        return math.sqrt(x)
    if name == "ABS":
        return abs(x)
    if name == "EXP":
        return math.exp(x)
    if name == "LN":
        if x <= 0.0:
            raise ExpressionError(f"LN of a non-positive number ({x:g})")
        return math.log(x)
    if name == "ROUND":
        return float(math.floor(abs(x) + 0.5)) * (1.0 if x >= 0 else -1.0)
    if name == "FIX":
        return float(math.floor(x))
    if name == "FUP":
        return float(math.ceil(x))
    raise AssertionError(name)  # pragma: no cover


def evaluate(
    expr,
    numbered: Callable[[float], float],
    named: Callable[[str], float],
    exists: Callable[[str], bool],
) -> float:
    """The value of ``expr`` (a float or an expression tuple).

    ``numbered(index)`` reads ``#index`` (it checks the range), ``named(name)`` reads
    ``#<name>`` and ``exists(name)`` answers ``EXISTS[#<name>]``. Raises
    :class:`ExpressionError` (without a position: the caller adds the word's) or whatever
    the callbacks raise.
    """
    if type(expr) is float:
        return expr
    try:
        result = _evaluate(expr, numbered, named, exists)
    except OverflowError:
        raise ExpressionError("arithmetic overflow in expression") from None
    if not math.isfinite(result):
        raise ExpressionError("expression value is not finite (overflow)")
    return result


def _evaluate(expr, numbered, named, exists) -> float:
    # Post-order walk with two stacks: ``todo`` holds nodes to visit and ("apply", node)
    # markers for operations whose operands are on ``values``.
    values: list[float] = []
    todo: list = [expr]
    push_value = values.append
    push = todo.append
    pop = todo.pop
    while todo:
        node = pop()
        if type(node) is float:
            push_value(node)
            continue
        tag = node[0]
        if tag == "apply":
            op = node[1]
            kind = op[0]
            if kind == "#":
                r = numbered(values.pop())
            elif kind == "neg":
                r = -values.pop()
            elif kind == "op":
                b = values.pop()
                a = values.pop()
                r = _binop(op[1], a, b)
            elif kind == "fn":
                r = _func(op[1], values.pop())
            elif kind == "existsn":
                r = 1.0 if 1 <= round(values.pop()) <= MAX_PARAMETER else 0.0
            else:  # atan
                x = values.pop()
                y = values.pop()
                r = degrees_as_linuxcnc(math.atan2(y, x))
            if not math.isfinite(r):
                raise ExpressionError("expression value is not finite (overflow)")
            push_value(r)
        elif tag == "<":
            push_value(named(node[1]))
        elif tag == "exists":
            push_value(1.0 if exists(node[1]) else 0.0)
        elif tag == "op":
            push(("apply", node))
            push(node[3])
            push(node[2])
        elif tag == "atan":
            push(("apply", node))
            push(node[2])
            push(node[1])
        else:  # "#", "neg", "fn", "existsn": one operand (the last element)
            push(("apply", node))
            push(node[-1])
    return values[-1]
