"""The equations of motion as a mechanics text writes them, for ``eom.md`` and ``flexbody show``.

Kane's method returns ``M u' = F`` with each link's force applied twice (``f`` on particle
i, ``-f`` on particle j) and left unsimplified, so internal forces that cancel in a row
are still printed twice with opposite signs.  Here every row is rebuilt from Kane's own
ingredients, ``F_r = sum_i (F_i - m_i a_i) . dv_i/du_r``, grouped by cause:

* **links**: each link l = (i, j) contributes ``f_l . (dv_i/du_r - dv_j/du_r)``, written
  with named terms defined once: its length ``ell_l = |r_i - r_j|``, its spring force
  ``fs_l = k_l (L_l - ell_l)`` along ``e_l = (r_i - r_j) / ell_l`` (positive when
  compressed), and its damper force, ``fd_l = c_l (v_j - v_i) . e_l`` along ``e_l``
  (axial) or the vector ``fd_l = c_l (v_j - v_i)`` (relative; components in the body's
  frame).  A link whose particles move together in a row (the rigid-body rows of the
  floating frame) contributes nothing there: the internal force cancels.
* **gravity**, collected by ``g_x``, ``g_y`` (and ``g_z`` in 3D);
* **velocity terms** (centripetal, Coriolis) ``-m_i (dv_i/dq) u . dv_i/du_r``, collected
  by products of speeds.

Vectors are dotted in the frame of their body (T in the floating formulation, N in the
particles one): both factors then carry no angle, so no trigonometric simplification is
needed.  The 3D floating frame (three angles) has no such form yet: its rows are Kane's
``M`` with the forcing named ``F_<speed>`` (not expanded: it is printed once, in the raw
rows), and its first angle's description in ``eom.md`` says so; :func:`check_identity`
does not apply to it.  :func:`check_identity` substitutes the named terms back and compares with Kane's
``M`` and ``F``; the tests run it.
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from .mechanics import SymbolicModel


@dataclass
class ReadableEquations:
    """Readable ``M u' = F``: row r reads ``sum_s lhs[r, s] u_s' = sum(rhs[r].values())``.

    ``rhs[r]`` holds the row's forcing by cause ("links", "gravity", "velocity"), in named
    terms.  ``terms`` maps each named symbol (link lengths and forces) to its definition in
    q, u, p and earlier named symbols; :meth:`expand` substitutes them back.
    """

    speeds: list[sp.Symbol]  # u, (nu,)
    coordinates: list[sp.Symbol]  # q, (nq,): u_r is the time derivative of q_r
    lhs: sp.Matrix  # (nu, nu), the simplified mass matrix
    rhs: list[dict[str, sp.Expr]]  # (nu,) rows, forcing by cause
    terms: dict[sp.Symbol, sp.Expr]  # named term -> definition, in definition order
    latex_names: dict[sp.Symbol, str]

    def expand(self) -> tuple[sp.Matrix, sp.Matrix]:
        """``M`` and ``F`` with every named term replaced by its definition (q, u, p only)."""
        values: dict[sp.Symbol, sp.Expr] = {}
        for name, definition in self.terms.items():  # definitions only use earlier names
            values[name] = definition.xreplace(values)
        return self.lhs, sp.Matrix([sp.Add(*row.values()).xreplace(values) for row in self.rhs])

    # ---------------------------------------------------------------- printing
    def _row(self, r: int, latex: bool) -> str:
        """``lhs = rhs`` of row r: mass-matrix terms, then links, gravity and velocity terms."""
        lhs = _signed_sum([(self.lhs[r, s], self._acceleration(s, latex)) for s in range(len(self.speeds))
                           if self.lhs[r, s] != 0], self._show(latex), latex)
        rhs = _signed_sum([(e, "") for e in self.rhs[r].values() if e != 0], self._show(latex), latex)
        return f"{lhs} = {rhs or '0'}"

    def _acceleration(self, s: int, latex: bool) -> str:
        if not latex:
            return f"{self.speeds[s].name}'"
        stem, sub = self.latex_names[self.coordinates[s]]
        return f"\\ddot{{{stem}}}_{{{sub}}}"

    def _show(self, latex: bool):
        if latex:
            names = self.symbol_names
            return lambda expr: sp.latex(expr, symbol_names=names, order="none")
        return lambda expr: sp.sstr(expr, order="none")

    @property
    def symbol_names(self) -> dict[sp.Symbol, str]:
        """LaTeX name of every coordinate, speed (dotted coordinate) and named term."""
        names = {}
        for q, u in zip(self.coordinates, self.speeds):
            stem, sub = self.latex_names[q]
            names[q], names[u] = f"{stem}_{{{sub}}}", f"\\dot{{{stem}}}_{{{sub}}}"
        return names | {s: v for s, v in self.latex_names.items() if isinstance(v, str)}

    def rows_text(self) -> list[str]:
        """One ``lhs = rhs`` line per row; ``u'`` is the time derivative of speed u."""
        return [self._row(r, False) for r in range(len(self.speeds))]

    def rows_latex(self) -> list[str]:
        """One LaTeX ``lhs = rhs`` per row, speeds as dotted coordinates (u = q')."""
        return [self._row(r, True) for r in range(len(self.speeds))]

    def terms_text(self) -> list[str]:
        show = self._show(False)
        return [f"{name} = {show(definition)}" for name, definition in self.terms.items()]

    def terms_latex(self) -> list[str]:
        names, show = self.symbol_names, self._show(True)
        return [f"{names[name]} = {show(definition)}" for name, definition in self.terms.items()]


def _signed_sum(items: list[tuple[sp.Expr, str]], show, latex: bool) -> str:
    """``a x + b y - c z`` from (coefficient, factor) pairs; sums in parentheses when factored."""
    out = ""
    for coeff, factor in items:
        negative = coeff.could_extract_minus_sign() and not isinstance(coeff, sp.Add)
        coeff = -coeff if negative else coeff
        if factor:
            text = "" if coeff == 1 else show(coeff)
            if isinstance(coeff, sp.Add):
                text = f"\\left({text}\\right)" if latex else f"({text})"
            text = f"{text} {factor}".strip() if latex or not text else f"{text}*{factor}"
        else:
            text = show(coeff)
            if text.startswith("-"):
                negative, text = not negative, text[1:].lstrip()
        out += (" - " if negative else " + ") + text if out else ("-" if negative else "") + text
    return out


_GREEK = {"theta": r"\theta", "xi": r"\xi", "eta": r"\eta", "zeta": r"\zeta", "alpha": r"\alpha",
          "beta": r"\beta", "gamma": r"\gamma"}


def _latex_coordinate(name: str) -> tuple[str, str]:
    """``theta0`` -> (``\\theta``, ``0``), ``x12`` -> (``x``, ``12``): stem and subscript."""
    stem = name.rstrip("0123456789")
    return _GREEK.get(stem, stem), name[len(stem):]


def _polynomial_in(expr: sp.Expr, variables: list[sp.Symbol]) -> sp.Expr:
    """``expr`` collected by monomials of ``variables``, each coefficient factored."""
    expr = sp.expand(expr)
    if expr == 0:
        return sp.S.Zero
    present = [v for v in variables if expr.has(v)]
    if not present:
        return sp.factor_terms(expr)
    poly = sp.Poly(expr, *present)
    return sp.Add(*(sp.factor_terms(c) * sp.Mul(*(v**k for v, k in zip(present, monomial)))
                    for monomial, c in poly.terms()))


def readable(model: SymbolicModel) -> ReadableEquations:
    """Rebuild ``M u' = F`` of ``model`` with named link forces, grouped by cause.

    Parameters
    ----------
    model : SymbolicModel
        From :func:`derivation.mechanics.derive`; uses its positions, velocities, q, u, p.

    Returns
    -------
    ReadableEquations
    """
    top = model.topology
    q, u = model.q, model.u
    sym = {s.name: s for s in model.p}
    names: dict = {s: _latex_coordinate(s.name) for s in q}  # coordinate -> (stem, subscript)
    if model.formulation == "floating" and top.dim == 3:  # not regrouped yet: F_r is printed once, in the raw rows
        forcing = [sp.Symbol(f"F_{s.name}", real=True) for s in u]
        names |= {f: rf"F_{{{r}}}" for r, f in enumerate(forcing)}
        return ReadableEquations(list(u), list(q), model.outputs["mass_matrix"], [{"raw": f} for f in forcing], {},
                                 names)
    by_name = {s.name: s for s in q}
    X = model.outputs["positions"]  # (n, 2) in N
    V = model.outputs["velocities"]  # (n, 2) in N, linear in u
    n, nu = top.n_particles, len(u)

    # The frame each particle's vectors are written in: its body's T (floating) or N.
    body_of, angle = [], []
    for b, body in enumerate(top.bodies):
        theta = by_name.get(f"theta{b}") if model.formulation == "floating" else None
        body_of += [b] * body.n_particles
        angle.append(theta)

    def in_body(vector: sp.Matrix, b: int) -> sp.Matrix:
        """N components -> components in body b's frame, angles cancelled exactly."""
        th = angle[b]
        if th is None:
            return vector.applyfunc(sp.expand)
        c, s = sp.cos(th), sp.sin(th)
        return (sp.Matrix([[c, s], [-s, c]]) * vector).applyfunc(lambda e: _pythagoras(e, th))

    Ju = [V[i, :].T.jacobian(u) for i in range(n)]  # dv_i/du, (2, nu) each
    # Position, velocity and partial velocities of each particle in its body's frame, once.
    X_b = [in_body(X[i, :].T, body_of[i]) for i in range(n)]
    V_b = [in_body(V[i, :].T, body_of[i]) for i in range(n)]
    Ju_b = [in_body(Ju[i], body_of[i]) for i in range(n)]
    mass = [sym[f"m{i}"] for i in range(n)]
    g_axes = [sym[f"g_{a}"] for a in "xyz"[: top.dim]]
    gravity = sp.Matrix(g_axes)
    rhs = [{"links": sp.S.Zero} for _ in range(nu)]
    terms: dict[sp.Symbol, sp.Expr] = {}

    # Links, in their body's frame: P = r_i - r_j and the partial velocities are both body-fixed.
    link, first = 0, 0
    for b, body in enumerate(top.bodies):
        if body.rigid:  # fixed in T: its links only draw it (no load, as in derivation.mechanics)
            link += len(body.links)
            first += body.n_particles
            continue
        for a, c_ in body.links:
            i, j = first + a, first + c_
            P, dv = (X_b[i] - X_b[j]).applyfunc(sp.expand), (V_b[j] - V_b[i]).applyfunc(sp.expand)
            W = (Ju_b[i] - Ju_b[j]).applyfunc(sp.expand)  # (2, nu) partial velocities of the stretch
            k, c, rest = sym[f"k{link}"], sym[f"c{link}"], sym[f"L{link}"]
            ell = sp.Symbol(f"ell{link}", positive=True)
            fs = sp.Symbol(f"fs{link}", real=True)
            terms[ell] = sp.sqrt(sum((sp.factor(x) ** 2 for x in P), sp.S.Zero))
            terms[fs] = k * (rest - ell)
            names[ell], names[fs] = rf"\ell_{{{link}}}", rf"f^{{s}}_{{{link}}}"
            axes = ("xi", "eta") if angle[b] is not None else tuple("xyz"[: top.dim])
            if body.damper == "axial":
                fd = sp.Symbol(f"fd{link}", real=True)
                terms[fd] = sp.expand(c * P.dot(dv)) / ell
                names[fd] = rf"f^{{d}}_{{{link}}}"
                for r in range(nu):
                    along = sp.expand(P.dot(W[:, r]))
                    if along != 0:
                        rhs[r]["links"] += (fs + fd) * sp.factor_terms(along) / ell
            else:
                fd = [sp.Symbol(f"fd{link}_{axis}", real=True) for axis in axes]
                for f, axis, component in zip(fd, axes, dv):
                    terms[f] = sp.factor_terms(c * component)
                    names[f] = rf"f^{{d,{_GREEK.get(axis, axis)}}}_{{{link}}}"
                for r in range(nu):
                    along = sp.expand(P.dot(W[:, r]))
                    if along != 0:
                        rhs[r]["links"] += fs * sp.factor_terms(along) / ell
                    rhs[r]["links"] += sum((f * w for f, w in zip(fd, W[:, r])), sp.S.Zero)
            link += 1
        first += body.n_particles

    # Gravity and the velocity terms of Kane's inertia forces, -m_i a_i(u' = 0).
    Jq = [V[i, :].T.jacobian(q) for i in range(n)]
    udot_free = [Jq[i] * sp.Matrix(u) for i in range(n)]
    for r in range(nu):
        g_r = sum((mass[i] * gravity.dot(Ju[i][:, r]) for i in range(n) if any(Ju[i][:, r])), sp.S.Zero)
        inertia = -sum((mass[i] * udot_free[i].dot(Ju[i][:, r]) for i in range(n) if any(Ju[i][:, r])), sp.S.Zero)
        for b, th in enumerate(angle):
            if th is not None:
                inertia = _pythagoras(inertia, th)
        rhs[r]["gravity"] = _polynomial_in(g_r, g_axes)
        rhs[r]["velocity"] = _polynomial_in(inertia, list(u))

    lhs = model.outputs["mass_matrix"].applyfunc(lambda e: sp.factor_terms(sp.expand(e)))
    return ReadableEquations(list(u), list(q), lhs, rhs, terms, names)


def _pythagoras(expr: sp.Expr, th: sp.Symbol) -> sp.Expr:
    """Expand and replace sin(th)^2 by 1 - cos(th)^2 until no square of sin is left."""
    expr = sp.expand(expr)
    s, c = sp.sin(th), sp.cos(th)
    if not expr.has(s):
        return expr
    w = sp.Dummy("w")
    poly = sp.Poly(expr.xreplace({s: w}), w)
    out = sp.S.Zero
    for (k,), coeff in poly.terms():
        out += coeff * (1 - c**2) ** (k // 2) * s ** (k % 2)
    return sp.expand(out)


def check_identity(model: SymbolicModel, eqs: ReadableEquations, *, points: int = 0, seed: int = 0) -> float:
    """Compare the readable equations, named terms substituted back, with Kane's.

    Parameters
    ----------
    points : int
        0: symbolic, ``simplify(readable - raw) == 0`` for every entry (returns 0.0 or raises).
        Otherwise the largest relative difference at that many random states.
    """
    M, F = eqs.expand()
    raw_M, raw_F = model.outputs["mass_matrix"], model.outputs["forcing"]
    if points == 0:
        for a, b in zip(list(M) + list(F), list(raw_M) + list(raw_F)):
            if sp.simplify(a - b) != 0:
                raise AssertionError(f"readable {a} != raw {b}")
        return 0.0
    import numpy as np

    rng = np.random.default_rng(seed)
    symbols = list(model.q) + list(model.u) + list(model.p)
    f = sp.lambdify(symbols, [M, F, raw_M, raw_F], modules="numpy", cse=True)
    worst = 0.0
    for _ in range(points):
        values = rng.uniform(0.5, 1.5, len(symbols)) * rng.choice([-1, 1], len(symbols))
        for s, k in zip(symbols, range(len(symbols))):
            if s.is_positive:
                values[k] = abs(values[k])
        m, fr, rm, rf = (np.asarray(x, dtype=float) for x in f(*values))
        scale = max(np.abs(rf).max(), np.abs(rm).max(), 1.0)
        worst = max(worst, np.abs(m - rm).max() / scale, np.abs(fr - rf).max() / scale)
    return worst
