"""Code printers: SymPy expressions to C99 and NumPy source text.

Inputs print as flat-array reads (``q[3]``, ``p[12]``) in C and as local names in Python;
small integer powers print as parenthesised products, which compilers and NumPy evaluate
faster and exactly (without the parentheses ``a/b**2`` printed as ``a/b*b``, which is ``a``).
"""

from __future__ import annotations

import sympy as sp
from sympy.printing.c import C99CodePrinter
from sympy.printing.numpy import NumPyPrinter


class CPrinter(C99CodePrinter):
    """C99 printer that maps input symbols to array elements (``x3`` -> ``q[6]``)."""

    def __init__(self, array_names: dict[str, str]) -> None:
        super().__init__()
        self.array_names = array_names

    def _print_Symbol(self, expr: sp.Symbol) -> str:
        return self.array_names.get(expr.name, expr.name)

    def _print_Pow(self, expr: sp.Pow) -> str:
        base, exp = expr.as_base_exp()
        if exp.is_Integer and 2 <= abs(int(exp)) <= 4:
            product = "*".join([self.parenthesize(base, 100)] * abs(int(exp)))
            return f"({product})" if exp > 0 else f"1.0/({product})"  # (): it may be a divisor, a/(b*b)
        if exp == -1:
            return f"1.0/{self.parenthesize(base, 100)}"
        if exp == sp.Rational(-1, 2):
            return f"1.0/sqrt({self._print(base)})"
        if exp == sp.Rational(-3, 2):
            b = self.parenthesize(base, 100)
            return f"1.0/({b}*sqrt({self._print(base)}))"
        return super()._print_Pow(expr)

    def _print_CopySign1(self, expr) -> str:
        return f"copysign(1.0, {self._print(expr.args[0])})"


class PyPrinter(NumPyPrinter):
    """NumPy printer writing ``numpy.sqrt`` etc.; symbols print as their names."""

    def __init__(self) -> None:
        super().__init__({"fully_qualified_modules": True})

    def _print_Pow(self, expr: sp.Pow, rational: bool = False) -> str:
        base, exp = expr.as_base_exp()
        if exp.is_Integer and 2 <= abs(int(exp)) <= 4:
            product = "*".join([self.parenthesize(base, 100)] * abs(int(exp)))
            return f"({product})" if exp > 0 else f"1.0/({product})"  # (): it may be a divisor, a/(b*b)
        return super()._print_Pow(expr, rational=rational)

    def _print_CopySign1(self, expr) -> str:
        return f"numpy.copysign(1.0, {self._print(expr.args[0])})"
