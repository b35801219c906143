"""Lemke's method (flexbody.lcp) and the contact problems built on it (flexbody.contact_problems).

References are independent of the code under test: brute-force enumeration of complementary
bases, a linear program for feasibility, closed forms derived by hand in the comments.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog

import flexbody.lcp
from flexbody.contact_problems import (
    delassus,
    is_decoupled,
    solve_forces,
    solve_forces_friction,
    solve_impact,
    solve_impact_friction,
    velocity_change,
)
from flexbody.lcp import solve_lcp, solve_pd_lcp

from .conftest import HAS_CC


def brute_force(M, q):
    """Every basic solution of LCP(M, q): for each index set S with M_SS invertible,
    z_S = -M_SS^-1 q_S, z = 0 elsewhere, kept when z >= 0 and w = M z + q >= 0."""
    n = q.size
    found = []
    scale = 1e-9 * (np.abs(M).sum() + np.abs(q).sum() + 1.0)
    for k in range(n + 1):
        for S in itertools.combinations(range(n), k):
            S = list(S)
            z = np.zeros(n)
            if S:
                block = M[np.ix_(S, S)]
                if np.linalg.cond(block) > 1e10:
                    continue
                z[S] = np.linalg.solve(block, -q[S])
            w = M @ z + q
            if z.min() >= -scale and w.min() >= -scale:
                found.append((z, w))
    return found


def feasible(M, q):
    """Is there z >= 0 with M z + q >= 0?  (a linear program; for copositive-plus M this is
    equivalent to LCP(M, q) having a solution, Lemke's theorem)."""
    n = q.size
    res = linprog(np.zeros(n), A_ub=-M, b_ub=q, bounds=[(0, None)] * n, method="highs")
    return res.status == 0


def random_p_matrix(rng, n):
    """Positive definite (not necessarily symmetric) or strictly row-diagonally dominant with a
    positive diagonal: both are P-matrices."""
    kind = rng.integers(3)
    A = rng.normal(size=(n, n))
    if kind == 0:
        return A @ A.T + 0.05 * np.eye(n)  # symmetric positive definite (a Delassus matrix)
    if kind == 1:
        return A @ A.T + 0.05 * np.eye(n) + (A - A.T)  # positive definite + skew: x^T M x > 0
    M = rng.normal(size=(n, n))
    np.fill_diagonal(M, np.abs(M).sum(axis=1) + rng.uniform(0.1, 1.0, n))
    return M


def assert_solves(sol, M, q, tol=1e-9):
    assert sol.status == "solved", sol.message
    scale = tol * (np.abs(M) @ np.abs(sol.z) + np.abs(q) + 1e-300)
    assert np.all(sol.z >= 0.0)
    np.testing.assert_allclose(sol.w, M @ sol.z + q, rtol=0, atol=1e-12 * (1 + np.abs(q).max()))
    assert np.all(sol.w >= -scale)
    assert np.all(np.abs(sol.w * sol.z) <= scale * np.maximum(sol.z, 1.0))


# --- Lemke against references -------------------------------------------------------------


@pytest.mark.parametrize("n", range(1, 9))
def test_p_matrix_unique_solution_equals_brute_force(n):
    rng = np.random.default_rng(100 + n)
    for _ in range(25 if n <= 6 else 6):
        M = random_p_matrix(rng, n)
        q = rng.normal(size=n)
        sol = solve_lcp(M, q)
        assert_solves(sol, M, q)
        found = brute_force(M, q)
        assert len(found) == 1  # a P-matrix: exactly one solution (checks the reference too)
        np.testing.assert_allclose(sol.z, found[0][0], rtol=1e-9, atol=1e-10)


@pytest.mark.parametrize("n", range(1, 9))
def test_principal_pivoting_equals_brute_force_on_positive_definite_matrices(n):
    """Murty's method on symmetric positive definite W (Delassus matrices) against every
    complementary basis, with every row order giving the same (permuted) answer; the starts
    are often wrong (q random), so its pivots are exercised, not only the first solve."""
    rng = np.random.default_rng(300 + n)
    pivoted = 0
    for _ in range(25 if n <= 6 else 6):
        A = rng.normal(size=(n, n + 1))
        M, q = A @ A.T + 0.01 * np.eye(n), rng.normal(size=n)
        sol = solve_pd_lcp(M, q)
        assert_solves(sol, M, q)
        np.testing.assert_allclose(sol.z, brute_force(M, q)[0][0], rtol=1e-9, atol=1e-10)
        order = rng.permutation(n)
        again = solve_pd_lcp(M[np.ix_(order, order)], q[order])
        np.testing.assert_allclose(again.z, sol.z[order], rtol=1e-12, atol=1e-14)
        pivoted += sol.pivots > 0
    assert n == 1 or pivoted  # some start was wrong and was pivoted out of


def test_principal_pivoting_leaves_a_contact_that_would_pull_by_hand():
    """W = [[2, 1], [1, 2]], q = [-1, -0.1]: holding both needs z = W^-1 (1, 0.1) = (0.633,
    -0.267), a pull; one pivot frees the second: z = (0.5, 0), w_2 = 0.5 - 0.1 = 0.4."""
    sol = solve_pd_lcp(np.array([[2.0, 1.0], [1.0, 2.0]]), np.array([-1.0, -0.1]))
    assert sol.solved and sol.pivots == 1
    np.testing.assert_allclose(sol.z, [0.5, 0.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(sol.w, [0.0, 0.4], rtol=0, atol=1e-15)


@pytest.mark.parametrize("M", [
    [[1.0, 1.0], [1.0, 1.0]],  # redundant contacts: semidefinite, Lemke's method decides
    [[1.0, 2.0], [0.0, 1.0]],  # a P-matrix, but not symmetric
    [[1.0, 2.0], [2.0, 1.0]],  # indefinite
])
def test_principal_pivoting_refuses_what_it_does_not_cover(M):
    assert solve_pd_lcp(np.array(M), np.array([-1.0, -1.0])) is None


def test_trivial_q_nonnegative_needs_no_pivot():
    M = np.array([[2.0, 1.0], [1.0, 2.0]])
    sol = solve_lcp(M, [0.0, 3.0])
    assert sol.status == "solved" and sol.pivots == 0
    np.testing.assert_array_equal(sol.z, [0.0, 0.0])


@pytest.mark.parametrize("seed", range(40))
def test_symmetric_psd_w_unique_or_ray_when_infeasible(seed):
    # M = A A^T with rank k < n: positive semidefinite, singular (redundant contacts).
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 7))
    A = rng.normal(size=(n, int(rng.integers(1, n))))
    M = A @ A.T
    q = rng.normal(size=n)
    sol = solve_lcp(M, q)
    if not feasible(M, q):
        assert sol.status == "ray"
        return
    assert_solves(sol, M, q)
    found = brute_force(M, q)
    assert found  # Lemke's final basis is one of them
    for _, w in found:  # z may differ between solutions; w may not
        np.testing.assert_allclose(sol.w, w, rtol=1e-8, atol=1e-9)


def test_psd_infeasible_ends_on_a_ray():
    # w1 = z1 - z2 - 1, w2 = -z1 + z2 - 1: w1 + w2 = -2 < 0 for every z, infeasible.
    M = np.array([[1.0, -1.0], [-1.0, 1.0]])
    sol = solve_lcp(M, [-1.0, -1.0])
    assert sol.status == "ray" and not sol.solved


@pytest.mark.parametrize("seed", range(30))
def test_degenerate_problems_terminate_with_a_valid_solution(seed):
    # Small integer data: q with zeros and ties, repeated rows of M (a repeated contact).
    rng = np.random.default_rng(1000 + seed)
    n = int(rng.integers(2, 7))
    A = rng.integers(-2, 3, size=(n, n)).astype(float)
    M = A @ A.T + np.eye(n)
    q = rng.integers(-2, 2, size=n).astype(float)
    if seed % 2:  # duplicate the first contact: rows/cols 0 and 1 equal, M singular PSD
        J = rng.integers(-2, 3, size=(n, 3)).astype(float)
        J[1] = J[0]
        M = J @ J.T
        q[1] = q[0]
    sol = solve_lcp(M, q)
    if not feasible(M, q):
        assert sol.status == "ray"
        return
    assert_solves(sol, M, q)
    for _, w in brute_force(M, q):
        np.testing.assert_allclose(sol.w, w, atol=1e-9)


#: Seeds of small integer problems (general M, degenerate q) on which Lemke's method with a
#: plain minimum-ratio test, ties broken by the last row, cycles forever (found by a search).
CYCLING_SEEDS = [39, 127, 592, 943, 1174, 2830]


def integer_problem(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 6))
    return rng.integers(-2, 3, size=(n, n)).astype(float), rng.integers(-1, 2, size=n).astype(float)


def _numpy_pivots(monkeypatch):
    """Lemke's path in NumPy (:func:`flexbody.lcp._path`), whose ratio test a test swaps:
    the compiled one, the same path bit for bit, does not see the swap."""
    monkeypatch.setattr(flexbody.lcp, "_compiled_path", lambda: None)


def _reference_problems():
    """The saved LCPs of fuzzed scenes (frictional, redundant, tied) and the integer problems
    with degenerate q (the cycling seeds and 120 more): (name, M, q)."""
    saved = sorted((Path(__file__).parent / "reference").glob("lcp_*.npz"))
    out = [(path.stem, np.load(path)["M"], np.load(path)["q"]) for path in saved]
    return out + [(f"integer {seed}", *integer_problem(seed)) for seed in CYCLING_SEEDS + list(range(120))]


@pytest.mark.skipif(not HAS_CC, reason="needs a C compiler")
def test_the_compiled_path_is_the_numpy_path_bit_for_bit():
    """``fb_lemke`` (generated/runtime/lcp.c) against :func:`flexbody.lcp._path` from the
    same start: the same end, the same pivot count, the same final tableau and basis, bit
    for bit (signed zeros too), from the covering vector of ones and from three of
    :func:`flexbody.lcp.solve_lcp`'s others, run to the end and stopped by a pivot limit of 5.
    It fails if one operation differs in order or rounding (a ratio test's tie judged on
    another quantity ends the saved friction row's path elsewhere, see above)."""
    compiled = flexbody.lcp._compiled_path()
    assert compiled is not None
    ends, checked = set(), 0
    for name, M, q in _reference_problems():
        if np.all(q >= 0.0):
            continue
        for seed in (None, 0, 1, 2):
            d = np.ones(q.size) if seed is None else np.random.default_rng(seed).uniform(0.5, 2.0, q.size)
            for limit in (100 * (q.size + 1), 5):
                T, basis, _ = flexbody.lcp._start(M, q, d)
                T_c, basis_c, _ = flexbody.lcp._start(M, q, d)
                end = flexbody.lcp._path(T, basis, d, limit, flexbody.lcp.PIVOT_TOL)
                assert compiled(T_c, basis_c, d, limit, flexbody.lcp.PIVOT_TOL) == end, (name, seed, limit)
                assert T_c.tobytes() == T.tobytes() and np.array_equal(basis_c, basis), (name, seed, limit)
                ends.add(end[0])
                checked += 1
    assert ends == {"solved", "ray", "iterations"} and checked > 400


def _naive_tie_break(T, rows, a, n, rhs, prefer=None):
    """Minimum ratio of the right-hand side only; ties to the last row (no lexicographic rule)."""
    ratio = T[rows, rhs] / a
    tied = rows[ratio <= ratio.min() + 1e-12]
    if prefer is not None and prefer.size and np.isin(prefer, tied).any():
        return int(prefer[0])
    return int(tied[-1])


@pytest.mark.parametrize("seed", CYCLING_SEEDS)
def test_lexicographic_rule_ends_where_a_naive_tie_break_cycles(seed, monkeypatch):
    M, q = integer_problem(seed)
    sol = solve_lcp(M, q)
    assert sol.status in ("solved", "ray")  # cycling would end at the pivot limit: "iterations"
    if sol.status == "solved":
        assert_solves(sol, M, q)
    else:  # M is not copositive-plus, so a ray proves nothing; but no basic solution exists here
        assert not brute_force(M, q)
    _numpy_pivots(monkeypatch)
    monkeypatch.setattr(flexbody.lcp, "_lex_min_row", _naive_tie_break)
    monkeypatch.setattr(flexbody.lcp, "COVERINGS", 0)  # (other covering vectors break the ties)
    monkeypatch.setattr(flexbody.lcp, "SEARCH_LARGEST", 0)  # (the mixed-integer search solves it)
    assert solve_lcp(M, q, max_pivots=500).status == "iterations"  # the same path without the rule cycles


def _key_tolerance_ties(keys, entries, a):
    """The ratio test's ties as judged on the keys themselves (this module's rule until the
    friction row's LCP below): rows whose keys are within 1e-12 of the lowest (of the
    largest key, at least 1), whatever their divisors ``a``."""
    return np.flatnonzero(keys <= keys.min() + 1e-12 * max(1.0, np.abs(keys).max()))


def test_rows_tie_only_where_pivoting_on_either_leaves_the_other_at_most_rounding_below_zero(monkeypatch):
    """Two rows of a large entering column (a = 3e3 and 3e6) whose keys b / a are 1e-13
    apart: pivoting on the second leaves the first's basic value at 3e3 * -1e-13 = -3e-10,
    not a rounding-level tie, however close the keys.  The first is the minimum; the second
    (holding z0, preferred in a tie) won when the keys were compared to 1e-12.  Scaling the
    column (the entering variable) does not change the choice; a row with a tiny divisor
    and a tiny entry (a key far above the minimum) does not tie either."""
    n, rhs = 3, 3
    a = np.array([3e3, 3e6, 1e-9])
    keys = np.array([1e-10, 1e-10 + 1e-13, 1e-4])
    T = np.zeros((n, n + 1))
    T[:, :n] = np.eye(n)[::-1]  # the basis inverse's rows favour the last rows in a tie
    T[:, rhs] = keys * a
    rows, prefer = np.arange(n), np.array([1])
    for scale in (1.0, 1e-6, 1e6):
        assert flexbody.lcp._lex_min_row(T, rows, scale * a, n, rhs, prefer=prefer) == 0
    T[:, rhs] = [3e-7, 3e-7 * (1.0 + 1e-14), 1e-13]  # within 1e-12 of 3e-7 below 0 either way: a tie
    assert flexbody.lcp._lex_min_row(T, rows, np.array([3e3, 3e3 * (1 + 1e-14), 1e-9]), n, rhs,
                                     prefer=prefer) == 1
    T[:, rhs] = keys * a
    _numpy_pivots(monkeypatch)
    monkeypatch.setattr(flexbody.lcp, "_tied", _key_tolerance_ties)
    assert flexbody.lcp._lex_min_row(T, rows, a, n, rhs, prefer=prefer) == 1


def test_a_frictional_lcp_whose_keys_tied_across_large_divisors_ends_at_rounding_level(monkeypatch):
    """The frictional force LCP of 17 held rows of three flexible boxes in a row
    (tests/reference/fuzz_friction_row_near_tie.json at t = 0.000745 s; 77 rows with the
    polygonal cone's; W_nn's smallest eigenvalue 1.6e-8 of its largest, two pairs of nearly
    redundant vertex rows).  Lemke's path in exact rational arithmetic ends on a solution
    after 54 pivots.  With keys compared to 1e-12, rows 12 and 16 (a = 78, keys 5.7e-9
    apart relative) tied at pivot 5, and at pivot 28 46 rows tied at keys ~8e-11 with
    divisors up to 2.9e6, z0 among them: it left with basic values 1.4e-6 below 0, which
    set to 0 left a normal row 1.06e-4 off complementarity.  Now every normal row holds to
    rounding, and no row is off by more than 1e-11 of max |q| (309): a friction row left
    at -5.5e-10 by later ties at the tie tolerance (1e-12 of max |q| per tie), beyond the
    row-wise check ("inaccurate") but not Signorini's law, which the driver checks."""
    data = np.load(Path(__file__).parent / "reference" / "lcp_friction_row_tie.npz")
    M, q = data["M"], data["q"]
    normal, scale = np.arange(17), np.abs(q).max()
    sol = solve_lcp(M, q)
    assert np.all(sol.z >= 0.0)
    assert sol.w.min() >= -1e-11 * scale and np.abs(sol.w * sol.z).max() <= 1e-11 * scale * sol.z.max()
    assert np.abs(sol.w[normal][sol.z[normal] > 0.0]).max() <= 1e-13 * scale
    assert sol.w[normal].min() >= -1e-13 * scale
    _numpy_pivots(monkeypatch)
    monkeypatch.setattr(flexbody.lcp, "_tied", _key_tolerance_ties)
    monkeypatch.setattr(flexbody.lcp, "SEARCH_LARGEST", 0)  # the path's own answer (the search finds a better one)
    before = solve_lcp(M, q)
    assert np.abs(before.w * before.z).max() > 1e-5 * before.z.max()  # measured 1.06e-4 * 3.95


def test_all_zero_q_and_tied_q_rows():
    # q = 0 is solved by z = 0; q = -1 everywhere with an identity-like M ties every first ratio.
    M = np.array([[2.0, 1.0, 1.0], [1.0, 2.0, 1.0], [1.0, 1.0, 2.0]])
    assert solve_lcp(M, np.zeros(3)).pivots == 0
    sol = solve_lcp(M, -np.ones(3))
    assert_solves(sol, M, -np.ones(3))
    np.testing.assert_allclose(sol.z, np.full(3, 0.25), rtol=1e-12)  # 4 z = 1 by symmetry


@pytest.mark.parametrize("seed", range(20))
def test_permuting_the_rows_permutes_the_solution(seed):
    rng = np.random.default_rng(2000 + seed)
    n = int(rng.integers(2, 9))
    M = random_p_matrix(rng, n)
    q = rng.normal(size=n)
    perm = rng.permutation(n)
    a = solve_lcp(M, q)
    b = solve_lcp(M[np.ix_(perm, perm)], q[perm])
    np.testing.assert_allclose(b.z, a.z[perm], rtol=0, atol=1e-12 * (1 + np.abs(a.z).max()))


def test_pivot_limit_gives_iterations_status(monkeypatch):
    rng = np.random.default_rng(7)
    M = random_p_matrix(rng, 6)
    q = -np.abs(rng.normal(size=6)) - 1.0
    full = solve_lcp(M, q)
    assert full.pivots > 2
    monkeypatch.setattr(flexbody.lcp, "SEARCH_LARGEST", 0)  # (the mixed-integer search would solve it)
    short = solve_lcp(M, q, max_pivots=2)
    assert short.status == "iterations"


@pytest.mark.parametrize(
    ("M", "q", "match"),
    [
        (np.ones((2, 3)), np.ones(2), "`M` must be a square"),
        (np.eye(2), np.ones(3), "`q` must have shape"),
        (np.eye(2), np.array([np.nan, 1.0]), "finite"),
    ],
)
def test_bad_arguments_are_named(M, q, match):
    with pytest.raises(ValueError, match=match):
        solve_lcp(M, q)


# --- contact problems ---------------------------------------------------------------------

G = 9.81


def bar(m=2.0, L=1.0, ends=(-0.5, 0.5), inertia=None):
    """A flat rigid bar in coordinates u = (y, theta) of its centre of mass: contact rows
    [1, d] for supports at horizontal offsets d from the centre (small angle: gap = y + d theta).
    Returns (J, M)."""
    inertia = m * L**2 / 12 if inertia is None else inertia
    J = np.array([[1.0, d] for d in ends])
    return J, np.diag([m, inertia])


def test_bar_delassus_by_hand():
    # W_ii = 1/m + (L/2)^2 12/(m L^2) = 4/m;  W_12 = 1/m - 3/m = -2/m.
    m, L = 2.0, 1.0
    W = delassus(*bar(m, L, (-L / 2, L / 2)))
    np.testing.assert_allclose(W, np.array([[4.0, -2.0], [-2.0, 4.0]]) / m, rtol=1e-14)
    assert not is_decoupled(W)


@pytest.mark.parametrize("e", [0.0, 0.5])
def test_bar_flat_landing_both_ends(e):
    # v1 = v - L w/2, v2 = v + L w/2, both < 0; W P = -(1 + e) v- with W^-1 = m/12 [[4, 2], [2, 4]]:
    #   P1 = -(1 + e) m (v/2 - L w/12),  P2 = -(1 + e) m (v/2 + L w/12).
    m, L, v, w = 2.0, 1.0, -1.0, 0.5
    J, M = bar(m, L, (-L / 2, L / 2))
    u = np.array([v, w])
    sol = solve_impact(delassus(J, M), J @ u, e)
    assert sol.method == "lcp" and sol.solved
    expected = -(1 + e) * m * np.array([v / 2 - L * w / 12, v / 2 + L * w / 12])
    np.testing.assert_allclose(sol.normal, expected, rtol=1e-12)
    np.testing.assert_allclose(sol.normal_rate, -e * (J @ u), rtol=1e-12)
    if e == 0.0:  # a plastic flat landing stops the bar: y' = theta' = 0
        np.testing.assert_allclose(u + velocity_change(J, M, sol.normal), 0.0, atol=1e-14)


@pytest.mark.parametrize("e", [0.0, 0.5])
def test_bar_landing_on_one_end_the_other_separates(e):
    # w = 20: v1 = -11, v2 = +9.  Only end 1 takes impulse: P1 = -(1 + e) v1 / W11 = -(1 + e) m v1 / 4;
    # end 2 then moves at v2 + W21 P1 = v2 + (1 + e) v1 / 2 = 3.5 (e = 0), 0.75 (e = 0.5): >= 0, consistent.
    m, L, v, w = 2.0, 1.0, -1.0, 20.0
    J, M = bar(m, L, (-L / 2, L / 2))
    v1, v2 = J @ np.array([v, w])
    sol = solve_impact(delassus(J, M), [v1, v2], e)
    np.testing.assert_allclose(sol.normal, [-(1 + e) * m * v1 / 4, 0.0], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(sol.normal_rate, [-e * v1, v2 + (1 + e) * v1 / 2], rtol=1e-12)


def test_bar_separating_end_is_pushed_into_the_ground_and_takes_impulse():
    # w = 10, e = 0.5: v1 = -6, v2 = +4.  End 1 alone (P1 = 4.5) would leave v2+ = 4 - 1.5 * 6 / 2 = -0.5:
    # end 2 must take impulse too, with v2+ = 0 (it does not approach, so no restitution):
    # q = [(1 + e) v1, v2] = [-9, 4], P = -W^-1 q = -(m/12) [[4, 2], [2, 4]] q = [14/3, 1/3].
    m, L = 2.0, 1.0
    J, M = bar(m, L, (-L / 2, L / 2))
    sol = solve_impact(delassus(J, M), J @ np.array([-1.0, 10.0]), 0.5)
    np.testing.assert_allclose(sol.normal, [14 / 3, 1 / 3], rtol=1e-12)
    np.testing.assert_allclose(sol.normal_rate, [3.0, 0.0], atol=1e-12)


def test_newton_law_can_add_energy_when_a_separating_contact_is_pushed():
    # Same bar, w = 10, e = 1: q = [2 v1, v2] = [-12, 4], P = -(m/12) [[4, 2], [2, 4]] q = [20/3, 4/3],
    # u+ = u + M^-1 J^T P = (-1, 10) + (8/2, (-20/6 + 4/6) 6) = (3, -6).  Kinetic energy
    # (m y'^2 + I theta'^2)/2 with m = 2, I = 1/6: before (2 + 100/6)/2 = 28/3, after (18 + 6)/2 = 12.
    J, M = bar(2.0, 1.0, (-0.5, 0.5))
    u = np.array([-1.0, 10.0])
    sol = solve_impact(delassus(J, M), J @ u, 1.0)
    np.testing.assert_allclose(sol.normal, [20 / 3, 4 / 3], rtol=1e-12)
    after = u + velocity_change(J, M, sol.normal)
    np.testing.assert_allclose(after, [3.0, -6.0], rtol=1e-12)
    np.testing.assert_allclose([u @ M @ u / 2, after @ M @ after / 2], [28 / 3, 12.0], rtol=1e-12)


@pytest.mark.parametrize("seed", range(30))
def test_newton_law_energy_where_it_is_consistent(seed):
    # dKE = -(1 - e)/(2 (1 + e)) P^T W P when every contact taking impulse approaches with one e,
    # and dKE = -P^T W P / 2 for e = 0 whatever the contacts do (see the module docstring).
    rng = np.random.default_rng(6000 + seed)
    nc = int(rng.integers(1, 4))
    J, M = rigid_body_on_ground(rng, nc)
    J = J[:nc]  # normal rows only
    u = rng.normal(size=3) - [0.0, 2.0, 0.0]
    e = 0.0 if seed % 3 == 0 else rng.uniform(0, 1)
    W = delassus(J, M)
    sol = solve_impact(W, J @ u, e)
    after = u + velocity_change(J, M, sol.normal)
    dke = (after @ M @ after - u @ M @ u) / 2
    P = sol.normal
    if e == 0.0 or np.all((J @ u)[P > 0] < 0):
        np.testing.assert_allclose(dke, -(1 - e) / (2 * (1 + e)) * (P @ W @ P), rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("w", [0.5, 10.0, 20.0])
def test_bar_landing_impulses_independent_of_particle_order(w):
    J, M = bar(2.0, 1.0, (-0.5, 0.5))
    u = np.array([-1.0, w])
    a = solve_impact(delassus(J, M), J @ u, 0.5)
    b = solve_impact(delassus(J[::-1], M), J[::-1] @ u, 0.5)
    np.testing.assert_allclose(b.normal, a.normal[::-1], rtol=0, atol=1e-12)


def test_untouching_contact_takes_no_impulse():
    J, M = bar(2.0, 1.0, (-0.5, 0.5))
    W = delassus(J, M)
    sol = solve_impact(W, [-1.0, -1.0], 0.0, touching=[True, False])
    assert sol.normal[1] == 0.0
    np.testing.assert_allclose(sol.normal[0], 1.0 / W[0, 0], rtol=1e-12)  # P1 = -v1 / W11


@pytest.mark.parametrize("e", [0.0, 1.0, 0.3])
def test_two_equal_particles_head_on(e):
    # Particles on a line, x1 < x2, gap x2 - x1: J = [-1, 1], W = 2/m, v- = v2 - v1.
    # P = -(1 + e) v- / W; v1+ = v1 - P/m, v2+ = v2 + P/m: e = 1 exchanges the velocities,
    # e = 0 leaves both at the common velocity (v1 + v2)/2.
    m, v1, v2 = 0.3, 3.0, -1.0
    J, M = np.array([[-1.0, 1.0]]), m * np.eye(2)
    W = delassus(J, M)
    np.testing.assert_allclose(W, [[2 / m]], rtol=1e-14)
    u = np.array([v1, v2])
    for fast in (True, False):
        sol = solve_impact(W, J @ u, e, fast=fast)
        after = u + velocity_change(J, M, sol.normal)
        np.testing.assert_allclose(sol.normal, [(1 + e) * m * (v1 - v2) / 2], rtol=1e-13)
        np.testing.assert_allclose(after.sum(), v1 + v2, rtol=1e-13)  # momentum
        if e == 1.0:
            np.testing.assert_allclose(after, [v2, v1], rtol=1e-13)
        if e == 0.0:
            np.testing.assert_allclose(after, [(v1 + v2) / 2] * 2, atol=1e-13)


@pytest.mark.parametrize("e", [0.0, 1.0])
def test_three_particle_chain_both_contacts_closed(e):
    # Equal particles in a row, touching (gaps x2 - x1 and x3 - x2), velocities (2, 0, -1):
    # W = (1/m) [[2, -1], [-1, 2]] couples the contacts.  Both take impulse, so v+ = -e v- per contact,
    # and momentum (sum = 1) closes it:  e = 0: all at 1/3;  e = 1: relative velocities (-2, -1) become
    # (2, 1): v1+ = a, v2+ = a + 2, v3+ = a + 3, 3 a + 5 = 1 -> (-4/3, 2/3, 5/3), kinetic energy kept.
    m = 0.2
    J, M = np.array([[-1.0, 1.0, 0.0], [0.0, -1.0, 1.0]]), m * np.eye(3)
    W = delassus(J, M)
    np.testing.assert_allclose(W, np.array([[2.0, -1.0], [-1.0, 2.0]]) / m, rtol=1e-14)
    u = np.array([2.0, 0.0, -1.0])
    sol = solve_impact(W, J @ u, e)
    after = u + velocity_change(J, M, sol.normal)
    expected = [1 / 3] * 3 if e == 0.0 else [-4 / 3, 2 / 3, 5 / 3]
    np.testing.assert_allclose(after, expected, rtol=1e-13)
    if e == 1.0:
        np.testing.assert_allclose(after @ after, u @ u, rtol=1e-13)


@pytest.mark.parametrize("x", [-0.2, 0.0, 0.3])
def test_bar_on_two_supports_forces_equal_statics(x):
    # Supports at the bar's ends +-L/2, centre of mass at x: offsets d = -L/2 - x, L/2 - x.
    # Statics: lam1 + lam2 = m g, lam1 d1 + lam2 d2 = 0  =>  lam1,2 = m g (L/2 -+ x) / L.
    m, L = 1.5, 1.0
    J, M = bar(m, L, (-L / 2 - x, L / 2 - x), inertia=0.07 * m)
    a_free = J @ np.array([-G, 0.0])
    sol = solve_forces(delassus(J, M), a_free)
    assert sol.solved and sol.method == "lcp"
    np.testing.assert_allclose(sol.normal, m * G * np.array([L / 2 - x, L / 2 + x]) / L, rtol=1e-12)
    np.testing.assert_allclose(sol.normal_rate, 0.0, atol=1e-12)


def test_bar_with_centre_beyond_a_support_tips_over():
    # x = 0.7 > L/2: holding both would need lam1 = m g (L/2 - x)/L < 0.  Only support 2 holds:
    # lam2 = g / W22 with W22 = 1/m + d2^2/I, d2 = L/2 - x; support 1 accelerates upward.
    m, L, x, inertia = 1.5, 1.0, 0.7, 0.1
    J, M = bar(m, L, (-L / 2 - x, L / 2 - x), inertia=inertia)
    sol = solve_forces(delassus(J, M), J @ np.array([-G, 0.0]))
    d2 = L / 2 - x
    np.testing.assert_allclose(sol.normal, [0.0, G / (1 / m + d2**2 / inertia)], rtol=1e-12, atol=1e-12)
    assert sol.normal_rate[0] > 0.0 and abs(sol.normal_rate[1]) < 1e-12


@pytest.mark.parametrize("perm", list(itertools.permutations(range(3))))
def test_bar_on_three_collinear_supports_psd(perm):
    # W (3 x 3) has rank 2: the forces are statically indeterminate (lam1 = lam3, lam2 = m g - 2 lam1
    # for a centred bar), Lemke returns one of them; the accelerations (all 0) are unique.  Landing flat
    # with e = 0 stops the bar whatever impulses are chosen: u+ = 0, total impulse = -m v.
    m, L = 2.0, 1.0
    J, M = bar(m, L, (-L / 2, 0.0, L / 2))
    J = J[list(perm)]
    W = delassus(J, M)
    assert np.linalg.matrix_rank(W) == 2
    forces = solve_forces(W, J @ np.array([-G, 0.0]))
    assert forces.solved
    np.testing.assert_allclose(forces.normal_rate, 0.0, atol=1e-12)
    np.testing.assert_allclose(J.T @ forces.normal, [m * G, 0.0], atol=1e-12)  # force and moment balance
    assert np.all(forces.normal >= 0.0)
    u = np.array([-1.5, 0.0])
    impact = solve_impact(W, J @ u, 0.0)
    assert impact.solved
    np.testing.assert_allclose(u + velocity_change(J, M, impact.normal), 0.0, atol=1e-12)
    np.testing.assert_allclose(impact.normal.sum(), 1.5 * m, rtol=1e-12)


def ground_particles(masses):
    """Point masses each touching a flat ground: rows [normals; tangents] in (x1, y1, x2, y2, ...)."""
    n = len(masses)
    Jn, Jt = np.zeros((n, 2 * n)), np.zeros((n, 2 * n))
    Jn[np.arange(n), 2 * np.arange(n) + 1] = 1.0
    Jt[np.arange(n), 2 * np.arange(n)] = 1.0
    return Jn, Jt, np.diag(np.repeat(masses, 2))


@pytest.mark.parametrize("seed", range(10))
def test_decoupled_fast_path_equals_the_lcp(seed):
    rng = np.random.default_rng(3000 + seed)
    n = int(rng.integers(1, 7))
    Jn, Jt, M = ground_particles(rng.uniform(0.01, 2.0, n))
    Wn, W2 = delassus(Jn, M), delassus(np.vstack([Jn, Jt]), M)
    assert is_decoupled(Wn) and is_decoupled(W2)
    v = rng.normal(size=2 * n)
    e, mu = rng.uniform(0, 1, n), rng.uniform(0, 1, n) * (rng.uniform(size=n) > 0.3)
    touching = rng.uniform(size=n) > 0.2
    pairs = [
        lambda fast: solve_impact(Wn, v[:n], e, touching=touching, fast=fast),
        lambda fast: solve_forces(Wn, v[:n], fast=fast),
        lambda fast: solve_impact_friction(W2, v, e, mu, touching=touching, fast=fast),
        lambda fast: solve_forces_friction(W2, v, mu, np.where(rng.uniform(size=n) > 0.5, v[n:], 0.0),
                                           fast=fast),
    ]
    for solve in pairs:
        state = rng.bit_generator.state
        quick = solve(True)
        rng.bit_generator.state = state  # the same sliding pattern for both paths
        slow = solve(False)
        assert quick.method == "decoupled" and slow.method == "lcp" and slow.solved
        for field in ("normal", "tangent", "normal_rate", "tangent_rate"):
            np.testing.assert_allclose(getattr(quick, field), getattr(slow, field), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize(("vt", "mu"), [(0.5, 0.8), (-0.5, 0.8), (3.0, 0.2), (-3.0, 0.2), (0.0, 0.5)])
def test_friction_impact_of_one_particle_equals_design_law(vt, mu):
    # DESIGN §6: P_n = (1 + e) m |v_n|, tangential impulse of size min(m |v_t|, mu P_n) against v_t.
    m, vn, e = 0.05, -2.0, 0.4
    Jn, Jt, M = ground_particles([m])
    W = delassus(np.vstack([Jn, Jt]), M)
    sol = solve_impact_friction(W, [vn, vt], e, mu, fast=False)
    assert sol.method == "lcp" and sol.solved
    Pn = (1 + e) * m * abs(vn)
    np.testing.assert_allclose(sol.normal, [Pn], rtol=1e-12)
    np.testing.assert_allclose(sol.tangent, [-np.sign(vt) * min(m * abs(vt), mu * Pn)], rtol=1e-12, atol=1e-15)


def rigid_body_on_ground(rng, nc):
    """A 2D rigid body (x, y, theta) touching a flat ground at nc points: its [normal; tangent] rows."""
    m, inertia = rng.uniform(0.5, 2.0), rng.uniform(0.05, 0.5)
    r = rng.uniform(-1, 1, size=(nc, 2)) * [1.0, 0.3] - [0.0, 0.3]  # contact points from the centre
    # velocity of point r: (x' - r_y theta', y' + r_x theta')
    Jn = np.column_stack([np.zeros(nc), np.ones(nc), r[:, 0]])
    Jt = np.column_stack([np.ones(nc), np.zeros(nc), -r[:, 1]])
    return np.vstack([Jn, Jt]), np.diag([m, m, inertia])


@pytest.mark.parametrize("seed", range(25))
def test_coupled_friction_impact_obeys_coulomb_and_dissipates(seed):
    # Anitescu-Potra: the impulse LCP is always solvable.  Check the laws themselves: no penetration,
    # |P_t| <= mu P_n, a sliding contact's friction opposes its slip at mu P_n, and (e = 0) the kinetic
    # energy does not grow: dKE = P.v+ - P^T W P / 2 with P.v+ = -mu P_n |v_t+| <= 0.
    rng = np.random.default_rng(4000 + seed)
    nc = int(rng.integers(1, 4))
    J, M = rigid_body_on_ground(rng, nc)
    u = rng.normal(size=3) - [0.0, 1.5, 0.0]
    mu = rng.uniform(0.0, 1.2, nc)
    e = 0.0 if seed % 2 == 0 else rng.uniform(0, 1)
    sol = solve_impact_friction(delassus(J, M), J @ u, e, mu)
    assert sol.solved, sol.message
    vn = (J @ u)[:nc]
    P = np.concatenate([sol.normal, sol.tangent])
    after = u + velocity_change(J, M, P)
    np.testing.assert_allclose(J @ after, np.concatenate([sol.normal_rate, sol.tangent_rate]), atol=1e-10)
    tol = 1e-9 * (1 + np.abs(P).max())
    assert np.all(sol.normal_rate + e * np.minimum(vn, 0.0) >= -1e-9)
    assert np.all(np.abs(sol.tangent) <= mu * sol.normal + tol)
    sliding = np.abs(sol.tangent_rate) > 1e-9
    np.testing.assert_allclose(sol.tangent[sliding], -mu[sliding] * sol.normal[sliding]
                               * np.sign(sol.tangent_rate[sliding]), atol=tol)
    if e == 0.0:
        assert after @ M @ after <= u @ M @ u + 1e-9


@pytest.mark.parametrize("seed", range(25))
def test_coupled_friction_forces_obey_coulomb(seed):
    # Held contacts of a rigid body, some sliding (v_t != 0), some at rest along the ground: check the
    # laws on the answer.  Normal: lam_n >= 0, a_n >= 0, lam_n a_n = 0.  Sliding: lam_t = -mu lam_n sign(v_t).
    # At rest: |lam_t| <= mu lam_n, and where the contact starts to slip (a_t != 0) lam_t = -mu lam_n sign(a_t).
    rng = np.random.default_rng(7000 + seed)
    nc = int(rng.integers(1, 5))
    J, M = rigid_body_on_ground(rng, nc)
    mu = rng.uniform(0.0, 0.6, nc)
    v_t = np.where(rng.uniform(size=nc) > 0.5, rng.normal(size=nc), 0.0)
    a_free = J @ np.array([0.0, -G, 0.0]) + rng.normal(size=2 * nc)
    sol = solve_forces_friction(delassus(J, M), a_free, mu, v_t)
    if sol.status == "ray":  # Painlevé: nothing to check but the message
        assert sol.message.startswith("Painlevé")
        return
    assert sol.solved, sol.message
    lam = np.concatenate([sol.normal, sol.tangent])
    rates = np.concatenate([sol.normal_rate, sol.tangent_rate])
    np.testing.assert_allclose(rates, a_free + delassus(J, M) @ lam, atol=1e-10)
    tol = 1e-9 * (1 + np.abs(lam).max() + np.abs(a_free).max())
    assert np.all(sol.normal >= 0) and np.all(sol.normal_rate >= -tol)
    assert np.all(np.abs(sol.normal * sol.normal_rate) <= tol * (1 + sol.normal))
    slide = (v_t != 0) & (mu > 0)
    np.testing.assert_allclose(sol.tangent[slide], -mu[slide] * np.sign(v_t[slide]) * sol.normal[slide], atol=tol)
    rest = ~slide
    assert np.all(np.abs(sol.tangent[rest]) <= mu[rest] * sol.normal[rest] + tol)
    slip = rest & (np.abs(sol.tangent_rate) > 1e-8)
    np.testing.assert_allclose(sol.tangent[slip], -mu[slip] * np.sign(sol.tangent_rate[slip]) * sol.normal[slip],
                               atol=tol)


@pytest.mark.parametrize("seed", range(8))
def test_friction_impact_independent_of_contact_order(seed):
    rng = np.random.default_rng(5000 + seed)
    nc = 3
    J, M = rigid_body_on_ground(rng, nc)
    u = rng.normal(size=3) - [0.0, 1.5, 0.0]
    mu, e = rng.uniform(0.1, 1.0, nc), rng.uniform(0, 1, nc)
    perm = rng.permutation(nc)
    rows = np.concatenate([perm, nc + perm])
    a = solve_impact_friction(delassus(J, M), J @ u, e, mu)
    b = solve_impact_friction(delassus(J[rows], M), J[rows] @ u, e[perm], mu[perm])
    # W (6 x 6) has rank 3 here, so the impulses need not be unique; compare the velocity they produce.
    # (Its uniqueness is a theorem for frictionless contacts only; with friction this checks that the
    # pivoting, not the problem, brings in no dependence on the order.)
    ua = u + velocity_change(J, M, np.concatenate([a.normal, a.tangent]))
    ub = u + velocity_change(J[rows], M, np.concatenate([b.normal, b.tangent]))
    np.testing.assert_allclose(ub, ua, atol=1e-12)


def painleve_rod(theta, m=1.0, half=0.5):
    """A rod (coordinates x, y, theta of its centre), lower end on the ground at
    (x - l cos theta, y - l sin theta), I = m (2 l)^2 / 12: rows [normal; tangent] of that end."""
    Jn = np.array([[0.0, 1.0, -half * np.cos(theta)]])
    Jt = np.array([[1.0, 0.0, half * np.sin(theta)]])
    return np.vstack([Jn, Jt]), np.diag([m, m, m * half**2 / 3])


@pytest.mark.parametrize(("mu", "v_t"), [(0.5, -1.0), (1.6, -1.0), (2.0, 1.0), (0.0, -1.0)])
def test_painleve_rod_below_critical_friction_is_solved(mu, v_t):
    # Stewart (2000, SIAM Review 42) rod at rest in rotation (a_free = [-g, 0]), end sliding.  By hand:
    # W_nn = (1 + 3 cos^2)/m, W_nt = -3 sin cos / m; friction lam_t = -mu sign(v_t) lam_n, so
    # a_n = -g + (1 + 3 cos^2 + 3 mu sign(v_t) sin cos) lam_n / m = 0:
    #   lam_n = m g / (1 + 3 cos^2 + 3 mu sign(v_t) sin cos)   (sliding toward -x: critical mu = 5/3 at 45 deg)
    theta, m = np.pi / 4, 1.0
    J, M = painleve_rod(theta, m)
    sol = solve_forces_friction(delassus(J, M), [-G, 0.0], mu, [v_t])
    assert sol.solved, sol.message
    c, s = np.cos(theta), np.sin(theta)
    lam_n = m * G / (1 + 3 * c**2 + 3 * mu * np.sign(v_t) * s * c)
    np.testing.assert_allclose(sol.normal, [lam_n], rtol=1e-12)
    np.testing.assert_allclose(sol.tangent, [-mu * np.sign(v_t) * lam_n], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(sol.normal_rate, [0.0], atol=1e-12)


@pytest.mark.parametrize("mu", [1.7, 2.0, 5.0])
def test_painleve_rod_above_critical_friction_has_no_force(mu):
    # mu > 5/3 with the end sliding toward -x: W_nn - mu W_nt sign... < 0 and a_free < 0: no lam_n >= 0
    # keeps a_n >= 0 (every push makes the end fall faster).
    J, M = painleve_rod(np.pi / 4)
    sol = solve_forces_friction(delassus(J, M), [-G, 0.0], mu, [-1.0])
    assert sol.status == "ray" and not sol.solved
    assert sol.message.startswith("Painlevé: no consistent contact force")


def test_painleve_rod_indeterminate_case_is_flagged():
    # mu = 2 > 5/3, sliding toward -x, but spinning: a_n_free = -g + l sin(theta) omega^2 > 0.
    # A = (1 + 3 cos^2 - 3 mu sin cos)/m < 0, so lam = 0 (a_n = a_free > 0) and lam = -a_free/A > 0
    # (a_n = 0) are both consistent.  Lemke returns the first (q >= 0); the message says so.
    theta, m, half, omega = np.pi / 4, 1.0, 0.5, 8.0
    J, M = painleve_rod(theta, m, half)
    a_n = -G + half * np.sin(theta) * omega**2
    a_t = half * np.cos(theta) * omega**2  # x_c'' = x'' + l sin th th'' + l cos th th'^2
    sol = solve_forces_friction(delassus(J, M), [a_n, a_t], 2.0, [-1.0])
    assert a_n > 0 and sol.solved
    np.testing.assert_allclose(sol.normal, [0.0], atol=1e-15)
    assert sol.message.startswith("Painlevé: the contact force may not be unique") and not sol.unique
    c, s = np.cos(theta), np.sin(theta)
    A = (1 + 3 * c**2 - 3 * 2.0 * s * c) / m
    other = -a_n / A
    assert other > 0  # the second solution, lam_n = -a_n_free / A, is a push too
    # below the critical mu the same spinning rod is flagged by nothing
    below = solve_forces_friction(delassus(J, M), [a_n, a_t], 0.5, [-1.0])
    assert "Painlevé" not in below.message and below.unique


def test_redundant_sliding_supports_are_not_called_painleve():
    # A flat bar (x, y, theta) sliding on three collinear supports at its centre line (r_y = 0): friction
    # is horizontal through the line of the supports, W_nt = 0, so the normal matrix is W_nn, singular
    # (rank 2) but with no negative minor: forces indeterminate as without friction, not Painlevé.
    # Balance: sum lam_n = m g, moment sum r_x lam_n = 0 (centred), lam_t = -mu lam_n.
    m, inertia, mu = 2.0, 2.0 / 12, 0.3
    rx = np.array([-0.5, 0.0, 0.5])
    Jn = np.column_stack([np.zeros(3), np.ones(3), rx])
    Jt = np.column_stack([np.ones(3), np.zeros(3), np.zeros(3)])
    J, M = np.vstack([Jn, Jt]), np.diag([m, m, inertia])
    sol = solve_forces_friction(delassus(J, M), J @ np.array([0.0, -G, 0.0]), mu, np.full(3, 0.7))
    assert sol.solved and "Painlevé" not in sol.message
    np.testing.assert_allclose([sol.normal.sum(), rx @ sol.normal], [m * G, 0.0], atol=1e-12)
    np.testing.assert_allclose(sol.tangent, -mu * sol.normal, atol=1e-12)
    np.testing.assert_allclose(sol.normal_rate, 0.0, atol=1e-12)


def test_sticking_contact_with_enough_friction_holds():
    # A rod leaning at 45 deg, end at rest (v_t = 0), no spin: with large mu it sticks (a_n = a_t = 0).
    # Then lam solves W [lam_n, lam_t] = -a_free, i.e. the end's acceleration vanishes.
    J, M = painleve_rod(np.pi / 4)
    W = delassus(J, M)
    sol = solve_forces_friction(W, [-G, 0.0], 10.0, [0.0])
    assert sol.solved
    np.testing.assert_allclose(np.concatenate([sol.normal, sol.tangent]), np.linalg.solve(W, [G, 0.0]),
                               rtol=1e-12)
    np.testing.assert_allclose([sol.normal_rate[0], sol.tangent_rate[0]], 0.0, atol=1e-12)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: solve_impact(np.eye(2), [-1.0, -1.0], 1.5), "`restitution` must be in"),
        (lambda: solve_impact(np.eye(2), [-1.0], 0.0), "must have shape"),
        (lambda: solve_impact(np.eye(2), [-1.0, -1.0], [0.1, -0.2]), "`restitution` must be a finite"),
        (lambda: solve_impact_friction(np.eye(3), [-1.0, 0, 0], 0.0, 0.1), "2 row"),
        (lambda: solve_forces_friction(np.eye(2), [-1.0, 0.0], 0.3, [0.0, 1.0]), "`v_t` must be"),
    ],
)
def test_bad_contact_arguments_are_named(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_entries_of_q_eight_orders_apart_are_all_solved():
    """An impact seen in a body-contact drop: two contacts graze (approach at 3e-11 m/s)
    beside one at 1.6e-3 m/s.  The LCP is homogeneous in q, so its answer cannot depend
    on the scale; it once left the grazing contact at w = -3e-11."""
    M = np.array([[31.18277, 4.70648, 0.0], [4.70648, 31.88978, 9.62532], [0.0, 9.62532, 33.6331]])
    q = np.array([-3.07741e-11, -3.44418e-11, -1.59486e-03])
    solution = solve_lcp(M, q)
    assert solution.status == "solved"
    z, w = solution.z, M @ solution.z + q
    assert np.all(z >= 0.0) and np.all(w >= -1e-9 * (np.abs(M) @ z + np.abs(q)))
    assert np.all(np.abs(z * w) <= 1e-12 * np.abs(z) * (np.abs(M) @ z + np.abs(q)).max())
    scaled = solve_lcp(M, q * 1e8)
    np.testing.assert_allclose(scaled.z * 1e-8, z, rtol=1e-9, atol=1e-20)


@pytest.mark.parametrize("seed", range(5))
def test_a_block_diagonal_problem_is_solved_block_by_block_as_a_whole(seed):
    """Contacts that do not act on each other (W zero between them, rows in any order) are
    solved as separate LCPs (a pile's held contacts): the forces must equal Lemke's on the
    whole matrix, and the blocks found must be the ones built."""
    from flexbody.contact_problems import independent_blocks

    rng = np.random.default_rng(seed)
    sizes = [1, 3, 2, 4, 1]
    W = np.zeros((sum(sizes), sum(sizes)))
    start = 0
    for n in sizes:
        A = rng.standard_normal((n, n + 2))
        W[start : start + n, start : start + n] = A @ A.T  # positive definite: the answer is unique
        start += n
    order = rng.permutation(len(W))
    W = W[np.ix_(order, order)]
    a_free = rng.standard_normal(len(W))
    blocks = independent_blocks(W)
    assert sorted(len(b) for b in blocks) == sorted(sizes)
    whole = solve_lcp(W, a_free)
    assert whole.solved
    split = solve_forces(W, a_free, fast=False)
    assert split.solved and split.method == "lcp"
    np.testing.assert_allclose(split.normal, whole.z, rtol=1e-12, atol=1e-12)
    assert_solves(solve_lcp(W, a_free), W, a_free)
    assert np.all(split.normal_rate >= -1e-12) and abs(split.normal @ split.normal_rate) < 1e-10


def test_contact_solve_takes_lapack_only_where_no_contact_is_near_redundant(rng, monkeypatch):
    """contact_solve factorises a well-conditioned W with LAPACK and equals its column loop
    (forced) to rounding; with a dependent row (a contact the others imply) it drops that
    column as model.c does: its force is 0 and every row still holds."""
    import flexbody.dynamics as dynamics

    for _ in range(5):
        J = rng.normal(size=(6, 9))
        W, b = J @ J.T, rng.normal(size=6)
        fast = dynamics.contact_solve(W, b)
        with monkeypatch.context() as m:
            m.setattr(dynamics, "CLEAR_PIVOTS", np.inf)
            loop = dynamics.contact_solve(W, b)
        np.testing.assert_allclose(fast, loop, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(W @ fast, b, rtol=1e-10, atol=1e-10)
        dependent = np.vstack([J, J[0] + 2.0 * J[3]])  # row 6 = row 0 + 2 row 3
        W = dependent @ dependent.T
        b = W @ rng.normal(size=7)  # consistent: in W's range
        x = dynamics.contact_solve(W, b)
        assert x[6] == 0.0
        np.testing.assert_allclose(W @ x, b, rtol=1e-8, atol=1e-8)


def test_contact_solve_survives_rounding_grown_through_a_small_kept_pivot(monkeypatch):
    """Two nearly equal rows (a pile's reverse vertex-to-vertex contacts: their difference
    1e-5 to 1e-4 of a row) and a row along that difference plus another row: W is positive
    semidefinite with one dependent row, but the ordered column loop keeps the near pair's
    small pivot and the rounding it amplifies drives the last pivot below -1e-12 of the
    largest, which it reported as 'not positive definite' (a blow-up of the 20-disc pile).
    Here the pivoted fallback drops the dependent row (force 0) and W x = b holds to
    rounding.  A truly indefinite W still raises."""
    import flexbody.dynamics as dynamics

    calls = []
    pivoted = dynamics._pivoted_solve
    monkeypatch.setattr(dynamics, "_pivoted_solve", lambda *args: calls.append(1) or pivoted(*args))
    rescued = 0
    for delta in (1e-5, 3e-5, 1e-4):
        for seed in range(20):
            rng = np.random.default_rng(seed)
            J = rng.normal(size=(12, 30))
            v = rng.normal(size=30)
            v *= np.linalg.norm(J[0]) / np.linalg.norm(v)
            J[1] = J[0] + delta * v
            J[11] = v + J[2]  # = (J[1] - J[0]) / delta + J[2]: dependent
            W = J @ J.T
            b = W @ np.abs(rng.normal(size=12))
            calls.clear()
            x = dynamics.contact_solve(W, b)
            rescued += bool(calls)
            np.testing.assert_allclose(W @ x, b, rtol=0, atol=1e-9 * np.abs(b).max())
            if calls:  # the fallback dropped a dependent row: its force is 0, the others hold it
                assert np.count_nonzero(x == 0.0) == 1
    assert rescued >= 20  # these cases took the fallback (measured: 25 of 60)
    with pytest.raises(FloatingPointError, match="not positive definite"):
        dynamics.contact_solve(np.array([[1.0, 2.0], [2.0, 1.0]]), np.ones(2))


def test_the_pivoted_fallback_drops_a_dependent_row_anywhere_and_refuses_an_indefinite_remainder():
    """_pivoted_solve directly, on a 90 x 90 W (LAPACK's blocked dpstrf) whose row 40 is a
    combination of three others: one of those four rows is dropped (force 0), the others
    solve W x = b to rounding and equal the solve of W without the dropped row.  A matrix that is positive definite but
    for a block of -1e-3 of its size is refused."""
    import flexbody.dynamics as dynamics

    rng = np.random.default_rng(3)
    J = rng.normal(size=(90, 200))
    J[40] = J[3] - 2.0 * J[17] + 0.5 * J[88]
    W = J @ J.T
    b = W @ rng.normal(size=90)  # in W's range
    x = dynamics._pivoted_solve(W, b, float(W.diagonal().max()))
    dropped = np.flatnonzero(x == 0.0)  # one of the four rows tied by the combination
    assert len(dropped) == 1 and dropped[0] in (3, 17, 40, 88)
    np.testing.assert_allclose(W @ x, b, rtol=0, atol=1e-10 * np.abs(b).max())
    rest = np.delete(np.arange(90), dropped)
    np.testing.assert_allclose(x[rest], np.linalg.solve(W[np.ix_(rest, rest)], b[rest]), rtol=1e-8, atol=1e-10)
    indefinite = np.diag(np.r_[np.ones(5), 1.0, 1.0])
    indefinite[5:, 5:] = [[1.0, 1.001], [1.001, 1.0]]  # eigenvalues 2.001 and -0.001
    with pytest.raises(FloatingPointError, match="not positive definite"):
        dynamics._pivoted_solve(indefinite, np.ones(7), 1.0)


@pytest.mark.parametrize("name, without", [("lcp_redundant_friction", "inaccurate"),
                                           ("lcp_redundant_friction_ray", "ray")])
def test_a_basis_that_rounding_left_infeasible_is_solved_again_on_a_shifted_matrix(monkeypatch, name, without):
    """Frictional force LCPs of held contacts in a fuzzed pile of rigid and flexible discs
    (redundant contacts): 23 rows, M's condition 2.6e16, the pivots ending on a basis with
    a z below 0 by 0.21 (w below 0 by 3.4); and 11 rows, condition 5e16, a secondary ray
    though enumerating the 2^11 bases finds a solution (to 1.2e-13).  Solved again on
    M + s I, the answer solves the original problem; an answer far larger than the pivots'
    last point is not taken (an infeasible problem has one of size ~1/s on M + s I).  (Ties
    of the ratio test in the tableau's units end both paths on a solution: the path of
    the tie test on the keys, which ended them so, is taken here to test the shifts.)"""
    data = np.load(Path(__file__).parent / "reference" / f"{name}.npz")
    M, q = data["M"], data["q"]
    _numpy_pivots(monkeypatch)
    monkeypatch.setattr(flexbody.lcp, "_tied", _key_tolerance_ties)
    monkeypatch.setattr(flexbody.lcp, "COVERINGS", 0)  # the shifts alone (other covering vectors solve it too)
    monkeypatch.setattr(flexbody.lcp, "SEARCH_LARGEST", 0)  # (and so does the mixed-integer search)
    sol = solve_lcp(M, q)
    assert sol.status == "solved" and "on M +" in sol.message, sol.message
    assert_solves(sol, M, q)
    monkeypatch.setattr(flexbody.lcp, "SHIFTS", ())
    assert solve_lcp(M, q).status == without
    monkeypatch.setattr(flexbody.lcp, "SHIFTS", (1e-13, 1e-12, 1e-11))
    monkeypatch.setattr(flexbody.lcp, "SHIFT_GROWTH", 0.5)  # no answer of the same size is ever this small
    assert solve_lcp(M, q).status == without


@pytest.mark.parametrize("name, without", [("lcp_fuzz_frictional_impact_ray", "ray"),
                                           ("lcp_fuzz_frictional_impact_2d", "inaccurate")])
def test_a_frictional_lcp_whose_path_ends_on_a_ray_is_solved_from_another_covering_vector(monkeypatch, name, without):
    """Frictional impact LCPs of a fuzz (a 3D slab on a rigid box, 30 rows, all plastic; a 2D
    pile, 24 rows): Lemke's path from the covering vector of ones ends on a secondary ray
    or on a basis whose z fails the check, and the run stopped `unsupported`; M is not
    copositive-plus (friction), so neither proves there is no solution, and 31 and 32 of
    50 orders of their rows solve them.  From another covering vector the path ends on a
    solution of the original problem.  (Ties of the ratio test in the tableau's units end
    both paths on a solution: the path of the tie test on the keys is taken here.)"""
    data = np.load(Path(__file__).parent / "reference" / f"{name}.npz")
    M, q = data["M"], data["q"]
    _numpy_pivots(monkeypatch)
    monkeypatch.setattr(flexbody.lcp, "_tied", _key_tolerance_ties)
    monkeypatch.setattr(flexbody.lcp, "_finish", _without_last_point(flexbody.lcp._finish))
    sol = solve_lcp(M, q)
    assert "covering vector" in sol.message, sol.message
    assert_solves(sol, M, q)
    monkeypatch.setattr(flexbody.lcp, "COVERINGS", 0)
    monkeypatch.setattr(flexbody.lcp, "SEARCH_LARGEST", 0)
    assert solve_lcp(M, q).status == without


@pytest.mark.parametrize("name", ["lcp_redundant_friction", "lcp_redundant_friction_ray",
                                  "lcp_fuzz_frictional_impact_ray", "lcp_fuzz_frictional_impact_2d"])
def test_frictional_lcps_that_key_ties_left_unsolved_are_solved_by_the_first_path(monkeypatch, name):
    """The four LCPs above whose path from the covering vector of ones ended on a basis
    failing the check or on a ray while ties were judged on the keys b / a: with ties
    judged in the tableau's own units (:func:`flexbody.lcp._lex_min_row`) that path ends on
    a solution, with no shift and no other covering vector."""
    data = np.load(Path(__file__).parent / "reference" / f"{name}.npz")
    M, q = data["M"], data["q"]
    monkeypatch.setattr(flexbody.lcp, "COVERINGS", 0)
    monkeypatch.setattr(flexbody.lcp, "SHIFTS", ())
    sol = solve_lcp(M, q)
    assert "on M +" not in sol.message and "covering vector" not in sol.message
    assert_solves(sol, M, q)


def _assert_solves_to_rounding(sol, M, q):
    """:func:`assert_solves` with the check's rounding floor: rows of redundant contacts
    (a singular W) come out at +-1e-16 of the impulses' terms."""
    floor = 16 * q.size * np.finfo(float).eps * (np.abs(M).max() * sol.z.max() + np.abs(q).max())
    level = 1e-9 * (np.abs(M) @ sol.z + np.abs(q)) + floor
    assert np.all(sol.z >= 0.0) and np.all(sol.w >= -level)
    assert np.all(np.abs(sol.w) <= level, where=sol.z > 0.0)


def _without_last_point(finish):
    """``flexbody.lcp._finish`` as it was before a ray's last point was checked: the rescues
    tried after it (shifts, other covering vectors) are tested on paths it would end."""
    return lambda *args: finish(*args[:9])


def test_a_path_stalled_at_rounding_level_z0_is_solved_by_its_last_point(monkeypatch):
    """A fuzz's plastic frictional impact (tests/reference/lcp_fuzz_plastic_impact_stall.npz:
    a rigid box sliding on the ground on four corners, a second one and a flexible box in a
    row, 12 contacts, 72 rows; W of rank 21 of 36).  With W positive semidefinite and the
    velocities before in its range the path cannot end on a secondary ray (Anitescu & Potra),
    but its z0 stalls at 2.7e-13 (the rounding level 1.1e-12) and then the entering column
    has no positive entry: the run stopped `unsupported`.  That last point solves the
    problem to rounding; so do the paths of two earlier fuzzes' impacts that ended so, rescued
    by a shift (below: z0 = 5.9e-13) and by another covering vector (above: z0 = 1.7e-15)."""
    _numpy_pivots(monkeypatch)  # the third takes the ratio test of the keys
    monkeypatch.setattr(flexbody.lcp, "COVERINGS", 0)
    monkeypatch.setattr(flexbody.lcp, "SHIFTS", ())
    monkeypatch.setattr(flexbody.lcp, "SEARCH_LARGEST", 0)
    finish = flexbody.lcp._finish
    for name, ties in [("lcp_fuzz_plastic_impact_stall", flexbody.lcp._tied),
                       ("lcp_fuzz_frictional_impact_shift", flexbody.lcp._tied),
                       ("lcp_fuzz_frictional_impact_ray", _key_tolerance_ties)]:
        data = np.load(Path(__file__).parent / "reference" / f"{name}.npz")
        M, q = data["M"], data["q"]
        monkeypatch.setattr(flexbody.lcp, "_tied", ties)
        monkeypatch.setattr(flexbody.lcp, "_finish", finish)
        sol = solve_lcp(M, q)
        assert sol.status == "solved" and "last point" in sol.message, sol.message
        _assert_solves_to_rounding(sol, M, q)  # each row is off by at most d z0, below the floor
        monkeypatch.setattr(flexbody.lcp, "_finish", _without_last_point(finish))
        assert solve_lcp(M, q).status == "ray"


def test_a_small_impulse_on_a_stiff_row_is_not_cleared_as_rounding():
    """The same impact from other covering vectors: every path ends on a complementary basis,
    and its z solves the problem to 4e-16, but contact 9 (approaching at 1.7e-12 m/s, W_99 =
    41) takes an impulse of 4.2e-14, below the rounding floor of the rates (1.1e-12) that
    was cleared to 0; its row was then left 1.7e-12 below 0 and the answer refused
    ("inaccurate"), from all 30 vectors tried.  The pivots' own values are now checked too."""
    data = np.load(Path(__file__).parent / "reference" / "lcp_fuzz_plastic_impact_stall.npz")
    M, q = data["M"], data["q"]
    for seed in range(3):
        covering = np.random.default_rng(seed).uniform(0.5, 2.0, q.size)
        sol = solve_lcp(M, q, covering=covering)
        assert sol.status == "solved", sol.message
        _assert_solves_to_rounding(sol, M, q)
        assert sol.z[9] > 0.0 and abs(sol.w[9]) <= 1e-15


def test_a_shifted_answer_is_checked_with_the_shift_s_compliance(monkeypatch):
    """A fuzz's frictional impact LCP (two flexible 3D bodies, 18 rows): a secondary ray from
    every order of its rows, yet 21 of its 2^18 bases solve it (the best to 3.5e-19).  On
    M + s I the pivots find an answer, which solves the original problem but for s z_i in
    each row: it was refused by 1.0e-11 = s z.  Now each row may be off by that much more,
    and no more."""
    data = np.load(Path(__file__).parent / "reference" / "lcp_fuzz_frictional_impact_shift.npz")
    M, q = data["M"], data["q"]
    monkeypatch.setattr(flexbody.lcp, "COVERINGS", 0)
    monkeypatch.setattr(flexbody.lcp, "_finish", _without_last_point(flexbody.lcp._finish))
    sol = solve_lcp(M, q)
    assert sol.status == "solved" and "on M +" in sol.message, sol.message
    size = np.abs(np.diag(M)).max()
    shift = next(r * size for r in flexbody.lcp.SHIFTS if f"on M + {r * size:.1e} I" in sol.message)
    assert np.all(sol.z >= 0.0)
    assert np.all(sol.w >= -(shift * sol.z.max() + 1e-9 * (np.abs(M) @ sol.z + np.abs(q))))
    assert np.abs(sol.w * sol.z).max() <= shift * sol.z.max() ** 2 + 1e-12
    monkeypatch.setattr(flexbody.lcp, "SHIFTS", ())
    monkeypatch.setattr(flexbody.lcp, "SEARCH_LARGEST", 0)
    assert solve_lcp(M, q).status == "ray"


@pytest.mark.parametrize("seed", range(8))
def test_small_and_large_problems_find_the_same_blocks(seed):
    """independent_blocks' closure (dense problems of at most DENSE_BLOCKS rows) and its
    connected components (larger or sparse ones) split a problem alike: random chains and
    scattered couplings, rows in any order, one-sided nonzeros linking as two-sided ones;
    each block is a set of rows with no nonzero to any other block, and no block splits."""
    from scipy.sparse import csr_matrix

    from flexbody.contact_problems import DENSE_BLOCKS, independent_blocks

    rng = np.random.default_rng(seed)
    for n in (2, 7, DENSE_BLOCKS, DENSE_BLOCKS + 5):
        A = np.zeros((n, n))
        chain = rng.permutation(n)[: rng.integers(1, n + 1)]  # a long path: many doublings
        A[chain[:-1], chain[1:]] = 1.0
        pairs = rng.integers(0, n, size=(n // 3, 2))
        A[pairs[:, 0], pairs[:, 1]] = rng.standard_normal(len(pairs))
        A[np.diag_indices(n)] = 1.0
        dense, sparse = independent_blocks(A), independent_blocks(csr_matrix(A))
        assert [b.tolist() for b in dense] == [b.tolist() for b in sparse]
        assert sorted(np.concatenate(dense).tolist()) == list(range(n))
        for i, block in enumerate(dense):
            rest = np.concatenate([b for j, b in enumerate(dense) if j != i] + [np.zeros(0, int)])
            assert not A[np.ix_(block, rest)].any() and not A[np.ix_(rest, block)].any()
            # connected within: the closure from its first row reaches all of it
            reach = {int(block[0])}
            for _ in range(len(block)):
                reach |= {int(j) for i2 in reach for j in np.flatnonzero((A[i2] != 0) | (A[:, i2] != 0))}
            assert reach == set(block.tolist())


def _no_rescue_but_the_search(monkeypatch):
    """Lemke's path from the covering vector of ones alone before the search: no last point,
    no shifts, no other covering vectors."""
    monkeypatch.setattr(flexbody.lcp, "COVERINGS", 0)
    monkeypatch.setattr(flexbody.lcp, "SHIFTS", ())
    monkeypatch.setattr(flexbody.lcp, "_finish", _without_last_point(flexbody.lcp._finish))


@pytest.mark.parametrize("name", ["lcp_fuzz_frictional_impact_shift", "lcp_fuzz_plastic_impact_stall"])
def test_a_path_that_finds_no_solution_is_followed_by_a_mixed_integer_search_that_does(monkeypatch, name):
    """Two fuzzes' frictional impact LCPs (18 and 72 rows) whose first path ends on a
    secondary ray, and which have solutions (enumeration found 21 bases for the first; the
    second's path stalls at one, Anitescu & Potra): with every other rescue off, the search
    finds a solution, which passes the check on the original problem."""
    data = np.load(Path(__file__).parent / "reference" / f"{name}.npz")
    M, q = data["M"], data["q"]
    _no_rescue_but_the_search(monkeypatch)
    sol = solve_lcp(M, q)
    assert sol.status == "solved" and "mixed-integer search" in sol.message, sol.message
    _assert_solves_to_rounding(sol, M, q)
    monkeypatch.setattr(flexbody.lcp, "SEARCH_LARGEST", 0)
    assert solve_lcp(M, q).status == "ray"


def test_the_search_agrees_with_enumerating_the_bases():
    """Small LCPs of no special class (integer entries, M indefinite, q with zeros): where the
    search returns a solution it passes the check, and where it proves there is none, no
    basis within its bound solves the problem (every basic solution enumerated).  Both
    verdicts occur."""
    verdicts = set()
    for seed in range(150):
        rng = np.random.default_rng(5000 + seed)
        n = int(rng.integers(2, 6))
        M = rng.integers(-3, 4, size=(n, n)).astype(float)
        q = rng.integers(-2, 2, size=n).astype(float)
        if np.all(q >= 0.0):
            continue
        unsolved = flexbody.lcp.LcpSolution(np.zeros(n), q.copy(), "ray", 0, "a path's end.")
        sol = flexbody.lcp._searched(M, q, unsolved, flexbody.lcp.CHECK_TOL)
        verdicts.add(sol.status)
        if sol.status == "solved":
            assert_solves(sol, M, q)
        else:
            assert "proves that none exists" in sol.message, sol.message
            z_unit = np.abs(q).max() / (np.abs(np.diag(M)).max() or np.abs(M).max())
            bound = flexbody.lcp.SEARCH_BOUND
            within = [z for z, w in brute_force(M, q)
                      if z.max() <= bound * z_unit and w.max() <= bound * np.abs(q).max()]
            assert not within, (seed, M, q)
    assert verdicts == {"solved", "ray"}


def test_painleve_s_friction_lcp_is_proven_to_have_no_solution():
    """A fuzz's frictional force LCP (tests/reference/lcp_painleve_friction_row.npz: three
    flexible boxes in a row, 16 held contacts, 6 sliding with mu 0.41-0.48, the polygonal
    cone's 51 rows; W_nn + W_nt D has a negative principal minor): every path ends on a
    secondary ray, and the mixed-integer search proves that no solution exists within its
    bound: the run's "Painlevé: no consistent contact force" is a fact, not the method's
    limit.  (Turning the polygons, or taking 8 or 16 sides, or dropping the sticking
    contacts' friction, leaves it without one: checked by the same search.)"""
    data = np.load(Path(__file__).parent / "reference" / "lcp_painleve_friction_row.npz")
    sol = solve_lcp(data["M"], data["q"])
    assert sol.status == "ray" and "proves that none exists" in sol.message, sol.message
