"""Linear complementarity problems, solved exactly by Lemke's complementary pivoting.

The problem ``LCP(M, q)``: find ``z`` with

    w = M z + q,   w >= 0,   z >= 0,   w . z = 0          (M: (n, n), q, z, w: (n,))

Coupled contacts (DESIGN §6) lead to it: the impulses of a simultaneous impact and the forces
of held contacts, with ``M`` the Delassus matrix ``W = J M^-1 J^T`` (see
:mod:`flexbody.contact_problems`).  :func:`solve_lcp` is a finite pivoting method, so its
answer is exact up to rounding (no iteration tolerance), and the answer does not depend on
the order in which the contacts are listed wherever the solution is unique.

What it guarantees, by the class of ``M`` (Cottle, Pang & Stone, *The Linear Complementarity
Problem*, 1992, ch. 4):

* **P-matrix** (every principal minor > 0; e.g. ``W`` of independent contacts, which is
  symmetric positive definite): the solution exists and is unique for every ``q``, and
  Lemke's method finds it.
* **copositive-plus** (includes every positive semidefinite ``M``; e.g. ``W`` of redundant
  contacts, a bar on three collinear supports): when the method ends on a secondary ray,
  the problem has no feasible point, so no solution; otherwise it finds one.  With a
  symmetric positive semidefinite ``M`` the solution ``z`` need not be unique, but ``w`` is:
  for two solutions, ``(z1 - z2) . (w1 - w2) = -z1 . w2 - z2 . w1 <= 0`` and also
  ``= (z1 - z2)^T M (z1 - z2) >= 0``, so ``M (z1 - z2) = 0``.  For contacts this means the
  impulses may be indeterminate but the velocities they produce are not.
* **symmetric positive definite** (a P-matrix): :func:`solve_pd_lcp` solves it by Murty's
  least-index principal pivoting, a few small linear solves instead of Lemke's tableau (a
  pile's many two- and three-contact blocks); it returns None for any other ``M``.
* other matrices (friction, :mod:`flexbody.contact_problems`): a secondary ray says that the
  method found no solution; for the frictional force problem that is Painlevé's paradox.

Rounding: with a nearly singular ``M`` (a rigid body's redundant contacts in a pile) the
pivots can end on a complementary basis whose ``z`` is infeasible (below 0).  Then
:func:`solve_lcp` runs again on ``M + s I`` for tiny ``s`` (:data:`SHIFTS`), and accepts an
answer of the same size only where it passes the check on the original ``M`` (each row
off by at most ``s z_i`` more, the shift's compliance): every answer returned as solved
solves the problem asked.  So does a secondary ray (its problem has an answer of the same
size, or the ray stands).  For a matrix that is not copositive-plus (friction) a ray proves
nothing: the path from another covering vector may end on a solution, and
:func:`solve_lcp` tries :data:`COVERINGS` of them (seeded, so the run is repeatable) before
it reports the ray; the same where the pivot limit stops a path that rounding made wander.
Where every path fails, a mixed-integer search (SciPy's ``milp``: HiGHS's branch and bound
over which side of each row is 0) either finds a solution, solved again exactly from its
pattern and checked, or proves that none exists with ``z`` and ``w`` within
:data:`SEARCH_BOUND` times their scales, which the message then says (Painlevé's paradox
proven, not merely met).

The pivots run in C where the runtime library is built (``fb_lemke``, generated from
``derivation/templates/lcp.c.jinja``): the same operations in the same order as
:func:`_path`, its NumPy twin, so the same path bit for bit, 13 to 41 times faster on the
fuzzes' saved problems (``flexbody bench --study lcp``).
Before all that, a path that ends with ``z0`` at the rounding level has its last point
checked (it solves ``q + d z0``): a plastic frictional impact with redundant contacts has a
solution (Anitescu & Potra), yet its path stalled so and then met a rounding-level ray.
"""

from __future__ import annotations

import ctypes
import dataclasses
import functools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .constants import LEMKE_LIMIT, LEMKE_RAY, LEMKE_SOLVED

__all__ = ["STATUSES", "LcpSolution", "solve_lcp", "solve_pd_lcp"]

#: Status values of :class:`LcpSolution` and what each means.
STATUSES = {
    "solved": "z solves the LCP (checked: feasibility and complementarity to the check tolerance).",
    "ray": "Lemke's method ended on a secondary ray: no solution was found (none exists for a "
           "copositive-plus M; the message says whether the mixed-integer search proved that none "
           "exists within its bound); z is the last almost-complementary point, not a solution.",
    "iterations": "The pivot limit was reached before a solution; z is the last point.",
    "inaccurate": "A complementary basis was found, but its z fails the feasibility or "
                  "complementarity check (an ill-conditioned M).",
}  # fmt: skip

#: Relative pivot tolerance: an entry of the entering column counts as positive only above
#: this fraction of the column's largest magnitude.
PIVOT_TOL = 1e-11
#: Relative tolerance of the final check, scaled per row by ``|M| |z| + |q|``.
CHECK_TOL = 1e-9
#: Tolerance for ties in the lexicographic ratio test, relative to the tableau entries
#: compared (the right side is in units of max |q|, the basis inverse starts as I): rows tie
#: where pivoting on the lowest ratio leaves the others' entries at most this far below 0.
TIE_TOL = 1e-12
#: Where Lemke's method ends on a complementary basis whose answer fails the check, or on a
#: secondary ray, it runs again on ``M + s I`` for each of these ``s`` (relative to M's
#: largest diagonal entry) until one answer solves the original problem (a fuzzed pile of
#: rigid and flexible discs: M's condition 2.6e16, a z below 0 by 0.2 after the pivots,
#: then 5e16 and a ray where enumerating the bases finds a solution; both solved at 1e-12) ...
SHIFTS = (1e-13, 1e-12, 1e-11)
#: ... and is at most this many times the size of the pivots' last point (or of |q| / M_ii).
SHIFT_GROWTH = 10.0
#: Then Lemke's method runs on the original problem with this many other covering vectors
#: (seeded, entries in [0.5, 2]): for a matrix that is not copositive-plus (friction) a
#: secondary ray proves nothing, and the path, which the covering vector sets, may end on a
#: solution from another start.  A fuzz's frictional impacts: 6 of 7 problems that ended on
#: a ray or an infeasible basis were solved by 19 to 40 of 50 orders of their contacts.
#: (Four of the five such problems in tests/reference, two of them the shifts', are solved
#: by the first path since the ratio test's ties are judged in the tableau's units.)
COVERINGS = 12
#: Last, where every path failed, a mixed-integer search (SciPy's ``milp``, HiGHS's branch
#: and bound) looks for the complementary pattern of a solution with ``z`` and ``w`` up to
#: this many times their scales (``|q| / max M_ii`` and ``|q|``), and proves that none
#: exists there where it finds none: for a matrix that is not copositive-plus a ray alone
#: proves nothing.  (A fuzz's frictional force LCP, 51 rows, Painlevé's: a ray from every
#: path; the search, 3 ms, finds no solution, nor with the friction polygons turned or of 8
#: or 16 sides: the contact force does not exist.)
SEARCH_BOUND = 1e3
#: ... in problems of at most this many rows (its cost can grow as 2^n) and this many
#: branch-and-bound nodes (a count, not a time: the answer is the same on any machine).
SEARCH_LARGEST = 200
SEARCH_NODES = 20000

#: A walk along Lemke's path (:func:`_path`, or its compiled twin): ``(T, basis, d, limit,
#: pivot_tol) -> (end, pivots)``, the tableau and basis changed in place.
Walk = Callable[[np.ndarray, np.ndarray, np.ndarray, int, float], tuple[str, int]]


@dataclass(frozen=True)
class LcpSolution:
    """The answer of :func:`solve_lcp`.

    Attributes
    ----------
    z : ndarray, shape (n,)
        The solution (meaningful only when ``status == "solved"``).
    w : ndarray, shape (n,)
        ``M z + q``, recomputed from ``z``.
    status : str
        One of :data:`STATUSES`.
    pivots : int
        Number of pivots performed (0 when ``q >= 0``).
    message : str
        What happened, in a sentence.
    """

    z: np.ndarray
    w: np.ndarray
    status: str
    pivots: int
    message: str

    @property
    def solved(self) -> bool:
        """True when ``z`` is a checked solution."""
        return self.status == "solved"


def solve_lcp(
    M: np.ndarray,
    q: np.ndarray,
    *,
    covering: np.ndarray | None = None,
    max_pivots: int | None = None,
    pivot_tol: float = PIVOT_TOL,
    check_tol: float = CHECK_TOL,
    compiled: bool = True,
) -> LcpSolution:
    """Solve ``w = M z + q, w >= 0, z >= 0, w . z = 0`` by Lemke's method.

    The method augments the problem with an artificial variable ``z0`` and a covering vector
    ``d > 0``: ``w = M z + q + d z0``.  Starting from ``w = q + d z0`` with ``z0`` just large
    enough to make ``w >= 0``, it pivots along a path of almost-complementary feasible bases
    (at most one complementary pair both basic): the variable that enters is always the
    complement of the one that left.  The path ends when ``z0`` leaves the basis (a
    solution) or when the entering column has no positive entry (a secondary ray).

    **Termination.**  The leaving row is chosen by the *lexicographic* minimum ratio test:
    among rows ``i`` with a positive entry ``a_i`` of the entering column, the smallest
    vector ``(b_i, (B^-1)_i) / a_i`` (``b`` the basic values, ``B^-1`` the basis inverse).
    The rows of ``B^-1`` are linearly independent, so there is never a tie: this is
    Lemke's method on the perturbed problem ``q + (eps, eps^2, ..., eps^n)``, which is
    non-degenerate for small ``eps``.  On a non-degenerate problem each almost-complementary
    basis has at most two neighbours on the path and the start has one, so the path never
    revisits a basis; there are finitely many bases, so it ends after finitely many pivots
    even when ``q`` has zeros or ``M`` repeated rows.  (The pivot limit guards against
    rounding only; exact arithmetic needs none.)

    Parameters
    ----------
    M : array_like, shape (n, n)
        The matrix (need not be symmetric).
    q : array_like, shape (n,)
    covering : array_like, shape (n,), optional
        The covering vector ``d`` (all > 0); default ones.
    max_pivots : int, optional
        Pivot limit; default ``100 (n + 1)``.  Reaching it gives status ``"iterations"``.
    pivot_tol : float
        Relative pivot tolerance (:data:`PIVOT_TOL`).
    check_tol : float
        Relative tolerance of the final check (:data:`CHECK_TOL`): row ``i`` may violate
        ``w_i >= 0`` or ``w_i z_i = 0`` by ``check_tol (|M| |z| + |q|)_i`` plus the rounding
        level ``16 n eps (max|M| max|z| + max|q|)``; basic values below that level count as 0.
    compiled : bool
        Pivot in C (the runtime library's ``fb_lemke``) where it is built; False: in NumPy.
        The path, and so the answer, is the same bit for bit.

    Returns
    -------
    LcpSolution
        ``z``, ``w``, status (:data:`STATUSES`), pivot count and a message.

    Raises
    ------
    ValueError
        When ``M`` is not square, ``q`` does not match it, or either is not finite.
    """
    M, q, d = _checked(M, q, covering)
    n = q.size
    if np.all(q >= 0.0):  # z = 0 already solves it
        return LcpSolution(np.zeros(n), q.copy(), "solved", 0, "q >= 0: z = 0 with no pivots.")
    limit = 100 * (n + 1) if max_pivots is None else int(max_pivots)
    walk = (_compiled_path() if compiled else None) or _path
    answer = _lemke(M, q, d, limit, pivot_tol, check_tol, walk)
    if answer.status == "solved":
        return answer
    # A nearly singular M (redundant contacts) can lose the pivots' feasibility to rounding,
    # or end them on a ray: again on M + shift I, a compliance far below the check's
    # tolerance.  Its answer counts only if it solves the original problem and is of the
    # size of the pivots' last point (M + s I has an answer of size ~1/s where the original
    # problem has none).  A path that reached the pivot limit (rounding made it wander)
    # goes to other paths at once.
    size = float(np.abs(np.diag(M)).max()) or float(np.abs(M).max()) or 1.0
    largest = SHIFT_GROWTH * max(float(np.abs(answer.z).max()), float(np.abs(q).max()) / size)
    for relative in SHIFTS if answer.status != "iterations" else ():
        shift = relative * size
        retry = _lemke(M + shift * np.eye(n), q, d, limit, pivot_tol, check_tol, walk)
        if retry.status == "solved" and np.abs(retry.z).max() <= largest:
            # it solves M + s I exactly: on M each row is off by s z_i more, a compliance
            # (measured: a frictional impact's answer, exact to 3.5e-19 by enumeration, was
            # refused by 1.0e-11 = s z)
            floor = _rounding_floor(M, q, retry.z)
            checked = _checked_solution(M, q, retry.z, answer.pivots + retry.pivots, check_tol,
                                        floor + shift * float(np.abs(retry.z).max()),
                                        f"{retry.message[:-1]} on M + {shift:.1e} I (without: {answer.message[:-1]}).")
            if checked.solved:
                return checked
    return _searched(M, q, _other_coverings(M, q, answer, limit, pivot_tol, check_tol, walk), check_tol)


def _other_coverings(M: np.ndarray, q: np.ndarray, answer: LcpSolution, limit: int, pivot_tol: float,
                     check_tol: float, walk: Walk) -> LcpSolution:
    """Lemke's method again from :data:`COVERINGS` other covering vectors: the first answer
    that solves the problem, else ``answer`` (the path from the vector of ones)."""
    pivots = answer.pivots
    for seed in range(COVERINGS):
        other = np.random.default_rng(seed).uniform(0.5, 2.0, q.size)
        retry = _lemke(M, q, other, limit, pivot_tol, check_tol, walk)
        pivots += retry.pivots
        if retry.status == "solved":
            return LcpSolution(retry.z, retry.w, "solved", pivots,
                               f"{retry.message[:-1]} with covering vector {seed + 1} of {COVERINGS} "
                               f"(with ones: {answer.message[:-1]}).")
    return answer


def _searched(M: np.ndarray, q: np.ndarray, answer: LcpSolution, check_tol: float) -> LcpSolution:
    """``answer`` if it solves the problem; else a solution that a mixed-integer search
    finds (see :data:`SEARCH_BOUND`), or ``answer`` with what the search showed.

    One binary ``b_i`` per row picks its side: ``0 <= z_i <= U b_i`` and ``0 <= w_i <= U (1
    - b_i)``, with ``w = M z + q``, in units where ``U`` is :data:`SEARCH_BOUND`.  The
    search's answer is met to its own tolerances only: its pattern's ``z`` is solved
    again exactly and checked as a path's basis (:func:`_complementary`).
    """
    n = q.size
    if answer.solved or n > SEARCH_LARGEST:
        return answer
    from scipy.optimize import Bounds, LinearConstraint, milp

    w_unit = float(np.abs(q).max())
    z_unit = w_unit / (float(np.abs(np.diag(M)).max()) or float(np.abs(M).max()) or 1.0)
    A, b, U = M * (z_unit / w_unit), q / w_unit, SEARCH_BOUND  # w / w_unit = A (z / z_unit) + b
    eye, zero = np.eye(n), np.zeros((n, n))
    found = milp(np.zeros(2 * n), integrality=np.r_[np.zeros(n), np.ones(n)],
                 bounds=Bounds(np.zeros(2 * n), np.r_[np.full(n, np.inf), np.ones(n)]),
                 constraints=[LinearConstraint(np.hstack([A, zero]), -b, np.inf),
                              LinearConstraint(np.hstack([eye, -U * eye]), -np.inf, 0.0),
                              LinearConstraint(np.hstack([A, U * eye]), -np.inf, U - b)],
                 options={"node_limit": SEARCH_NODES})
    bound = f"z and w up to {U:g} times their scales"
    if found.status == 2:  # infeasible
        return dataclasses.replace(answer, message=f"{answer.message[:-1]}; a mixed-integer search proves "
                                                   f"that none exists with {bound}.")
    if found.x is None:
        return dataclasses.replace(answer, message=f"{answer.message[:-1]}; a mixed-integer search stopped "
                                                   f"before it found one with {bound} ({found.message}).")
    z = np.where(found.x[n:] > 0.5, found.x[:n] * z_unit, 0.0)
    solution = _complementary(M, q, z, answer.pivots, check_tol,
                              f"solved by a mixed-integer search, after the pivots ({answer.message[:-1]}).")
    return solution if solution.solved else answer


def _lemke(M: np.ndarray, q: np.ndarray, d: np.ndarray, limit: int, pivot_tol: float,
           check_tol: float, walk: Walk) -> LcpSolution:
    """Lemke's method on checked ``M``, ``q`` (not all >= 0), covering ``d`` (see
    :func:`solve_lcp`), its path walked by ``walk`` (:func:`_path` or its compiled twin)."""
    T, basis, unit = _start(M, q, d)
    status, pivots = walk(T, basis, d, limit, pivot_tol)
    message = {"solved": f"solved in {pivots} pivots.",
               "ray": f"secondary ray after {pivots} pivots: no solution found.",
               "iterations": f"pivot limit {limit} reached before a solution."}[status]
    return _finish(M, q, T, basis, status, pivots, check_tol, unit, message, d)


def _start(M: np.ndarray, q: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The start of Lemke's path on ``LCP(M, q)`` (``q`` not all >= 0) from the covering
    vector ``d``: the tableau (n, 2 n + 2), the basis (n,) and the unit of its right side."""
    n = q.size
    # z(a q) = a z(q): pivot on q / max|q| so the ratio and tie tests, whose tolerances are
    # absolute below 1, see every entry of q at its relative size (a contact approaching at
    # 3e-11 m/s beside one at 1.6e-3 m/s was otherwise left out, its w below 0).
    unit = float(np.abs(q).max())
    # Tableau of  w - M z - d z0 = q:  columns w (0..n-1), z (n..2n-1), z0 (2n), right side (2n+1).
    # Its first n columns are always the basis inverse (the start basis is w, the identity).
    T = np.hstack([np.eye(n), -M, -d[:, None], q[:, None] / unit])
    return T, np.arange(n, dtype=np.int64), unit  # the basis: the variable held in each row


def _path(T: np.ndarray, basis: np.ndarray, d: np.ndarray, limit: int, pivot_tol: float) -> tuple[str, int]:
    """Lemke's path on the tableau ``T`` (n, 2 n + 2) from the basis ``basis`` (n,) of
    :func:`_lemke`, covering ``d`` (n,): both changed in place to its end; how it ended
    ("solved", "ray" or "iterations") and the pivots made."""
    n = basis.size
    z0, rhs = 2 * n, 2 * n + 1
    # First pivot: z0 enters at the row where q_i / d_i is (lexicographically) smallest.
    row = _lex_min_row(T, np.arange(n), d, n, rhs)
    _pivot(T, row, z0)
    leaving, basis[row] = basis[row], z0
    pivots = 1
    while True:
        entering = leaving + n if leaving < n else leaving - n  # the complement of what left
        column = T[:, entering]
        top = np.abs(column).max()
        rows = np.flatnonzero(column > pivot_tol * top) if top > 0.0 else np.empty(0, int)
        if rows.size == 0:
            return "ray", pivots
        if pivots >= limit:
            return "iterations", pivots
        row = _lex_min_row(T, rows, column[rows], n, rhs, prefer=np.flatnonzero(basis == z0))
        _pivot(T, row, entering)
        leaving, basis[row] = basis[row], entering
        pivots += 1
        if leaving == z0:
            return "solved", pivots


@functools.cache
def _compiled_path() -> Walk | None:
    """:func:`_path` compiled (``fb_lemke`` of the runtime library: the same pivots, bit for
    bit, a few microseconds each instead of ~90), or None where the library cannot be built
    (no C compiler): then :func:`_path` runs."""
    from . import cbuild, runtime  # here: the module itself is NumPy's alone

    try:
        lemke = runtime.library().fb_lemke
    except cbuild.CompilationError:
        return None
    ends = {LEMKE_SOLVED: "solved", LEMKE_RAY: "ray", LEMKE_LIMIT: "iterations"}

    def path(T: np.ndarray, basis: np.ndarray, d: np.ndarray, limit: int, pivot_tol: float) -> tuple[str, int]:
        n = basis.size
        d = np.ascontiguousarray(d, dtype=float)
        pivots = ctypes.c_int(0)
        work, iwork = np.empty(5 * n + 2), np.empty(3 * n, np.intc)
        end = lemke(n, T.ctypes.data, basis.ctypes.data, d.ctypes.data, int(limit), float(pivot_tol), TIE_TOL,
                    ctypes.byref(pivots), work.ctypes.data, iwork.ctypes.data)
        return ends[end], pivots.value

    return path


def _checked(M, q, covering) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``M``, ``q`` and the covering vector as float arrays, or one ValueError that says why."""
    M = np.asarray(M, dtype=float)
    q = np.asarray(q, dtype=float)
    if M.ndim != 2 or M.shape[0] != M.shape[1]:
        raise ValueError(f"`M` must be a square matrix, got shape {M.shape}.")
    if q.shape != (M.shape[0],):
        raise ValueError(f"`q` must have shape ({M.shape[0]},) to match `M`, got shape {q.shape}.")
    if not (np.all(np.isfinite(M)) and np.all(np.isfinite(q))):
        raise ValueError("`M` and `q` must be finite (found inf or nan).")
    d = np.ones_like(q) if covering is None else np.asarray(covering, dtype=float)
    if d.shape != q.shape or not np.all(d > 0.0) or not np.all(np.isfinite(d)):
        raise ValueError(f"`covering` must have shape {q.shape} with finite entries > 0, got {d!r}.")
    return M, q, d


def _lex_min_row(T: np.ndarray, rows: np.ndarray, a: np.ndarray, n: int, rhs: int,
                 prefer: np.ndarray | None = None) -> int:
    """The row among ``rows`` whose ``(b_i, (B^-1)_i) / a_i`` is lexicographically smallest.

    ``a`` (shape ``(len(rows),)``, > 0) are the divisors.  Ties in the first component (a
    degenerate step) are broken by the basis inverse's rows, except that a row in ``prefer``
    (the one holding ``z0``) wins a first-component tie at once: letting ``z0`` leave there
    ends the path on a solution.  Rows tie in a component as :func:`_tied` judges: in the
    tableau's units, which do not change when the entering variable is scaled (its column
    ``a`` by ``c``, the keys by ``1 / c``).
    """
    alive = np.arange(rows.size)
    for k, column in enumerate((rhs, *range(n))):
        # each component for the rows still tied only: after the first, usually one row is left
        entries = T[rows[alive], column]
        alive = alive[_tied(entries / a[alive], entries, a[alive])]
        if k == 0 and prefer is not None and prefer.size:
            hit = np.flatnonzero((rows[alive, None] == prefer[None, :]).any(axis=1))
            if hit.size:
                return int(rows[alive[hit[0]]])
        if alive.size == 1:
            break
    return int(rows[alive[0]])  # several left only if B^-1 lost rank to rounding


def _tied(keys: np.ndarray, entries: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The rows that tie with the lowest of ``keys`` (k,) in one component of the ratio
    test, as indices into ``keys`` (the lowest among them): their ``entries`` (k,) in that
    column over the divisors ``a`` (k,, > 0) are the keys.

    Pivoting on row i leaves row j's entry at ``a_j (key_j - key_i)``: row i ties where that
    is at most :data:`TIE_TOL` (of the largest ``|entry|``, at least 1) below 0 for every j,
    the lowest row's too.  (A tolerance on the keys themselves scales with 1 / a: a
    frictional LCP's rows with a ~ 3e3..3e6 tied at keys ~8e-11 apart, and z0 left with
    basic values 1e-6 below 0; a row with a ~ 1e-9 and an entry ~1e-13 has a key far off,
    yet passes a test of its own entry alone.)
    """
    tol = TIE_TOL * max(1.0, np.abs(entries).max())
    lowest = int(np.argmin(keys))
    near = np.flatnonzero(a[lowest] * (keys - keys[lowest]) <= tol)
    if near.size > 1:  # each of these against every row it would push below 0 (the lowest: none)
        near = near[((keys[near, None] - keys[None, :]) * a).max(axis=1) <= tol]
    return near


def _pivot(T: np.ndarray, row: int, col: int) -> None:
    """Gauss-Jordan pivot of the tableau ``T`` in place on entry ``(row, col)``."""
    T[row] /= T[row, col]
    factors = T[:, col].copy()
    factors[row] = 0.0
    T -= np.outer(factors, T[row])
    T[:, col] = 0.0
    T[row, col] = 1.0


def _finish(M: np.ndarray, q: np.ndarray, T: np.ndarray, basis: np.ndarray, status: str, pivots: int,
            check_tol: float, unit: float, message: str, d: np.ndarray | None = None) -> LcpSolution:
    """Read ``z`` off the final basis (its right side is in units of ``unit``), polish it,
    check it and wrap it up.

    A path that ends on a ray or at the pivot limit (covering vector ``d``) has its last
    point checked where ``d z0`` is at the rounding level: that point solves ``LCP(M, q +
    d z0)``, in rounding the problem asked (a fuzz's plastic frictional impact, 72 rows of
    redundant contacts: its path stalled at ``z0 = 2.7e-13``, the rounding level 1.1e-12,
    then met a column with no positive entry, where in exact arithmetic it has none).
    """
    n = q.size
    values = np.zeros(2 * n + 1)
    values[basis] = T[:, -1] * unit
    z = values[n:2 * n]
    if status != "solved" and d is not None and values[2 * n] * d.max() <= _rounding_floor(M, q, z):
        ended = "secondary ray" if status == "ray" else "pivot limit"
        last = _complementary(M, q, z, pivots, check_tol, f"solved by the last point of the path (z0 = "
                              f"{values[2 * n]:.2g}), which ended on a {ended} after {pivots} pivots.")
        if last.solved:
            return last
    if status != "solved":
        return LcpSolution(z, M @ z + q, status, pivots, message)
    return _complementary(M, q, z, pivots, check_tol, message)


def _complementary(M: np.ndarray, q: np.ndarray, z: np.ndarray, pivots: int, check_tol: float,
                   message: str) -> LcpSolution:
    """The basic values ``z`` (n,) of a complementary basis, rounding removed, checked and
    wrapped up (status ``"solved"`` or ``"inaccurate"``)."""
    n = q.size
    floor = _rounding_floor(M, q, z)
    raw = np.maximum(z, 0.0)
    z = np.where(z > floor, z, 0.0)
    # The basic z solve M_SS z_S = -q_S exactly: re-solving this small system removes the
    # rounding the pivots accumulated (order independence to 1e-12 depends on it).
    S = np.flatnonzero(z > 0.0)
    if S.size:
        try:
            polished = np.linalg.solve(M[np.ix_(S, S)], -q[S])
        except np.linalg.LinAlgError:
            polished = None
        if polished is not None and np.all(polished >= 0.0):
            z = np.zeros(n)
            z[S] = polished
    checked = _checked_solution(M, q, z, pivots, check_tol, floor, message)
    if checked.solved:
        return checked
    # The floor is a rate, z an impulse: a small impulse on a stiff row can be needed (a
    # contact approaching at 1.7e-12 m/s with W_ii = 41 takes 4.2e-14, below the floor
    # 1.1e-12, and without it its row fails the check).  The pivots' own values may pass.
    unpolished = _checked_solution(M, q, raw, pivots, check_tol, floor, message)
    return unpolished if unpolished.solved else checked


def _rounding_floor(M: np.ndarray, q: np.ndarray, z: np.ndarray) -> float:
    """The rounding level of ``LCP(M, q)`` at ``z`` (n,): a degenerate basic variable
    (exactly 0 in exact arithmetic) comes out as +-1e-16, and a row with small entries
    cannot resolve less."""
    return 16 * q.size * np.finfo(float).eps * (np.abs(M).max() * np.abs(z).max() + np.abs(q).max())


def _checked_solution(M: np.ndarray, q: np.ndarray, z: np.ndarray, pivots: int, check_tol: float,
                      floor: float, message: str) -> LcpSolution:
    """``z`` (n,) checked for feasibility and complementarity (see :func:`solve_lcp`'s
    ``check_tol``; ``floor``: the problem's rounding level) and wrapped up."""
    w = M @ z + q
    scale = check_tol * (np.abs(M) @ z + np.abs(q)) + floor
    infeasible = np.maximum(-w - scale, 0.0).max()
    gap = np.where(z > 0.0, np.maximum(np.abs(w) - scale, 0.0), 0.0).max()
    if infeasible > 0.0 or gap > 0.0:
        return LcpSolution(z, w, "inaccurate", pivots,
                           f"{message[:-1]}, but the check fails: w below 0 by {infeasible:.3g} "
                           f"beyond tolerance, complementarity off by {gap:.3g}.")
    return LcpSolution(z, w, "solved", pivots, message)


#: Largest problem :func:`solve_pd_lcp` takes: its pivot bound 2^n is then still small, and
#: a larger block is rare enough for Lemke's method.
PD_LARGEST = 12
#: ... and the smallest eigenvalue it takes, relative to the largest: a nearly redundant
#: contact (a nearly singular M) is left to Lemke's method.
PD_CONDITION = 1e-8


def solve_pd_lcp(M: np.ndarray, q: np.ndarray, *, check_tol: float = CHECK_TOL) -> LcpSolution | None:
    """Solve ``LCP(M, q)`` for a symmetric positive definite ``M`` by Murty's least-index
    principal pivoting; None when ``M`` is not one, is nearly singular (:data:`PD_CONDITION`)
    or ``n >`` :data:`PD_LARGEST`, for :func:`solve_lcp` to take.

    Each complementary basis is a set ``S`` of positive unknowns: ``z_S`` solves ``M_SS z_S
    = -q_S``, ``z = 0`` elsewhere.  While some ``i`` is infeasible (``z_i < 0`` in ``S``, or
    ``w_i < 0`` outside it), the *least* such ``i`` changes side.  For a P-matrix this visits
    no basis twice and ends on the unique solution (Murty, "Note on a Bard-type scheme for
    solving the complementarity problem", Opsearch 11, 1974; Cottle, Pang & Stone, §4.2), so
    within ``2^n`` pivots; the start is ``S = {i : q_i < 0}``, right at once when every
    pressed contact stays pressed (most of a pile's blocks).  Infeasibility below the
    rounding level does not count; the answer passes the same check as Lemke's.

    Parameters
    ----------
    M : array_like, shape (n, n)
    q : array_like, shape (n,)

    Returns
    -------
    LcpSolution or None
        ``pivots`` counts the side changes.
    """
    M, q, _ = _checked(M, q, None)
    n = q.size
    if np.all(q >= 0.0):
        return LcpSolution(np.zeros(n), q.copy(), "solved", 0, "q >= 0: z = 0 with no pivots.")
    if n > PD_LARGEST or np.abs(M - M.T).max() > TIE_TOL * np.abs(M).max():
        return None
    eigenvalues = np.linalg.eigvalsh(M)  # every M_SS's smallest is at least M's (interlacing)
    if eigenvalues[0] <= PD_CONDITION * eigenvalues[-1]:
        return None
    S = q < 0.0
    for pivots in range(2**n):
        z = np.zeros(n)
        z[S] = np.linalg.solve(M[np.ix_(S, S)], -q[S])
        w = M @ z + q
        floor = _rounding_floor(M, q, z)
        infeasible = np.flatnonzero(np.where(S, z, w) < -floor)
        if not infeasible.size:
            z = np.maximum(z, 0.0)
            return _checked_solution(M, q, z, pivots, check_tol, floor,
                                     f"solved by principal pivoting in {pivots} pivots.")
        S[infeasible[0]] = ~S[infeasible[0]]
    return None  # rounding broke the P-matrix bound: Lemke's method decides
