"""Lemke's method (flexbody.lcp) and the contact problems built on it (flexbody.contact_problems).

References are independent of the code under test: brute-force enumeration of complementary
bases, a linear program for feasibility, closed forms derived by hand in the comments.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from scipy.optimize import linprog

from flexbody.lcp import solve_lcp


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
    assert sol.pivots <= 2 * n + 2  # small problems; the limit would say "iterations"
    for _, w in brute_force(M, q):
        np.testing.assert_allclose(sol.w, w, atol=1e-9)


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


def test_pivot_limit_gives_iterations_status():
    rng = np.random.default_rng(7)
    M = random_p_matrix(rng, 6)
    q = -np.abs(rng.normal(size=6)) - 1.0
    full = solve_lcp(M, q)
    assert full.pivots > 2
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
