"""The derivation's code printers: what they print evaluates to what SymPy means.

Small integer powers print as products; a product in a divisor needs parentheses
(``a/b**2`` printed as ``a/b*b`` is ``a``: that bug once made a derived kernel output wrong).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

sp = pytest.importorskip("sympy")

from derivation.printers import CPrinter, PyPrinter  # noqa: E402

a, b, c = sp.symbols("a b c", real=True)
VALUES = {a: 1.7, b: -0.6, c: 2.3}
EXPRESSIONS = [a / b**2, a / b**3, a / (b**2 * c**4), (a + b) ** 2 / c, a * b**-2, a**2 - b**3 / c**2,
               a / (b + c) ** 2, a / c ** sp.Rational(3, 2)]


@pytest.mark.parametrize("expr", EXPRESSIONS, ids=str)
def test_the_python_printer_keeps_the_value(expr):
    text = PyPrinter().doprint(expr)
    env = {s.name: v for s, v in VALUES.items()} | {"numpy": np}
    assert eval(text, env) == pytest.approx(float(expr.subs(VALUES)), rel=1e-14), text


@pytest.mark.parametrize("expr", EXPRESSIONS, ids=str)
def test_the_c_printer_keeps_the_value(expr):
    """C's arithmetic on these operators is Python's: the printed text evaluates alike."""
    text = CPrinter({}).doprint(expr).replace("sqrt", "math.sqrt")
    env = {s.name: v for s, v in VALUES.items()} | {"math": math}
    assert eval(text, env) == pytest.approx(float(expr.subs(VALUES)), rel=1e-14), text
