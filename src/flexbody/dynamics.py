"""Contact-constrained dynamics on top of a generated model (NumPy reference path).

With held contacts S, the accelerations solve ``M u' = F + J_S^T lam + J^T push`` with
``J_S u' + bias_S = 0``, so ``lam = -(J_S M^-1 J_S^T)^-1 (J_S M^-1 (F + J^T push) + bias_S)``.
For point masses on flat grounds ``J M^-1 J^T`` is diagonal (``1/m_i``) whichever
coordinates are used, so each contact's force is that of its own particle; the general
formula is kept so both formulations run the same code.  The C template implements the
same algorithm (``fb_rhs``); tests check the two agree.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .model import Model


def mass_solver(model: Model, q, p):
    """``x -> M(q)^-1 x`` for x of shape (nu,) or (nu, k): a division when M is diagonal."""
    if model.manifest["mass_matrix_diagonal"]:
        d = model._call("mass_diagonal", q, None, p)
        return lambda x: x / (d if np.ndim(x) == 1 else d[:, None])
    M = model.mass_matrix(q, p)
    return lambda x: np.linalg.solve(M, x)


#: A contact matrix pivot at or below this share of its largest diagonal entry is a redundant
#: contact (the twin of REDUNDANT in model.c).
REDUNDANT = 1e-12
#: Pivots above this many times REDUNDANT's threshold are clear of it: LAPACK may factorise.
CLEAR_PIVOTS = 1e3


def contact_solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``x`` with ``A x = b`` for a contact matrix ``A (k, k)``, positive semidefinite.

    A Cholesky factorisation that drops the columns of redundant contacts (pivot at or below
    :data:`REDUNDANT` of the largest diagonal entry: their forces are 0, the others hold
    them), in the order of model.c's ``cholesky`` so both give the same numbers wherever that
    one succeeds.

    Where that loop meets a pivot below ``-REDUNDANT`` without ``A`` being indefinite it is
    rounding grown through a small pivot kept just above the threshold (a pile's reverse
    vertex-to-vertex contacts: two rows nearly equal, and a third along their difference):
    the solve is then done again by LAPACK's pivoted Cholesky (``dpstrf``, largest pivot
    first, so nothing grows), dropping the same way (:func:`_pivoted_solve`).  model.c has
    no such fallback: a whole-scene C model still reports that matrix as not positive
    definite (status ``blow_up``); contacts between bodies are solved here only.

    Raises
    ------
    FloatingPointError
        If ``A`` is not positive semidefinite: the ordered loop meets a pivot below
        ``-REDUNDANT`` and the pivoted one leaves a remainder above :data:`INDEFINITE` of
        the largest diagonal entry (rounding grown through small pivots reaches ~1e-8 of
        it; an indefinite matrix's remainder is of its own size).
    """
    n = len(b)
    largest = float(np.max(np.diag(A))) if n else 0.0
    if n > 1:
        # No contact near redundant (every pivot far above the drop threshold): LAPACK's
        # factorisation gives the same answer to rounding, without a Python loop per column.
        try:
            factor = np.linalg.cholesky(A)
        except np.linalg.LinAlgError:
            factor = None
        if factor is not None and np.min(np.diag(factor)) ** 2 > CLEAR_PIVOTS * REDUNDANT * largest:
            from scipy.linalg import cho_solve

            # finite: A was factorised, and a non-finite b gives a non-finite answer the driver reports
            return cho_solve((factor, True), np.asarray(b, float), check_finite=False)
    L = np.zeros((n, n))
    for j in range(n):
        d = A[j, j] - L[j, :j] @ L[j, :j]
        if not d > -REDUNDANT * largest:
            return _pivoted_solve(A, b, largest)
        if d <= REDUNDANT * largest:
            continue  # dependent: dropped
        L[j, j] = np.sqrt(d)
        L[j + 1 :, j] = (A[j + 1 :, j] - L[j + 1 :, :j] @ L[j, :j]) / L[j, j]
    x = np.array(b, float)
    for i in range(n):
        x[i] = (x[i] - L[i, :i] @ x[:i]) / L[i, i] if L[i, i] > 0.0 else 0.0
    for i in range(n - 1, -1, -1):
        x[i] = (x[i] - L[i + 1 :, i] @ x[i + 1 :]) / L[i, i] if L[i, i] > 0.0 else 0.0
    return x


#: Past the pivoted factorisation's drop, a remainder (Schur complement) entry above this
#: share of the largest diagonal entry means ``A`` is indefinite, not rounding.
INDEFINITE = 1e-9


def _pivoted_solve(A: np.ndarray, b: np.ndarray, largest: float) -> np.ndarray:
    """``x`` (k,) with ``A x = b`` by pivoted Cholesky, contacts whose pivot falls to
    :data:`REDUNDANT` of ``largest`` dropped (force 0): :func:`contact_solve`'s fallback."""
    from scipy.linalg import solve_triangular
    from scipy.linalg.lapack import dpstrf

    c, order, rank, _ = dpstrf(A, tol=REDUNDANT * largest, lower=1)
    order = order - 1  # LAPACK counts from 1
    L = np.tril(c)[:, :rank]
    kept, dropped = order[:rank], order[rank:]
    remainder = A[np.ix_(dropped, dropped)] - L[rank:] @ L[rank:].T
    if not (np.all(np.isfinite(c)) and np.all(np.diag(L)[:rank] > 0.0)
            and np.all(np.abs(remainder) <= INDEFINITE * largest)):
        raise FloatingPointError("mass or contact matrix not positive definite at this state")
    x = np.zeros(len(b))
    head = L[:rank]
    x[kept] = solve_triangular(head.T, solve_triangular(head, np.asarray(b, float)[kept], lower=True), lower=False)
    return x


def constrained_rhs(model: Model, y, p, held, push) -> tuple[np.ndarray, np.ndarray]:
    """``(ydot (ny,), lam (nc,))`` for state ``y = [q, u, w]``; see :meth:`Model.rhs`."""
    q, u = y[: model.nq], y[model.nq : model.nq + model.nu]
    solve = mass_solver(model, q, p)
    F = model.forcing(q, u, p)
    held = np.asarray(held, dtype=bool)
    push = np.asarray(push, dtype=float)
    lam = np.zeros(model.n_contacts)
    impact_power = 0.0
    if held.any() or push.any():
        J = model.gap_jacobian(q, p)
        bias = model.gap_bias(q, u, p)
        F = F + J.T @ push
        impact_power = -float(push @ (J @ u))
    acc = solve(F)
    if held.any():
        Js = J[held]
        X = solve(Js.T)
        lam_s = contact_solve(Js @ X, -(Js @ acc + bias[held]))
        acc = acc + X @ lam_s
        lam[held] = lam_s
    ydot = np.concatenate([u, acc, [model._call("damping_power", q, u, p), impact_power]])
    return ydot, lam


def contact_state(model: Model, y, p, held, push) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Gaps, normal velocities and held-contact forces, each shape (nc,)."""
    q, u = y[: model.nq], y[model.nq : model.nq + model.nu]
    _, lam = constrained_rhs(model, y, p, held, push)
    return model.gaps(q, p), model.gap_jacobian(q, p) @ u, lam


def impact(model: Model, y, p, stop) -> tuple[np.ndarray, float]:
    """Plastic impulses ``u+ = u + M^-1 J_S^T L`` with ``J_S u+ = 0`` for the contacts S in ``stop``.

    Returns the new state, shape (ny,), and the kinetic energy removed (J).
    """
    nq, nu = model.nq, model.nu
    q, u = y[:nq], y[nq : nq + nu]
    stop = np.asarray(stop, dtype=bool)
    J = model.gap_jacobian(q, p)[stop]
    X = mass_solver(model, q, p)(J.T)
    out = y.copy()
    out[nq : nq + nu] = u + X @ contact_solve(J @ X, -(J @ u))
    loss = model.energies(q, u, p)[0] - model.energies(q, out[nq : nq + nu], p)[0]
    return out, float(loss)


def state_jacobian(model: Model, y, p, held) -> np.ndarray:
    """Jacobian of the right-hand side with respect to ``y``, shape (ny, ny).

    Exact for free contacts; for held ones the unconstrained Jacobian is projected onto
    the constraint (the variation of J and of the bias is neglected), which is what an
    implicit method's Newton iteration needs.
    """
    nq, nu = model.nq, model.nu
    q, u = y[:nq], y[nq : nq + nu]
    ydot, _ = model.rhs(y, p, held, np.zeros(model.n_contacts))
    acc = ydot[nq : nq + nu]
    Jq, Ju = model.forcing_jacobians(q, u, p, acc)
    solve = mass_solver(model, q, p)
    A = solve(np.hstack([Jq, Ju]))
    held = np.asarray(held, dtype=bool)
    if held.any():
        Js = model.gap_jacobian(q, p)[held]
        X = solve(Js.T)
        A = A - X @ np.linalg.solve(Js @ X, Js @ A)
    out = np.zeros((model.ny, model.ny))
    out[:nq, nq : nq + nu] = np.eye(nq, nu)
    out[nq : nq + nu, : nq + nu] = A
    return out
