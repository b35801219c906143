"""The impact and contact-force problems of coupled contacts as LCPs (DESIGN §6).

Contacts couple when the contact-space inverse mass, the *Delassus matrix*

    W = J M^-1 J^T            (J: (m, nu) contact rows of the gap Jacobian, M: (nu, nu))

is not diagonal: contacts between bodies, several contacts of one rigid body.  Each problem
below is then one linear complementarity problem, solved by :func:`flexbody.lcp.solve_lcp`
(exact, finite, independent of the order of the contacts where the answer is unique).
Where ``W`` is diagonal (point masses on grounds) every contact has a closed-form answer:
the *decoupled fast path*, which gives the same numbers as the LCP.

Conventions.  Frictionless problems take ``W`` of the normal rows only, ``(nc, nc)``.  The
2D frictional ones take ``W`` of the stacked rows ``[normal rows; tangent rows]``,
``(2 nc, 2 nc)``, i.e. ``delassus(np.vstack([Jn, Jt]), M)``: contact ``i`` has a unit
normal (its gap grows along it) and one unit tangent ``t_i``; a positive tangential
velocity, impulse or force points along ``t_i``.  Velocities and accelerations are those
of the contact points along these directions.

* **Impact** (an instant; Newton's law per contact): impulses ``P >= 0`` with
  ``v+ = v- + W P``, and ``v+ + e v-  >= 0`` complementary to ``P``.  Which contacts may
  take impulse: every *touching* contact (gap 0), whether it approaches or not; restitution
  acts only on approaching ones (``v- < 0``), a touching contact that does not approach
  only gets ``v+ >= 0``.  Including the non-approaching ones is necessary: a bar landing on
  one end can drive its other, resting or even separating end into the ground.  Contacts
  with a gap (``touching`` False) take none.  With several contacts this is one choice
  among impact laws (the thesis's "indeterminate multiple simultaneous impact"), and it is
  not energy-consistent in general.  The kinetic energy changes by
  ``dKE = P . (v+ + v-) / 2 = P . v+ - P^T W P / 2``: with ``e = 0`` (``P . v+ = 0``) it
  never grows; when every contact taking impulse approaches and all share one ``e``,
  ``dKE = -(1 - e) / (2 (1 + e)) P^T W P <= 0``; but a touching contact that does not
  approach and is pushed (``v+ = 0`` while ``v- > 0``), or unequal ``e``, can make it
  *grow* (a bar landing on one end with ``e = 1``: 28/3 J -> 12 J, in the tests).
* **Contact forces** (held contacts): accelerations ``a = a_free + W lam >= 0``
  complementary to ``lam >= 0``.
* **Friction in 2D** (Stewart & Trinkle 1996; Anitescu & Potra 1997): the tangential
  impulse (force) of a contact with ``mu > 0`` is split as ``P+ - P-`` with ``P+, P- >= 0``,
  plus a slack ``s`` that equals the sliding speed:

      v_t+ + s >= 0  _|_ P+ >= 0,     -v_t+ + s >= 0  _|_ P- >= 0,
      mu P_n - P+ - P- >= 0  _|_  s >= 0.

  In 2D the friction cone has exactly two directions, so this *is* Coulomb's law: stick
  (``v_t+ = 0``, ``|P_t| <= mu P_n``) or slide (``|P_t| = mu P_n`` against ``v_t+``).  At the
  impulse level the LCP matrix is copositive and always solvable (Anitescu & Potra); for
  one particle on a ground it reduces to DESIGN §6's ``min(m |v_t|, mu P_n)``.  At the force
  level a *sliding* contact's friction is ``-mu lam_n sign(v_t)``, which makes the normal
  problem's matrix ``W_nn - mu W_nt sign(v_t)`` possibly not copositive: the problem can
  have no solution (Painlevé's paradox; status ``"ray"``) or several (Lemke returns one).
  A *sticking* contact (``v_t = 0``) gets the LCP above in accelerations.
* **3D friction is not built**: a polygonal cone is not Coulomb's circular cone, so the LCP
  would not be exact there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .lcp import solve_lcp, solve_pd_lcp

__all__ = ["ContactSolution", "delassus", "is_decoupled", "solve_forces", "solve_forces_friction",
           "solve_impact", "solve_impact_friction", "velocity_change"]

#: How the message of a frictional force problem with possibly several answers starts.
INDETERMINATE = "Painlevé: the contact force may not be unique"
#: Relative size below which an off-diagonal entry of W counts as zero (decoupled contacts).
DECOUPLED_TOL = 1e-12


@dataclass(frozen=True)
class ContactSolution:
    """Impulses (impact) or forces (held contacts) of ``nc`` contacts.

    Attributes
    ----------
    normal : ndarray, shape (nc,)
        Normal impulses ``P_n`` (N s) or forces ``lam_n`` (N), >= 0.
    tangent : ndarray, shape (nc,)
        Tangential impulses or forces along each contact's tangent (0 without friction).
    normal_rate : ndarray, shape (nc,)
        Normal velocity after the impact ``v_n+`` (m/s), or normal acceleration ``a_n`` (m/s^2).
    tangent_rate : ndarray, shape (nc,)
        The same along the tangents (zeros for a frictionless problem).
    status : str
        ``"solved"``, or an :data:`flexbody.lcp.STATUSES` value saying why not.
    message : str
    method : str
        ``"decoupled"`` (closed form per contact) or ``"lcp"``.
    pivots : int
        Lemke pivots (0 on the decoupled path).
    unique : bool
        False where other impulses or forces would be as consistent (Painlevé's
        indeterminate case; the message says so).
    """

    normal: np.ndarray
    tangent: np.ndarray
    normal_rate: np.ndarray
    tangent_rate: np.ndarray
    status: str
    message: str
    method: str
    pivots: int = 0
    unique: bool = True

    @property
    def solved(self) -> bool:
        """True when the impulses or forces are a checked solution."""
        return self.status == "solved"


def delassus(J: np.ndarray, M: np.ndarray) -> np.ndarray:
    """The contact-space inverse mass ``W = J M^-1 J^T``.

    Parameters
    ----------
    J : array_like, shape (m, nu)
        Contact rows (normal, then tangent rows for friction) of the velocity Jacobian.
    M : array_like, shape (nu, nu)
        Symmetric positive definite mass matrix.

    Returns
    -------
    ndarray, shape (m, m)
        Symmetric, positive semidefinite (definite when the rows of ``J`` are independent).
    """
    J = np.atleast_2d(np.asarray(J, dtype=float))
    W = J @ np.linalg.solve(np.asarray(M, dtype=float), J.T)
    return 0.5 * (W + W.T)  # exactly symmetric, so a permutation permutes it exactly


def velocity_change(J: np.ndarray, M: np.ndarray, impulses: np.ndarray) -> np.ndarray:
    """Generalized velocity change ``M^-1 J^T P`` of contact impulses ``P`` (shape (m,)); shape (nu,)."""
    J = np.atleast_2d(np.asarray(J, dtype=float))
    return np.linalg.solve(np.asarray(M, dtype=float), J.T @ np.asarray(impulses, dtype=float))


def is_decoupled(W: np.ndarray, tol: float = DECOUPLED_TOL) -> bool:
    """True when ``W`` (shape (m, m)) is diagonal: ``|W_ij| <= tol sqrt(W_ii W_jj)`` for ``i != j``."""
    W = np.asarray(W, dtype=float)
    d = np.sqrt(np.abs(np.diag(W)))
    off = np.abs(W - np.diag(np.diag(W)))
    return bool(np.all(off <= tol * np.outer(d, d)))


def solve_impact(W: np.ndarray, v_minus: np.ndarray, restitution: np.ndarray | float = 0.0, *,
                 touching: np.ndarray | None = None, fast: bool = True) -> ContactSolution:
    """Frictionless impulses of a simultaneous impact (Newton's law per contact).

    Parameters
    ----------
    W : array_like, shape (nc, nc)
        Delassus matrix of the normal rows.
    v_minus : array_like, shape (nc,)
        Normal velocities before the impact (< 0: approaching).
    restitution : float or array_like, shape (nc,)
        Newton's ``e`` in [0, 1] per contact.
    touching : array_like of bool, shape (nc,), optional
        Contacts at gap 0, which may take impulse (default: all).
    fast : bool
        Use the closed form when ``W`` is diagonal (:func:`is_decoupled`).

    Returns
    -------
    ContactSolution
        ``normal`` the impulses, ``normal_rate`` the velocities after.
    """
    W, v, e, on = _impact_args(W, v_minus, restitution, touching, 1)
    q = np.where(on, v + e * np.minimum(v, 0.0), 0.0)  # e acts on approaching contacts only
    P, status, message, method, pivots = _normal_lcp(W, q, on, fast)
    zeros = np.zeros_like(v)
    return ContactSolution(P, zeros, v + W @ P, zeros.copy(), status, message, method, pivots)


def solve_forces(W: np.ndarray, a_free: np.ndarray, *, fast: bool = True) -> ContactSolution:
    """Frictionless forces of held contacts: ``a = a_free + W lam >= 0`` complementary to ``lam >= 0``.

    Parameters
    ----------
    W : array_like, shape (nc, nc)
        Delassus matrix of the normal rows.
    a_free : array_like, shape (nc,)
        Normal accelerations of the contact points without contact forces.
    fast : bool
        Use the closed form ``lam_i = max(0, -a_free_i / W_ii)`` when ``W`` is diagonal.

    Returns
    -------
    ContactSolution
        ``normal`` the forces, ``normal_rate`` the accelerations; status ``"ray"`` when the
        held contacts admit no consistent force (contradictory constraints).
    """
    W, a, _, on = _impact_args(W, a_free, 0.0, None, 1)
    lam, status, message, method, pivots = _normal_lcp(W, a, on, fast)
    if status == "ray":
        message = f"no consistent contact force: the held contacts contradict each other ({message})"
    zeros = np.zeros_like(a)
    return ContactSolution(lam, zeros, a + W @ lam, zeros.copy(), status, message, method, pivots)


def solve_impact_friction(W: np.ndarray, v_minus: np.ndarray, restitution: np.ndarray | float,
                          mu: np.ndarray | float, *, touching: np.ndarray | None = None,
                          fast: bool = True) -> ContactSolution:
    """Impulses of a simultaneous 2D impact with Coulomb friction (Newton's law per contact).

    Parameters
    ----------
    W : array_like, shape (2 nc, 2 nc)
        Delassus matrix of the stacked rows ``[normal; tangent]``.
    v_minus : array_like, shape (2 nc,)
        Normal then tangential contact velocities before the impact.
    restitution, mu : float or array_like, shape (nc,)
        Newton's ``e`` in [0, 1] and Coulomb's ``mu >= 0`` per contact.
    touching : array_like of bool, shape (nc,), optional
        Contacts at gap 0 (default: all).
    fast : bool
        Use the closed form when ``W`` is diagonal: ``P_n = -(1 + e) v_n- / W_nn`` and a
        tangential impulse ``min(|v_t-| / W_tt, mu P_n)`` against ``v_t-``.

    Returns
    -------
    ContactSolution
        Impulses and the velocities after, normal and tangential.
    """
    W, v, e, on = _impact_args(W, v_minus, restitution, touching, 2)
    nc = e.size
    mu = _per_contact(mu, nc, "mu")
    vn, vt = v[:nc], v[nc:]
    qn = np.where(on, vn + e * np.minimum(vn, 0.0), 0.0)
    if fast and is_decoupled(W):
        Wn, Wt = np.diag(W)[:nc], np.diag(W)[nc:]
        Pn = np.where(on, np.maximum(-qn, 0.0) / Wn, 0.0)
        Pt = -np.sign(vt) * np.minimum(np.abs(vt) / Wt, mu * Pn)  # stop sliding, or slide on
        P = np.concatenate([Pn, Pt])
        return _friction_solution(W, v, P, "solved", "decoupled contacts: closed form.", "decoupled", 0)
    friction = on & (mu > 0.0)
    slide = np.zeros((nc, nc))  # impulses: every frictional contact gets the stick/slip rows
    P, status, message, pivots = _friction_lcp(W, qn, vt, mu, on, friction, slide)
    return _friction_solution(W, v, P, status, message, "lcp", pivots)


def solve_forces_friction(W: np.ndarray, a_free: np.ndarray, mu: np.ndarray | float,
                          v_t: np.ndarray, *, fast: bool = True) -> ContactSolution:
    """Forces of held 2D contacts with Coulomb friction; Painlevé's paradox is reported.

    A contact sliding (``v_t != 0``) gets the kinetic friction force ``-mu lam_n sign(v_t)``;
    a sticking one (``v_t == 0``) the stick/slip complementarity in accelerations.  The
    caller decides, with its own tolerance, which contacts slide (pass ``v_t`` = 0 exactly
    for those that stick).

    Parameters
    ----------
    W : array_like, shape (2 nc, 2 nc)
        Delassus matrix of the stacked rows ``[normal; tangent]``.
    a_free : array_like, shape (2 nc,)
        Normal then tangential accelerations of the contact points without contact forces.
    mu : float or array_like, shape (nc,)
        Coulomb's ``mu >= 0`` per contact.
    v_t : array_like, shape (nc,)
        Tangential (sliding) velocities of the contact points.
    fast : bool
        Use the closed form per contact when ``W`` is diagonal.

    Returns
    -------
    ContactSolution
        Forces and accelerations; status ``"ray"`` with the message "Painlevé: no consistent
        contact force" when none exists.  When one is found but the normal matrix with the
        sliding friction, ``W_nn + W_nt D`` (``D = diag(-mu sign(v_t))``), has a negative
        principal minor (Painlevé's indeterminate case: other forces may also be consistent;
        zero minors are redundant contacts, not flagged), the status
        stays ``"solved"`` and the message starts "Painlevé: the contact force may not be
        unique".
    """
    W, a, _, on = _impact_args(W, a_free, 0.0, None, 2)
    nc = on.size
    mu = _per_contact(mu, nc, "mu")
    v_t = np.asarray(v_t, dtype=float)
    if v_t.shape != (nc,) or not np.all(np.isfinite(v_t)):
        raise ValueError(f"`v_t` must be finite with shape ({nc},), got shape {v_t.shape}.")
    an, at = a[:nc], a[nc:]
    sliding = (mu > 0.0) & (v_t != 0.0)
    drag = np.diag(np.where(sliding, -mu * np.sign(v_t), 0.0))  # lam_t = drag lam_n when sliding
    if fast and is_decoupled(W):
        Wn, Wt = np.diag(W)[:nc], np.diag(W)[nc:]
        lam_n = np.maximum(-an, 0.0) / Wn
        stick = np.clip(-at / Wt, -mu * lam_n, mu * lam_n)  # held if it can be, else slip at mu lam_n
        lam = np.concatenate([lam_n, np.where(sliding, np.diag(drag) * lam_n, stick)])
        return _friction_solution(W, a, lam, "solved", "decoupled contacts: closed form.", "decoupled", 0)
    lam, status, message, pivots = _friction_lcp(W, an, at, mu, on, (mu > 0.0) & ~sliding, drag)
    unique = True
    if status == "ray":
        message = ("Painlevé: no consistent contact force (friction of a sliding contact would "
                   f"need the contact to pull; {message})")
    elif status == "solved" and sliding.any() and not _is_p0_matrix(W[:nc, :nc] + W[:nc, nc:] @ drag):
        unique = False
        message = (f"{INDETERMINATE} (with the sliding friction the "
                   f"normal matrix W_nn + W_nt D has a negative principal minor); one solution returned, "
                   f"{message}")
    return _friction_solution(W, a, lam, status, message, "lcp", pivots, unique)


def _is_p0_matrix(A: np.ndarray, largest: int = 12) -> bool:
    """True when no principal minor of ``A`` (shape (n, n)) is negative (a P0-matrix).

    Zero minors are redundant contacts (forces indeterminate even without friction), not
    Painlevé's case; a negative one is.  Checked for n <= ``largest`` (2^n minors); beyond
    that True is returned (no claim of ill-posedness).
    """
    n = A.shape[0]
    if n > largest:
        return True
    scale = np.abs(A).max()
    for mask in range(1, 2**n):
        S = [i for i in range(n) if mask >> i & 1]
        if np.linalg.det(A[np.ix_(S, S)]) < -1e-10 * scale ** len(S):
            return False
    return True
    scale = np.abs(A).max()
    for mask in range(1, 2**n):
        S = [i for i in range(n) if mask >> i & 1]
        if np.linalg.det(A[np.ix_(S, S)]) <= 1e-12 * scale ** len(S):
            return False
    return True


def _normal_lcp(W: np.ndarray, q: np.ndarray, on: np.ndarray, fast: bool
                ) -> tuple[np.ndarray, str, str, str, int]:
    """Solve ``W x + q >= 0 _|_ x >= 0`` over the contacts ``on``; x = 0 elsewhere."""
    x = np.zeros_like(q)
    if fast and is_decoupled(W):
        x[on] = np.maximum(-q[on], 0.0) / np.diag(W)[on]
        return x, "solved", "decoupled contacts: closed form.", "decoupled", 0
    idx = np.flatnonzero(on)
    status, message, pivots = "solved", "", 0
    blocks = independent_blocks(W[np.ix_(idx, idx)])
    alone = idx[[b[0] for b in blocks if len(b) == 1]]
    x[alone] = np.maximum(-q[alone], 0.0) / np.diag(W)[alone]  # a contact on its own: closed form
    for block in (b for b in blocks if len(b) > 1):
        rows = idx[block]
        block_W, block_q = W[np.ix_(rows, rows)], q[rows]
        sol = solve_pd_lcp(block_W, block_q)  # W is symmetric; positive definite unless redundant
        if sol is None or not sol.solved:
            sol = solve_lcp(block_W, block_q)
        x[rows] = sol.z
        pivots += sol.pivots
        if status == "solved":  # the first block that fails says why
            status, message = sol.status, sol.message
    return x, status, message, "lcp", pivots


def independent_blocks(A) -> list[np.ndarray]:
    """The rows of ``A`` (n, n; dense or scipy.sparse) in blocks that do not act on each other
    (``A[i, j] = 0`` and ``A[j, i] = 0`` between blocks), each ascending: a block-diagonal LCP
    is one LCP per block, exactly (a pile's held contacts: many small blocks, not one problem
    of all of them, whose pivots grow with its size)."""
    n = A.shape[0]
    if n < 2:
        return [np.arange(n)]
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    n_blocks, label = connected_components(csr_matrix(A != 0.0), directed=False)
    if n_blocks == 1:
        return [np.arange(n)]
    order = np.argsort(label, kind="stable")
    return np.split(order, np.flatnonzero(np.diff(label[order])) + 1)


def _friction_lcp(W: np.ndarray, qn: np.ndarray, qt: np.ndarray, mu: np.ndarray, on: np.ndarray,
                  friction: np.ndarray, drag: np.ndarray) -> tuple[np.ndarray, str, str, int]:
    """The 2D Coulomb LCP; returns the stacked ``[normal; tangent]`` impulses or forces.

    Unknowns ``[x_n (contacts on), x+ , x-, s (contacts in friction)]``.  ``drag`` (nc, nc),
    diagonal, gives the tangential part fixed by the normal one (sliding contacts at the
    force level, ``-mu sign(v_t)``); the columns of ``x_n`` carry it.
    """
    nc = on.size
    N, F = np.flatnonzero(on), np.flatnonzero(friction)
    nn, nf = N.size, F.size
    # Effect of the normal unknowns on all 2 nc rows, including the friction they drag along.
    C = W[:, :nc] + W[:, nc:] @ drag
    rows_n, rows_t = N, nc + F
    G = C[:, N]
    T = W[:, rows_t]  # effect of a tangential unknown (along +t)
    E = np.eye(nf)
    mu_rows = np.zeros((nf, nn))
    mu_rows[np.arange(nf), np.searchsorted(N, F)] = mu[F]
    A = np.block([
        [G[rows_n], T[rows_n], -T[rows_n], np.zeros((nn, nf))],
        [G[rows_t], T[rows_t], -T[rows_t], E],
        [-G[rows_t], -T[rows_t], T[rows_t], E],
        [mu_rows, -E, -E, np.zeros((nf, nf))],
    ])  # fmt: skip
    q = np.concatenate([qn[N], qt[F], -qt[F], np.zeros(nf)])
    sol = solve_lcp(A, q)
    x = np.zeros(2 * nc)
    x[N] = sol.z[:nn]
    x[nc:] = drag @ x[:nc]
    x[nc + F] = sol.z[nn:nn + nf] - sol.z[nn + nf:nn + 2 * nf]
    return x, sol.status, sol.message, sol.pivots


def _friction_solution(W: np.ndarray, v: np.ndarray, x: np.ndarray, status: str, message: str,
                       method: str, pivots: int, unique: bool = True) -> ContactSolution:
    """Wrap stacked impulses/forces ``x`` (2 nc,) and the rates ``v + W x`` they produce."""
    nc = x.size // 2
    rate = v + W @ x
    return ContactSolution(x[:nc], x[nc:], rate[:nc], rate[nc:], status, message, method, pivots, unique)


def _impact_args(W, v, restitution, touching, rows_per_contact: int
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Checked ``W`` (m, m), ``v`` (m,), ``e`` (nc,) and ``touching`` (nc,) with m = rows_per_contact nc."""
    W = np.asarray(W, dtype=float)
    v = np.asarray(v, dtype=float)
    if W.ndim != 2 or W.shape[0] != W.shape[1] or W.shape[0] % rows_per_contact:
        raise ValueError(f"`W` must be square with {rows_per_contact} row(s) per contact, got shape {W.shape}.")
    if v.shape != (W.shape[0],):
        raise ValueError(f"the contact velocities must have shape ({W.shape[0]},) to match `W`, got {v.shape}.")
    if not (np.all(np.isfinite(W)) and np.all(np.isfinite(v))):
        raise ValueError("`W` and the contact velocities must be finite (found inf or nan).")
    nc = W.shape[0] // rows_per_contact
    if np.any(np.diag(W)[:nc] <= 0.0):
        raise ValueError("`W` must have a positive diagonal (each contact row moves under its own impulse).")
    e = _per_contact(restitution, nc, "restitution")
    if np.any(e > 1.0):
        raise ValueError(f"`restitution` must be in [0, 1], got {e.max()!r}.")
    on = np.ones(nc, bool) if touching is None else np.asarray(touching, dtype=bool)
    if on.shape != (nc,):
        raise ValueError(f"`touching` must have shape ({nc},), got {on.shape}.")
    return W, v, e, on


def _per_contact(value, nc: int, name: str) -> np.ndarray:
    """A non-negative, finite scalar or per-contact array as shape (nc,)."""
    arr = np.asarray(value, dtype=float)
    if arr.ndim == 0:
        arr = np.full(nc, float(arr))
    if arr.shape != (nc,) or not np.all(np.isfinite(arr)) or np.any(arr < 0.0):
        raise ValueError(f"`{name}` must be a finite number >= 0 or {nc} of them, got {value!r}.")
    return arr
