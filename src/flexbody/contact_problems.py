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
velocity, impulse or force points along ``t_i``.  The 3D ones (``dim=3``) take ``W`` of
``[normal rows; first-tangent rows; second-tangent rows]``, ``(3 nc, 3 nc)``, i.e.
``delassus(np.vstack([Jn, Jt1, Jt2]), M)``, each contact's ``(t1, t2)`` an orthonormal pair
of its tangent plane; their tangential results have shape ``(nc, 2)`` (components along
``t1``, ``t2``).  Velocities and accelerations are those of the contact points along these
directions.

* **Impact** (an instant; Newton's law per contact): impulses ``P >= 0`` with
  ``v+ = v- + W P``, and ``v+ + e v-  >= 0`` complementary to ``P``.  Which contacts may
  take impulse: every *touching* contact (gap 0), whether it approaches or not; restitution
  acts only on approaching ones (``v- < 0``), a touching contact that does not approach
  only gets ``v+ >= 0``.  Including the non-approaching ones is necessary: a bar landing on
  one end can drive its other, resting or even separating end into the ground.  Contacts
  with a gap (``touching`` False) take none.  With several contacts this is one choice
  among impact laws (the thesis's "indeterminate multiple simultaneous impact"), and it is
  not energy-consistent in general; nor has it always an answer (a body pinched between
  others with unequal ``e``: :func:`flexbody.coupled._poisson`).  The kinetic energy changes by
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
* **Friction in 3D** (Coulomb's circular cone: ``|f| <= mu P_n``, and ``f = -mu P_n w / |w|``
  where the tangential rate after, ``w``, is not 0).  The LCP above is the case ``K = 2`` of a
  polygonal cone: friction ``f = sum_j beta_j d_j`` over ``K`` unit directions ``d_j`` of the
  tangent plane, ``beta_j >= 0``, with ``d_j . w + s >= 0 _|_ beta_j`` and
  ``mu P_n - sum_j beta_j >= 0 _|_ s``.  In 3D each contact gets ``K = 4``,
  ``d_j = (cos(th + j pi/2), sin(th + j pi/2))`` in its ``(t1, t2)`` plane, turned by an angle
  ``th`` of its own.  An inscribed square is not the circle: a sticking contact's ``f`` lies
  in the square, so in the disc, but a sliding one's sits on a corner or an edge of the
  square, not against ``w`` in general.  **An answer whose squares are aligned is Coulomb's
  exactly**: where a contact slides and its square has the corner ``d_2 = -w / |w|``, the row
  of ``d_2`` gives ``s >= |w| > 0``, so ``sum_j beta_j = mu P_n``; and ``beta_j > 0`` needs
  ``d_j . w = -s <= -|w|``, which only ``d_2`` reaches (the others give 0 or ``|w|``), so
  ``f = mu P_n d_2 = -mu P_n w / |w|``.

  *Alignment.*  Each ``th`` starts along the contact's tangential rate before (``v_t-``, or
  the free acceleration; 0 where it is 0).  Turning ``th`` to the angle of the ``w`` it
  produced and solving again (a fixed-point iteration) does not work in general: where the
  square's friction sits on an edge, maximal dissipation pins ``w`` to that edge's normal,
  exactly 45 degrees from the corners, whatever the true slip; and ``angle(w)`` turns
  against ``th`` with slope ``-mu P_n (e.W_tt e) / |w|`` (one contact, ``e`` across the slip),
  below -1 where friction nearly stops the slip, so there the fixed point repels.
  Measured, that iteration cycled in about half of random coupled impacts and in most of a
  rigid box's landings on 2-4 corners.  So each round takes the *pattern* the polygonal
  answer shows (which contacts hold, which of them stick, which slide) and solves it with
  round friction: a sliding contact's friction is ``-mu P_n (cos a, sin a)``, as at the force
  level, and Newton's method finds the slip angles ``a`` with ``angle(w) = a`` (the pattern
  is linear in the unknowns, so its Jacobian is exact).  First a contact that the square let
  slide but whose stick friction fits in the disc (to the check's tolerance: the square's
  corner often puts it on the circle to a rounding) is made to stick; a slide whose Newton
  iteration does not align is taken again from its stick friction, reversed (a slow slip
  leaves from there); afterwards a sticking one whose friction leaves the disc slides, and a
  held one that would pull lets go.  The answer
  solves the polygonal LCP whose squares have a corner against each slip and along each
  sticking friction, so by the argument above it is Coulomb's if its pattern is right: it is
  accepted if it passes the check below, else the LCP of those squares gives the next round
  its pattern.

  *What is guaranteed.*  Every 3D answer returned as ``"solved"`` has been checked against the
  circular law and the normal law, to :data:`COULOMB_TOL` relative (the normal law as the LCP
  checks it).  That the rounds reach such an answer is **not proven**: Newton's method may not
  converge for a pattern, and patterns may alternate.  After :data:`ALIGN_ROUNDS` rounds, or a
  round that turns no square, the last polygonal answer is returned as ``"inaccurate"`` with
  its misfit and the number of rounds.  Measured: one round for most problems (the first
  LCP's pattern is right); of 300 random impacts of 1-4 coupled contacts (12 coordinates)
  2 ended ``"inaccurate"``, of 800 landings of a rigid box on 1-4 corners (redundant contacts:
  singular ``W``, impulses not unique) 9, all on 2-4 corners.  Before the stick tolerance,
  the restart and the stall rule of :func:`_newton_slips`: 1 and 13; 6 of those 14 are
  solved now, and 3 that were solved are not (on such hard cases the rounds' outcome turns
  on small changes).  A fuzz's 3D piles with friction: every force problem that ended
  ``"inaccurate"`` (after 27-50 rounds, ~1 s each) is solved in one round.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from .lcp import solve_lcp, solve_pd_lcp

__all__ = ["ContactSolution", "delassus", "is_decoupled", "solve_forces", "solve_forces_friction",
           "solve_impact", "solve_impact_friction", "velocity_change"]

#: How the message of a frictional force problem with possibly several answers starts.
INDETERMINATE = "Painlevé: the contact force may not be unique"
#: How the message of a 3D frictional answer that missed the circular law starts ("inaccurate").
UNALIGNED = "the friction directions did not converge"
#: Relative size below which an off-diagonal entry of W counts as zero (decoupled contacts),
#: and below which a 3D contact's two tangential diagonal entries count as equal.
DECOUPLED_TOL = 1e-12
#: Most alignment rounds (polygonal LCPs) of the 3D friction before it gives up ("inaccurate").
ALIGN_ROUNDS = 50
#: Relative misfit of the contact laws (of mu P_n for friction) the 3D answer's check allows.
COULOMB_TOL = 1e-9
#: A round that turns no friction direction by more than this (rad) cannot change the next LCP;
#: Newton's method on the slips stops within it (below, its steps only stir the rounding: on
#: random coupled impacts a converged iteration went on for ~30 patterns at 1e-15 to 1e-14).
ALIGN_ANGLE = 1e-12
#: Tangential rate (relative to its terms) below which a contact of a polygonal answer sticks.
SLIP_TOL = 1e-12
#: Newton steps on the slip directions of one stick/slip pattern, and the pattern's corrections.
NEWTON_STEPS, PATTERN_SWEEPS = 30, 5


@dataclass(frozen=True)
class ContactSolution:
    """Impulses (impact) or forces (held contacts) of ``nc`` contacts.

    Attributes
    ----------
    normal : ndarray, shape (nc,)
        Normal impulses ``P_n`` (N s) or forces ``lam_n`` (N), >= 0.
    tangent : ndarray, shape (nc,) or, in 3D, (nc, 2)
        Tangential impulses or forces along each contact's tangent (0 without friction); in
        3D the components along ``(t1, t2)``.
    normal_rate : ndarray, shape (nc,)
        Normal velocity after the impact ``v_n+`` (m/s), or normal acceleration ``a_n`` (m/s^2).
    tangent_rate : ndarray, shape (nc,) or, in 3D, (nc, 2)
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
                          fast: bool = True, dim: int = 2) -> ContactSolution:
    """Impulses of a simultaneous impact with Coulomb friction (Newton's law per contact).

    Parameters
    ----------
    W : array_like, shape (dim nc, dim nc)
        Delassus matrix of the stacked rows ``[normal; tangent]`` (2D) or
        ``[normal; first tangent; second tangent]`` (3D).
    v_minus : array_like, shape (dim nc,)
        Contact velocities before the impact, in the rows of ``W``.
    restitution, mu : float or array_like, shape (nc,)
        Newton's ``e`` in [0, 1] and Coulomb's ``mu >= 0`` per contact.
    touching : array_like of bool, shape (nc,), optional
        Contacts at gap 0 (default: all).
    fast : bool
        Use the closed form when ``W`` is diagonal (in 3D also with equal tangential entries
        per contact): ``P_n = -(1 + e) v_n- / W_nn`` and a tangential impulse
        ``min(|v_t-| / W_tt, mu P_n)`` against ``v_t-``.
    dim : int
        2 or 3: the 3D circular friction cone is solved by aligned polygonal LCPs (module
        docstring); the message says how many.

    Returns
    -------
    ContactSolution
        Impulses and the velocities after, normal and tangential (tangential of shape
        ``(nc, 2)`` in 3D).  Status ``"inaccurate"`` in 3D when the friction directions did
        not converge to the circular law.
    """
    dim = _checked_dim(dim)
    W, v, e, on = _impact_args(W, v_minus, restitution, touching, dim)
    nc = e.size
    mu = _per_contact(mu, nc, "mu")
    vn, vt = v[:nc], v[nc:]
    qn = np.where(on, vn + e * np.minimum(vn, 0.0), 0.0)
    if fast and _decoupled(W, nc):
        Wn, Wt = np.diag(W)[:nc], _moving(np.diag(W)[nc:])
        Pn = np.where(on, np.maximum(-qn, 0.0) / Wn, 0.0)
        if dim == 2:
            Pt = -np.sign(vt) * np.minimum(np.abs(vt) / Wt, mu * Pn)  # stop sliding, or slide on
        else:
            Pt = _into_disc(-vt / Wt, mu * Pn)  # the same, radially
        P = np.concatenate([Pn, Pt])
        return _friction_solution(nc, W, v, P, "solved", "decoupled contacts: closed form.", "decoupled", 0)
    friction = on & (mu > 0.0)
    slide = np.zeros(((dim - 1) * nc, nc))  # impulses: every frictional contact gets the stick/slip rows
    P, status, message, pivots = _friction_lcp(W, qn, vt, mu, on, friction, slide)
    return _friction_solution(nc, W, v, P, status, message, "lcp", pivots)


def solve_forces_friction(W: np.ndarray, a_free: np.ndarray, mu: np.ndarray | float,
                          v_t: np.ndarray, *, fast: bool = True, dim: int = 2) -> ContactSolution:
    """Forces of held contacts with Coulomb friction; Painlevé's paradox is reported.

    A contact sliding (``v_t`` not 0) gets the kinetic friction force ``-mu lam_n v_t / |v_t|``
    (``-mu lam_n sign(v_t)`` in 2D); a sticking one (``v_t`` exactly 0) the stick/slip
    complementarity in accelerations.  The caller decides, with its own tolerance, which
    contacts slide (pass ``v_t`` = 0 exactly for those that stick).

    Parameters
    ----------
    W : array_like, shape (dim nc, dim nc)
        Delassus matrix of the stacked rows ``[normal; tangent]`` (2D) or
        ``[normal; first tangent; second tangent]`` (3D).
    a_free : array_like, shape (dim nc,)
        Accelerations of the contact points without contact forces, in the rows of ``W``.
    mu : float or array_like, shape (nc,)
        Coulomb's ``mu >= 0`` per contact.
    v_t : array_like, shape (nc,) or, in 3D, (nc, 2)
        Tangential (sliding) velocities of the contact points.
    fast : bool
        Use the closed form per contact when ``W`` is diagonal (in 3D also with equal
        tangential entries per contact).
    dim : int
        2 or 3 (3D: aligned polygonal LCPs, module docstring).

    Returns
    -------
    ContactSolution
        Forces and accelerations (tangential of shape ``(nc, 2)`` in 3D); status ``"ray"``
        with the message "Painlevé: no consistent contact force" when none exists.  When one
        is found but the normal matrix with the sliding friction, ``W_nn + W_nt D`` (``D``,
        shape ``((dim - 1) nc, nc)``, holds ``-mu v_t / |v_t|`` of the sliding contacts), has
        a negative principal minor (Painlevé's indeterminate case: other forces may also be
        consistent; zero minors are redundant contacts, not flagged), the status stays
        ``"solved"`` and the message starts "Painlevé: the contact force may not be unique".
    """
    dim = _checked_dim(dim)
    W, a, _, on = _impact_args(W, a_free, 0.0, None, dim)
    nc = on.size
    mu = _per_contact(mu, nc, "mu")
    v_t = np.asarray(v_t, dtype=float)
    shape = (nc,) if dim == 2 else (nc, 2)
    if v_t.shape != shape or not np.all(np.isfinite(v_t)):
        raise ValueError(f"`v_t` must be finite with shape {shape} (dim={dim}), got shape {v_t.shape}.")
    an, at = a[:nc], a[nc:]
    slip = v_t.reshape(nc, dim - 1)
    speed = _lengths(slip)
    sliding = (mu > 0.0) & (speed > 0.0)
    along = slip / np.where(sliding, speed, 1.0)[:, None]  # the slip's unit direction (sign in 2D)
    kinetic = np.where(sliding[:, None], -mu[:, None] * along, 0.0)  # lam_t / lam_n when sliding
    drag = np.vstack([np.diag(k) for k in kinetic.T])  # lam_t = drag lam_n: ((dim - 1) nc, nc)
    if fast and _decoupled(W, nc):
        Wn, Wt = np.diag(W)[:nc], _moving(np.diag(W)[nc:])
        lam_n = np.maximum(-an, 0.0) / Wn
        if dim == 2:
            stick = np.clip(-at / Wt, -mu * lam_n, mu * lam_n)  # held if it can be, else slip at mu lam_n
        else:
            stick = _into_disc(-at / Wt, mu * lam_n)  # the same, radially
        lam = np.concatenate([lam_n, np.where(np.tile(sliding, dim - 1), (kinetic * lam_n[:, None]).T.ravel(), stick)])
        return _friction_solution(nc, W, a, lam, "solved", "decoupled contacts: closed form.", "decoupled", 0)
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
    return _friction_solution(nc, W, a, lam, status, message, "lcp", pivots, unique)


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
    for k in range(1, n + 1):  # the minors of each size in one call (one per minor took 58 ms at n = 12)
        S = np.array(list(itertools.combinations(range(n), k)))
        if (np.linalg.det(A[S[:, :, None], S[:, None, :]]) < -1e-10 * scale**k).any():
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


#: :func:`independent_blocks` of dense problems of at most this many rows takes the closure
#: of their coupling (a few products of n x n matrices), not SciPy's connected components,
#: whose set-up costs half a millisecond: a pile of discs solves thousands of problems of
#: 2 to 13 rows, and they took 6 % of its run.
DENSE_BLOCKS = 64


def independent_blocks(A) -> list[np.ndarray]:
    """The rows of ``A`` (n, n; dense or scipy.sparse) in blocks that do not act on each other
    (``A[i, j] = 0`` and ``A[j, i] = 0`` between blocks), each ascending: a block-diagonal LCP
    is one LCP per block, exactly (a pile's held contacts: many small blocks, not one problem
    of all of them, whose pivots grow with its size)."""
    n = A.shape[0]
    if n < 2:
        return [np.arange(n)]
    if n <= DENSE_BLOCKS and isinstance(A, np.ndarray):
        # rows linked by a path of nonzeros: the path lengths double with each product
        linked = ((A != 0.0) | (A != 0.0).T | np.eye(n, dtype=bool)).astype(float)
        while True:
            wider = ((linked @ linked) > 0.0).astype(float)
            if (wider == linked).all():
                break
            linked = wider
        label = linked.argmax(axis=1)  # each row's block by its first row
    else:
        from scipy.sparse import csr_matrix
        from scipy.sparse.csgraph import connected_components

        label = connected_components(csr_matrix(A != 0.0), directed=False)[1]
    if (label == label[0]).all():
        return [np.arange(n)]
    order = np.argsort(label, kind="stable")
    return np.split(order, np.flatnonzero(np.diff(label[order])) + 1)


def _friction_lcp(W: np.ndarray, qn: np.ndarray, qt: np.ndarray, mu: np.ndarray, on: np.ndarray,
                  friction: np.ndarray, drag: np.ndarray) -> tuple[np.ndarray, str, str, int]:
    """The Coulomb problem; returns the stacked impulses or forces ``x`` (dim nc,), a status,
    a message and the pivots of all LCPs solved.

    ``W`` (dim nc, dim nc) and ``qt`` ((dim - 1) nc,), the tangential rates before (velocities
    or free accelerations), give ``dim``.  In 2D one polygonal LCP is Coulomb's law.  In 3D
    the polygons are turned until an answer is aligned, which is then Coulomb's (module
    docstring); every answer returned as solved has passed :func:`_law_misfit`.
    """
    nc = on.size
    if W.shape[0] == 2 * nc:  # 2D: the two directions +-t are the whole cone
        return _polygon_lcp(W, qn, qt, mu, on, friction, drag)
    angles = _angles(_planar(qt))  # a first guess of the slip: the rate before
    total, moved = 0, np.inf
    for rounds in range(1, ALIGN_ROUNDS + 1):
        x, status, message, pivots = _polygon_lcp(W, qn, qt, mu, on, friction, drag, angles)
        total += pivots
        if status != "solved":
            return x, status, f"{message[:-1]} (polygonal friction cone, alignment round {rounds}).", total
        if _law_misfit(W, qn, qt, x, mu, on, friction).max() <= COULOMB_TOL:
            return x, "solved", (f"circular Coulomb friction in {rounds} alignment round(s) (the polygonal "
                                 f"LCP's answer); {total} pivots."), total
        aligned, turned = _align(W, qn, qt, mu, on, friction, drag, x, angles)
        if _law_misfit(W, qn, qt, aligned, mu, on, friction).max() <= COULOMB_TOL:
            return aligned, "solved", (f"circular Coulomb friction in {rounds} alignment round(s) (slip "
                                       f"directions aligned by Newton's method); {total} pivots."), total
        moved = float(np.abs(_wrap(turned - angles)).max())
        angles = turned
        if moved <= ALIGN_ANGLE:  # the next LCP would be this one
            break
    misfit = _law_misfit(W, qn, qt, x, mu, on, friction)
    worst = int(np.argmax(misfit))
    return x, "inaccurate", (
        f"{UNALIGNED}: after {rounds} alignment round(s) the answer of contact "
        f"{worst} misses the circular Coulomb law by {misfit[worst]:.3g} (relative; the last round turned a "
        f"direction by {moved:.3g} rad); {total} pivots."), total


def _align(W: np.ndarray, qn: np.ndarray, qt: np.ndarray, mu: np.ndarray, on: np.ndarray,
           friction: np.ndarray, drag: np.ndarray, x: np.ndarray, angles: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray]:
    """Align the slips of the stick/slip pattern that a polygonal answer ``x`` (3 nc,) shows.

    The pattern: which contacts hold (``P_n > 0``), which of those stick and which slide.
    A contact the square lets slide may stick in the circle (its stick friction fits in the
    disc but not in the square): it is tried sticking first.  Then Newton's method turns the
    sliding ones' friction against their slips (:func:`_newton_slips`), and a sticking one
    whose friction leaves the disc, or a held one that would pull, changes side.

    Returns
    -------
    aligned : ndarray, shape (3 nc,)
        The pattern's answer (for :func:`_law_misfit` to judge).
    turned : ndarray, shape (nc,)
        Angles whose squares put a corner against each slip and along each sticking friction:
        ``aligned`` solves the polygonal LCP of these.
    """
    nc = on.size
    q = np.concatenate([qn, qt])
    f, w = _planar(x[nc:]), _planar((q + W @ x)[nc:])
    held = on & (x[:nc] > 0.0)
    loaded = friction & held
    terms = _lengths(_planar(np.abs(qt) + np.abs(W[nc:]) @ np.abs(x)))
    slides = loaded & (_lengths(w) > SLIP_TOL * terms)
    slip = _angles(-f)  # a slide's friction is against its slip: start there
    leaves = np.full(nc, np.nan)  # a refused stick's friction, reversed: where its slip leaves from
    for i in np.flatnonzero(slides):
        trial = slides.copy()
        trial[i] = False
        y, _, _, holds = _pattern(W, q, mu, drag, held, loaded & ~trial, trial, slip)
        # In the disc to the law's tolerance, as `over` judges a sticking one below: a stick
        # whose friction lies on the circle to a rounding (the square's corner put it there)
        # has no slide to align, its rate's angle jumps by pi across its own direction.
        # Measured in a fuzzed pile: 377 of 428 such slides 7e-13 to 1.2e-12 over mu P_n,
        # each one's Newton iteration spent 300 patterns cycling across that jump.
        if holds and np.hypot(y[nc + i], y[2 * nc + i]) <= (1.0 + COULOMB_TOL) * mu[i] * y[i]:
            slides = trial
        elif holds and y[i] > 0.0 and np.hypot(y[nc + i], y[2 * nc + i]) > 0.0:  # a direction to leave from
            leaves[i] = np.arctan2(-y[2 * nc + i], -y[nc + i])
    for _ in range(PATTERN_SWEEPS):
        slip, y, holds, misfit = _newton_slips(W, q, mu, drag, held, loaded & ~slides, slides, slip)
        retry = slides & np.isfinite(leaves)
        # (an angle misfit of d rad misses the law by about d relative: the check's tolerance)
        if misfit > COULOMB_TOL and retry.any():
            # A slide whose stick friction barely leaves the disc slips slowly, and its rate's
            # angle turns fast with its friction's: Newton's basin is narrow there, and the
            # square's corner can start outside it (measured: 5.4e-3 rad off in a fuzzed
            # pile, a slip 2.3e-4 of its terms, Newton stalled at pi/2 for 50 rounds).  Such
            # a slip leaves along its stick friction, reversed: taken again from there.
            again = _newton_slips(W, q, mu, drag, held, loaded & ~slides, slides, np.where(retry, leaves, slip))
            if again[3] < misfit and (again[2] or not holds):  # better aligned, its rows holding
                slip, y, holds, misfit = again
        leaves[:] = np.nan  # the trial sticks were this pattern's
        f = _planar(y[nc:])
        over = loaded & ~slides & (_lengths(f) > (1.0 + COULOMB_TOL) * mu * y[:nc])
        pulls = held & (y[:nc] < 0.0)
        if not holds or not (over.any() or pulls.any()):
            break
        slip = np.where(over, _angles(-f), slip)
        held, loaded, slides = held & ~pulls, loaded & ~pulls, (slides | over) & ~pulls
    return y, np.where(slides, slip, np.where(loaded, _angles(f), angles))


def _pattern(W: np.ndarray, q: np.ndarray, mu: np.ndarray, drag: np.ndarray, held: np.ndarray,
             stick: np.ndarray, slide: np.ndarray, slip: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """The answer of one 3D stick/slip pattern, a linear system.

    The normal rows of the ``held`` contacts and both tangential rows of the ``stick`` ones are
    held at 0; a ``slide`` contact's friction is ``-mu P_n (cos slip, sin slip)`` (against its
    slip direction), ``drag``'s contacts keep theirs; all other unknowns are 0.  ``W`` is
    singular for redundant contacts (a rigid body on four corners): least squares then picks
    one of the answers, and a pattern whose rows contradict each other is reported.

    Returns
    -------
    x : ndarray, shape (3 nc,)
    Z : ndarray, shape (3 nc, k)
        ``x = Z y`` for the pattern's ``k`` unknowns ``y`` (normal of held, tangential of stick).
    rows : ndarray, shape (k,)
        The rows held at 0.
    holds : bool
        Whether those rows are 0 (to :data:`COULOMB_TOL` of their terms).
    """
    nc = mu.size
    turn = np.column_stack([np.cos(slip), np.sin(slip)])
    kinetic = drag - np.vstack([np.diag(np.where(slide, mu * turn[:, c], 0.0)) for c in range(2)])
    K = np.flatnonzero(stick)
    unit = np.zeros((3 * nc, 2 * K.size))
    unit[np.concatenate([nc + K, 2 * nc + K]), np.arange(2 * K.size)] = 1.0
    Z = np.hstack([np.vstack([np.eye(nc), kinetic])[:, held], unit])  # a held P_n drags its friction along
    rows = np.concatenate([np.flatnonzero(held), nc + K, 2 * nc + K])
    A = (W @ Z)[rows]
    y = least_squares(A, -q[rows])
    left = np.abs(A @ y + q[rows])
    holds = bool(np.all(left <= COULOMB_TOL * (np.abs(A) @ np.abs(y) + np.abs(q[rows])) + np.finfo(float).tiny))
    return Z @ y, Z, rows, holds


def _newton_slips(W: np.ndarray, q: np.ndarray, mu: np.ndarray, drag: np.ndarray, held: np.ndarray,
                  stick: np.ndarray, slide: np.ndarray, slip: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray, bool, float]:
    """Newton's method on ``g_i = angle(w_i) - slip_i = 0`` (wrapped to [-pi, pi)) over the
    ``slide`` contacts of a pattern (:func:`_pattern`): each one's tangential rate ``w_i``
    along the slip its friction opposes.  The Jacobian is exact for the pattern.  A step is
    halved until ``max |g|`` shrinks (the smallest is taken anyway, to leave a shallow
    minimum); three steps in a row that do not bring it below the least yet end the
    iteration (the least, not the last: where ``g`` jumps, a rate passing through 0, the
    smallest steps alternate across the jump, each a little below the one before it).

    Returns the slip angles (nc,) it ended at, the pattern's answer there (3 nc,), whether
    its rows hold and its ``max |g|`` (rad; 0 without slides).
    """
    nc = mu.size
    S, k = np.flatnonzero(slide), np.arange(slide.sum())

    def at(slip):  # the pattern's answer, its slides' rates and their misfit g
        x, Z, rows, holds = _pattern(W, q, mu, drag, held, stick, slide, slip)
        w = _planar((q + W @ x)[nc:])[S]
        return x, Z, rows, holds, w, _wrap_pi(_angles(w) - slip[S])

    x, Z, rows, holds, w, g = at(slip)
    stalls, least = 0, np.abs(g).max(initial=0.0)
    for _ in range(NEWTON_STEPS if S.size else 0):
        if np.abs(g).max() <= ALIGN_ANGLE or stalls == 3:  # aligned to a thousandth of the law's check
            break
        # d x / d slip_i: slide i's friction -mu P_n (cos, sin) turns, then the unknowns respond
        dx = np.zeros((3 * nc, S.size))
        dx[nc + S, k] = mu[S] * x[S] * np.sin(slip[S])
        dx[2 * nc + S, k] = -mu[S] * x[S] * np.cos(slip[S])
        dx += Z @ least_squares((W @ Z)[rows], -(W @ dx)[rows])
        dw = W[nc:] @ dx
        rates = (w**2).sum(axis=1)
        if not ((rates > 0.0).all() and np.isfinite(g).all()):
            break  # a slide whose rate is 0 has no angle to align: its answer is checked as it stands
        J = (w[:, :1] * dw[nc + S] - w[:, 1:] * dw[S]) / rates[:, None] - np.eye(S.size)
        step = least_squares(J, -g)
        for t in 0.5 ** np.arange(10):
            trial = slip.copy()
            trial[S] += t * step
            new = at(trial)
            if np.abs(new[-1]).max() < np.abs(g).max():
                break
        stalls = 0 if np.abs(new[-1]).max() < least else stalls + 1
        least = min(least, np.abs(new[-1]).max())
        slip, (x, Z, rows, holds, w, g) = trial, new
    # the last point, not the best: measured on random problems, returning the best one the
    # steps passed (often the start, where Newton does not converge) left 29 of 1 100
    # "inaccurate" instead of 11: the next pattern starts better from where the steps went
    return slip, x, holds, float(np.abs(g).max(initial=0.0))


def _polygon_lcp(W: np.ndarray, qn: np.ndarray, qt: np.ndarray, mu: np.ndarray, on: np.ndarray,
                 friction: np.ndarray, drag: np.ndarray, angles: np.ndarray | None = None
                 ) -> tuple[np.ndarray, str, str, int]:
    """One LCP of a polygonal friction cone; returns the stacked impulses or forces (dim nc,).

    Unknowns ``[x_n (contacts on), beta_0, ..., beta_{K-1}, s (contacts in friction)]``, each
    ``beta_j`` the friction along direction ``j`` of every frictional contact: ``+-t`` in 2D
    (``K = 2``; ``beta_0, beta_1`` are ``P+, P-``), the square turned by ``angles`` (nc,) in
    3D (``K = 4``).  ``drag`` ((dim - 1) nc, nc) gives the tangential part fixed by the
    normal one (sliding contacts at the force level, ``-mu v_t / |v_t|``); the columns of
    ``x_n`` carry it.
    """
    nc = on.size
    N, F = np.flatnonzero(on), np.flatnonzero(friction)
    nn, nf = N.size, F.size
    d = _cone_directions(None if angles is None else angles[F], nf)  # (K, nf, dim - 1)
    K, planes = d.shape[0], d.shape[2]
    # B ((dim - 1) nc, K nf): column (j, k) is direction j of contact F[k] in the tangent rows,
    # so the friction is B beta and the rows d_j . w are B^T w.
    B = np.zeros((planes * nc, K * nf))
    B[np.arange(planes) * nc + F[:, None], np.arange(K)[:, None, None] * nf + np.arange(nf)[:, None]] = d
    # Effect of the normal unknowns on all dim nc rows, including the friction they drag along.
    C = W[:, :nc] + W[:, nc:] @ drag
    G = C[:, N]
    T = W[:, nc:] @ B  # effect of a friction unknown (along its direction)
    E = np.eye(nf)
    mu_rows = np.zeros((nf, nn))
    mu_rows[np.arange(nf), np.searchsorted(N, F)] = mu[F]
    A = np.block([
        [G[N], T[N], np.zeros((nn, nf))],
        [B.T @ G[nc:], B.T @ T[nc:], np.tile(E, (K, 1))],
        [mu_rows, -np.tile(E, (1, K)), np.zeros((nf, nf))],
    ])  # fmt: skip
    q = np.concatenate([qn[N], B.T @ qt, np.zeros(nf)])
    sol = solve_lcp(A, q)
    x = np.zeros(W.shape[0])
    x[N] = sol.z[:nn]
    x[nc:] = drag @ x[:nc] + B @ sol.z[nn:nn + K * nf]
    return x, sol.status, sol.message, sol.pivots


def least_squares(A: np.ndarray, b: np.ndarray, rcond: float | None = None) -> np.ndarray:
    """The least-norm least-squares ``x`` of ``A x = b`` (``A`` (m, k), ``b`` (m,)), singular
    values below ``rcond`` of the largest dropped (default: NumPy's): LAPACK's
    divide-and-conquer SVD (``gelsd``, NumPy's), and where that does not converge the
    QR-iteration SVD (``gelss``), which does.  (Measured: a fuzz's 70 x 70 stick/slip pattern
    of condition 3.8, its singular values clustered at 21.05, stopped a run with "SVD did not
    converge"; ``gelss`` solves it to 4e-14.)"""
    try:
        return np.linalg.lstsq(A, b, rcond=rcond)[0]
    except np.linalg.LinAlgError:
        import scipy.linalg

        cond = np.finfo(float).eps * max(np.shape(A)) if rcond is None else rcond
        return scipy.linalg.lstsq(A, b, cond=cond, lapack_driver="gelss")[0]


def _cone_directions(angles: np.ndarray | None, nf: int) -> np.ndarray:
    """Directions of the polygonal cone of ``nf`` contacts, shape (K, nf, dim - 1): ``+-t``
    (2D, ``angles`` None) or ``d_j = (cos(th + j pi/2), sin(th + j pi/2))`` for ``th`` in
    ``angles`` (nf,) (3D), built from one cosine and sine so opposite ones are exactly opposite."""
    if angles is None:
        return np.stack([np.ones((nf, 1)), -np.ones((nf, 1))])
    first = np.column_stack([np.cos(angles), np.sin(angles)])
    second = np.column_stack([-first[:, 1], first[:, 0]])  # first turned by pi/2
    return np.stack([first, second, -first, -second])


def _law_misfit(W: np.ndarray, qn: np.ndarray, qt: np.ndarray, x: np.ndarray, mu: np.ndarray,
                on: np.ndarray, friction: np.ndarray) -> np.ndarray:
    """How far a 3D answer ``x`` (3 nc,) is from the contact laws, per contact (nc,): 0 on them.

    Normal (as the LCP's own check): ``P_n >= 0``, 0 where not ``on``; the normal rate
    ``qn + (W x)_n`` at least 0, and 0 where ``P_n > 0``, relative to the size of its terms
    ``|qn| + |W_n| |x|``.  Friction of the ``friction`` contacts, Coulomb's circular law
    ``|f| <= mu P_n`` and ``|w| f + mu P_n w = 0`` (``f`` against a nonzero tangential rate
    ``w``, anywhere in the disc where ``w = 0``), relative to ``mu P_n``; the second residual is
    divided by the size of ``w``'s terms (at least ``|w|``): a slip of that size must have ``f``
    against it to the tolerance, a slip at the rounding level of its terms has no direction to
    hold ``f`` to.  Misfits within the rounding level of the problem count as 0, and so do
    those within ``COULOMB_TOL`` of its largest rate or impulse: the answer of a stick/slip
    pattern is a linear solve, exact to its condition times the rounding, not to the
    rounding alone (measured in fuzzes: contacts carrying no impulse read a friction of
    2.3e-12 N s, or a normal rate of -6.3e-13 m/s, where the largest rate was 0.12 m/s:
    misfits of 2.9e3 and 0.99 against the rounding floor, warned of as unconverged).
    """
    nc = mu.size
    q = np.concatenate([qn, qt])
    rate, terms = q + W @ x, np.abs(q) + np.abs(W) @ np.abs(x)
    eps = 16 * x.size * np.finfo(float).eps
    tiny = np.finfo(float).tiny
    floor = eps * np.abs(W).max() * np.abs(x).max() + max(eps, COULOMB_TOL) * np.abs(q).max() + tiny  # rates
    level = max(eps, COULOMB_TOL) * np.abs(x).max() + tiny  # impulses

    def relative(excess, size):
        return np.maximum(excess - floor, 0.0) / np.maximum(size, floor)

    Pn, f, w = x[:nc], _planar(x[nc:]), _planar(rate[nc:])
    pull = np.where(on, np.maximum(-Pn, 0.0), np.abs(Pn))
    gap = np.where(Pn > 0.0, np.abs(rate[:nc]), np.maximum(-rate[:nc], 0.0))
    normal = np.maximum(np.maximum(pull - level, 0.0) / np.abs(x).max().clip(level),
                        np.where(on, relative(gap, terms[:nc]), 0.0))
    bound = mu * Pn
    against = _lengths(_lengths(w)[:, None] * f + bound[:, None] * w) / np.maximum(_lengths(_planar(terms[nc:])),
                                                                                   floor)
    coulomb = np.where(friction, np.maximum(_lengths(f) - bound, against), 0.0)
    return np.maximum(normal, np.maximum(coulomb - level, 0.0) / np.maximum(bound, level))


def _friction_solution(nc: int, W: np.ndarray, v: np.ndarray, x: np.ndarray, status: str, message: str,
                       method: str, pivots: int, unique: bool = True) -> ContactSolution:
    """Wrap stacked impulses/forces ``x`` (dim nc,) of ``nc`` contacts and the rates ``v + W x``
    they produce; the tangential parts as (nc,) in 2D, (nc, 2) in 3D."""
    rate = v + W @ x
    if x.size == 2 * nc:
        return ContactSolution(x[:nc], x[nc:], rate[:nc], rate[nc:], status, message, method, pivots, unique)
    return ContactSolution(x[:nc], _planar(x[nc:]), rate[:nc], _planar(rate[nc:]), status, message, method,
                           pivots, unique)


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


def _checked_dim(dim) -> int:
    """``dim``, 2 or 3, as an int; a ValueError naming it otherwise."""
    if isinstance(dim, bool) or dim not in (2, 3):
        raise ValueError(f"`dim` must be 2 or 3, got {dim!r}.")
    return int(dim)


def _decoupled(W: np.ndarray, nc: int) -> bool:
    """True when every contact of ``W`` (dim nc, dim nc) has its closed form: ``W`` diagonal and,
    in 3D, each contact's two tangential entries equal (to :data:`DECOUPLED_TOL`), so its
    tangential response is a multiple of the impulse (isotropic)."""
    if not is_decoupled(W):
        return False
    if W.shape[0] == 2 * nc:
        return True
    t1, t2 = np.diag(W)[nc:].reshape(2, nc)
    return bool(np.all(np.abs(t1 - t2) <= DECOUPLED_TOL * np.maximum(t1, t2)))


def _planar(x: np.ndarray) -> np.ndarray:
    """Stacked 3D tangential rows ``[t1 rows; t2 rows]`` (2 nc,) as ``(t1, t2)`` per contact (nc, 2)."""
    return x.reshape(2, -1).T


def _lengths(x: np.ndarray) -> np.ndarray:
    """Euclidean length of each row of ``x`` (nc, 1 or 2), without overflow or underflow."""
    return np.abs(x[:, 0]) if x.shape[1] == 1 else np.hypot(x[:, 0], x[:, 1])


def _angles(x: np.ndarray) -> np.ndarray:
    """The angle of each row of ``x`` (nc, 2) in its plane (rad), 0 for a zero row."""
    return np.where(_lengths(x) > 0.0, np.arctan2(x[:, 1], x[:, 0]), 0.0)


def _wrap(angle: np.ndarray) -> np.ndarray:
    """An angle change modulo pi/2, in [-pi/4, pi/4): the square of directions is the same
    turned by pi/2."""
    return (angle + np.pi / 4) % (np.pi / 2) - np.pi / 4


def _wrap_pi(angle: np.ndarray) -> np.ndarray:
    """An angle in [-pi, pi)."""
    return (angle + np.pi) % (2 * np.pi) - np.pi


def _moving(Wt: np.ndarray) -> np.ndarray:
    """The tangential diagonal ``Wt`` of decoupled contacts with 1 for a row that moves
    nothing (an edge contact's: frictionless, no tangent rows), whose rate is then 0 and
    its force 0, not 0 / 0."""
    return np.where(Wt > 0.0, Wt, 1.0)


def _into_disc(f: np.ndarray, radius: np.ndarray) -> np.ndarray:
    """Stacked 3D tangential vectors ``f`` (2 nc,) scaled radially down to length ``radius`` (nc,)
    where they are longer."""
    length = _lengths(_planar(f))
    shrink = np.where(length > radius, radius / np.where(length > 0.0, length, 1.0), 1.0)
    return f * np.tile(shrink, 2)
