"""Code generation: SymbolicModel -> one CSE pass -> printed blocks -> jinja2 templates.

The math (CSE, printing) happens here in Python; the templates in ``templates/`` only
lay the printed blocks out.  Output is deterministic: no timestamps, symbols in manifest
order, CSE with ``order='none'`` over all outputs together.
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass
from pathlib import Path

import jinja2
import numpy as np
import sympy as sp

from flexbody.topology import GENERATOR_VERSION

from .mechanics import ENERGY_NAMES, SymbolicModel
from .printers import CPrinter, PyPrinter

TEMPLATES = Path(__file__).parent / "templates"
#: Rendered files: template name -> output file name.
FILES = {
    "model.py.jinja": "model.py",
    "model.c.jinja": "model.c",
    "model.h.jinja": "model.h",
    "eom.md.jinja": "eom.md",
}
#: Generated functions in the order they appear, with one-line descriptions.
FUNCTIONS = {
    "mass_matrix": "Mass matrix M(q, p) of M u' = F.",
    "forcing": "Forcing F(q, u, p) of M u' = F: springs, dampers, gravity and velocity terms.",
    "energies": "Kinetic, spring and gravity energy (J) and damping power (W, >= 0).",
    "damping_power": "Power dissipated by the dampers (W, >= 0).",
    "positions": "Particle positions in N (m).",
    "velocities": "Particle velocities in N (m/s).",
    "gaps": "Ground gap of every contact (particle * n_grounds + ground), m; < 0 is penetration.",
    "gap_jacobian": "d gaps / dq (with q' = u, gap rates are gap_jacobian @ u).",
    "gap_bias": "d/dt(gap_jacobian) @ u: gap accelerations are gap_jacobian @ u' + gap_bias.",
    "particle_jacobian": "d velocities / du, rows particle-major (particle * dim + axis): velocities = this @ u.",
    "particle_bias": "d/dt(particle_jacobian) @ u: particle accelerations are particle_jacobian @ u' + this.",
    "jacobian_q": "d(F - M a)/dq at acceleration a.",
    "jacobian_u": "dF/du.",
}


@dataclass
class Block:
    """One generated function: CSE temporaries it needs and its nonzero output entries."""

    name: str
    doc: str
    shape: tuple[int, ...]
    inputs: list[str]  # the argument groups it reads, subset of q, u, p, a
    unpack: list[tuple[str, str, int]]  # (symbol, group, index) for the Python module
    temporaries: list[tuple[str, str, str]]  # (name, C expression, Python expression)
    entries: list[tuple[int, tuple[int, ...], str, str]]  # (flat index, index, C, Python)
    ops: int


def _cse(model: SymbolicModel) -> tuple[list[tuple[sp.Symbol, sp.Expr]], dict[str, list[sp.Expr]]]:
    """One CSE pass over every output together; returns temporaries and reduced outputs."""
    flat: list[sp.Expr] = []
    spans: dict[str, tuple[int, int]] = {}
    for name in FUNCTIONS:
        entries = list(model.outputs[name])
        spans[name] = (len(flat), len(flat) + len(entries))
        flat.extend(entries)
    temporaries, reduced = sp.cse(flat, symbols=sp.numbered_symbols("w"), order="none")
    return temporaries, {name: reduced[a:b] for name, (a, b) in spans.items()}


def _check_coverage(model: SymbolicModel) -> None:
    """Every free symbol of every output must be an input (q, u, p or a)."""
    inputs = set(model.q) | set(model.u) | set(model.p) | set(model.a)
    missing = {
        name: sorted(str(s) for s in matrix.free_symbols - inputs) for name, matrix in model.outputs.items()
    }
    missing = {k: v for k, v in missing.items() if v}
    if missing:
        raise RuntimeError(f"outputs use symbols that are not inputs (q, u, p, a): {missing}")


def build_blocks(model: SymbolicModel) -> list[Block]:
    """CSE all outputs once, then give each function the temporaries it depends on."""
    _check_coverage(model)
    temporaries, reduced = _cse(model)
    reduced = dict(reduced)
    extra_docs = {}
    if model.mass_matrix_is_diagonal:
        n = model.outputs["mass_matrix"].rows
        reduced["mass_diagonal"] = [reduced["mass_matrix"][i * n + i] for i in range(n)]
        model.outputs["mass_diagonal"] = sp.Matrix([model.outputs["mass_matrix"][i, i] for i in range(n)])
        extra_docs["mass_diagonal"] = "Diagonal of the (diagonal) mass matrix."
    pattern = gap_jacobian_pattern(model)
    reduced["gap_jacobian_values"] = [reduced["gap_jacobian"][k] for k in pattern.flat]
    model.outputs["gap_jacobian_values"] = sp.Matrix([list(model.outputs["gap_jacobian"])[k] for k in pattern.flat])
    extra_docs["gap_jacobian_values"] = "Nonzeros of gap_jacobian, row by row (pattern GJ_START, GJ_COL)."
    groups = {"q": model.q, "u": model.u, "p": model.p, "a": model.a}
    where = {s: (g, i) for g, syms in groups.items() for i, s in enumerate(syms)}
    c_printer = CPrinter({s.name: f"{g}[{i}]" for s, (g, i) in where.items()})
    py_printer = PyPrinter()

    def py(expr) -> str:
        # Functions print as `_m.sqrt`: `_m` is numpy for batches, a scalar math namespace otherwise.
        return re.sub(r"\bnumpy\.", "_m.", py_printer.doprint(expr))
    defined = dict(temporaries)
    order = {t: k for k, (t, _) in enumerate(temporaries)}
    blocks = []
    for name, doc in (FUNCTIONS | extra_docs).items():
        exprs = reduced[name]
        shape = model.outputs[name].shape
        shape = (shape[0],) if shape[1] == 1 and name not in ("positions", "velocities", "particle_bias") else shape
        shape = (max(shape[0], 1),) + tuple(shape[1:])  # C has no zero-length arrays
        needed: set[sp.Symbol] = set()
        stack = [s for e in exprs for s in e.free_symbols if s in defined]
        while stack:
            t = stack.pop()
            if t not in needed:
                needed.add(t)
                stack.extend(s for s in defined[t].free_symbols if s in defined)
        used_temps = sorted(needed, key=order.__getitem__)
        free = set().union(*(e.free_symbols for e in exprs), *(defined[t].free_symbols for t in used_temps))
        inputs = sorted({where[s][0] for s in free if s in where}, key="qupa".index)
        unpack = sorted(((s.name, *where[s]) for s in free if s in where), key=lambda x: ("qupa".index(x[1]), x[2]))
        cols = shape[1] if len(shape) == 2 else 1
        entries = [
            (k, divmod(k, cols) if len(shape) == 2 else (k,), c_printer.doprint(e), py(e))
            for k, e in enumerate(exprs)
            if e != 0
        ]
        blocks.append(
            Block(
                name=name,
                doc=doc,
                shape=tuple(shape),
                inputs=inputs,
                unpack=unpack,
                temporaries=[(t.name, c_printer.doprint(defined[t]), py(defined[t])) for t in used_temps],
                entries=entries,
                ops=int(sp.count_ops([defined[t] for t in used_temps] + list(exprs))),
            )
        )
    return blocks


class SparsePattern:
    """Nonzeros of the gap Jacobian in row order: ``start`` (nc + 1,), ``col`` (nnz,), ``flat``
    (nnz,) = row-major index of each nonzero."""

    def __init__(self, matrix: sp.Matrix) -> None:
        self.start, self.col, self.flat = [0], [], []
        for i in range(matrix.rows):
            for j in range(matrix.cols):
                if matrix[i, j] != 0:
                    self.col.append(j)
                    self.flat.append(i * matrix.cols + j)
            self.start.append(len(self.col))


def gap_jacobian_pattern(model: SymbolicModel) -> SparsePattern:
    return SparsePattern(model.outputs["gap_jacobian"])


def cholesky_code(M: sp.Matrix) -> dict[str, list[str]]:
    """Straight-line C for the Cholesky factor and solve of M's sparsity pattern.

    Unknowns with the fewest couplings go first and the dense rigid-body rows of the
    floating formulation last, so the arrowhead pattern factors without fill-in: O(n)
    work instead of O(n^3).  The factor overwrites M's lower triangle (in that order).
    """
    n = M.rows
    pattern = np.array([[M[i, j] != 0 for j in range(n)] for i in range(n)])
    order = sorted(range(n), key=lambda i: (int(pattern[i].sum()), i))
    L = np.tril(pattern[np.ix_(order, order)])
    for j in range(n):  # symbolic elimination: the fill-in pattern
        rows = np.flatnonzero(L[j + 1 :, j]) + j + 1
        L[np.ix_(rows, rows)] |= np.tril(np.ones((len(rows), len(rows)), bool))

    def m(i: int, j: int) -> str:
        return f"m[{order[i] * n + order[j]}]"

    factor, solve = [], []
    for j in range(n):
        terms = "".join(f" - {m(j, k)} * {m(j, k)}" for k in range(j) if L[j, k])
        factor.append(f"d = {m(j, j)}{terms}; if (!(d > 0.0)) return -1; {m(j, j)} = sqrt(d);")
        for i in range(j + 1, n):
            if L[i, j]:
                terms = "".join(f" - {m(i, k)} * {m(j, k)}" for k in range(j) if L[i, k] and L[j, k])
                factor.append(f"{m(i, j)} = ({m(i, j)}{terms}) / {m(j, j)};")
    for i in range(n):
        terms = "".join(f" - {m(i, k)} * x[{order[k]}]" for k in range(i) if L[i, k])
        solve.append(f"x[{order[i]}] = (x[{order[i]}]{terms}) / {m(i, i)};")
    for i in reversed(range(n)):
        terms = "".join(f" - {m(k, i)} * x[{order[k]}]" for k in range(i + 1, n) if L[k, i])
        solve.append(f"x[{order[i]}] = (x[{order[i]}]{terms}) / {m(i, i)};")
    return {"factor": factor, "solve": solve}


def environment() -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(TEMPLATES)),
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
        autoescape=False,
    )


def _c_array(values) -> str:
    """A C initializer with every double printed so it reads back exactly."""
    values = np.asarray(values, dtype=float)
    if values.ndim == 1:
        return "{" + ", ".join(repr(float(v)) for v in values) + "}"
    return "{\n    " + ",\n    ".join(_c_array(row) for row in values) + "}"


def _combination(weights) -> str:
    """``(w0 * K[0][i] + w2 * K[2][i] + ...)`` over the nonzero weights, each printed exactly.

    The integrator's stage sums are unrolled this way, so each is one pass over the state."""
    return "(" + " + ".join(f"{float(w)!r} * K[{j}][i]" for j, w in enumerate(weights) if w != 0.0) + ")"


def runge_kutta_tables() -> dict:
    """Butcher tableaux, error weights and dense-output coefficients (Dormand & Prince;
    Hairer, Norsett & Wanner), read as data from SciPy so both integration paths agree,
    as C initializers and as unrolled stage sums."""
    from scipy.integrate import RK45
    from scipy.integrate._ivp import dop853_coefficients as d8

    n8 = d8.N_STAGES
    return {
        "d5": {
            "n_stages": RK45.n_stages,
            "stages": [{"c": repr(float(RK45.C[s])), "sum": _combination(RK45.A[s, :s])} for s in range(1, 6)],
            "solution": _combination(RK45.B),
            "error": _combination(RK45.E),
            # dense output: stage j's weight at x = (t - t_old) / h is sum_r P[j][r] x^(r+1)
            "dense": _c_array(RK45.P),
            "dense_stages": [j for j in range(len(RK45.P)) if np.any(RK45.P[j] != 0.0)],
        },
        "d8": {
            "n_stages": n8,
            "stages": [{"c": repr(float(d8.C[s])), "sum": _combination(d8.A[s, :s])} for s in range(1, n8)],
            "solution": _combination(d8.B),
            "error5": _combination(d8.E5),
            "error3": _combination(d8.E3),
            "dense_stages": [{"index": s, "c": repr(float(d8.C[s])), "sum": _combination(d8.A[s, :s])}
                             for s in range(n8 + 1, 16)],
            "dense": [_combination(row) for row in d8.D],
        },
    }


def _equations(model: SymbolicModel) -> dict:
    """The equations of motion to read: readable rows with their named terms, and Kane's raw rows.

    Returns
    -------
    dict
        ``rows``: [{speed, text, latex}] per row of the readable form
        (:mod:`derivation.readable`); ``terms``: [{text, latex}] the named terms'
        definitions; ``raw``: [{speed, text, latex}] ``sum_j M_rj u_j' = F_r`` as derived,
        unsimplified (for debugging).
    """
    from .readable import readable

    eqs = readable(model)
    rows = [{"speed": u.name, "text": text, "latex": latex}
            for u, text, latex in zip(model.u, eqs.rows_text(), eqs.rows_latex())]
    terms = [{"text": text, "latex": latex} for text, latex in zip(eqs.terms_text(), eqs.terms_latex())]
    M, F = model.outputs["mass_matrix"], model.outputs["forcing"]
    raw = []
    for r, speed in enumerate(model.u):
        lhs = sum((M[r, j] * sp.Symbol(f"{model.u[j].name}'") for j in range(M.cols) if M[r, j] != 0), sp.S.Zero)
        raw.append({"speed": speed.name, "text": f"{lhs} = {F[r]}", "latex": f"{sp.latex(lhs)} = {sp.latex(F[r])}"})
    return {"rows": rows, "terms": terms, "raw": raw}


def render(model: SymbolicModel, *, source: str, command: str) -> dict[str, str]:
    """Render every generated file of ``model`` to text.

    Parameters
    ----------
    model : SymbolicModel
    source : str
        The scene the model was derived from, named in each file's header.
    command : str
        The command that regenerates the files, named in each file's header.

    Returns
    -------
    dict
        File name -> text, including ``manifest.json``.
    """
    import jinja2 as _jinja2  # for the version only

    blocks = build_blocks(model)
    top = model.topology
    digest = top.digest(model.formulation)
    contacts = [(i, g) for i in range(top.n_particles) for g in range(top.n_grounds)]
    context = {
        "source": source,
        "command": command,
        "digest": digest,
        "formulation": model.formulation,
        "q_names": tuple(s.name for s in model.q),
        "u_names": tuple(s.name for s in model.u),
        "p_names": tuple(s.name for s in model.p),
        "descriptions": model.descriptions,
        "nq": len(model.q),
        "nu": len(model.u),
        "np_": len(model.p),
        "nc": len(contacts),
        "n_particles": top.n_particles,
        "dim": top.dim,
        "n_links": top.n_links,
        "n_grounds": top.n_grounds,
        "energy_names": ENERGY_NAMES,
        "diagonal": model.mass_matrix_is_diagonal,
        "blocks": blocks,
        "equations": _equations(model),
        "gj": gap_jacobian_pattern(model),
        "cholesky": cholesky_code(model.outputs["mass_matrix"]),
    }
    env = environment()
    files = {}
    for template, out in FILES.items():
        files[out] = env.get_template(template).render(template=template, **context)
    manifest = {
        "model": f"flexbody model {digest}",
        "digest": digest,
        "formulation": model.formulation,
        "source": source,
        "regenerate": command,
        "topology": json.loads(top.to_json()),
        "q_names": context["q_names"],
        "u_names": context["u_names"],
        "p_names": context["p_names"],
        "n_particles": top.n_particles,
        "n_contacts": len(contacts),
        "contacts": contacts,
        "energy_names": list(ENERGY_NAMES),
        "mass_matrix_diagonal": model.mass_matrix_is_diagonal,
        "functions": {b.name: {"shape": list(b.shape), "ops_after_cse": b.ops} for b in blocks},
        "python_math": sorted(set(re.findall(r"\b_m\.(\w+)", files["model.py"]))),
        "versions": {"generator": GENERATOR_VERSION, "sympy": sp.__version__, "jinja2": _jinja2.__version__},
        "sha256": {name: hashlib.sha256(text.encode()).hexdigest() for name, text in sorted(files.items())},
    }
    files["manifest.json"] = json.dumps(manifest, indent=1) + "\n"
    return files
