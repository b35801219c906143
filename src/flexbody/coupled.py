"""Impacts of coupled contacts, solved exactly as one linear complementarity problem.

A rigid body's contacts couple: its Delassus matrix ``W = J M^-1 J^T`` is not diagonal, so
stopping each hit contact on its own, or all of them jointly, is not the impact law. At an
instant the touching contacts (those hit and those held) take impulses ``P >= 0`` with
Newton's law per contact, ``v+ + e v-  >= 0`` complementary to ``P``
(:func:`flexbody.contact_problems.solve_impact`, Lemke's method: exact, finite and
independent of the order of the contacts); where that law has no answer (a body pinched
between others with unequal restitution) the impact follows Poisson's two phases instead
(:func:`_poisson`).  A contact left at ``v+ = 0`` with a plastic law
is held; one that leaves (a rebound, or an end lifted by the others' impulses) is free.
The held contacts' forces are decided the same way (:func:`coupled_release`): Signorini's
law ``a = a_free + W lam >= 0`` complementary to ``lam >= 0`` as one LCP, so which contacts
lift off does not depend on the order they are tried in.  Used for whole-scene models with
rigid bodies (:attr:`flexbody.model.GeneratedModel.coupled`) and for contacts between
bodies (:mod:`flexbody.body_contact`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .constants import HELD, SLIDING
from .contact_problems import (UNALIGNED, delassus, independent_blocks, solve_forces, solve_forces_friction,
                               solve_impact, solve_impact_friction, velocity_change)
from .dynamics import contact_solve

#: Rows too slow to leave are stopped (:func:`coupled_impact`) only where that takes at most
#: this many times the kinetic energy of their speeds, each row alone (``v^2 / (2 W_ii)``):
#: far more means nearly parallel rows, whose stop would turn the motion along them.  So a
#: stop changes the velocities (in the kinetic metric) by at most ten times the stopped
#: rows' own speeds, each below the Zeno speed; two rows at an angle ``a`` take
#: ``1 / sin(a)^2`` times it, 100 at 5.7 degrees.  Measured in the bodies study's stiff 2D
#: pile: of 3 700 such stops 90 % take at most 1.08 times it, 3 take 12-100 and 14 take
#: 100-2e8 (a crease bent by 1e-4 rad: 1e8).  Two 3D spheres of a pile pressed face to face
#: (faces 15 degrees apart, each touching near the other's vertex) take up to 16 times it:
#: with a bound of 10 they rocked on the two rows, each impact of one lifting the other, 26
#: times within 1 ms ("chattering"; tests/test_zeno_stop.py).  A stop taking no more than
#: the rows' Zeno speeds would (each alone, ``floor^2 / (2 W_ii)``) turns nothing the
#: threshold does not already neglect, and is taken whatever this ratio; a stop beyond both
#: lets leave only the slow leaver whose stop takes the largest share of it, one at a time.
STOP_ENERGY = 100.0
#: How the message of an impact that Newton's law could not resolve starts (:func:`_poisson`).
POISSON = "Newton's law has no answer here"


class CoupledImpactError(RuntimeError):
    """The impact problem has no solution the solver could find (its status and message)."""


@dataclass(frozen=True)
class CoupledImpact:
    """The outcome of one instant's impacts.

    Attributes
    ----------
    y : ndarray, shape (ny,)
        The state after the impulses.
    loss : float
        Kinetic energy the impulses removed (J).
    impulses : ndarray, shape (nc,)
        Normal impulse of every contact (N s; 0 where it took none).
    leaving : ndarray of bool, shape (nc,)
        Touching contacts that separate after the impulses (normal velocity > ``speed_floor``).
    """

    y: np.ndarray
    loss: float
    impulses: np.ndarray
    leaving: np.ndarray


def _rounded(rates: np.ndarray, J: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Contact rates ``J x`` with what is round-off of their terms set to 0: a contact at rest
    reads +-1e-17 m/s, and a solver asked to keep that sign exactly would fail its check."""
    largest = float(abs(J).max()) if J.shape[0] * J.shape[1] else 0.0  # J dense or scipy.sparse
    level = 1e-13 * largest * float(np.abs(x).max(initial=0.0))
    return np.where(np.abs(rates) <= level, 0.0, rates)


def _within_rounding(solution, rates: np.ndarray, slowest: np.ndarray | float = 0.0,
                     restitution: np.ndarray | float = 0.0) -> bool:
    """Whether an ``inaccurate`` LCP answer misses Newton's or Signorini's law only by
    rounding: every impulse or force >= 0, and every contact rate >= 0 and complementary to
    it up to 1e-9 of the largest rate before, or up to ``slowest`` (per contact).  Lemke's
    final check is relative to each row; on semidefinite problems (two bodies' slots that
    constrain the same pair of points, a pile) a row can be off by 1e-12 of the others, and
    contacts stopped at an earlier instant keep ~1e-11 m/s of what was stopped.  What such
    an answer leaves approaching is at most that slow, and stays held: it is stopped
    exactly after the impulses, and the held forces' events watch the rest.  With Newton's
    ``restitution`` e (an impact's), the rate checked is the LCP's own, ``v+ + e v-`` for
    an approaching contact (``rates``: the velocities before): an impulse leaves its
    contact at ``-e v-``, not at rest."""
    if solution.status != "inaccurate":
        return False
    level = np.maximum(1e-9 * max(float(np.abs(rates).max(initial=0.0)), 1e-300), slowest)
    z, w = solution.normal, solution.normal_rate + restitution * np.minimum(rates, 0.0)
    level = np.broadcast_to(level, w.shape)
    return bool(np.all(z >= 0.0) and np.all(w >= -level) and np.all(np.abs(w) <= level, where=z > 0.0))


def _frictional(model, rows: np.ndarray) -> bool:
    """Whether any of the contacts ``rows`` has Coulomb friction (models with ``mu`` (nc,))."""
    return model.mu is not None and bool((model.mu[rows] > 0.0).any())


def _coupling(model, q: np.ndarray, u: np.ndarray, p: np.ndarray, rows: np.ndarray, tangents: bool = False):
    """The contacts ``rows``: their Jacobian ``J`` (k, c) on the coordinates ``columns`` (an
    index array, or every one), ``W = J M^-1 J^T`` (k, k), ``P -> M^-1 J^T P`` (nu,) and the
    gap accelerations' velocity terms (k,).  The model's own where it has them (contacts
    between bodies: the few particles they move, M diagonal), else from its dense matrices.
    With ``tangents`` (models with friction) the k tangent rows follow the k normal ones."""
    if model.contact_coupling is not None:
        return model.contact_coupling(q, u, p, rows, tangents)
    M, J = model.mass_matrix(q, p), model.gap_jacobian(q, p)[rows]
    return J, slice(None), delassus(J, M), lambda P: velocity_change(J, M, P), model.gap_bias(q, u, p)[rows]


def project_held(model, y: np.ndarray, p: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """The state ``y`` with the held contacts ``rows`` put back on what holds them: gap and
    normal velocity 0, each by the smallest change in the kinetic metric (one Gauss-Newton
    step ``dq = -M^-1 J^T W^-1 g``, with ``q' = u``; then ``du = -M^-1 J^T W^-1 J u``).

    Held contacts are kept on accelerations, and where a gap is not linear in the
    coordinates (a rigid body's, a contact between bodies) the integrator's error drifts it;
    the driver calls this when the drift exceeds a few gap tolerances.  The velocity step
    removes kinetic energy ``(J u)^T W^-1 (J u) / 2`` (second order in the drift)."""
    nq, nu = model.nq, model.nu
    out = np.array(y, float)
    q, u = out[:nq], out[nq : nq + nu]
    _, _, W, response, _ = _coupling(model, q, u, p, rows)
    q += response(-contact_solve(W, model.held_gaps(q, p, rows)))
    J, cols, W, response, _ = _coupling(model, q, u, p, rows)
    u += response(-contact_solve(W, J @ u[cols]))
    return out


def coupled_impact(model, y: np.ndarray, p: np.ndarray, touching: np.ndarray, restitution: np.ndarray,
                   slowest: np.ndarray, zeno_rise: float = 0.0, notes: list[str] | None = None) -> CoupledImpact:
    """Impulses on the ``touching`` contacts (bool, shape (nc,)) by Newton's law per contact.

    Parameters
    ----------
    model : GeneratedModel
        Gives ``mass_matrix``, ``gap_jacobian`` and ``energies``.
    y : ndarray, shape (ny,)
    p : ndarray, shape (np,)
    touching : ndarray of bool, shape (nc,)
        Contacts at the ground (hit now, or held): the only ones that may take impulse.
    restitution : ndarray, shape (nc,)
        Newton's e per contact (0 where a rebound would be too slow: plastic).
    slowest : ndarray, shape (nc,)
        A contact the impulses leave slower than this (m/s) is stopped with the held ones:
        it would not rise 1e-9 of the scene's size (:data:`flexbody.constants.ZENO_RISE`),
        as for rebounds.  Without it a block rocking on two corners would lift each off the
        other's plastic impact, ever faster (an accumulation of impacts, Zeno).  The kinetic
        energy this takes is at most that of those speeds.
    zeno_rise : float, optional
        The rise (m) ``slowest`` stands for, against its pull (gravity along a ground's
        normal; between bodies |g|, at least 1 m/s^2).  A contact that would leave faster
        but is pulled back harder (``a``: minus its gap's acceleration after the impulses
        with every contact set free) is also stopped when it leaves slower than ``sqrt(2 a zeno_rise)``:
        it would not rise that far either.  Without it a particle pressed into a notch
        far harder than by its weight (a pile's) was handed flank to flank more than 25
        times within 1 ms on its way to the Zeno threshold (``chattering``).
    notes : list of str, optional
        Receives the message of a 3D frictional answer that missed Coulomb's circular law
        (:func:`_note_unaligned`).

    Raises
    ------
    CoupledImpactError
        When the solver reports no solution (its message).
    """
    nq, nu = model.nq, model.nu
    q, u = y[:nq], y[nq : nq + nu]
    rows = np.flatnonzero(touching)
    impulses = np.zeros(model.n_contacts)
    leaving = np.zeros(model.n_contacts, bool)
    if not len(rows):
        return CoupledImpact(np.array(y, float), 0.0, impulses, leaving)
    k = len(rows)
    friction = _frictional(model, rows)
    J, cols, W, response, _ = _coupling(model, q, u, p, rows, friction)
    e = restitution[rows]

    def newton(v_minus: np.ndarray, e: np.ndarray):
        """Newton's law at the contact velocities ``v_minus``: the solution and its stacked impulses."""
        if friction:  # Coulomb's law per contact too: normal and tangential impulses, one LCP
            solution = solve_impact_friction(W, v_minus, e, model.mu[rows], dim=model.dim)
            return solution, np.concatenate([solution.normal, _blocks(solution.tangent)])
        solution = solve_impact(W, v_minus, e)
        return solution, solution.normal

    def found(solution, v_minus: np.ndarray, e: np.ndarray) -> bool:
        # left approaching slower than a Zeno rebound, a contact is stopped below anyway
        return solution.solved or _within_rounding(solution, v_minus[:k], slowest[rows], e)

    v_minus = _rounded(J @ u[cols], J, u[cols])
    solution, P = newton(v_minus, e)
    if not found(solution, v_minus, e):
        poisson = _poisson(newton, found, W, v_minus, e, k, solution.message) if e.any() else None
        if poisson is None:
            raise CoupledImpactError(f"the impact of contacts {rows.tolist()} has no solution found: {solution.message}")
        solution, P = poisson
        if notes is not None:
            notes.append(f"the impact of contacts {rows.tolist()}: {solution.message}")
    _note_unaligned(solution, rows, notes)
    out = np.array(y, float)
    u_new = u + response(P)
    impulses[rows] = solution.normal
    floor = np.maximum(slowest[rows], 1e-12)
    leaving_now = solution.normal_rate > floor
    if zeno_rise > 0.0 and leaving_now.any():  # only those that would leave: is their own pull harder?
        pull = _held_back(model, np.concatenate([q, u_new, y[nq + nu :]]), p, rows[leaving_now])
        floor[leaving_now] = np.maximum(floor[leaving_now], np.sqrt(2.0 * pull * zeno_rise))
    leaves = solution.normal_rate > floor
    while (~leaves).any():  # what stays is stopped exactly (v+ = 0 up to round-off, or too slow to leave)
        stopped = np.flatnonzero(~leaves)
        if friction:  # and what sticks keeps sticking: else that stop's impulse would slide it
            stuck = ~leaves & (model.mu[rows] > 0.0) & (_speeds(solution.tangent_rate) <= np.maximum(slowest[rows], 1e-12))
            stopped = np.concatenate([stopped, *(k * (j + 1) + np.flatnonzero(stuck) for j in range(model.dim - 1))])
        rates, W_stopped = J[stopped] @ u_new[cols], W[np.ix_(stopped, stopped)]
        extra = np.zeros(len(J))
        extra[stopped] = contact_solve(W_stopped, -rates)
        # A slow leaver stopped with a nearly parallel row (a particle sliding over a
        # crease bent by 1e-4 rad leaves one of its two faces at 3e-5 m/s) is no Zeno
        # rebound: stopping both turns its slide, with impulses far beyond its speed's (the
        # stop took half the speed of a 0.4 m/s slide).  Then that slow leaver leaves.
        # Relative to speeds at round-off this ratio says nothing: a stop within the energy
        # of the rows' Zeno speeds changes the velocities by no more than the threshold
        # neglects (two flexible boxes face to face, rows at 1e-9 m/s: 1e6 times their own,
        # 6e-4 of that).
        share = extra[stopped] * (W_stopped @ extra[stopped])  # each row's part of 2 taken
        taken = 0.5 * float(share.sum())
        own = 0.5 * float(np.sum(rates**2 / np.diag(W_stopped)))
        zeno = 0.5 * float(np.sum(floor[stopped % k] ** 2 / np.diag(W_stopped)))
        slow = np.flatnonzero((stopped < k) & (rates > 0.0))
        if taken > max(STOP_ENERGY * own, zeno) and len(slow):
            # Only the row whose stop takes the most is turned, then the rest is tried again:
            # the others (a corner held on the ground at 1e-18 m/s beside three edge rows of
            # one vertex, nearly equal) stay, not lifted off to hit again 1e-7 s later.
            leaves[stopped[slow[np.argmax(share[slow])]]] = True
            continue
        u_new = u_new + response(extra)
        impulses[rows] += extra[:k]
        break
    out[nq : nq + nu] = u_new
    before = float(model.energies(q, u, p)[0])
    after = float(model.energies(q, u_new, p)[0])
    leaving[rows] = leaves
    return CoupledImpact(out, before - after, impulses, leaving)


def _poisson(newton, found, W: np.ndarray, v_minus: np.ndarray, e: np.ndarray, k: int, why: str):
    """Poisson's two phases where Newton's law has no answer (``why``: its solver's message):
    the solution and its stacked impulses, or None where a phase found none.

    Newton's law can ask for the impossible where restitution differs between contacts that
    act on each other: a body pinched between two others, hit on one side (``e > 0``) while
    touching on the other, would have to leave both.  Its LCP is then infeasible (Lemke ends
    on a secondary ray): with ``z >= 0`` and ``J^T z = 0``, ``q . z = sum e_i min(v_i, 0)
    z_i < 0``.  Instead: *compression*, the plastic impact (``e = 0``, always solvable, also
    with friction: Anitescu & Potra), impulses ``P_c``; then *restitution*, the normal
    impulses ``e P_c`` applied, and from the velocities they give another plastic impact,
    so that nothing is left approaching (Glocker's Poisson law: each contact's restitution
    impulse at least ``e`` times its compression's).  Both phases are plastic impacts at
    velocities ``J u`` of the bodies, so both have answers.  For one contact, or where
    the restitution impulses leave every contact, this is Newton's ``v+ = -e v-``.  The
    friction of the restitution phase is bounded by that phase's own normal impulse, so the
    total impulse lies in Coulomb's cone."""
    plastic = np.zeros_like(e)
    compressed, P_c = newton(v_minus, plastic)
    if not found(compressed, v_minus, plastic):
        return None
    kick = np.zeros_like(P_c)
    kick[:k] = e * compressed.normal
    v_kicked = v_minus + W @ (P_c + kick)  # J M^-1 J^T P: the contacts' velocities after P
    restored, P_r = newton(v_kicked, plastic)
    if not found(restored, v_kicked, plastic):
        return None
    P = P_c + kick + P_r
    pivots = compressed.pivots + restored.pivots
    return dataclasses.replace(
        restored, normal=P[:k], tangent=compressed.tangent + restored.tangent, pivots=pivots,
        message=(f"{POISSON} ({why.rstrip('.')}): Poisson's two phases were used, compression and restitution, "
                 f"each a plastic impact ({pivots} pivots).")), P


def _held_back(model, y: np.ndarray, p: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """How hard each contact ``rows (k,)`` is pulled back onto its surface at ``y`` with no
    contact holding anything (m/s^2, >= 0): minus its gap's free acceleration, shape (k,)."""
    nq, nu = model.nq, model.nu
    free, _ = model.rhs(y, p, np.zeros(model.n_contacts, np.intc), np.zeros(model.n_contacts))
    J, cols, _, _, bias = _coupling(model, y[:nq], y[nq : nq + nu], p, rows)
    return np.maximum(0.0, -(J @ free[nq : nq + nu][cols] + bias))


def coupled_release(model, y: np.ndarray, p: np.ndarray, held: np.ndarray, push: np.ndarray, leaving: np.ndarray,
                    force_tolerance: np.ndarray, codes: np.ndarray | None = None,
                    notes: list[str] | None = None, speed_tolerance: float = np.inf
                    ) -> tuple[np.ndarray, np.ndarray]:
    """Held contacts that lift off: Signorini's law over the ``held`` contacts as one LCP.

    Parameters
    ----------
    held : ndarray of bool, shape (nc,)
    push : ndarray, shape (nc,)
        Prescribed normal forces (the thesis mode's windows), as for the right-hand side.
    leaving : ndarray of bool, shape (nc,)
        Held contacts whose force event fired: released where the LCP's force is at most
        ``force_tolerance`` (the crossing itself, where force and acceleration are both ~0).
    force_tolerance : ndarray, shape (nc,)
    codes : ndarray of int, shape (nc,), optional
        The held contacts' laws (``Phases.held``): with friction, a ``SLIDING`` contact's
        friction is ``-mu lam`` against its slip, and the others stick (Coulomb's LCP).
        A contact slipping faster than ``speed_tolerance`` slides whatever its code (one
        that starts on the ground, or was just hit, while moving along it).
    notes : list of str, optional
        Receives the solver's message when the forces found may not be the only consistent
        ones (Painlevé's indeterminate case, :func:`_note_indeterminate`).

    Returns
    -------
    release : ndarray of bool, shape (nc,)
        The held contacts that lift off (their force would pull).
    implied : ndarray of bool, shape (nc,)
        Held contacts the LCP gives no force while they stay (acceleration 0): with more
        contacts than the body has freedoms (a box flat on four corners) the forces are not
        unique, and the LCP's answer carries the weight on the others.  They are set free
        without an event: their gap stays 0 because the held ones imply it, and if that
        changes, their gap event finds them.  Without friction, so is one the LCP leaves
        without force, accelerating away below the release floor, that held at 0 would pull
        (:func:`_held_pulling`: a row within rounding of the others' span).

    Raises
    ------
    CoupledImpactError
        When the held contacts admit no consistent force.
    """
    nq, nu = model.nq, model.nu
    release = np.zeros(model.n_contacts, bool)
    implied = np.zeros(model.n_contacts, bool)
    rows = np.flatnonzero(held)
    if not len(rows):
        return release, implied
    q, u = y[:nq], y[nq : nq + nu]
    free, _ = model.rhs(y, p, np.zeros(model.n_contacts, np.intc), push)
    k = len(rows)
    friction = _frictional(model, rows)
    J, cols, W, _, bias = _coupling(model, q, u, p, rows, friction)
    acc = free[nq : nq + nu][cols]
    a_free = _rounded(J @ acc + bias, J, acc)
    if friction:
        codes = np.zeros(model.n_contacts, np.intc) if codes is None else np.asarray(codes)
        solution = solve_forces_friction(W, a_free, model.mu[rows],
                                         _sliding_rates(J, u[cols], rows, codes, speed_tolerance), dim=model.dim)
        _note_indeterminate(solution, rows, notes)
        _note_unaligned(solution, rows, notes)
        J, a_free = J[:k], a_free[:k]  # the normal rows decide who lifts off
    else:
        solution = solve_forces(W, a_free)
    if not (solution.solved or _within_rounding(solution, a_free)):
        raise CoupledImpactError(f"the forces of held contacts {rows.tolist()} have no solution found: "
                                 f"{solution.message}")
    # a contact without force leaves where it accelerates away beyond round-off of the others' terms
    floor = 1e-10 * max(1.0, float(np.abs(a_free).max()))
    lifted = (solution.normal == 0.0) & (solution.normal_rate > floor)
    release[rows] = lifted | (leaving[rows] & (solution.normal <= force_tolerance[rows]))
    unloaded = (solution.normal == 0.0) & ~release[rows]
    if unloaded.any():
        implied[rows] = unloaded & _redundant(J, unloaded)  # the others carry it
        if not friction:  # the segment's solve holds the rest at 0: none of them may pull there
            kept = ~release[rows] & ~implied[rows]
            implied[rows] |= unloaded & _held_pulling(W, a_free, kept, force_tolerance[rows])
    return release, implied


def _held_pulling(W: np.ndarray, a_free: np.ndarray, kept: np.ndarray, force_tolerance: np.ndarray) -> np.ndarray:
    """Which of the ``kept`` rows (bool (k,)) would pull, bool (k,): their forces as the
    segment's right-hand side takes them, every kept row's acceleration held at 0 (the
    ordered Cholesky of :func:`flexbody.dynamics.contact_solve` on their block of ``W``),
    below ``-force_tolerance`` (k,).  The LCP leaves a row without force while it
    accelerates away slower than its release floor; holding it then takes that rate off
    through ``W``'s near-null direction, where its row is within rounding of another's but
    not in their span (a vertex's slot and the edge row at that vertex, 2e-6 apart: 1.5e-9
    m/s^2 held off by -2.35 N on the slot, +2.39 N on the edge), and its lift-off event,
    starting below 0, never fires."""
    out = np.zeros(len(kept), bool)
    rows = np.flatnonzero(kept)
    if not len(rows):
        return out
    out[rows] = contact_solve(W[np.ix_(rows, rows)], -a_free[rows]) < -force_tolerance[rows]
    return out


def _redundant(J: np.ndarray, asked: np.ndarray) -> np.ndarray:
    """Which of the ``asked`` rows (bool (k,)) of ``J`` (k, c) are in the span of the other
    rows, bool (k,): those with a share in a left null vector (``z^T J = 0``), the rank
    counting singular values above 1e-9 of ``J``'s largest entry.  Only such a row is held
    at its constraint by the others when it carries no force; a row without force beside
    two dependent rows elsewhere is not.  Rows that share no coordinate are independent of
    each other, so the null space is found per block of rows linked through shared columns
    (a pile's held contacts fall into many small blocks: one SVD of the whole took a third
    of a second)."""
    out = np.zeros(len(J), bool)
    if len(J) < 2:
        return out
    from scipy.sparse import csr_matrix

    tol = 1e-9 * max(1.0, float(np.abs(J).max()))
    links = csr_matrix(J != 0.0)
    for block in independent_blocks(links @ links.T):  # rows sharing a column, directly or not
        if len(block) < 2 or not asked[block].any():
            continue
        rows = J[block]
        used = rows[:, (rows != 0.0).any(axis=0)]
        U, singular, _ = np.linalg.svd(used)
        rank = int((singular > tol).sum())
        if rank < len(block):  # left null vectors: U's columns past the rank (unit vectors)
            out[block] = asked[block] & (np.linalg.norm(U[:, rank:], axis=1) > NULL_SHARE)
    return out


#: A row's share in the left null space above which :func:`_redundant` counts it.
NULL_SHARE = 1e-6


def _sliding_rates(J: np.ndarray, u: np.ndarray, rows: np.ndarray, codes: np.ndarray,
                   speed_tolerance: float = np.inf) -> np.ndarray:
    """Slip rates of the held contacts ``rows`` that slide (code SLIDING, or faster than
    ``speed_tolerance``), from the tangent rows of ``J`` (dim k, c): (k,) in 2D, (k, 2) in
    3D; 0 for those that stick, and for a sliding one at its stop (exactly, or within
    ``speed_tolerance`` where one is given: the instant's friction stops such a slip, and
    its direction there is round-off), which the LCP then treats as sticking."""
    slip = _slip_rates(J, u, len(rows))
    speed = _speeds(slip)
    at_stop = np.isfinite(speed_tolerance) & (speed <= speed_tolerance)
    sliding = ((codes[rows] == SLIDING) & ~at_stop) | (speed > speed_tolerance)
    return np.where(sliding[:, None] if slip.ndim == 2 else sliding, slip, 0.0)


def _slip_rates(J: np.ndarray, u: np.ndarray, k: int) -> np.ndarray:
    """The slip rates of k contacts from the tangent rows of ``J`` (dim k, c): (k,) in 2D,
    (k, 2) in 3D (along each contact's t1, t2), as the solvers of
    :mod:`flexbody.contact_problems` take them."""
    slip = J[k:] @ u
    return slip if len(slip) == k else slip.reshape(-1, k).T


def _speeds(rates: np.ndarray) -> np.ndarray:
    """Each contact's slip speed: ``|rate|`` of (k,) rates, the row norms of (k, 2) ones."""
    return np.abs(rates) if rates.ndim == 1 else np.linalg.norm(rates, axis=1)


def _blocks(tangent: np.ndarray) -> np.ndarray:
    """Tangential impulses or forces as the tangent blocks of the stacked rows: (k,) in 2D,
    the (k, 2) components of 3D as t1's block then t2's, shape (2 k,)."""
    return tangent if tangent.ndim == 1 else tangent.T.ravel()


def _note_indeterminate(solution, rows: np.ndarray, notes: list[str] | None) -> None:
    """Keep the message of a frictional force problem solved where other forces may be
    consistent too (Painlevé's indeterminate case: the run goes on with Lemke's answer, and
    its warnings say so)."""
    if notes is not None and solution.solved and not solution.unique:
        notes.append(f"held contacts {rows.tolist()}: {solution.message}")


def _note_unaligned(solution, rows: np.ndarray, notes: list[str] | None) -> None:
    """Keep the message of a 3D frictional answer whose friction directions did not reach
    Coulomb's circular law (:data:`flexbody.contact_problems.UNALIGNED`).  It met the normal
    law (else the caller raised), and its friction lies in each contact's disc (an inscribed
    square's), but not exactly against the slip: the run goes on with it, and its warnings
    say where."""
    if notes is not None and solution.status == "inaccurate" and solution.message.startswith(UNALIGNED):
        notes.append(f"contacts {rows.tolist()}: {solution.message}")


def _turned_back(model, y: np.ndarray, p: np.ndarray, phases, rows: np.ndarray, leaving: np.ndarray,
                 speed_tolerance: float) -> np.ndarray:
    """Which sliding 3D contacts ``rows`` (k,) stop here although their slip is not 0: their
    event fired where their slip, turning, has no part left along its direction at the
    step's start (the friction's direction through the step).  In 2D a slip that stops
    crosses 0; in 3D it passes by 0, and what is left across that direction, bool (k,), is
    what friction held at one direction let through in the last step, not a slide: a
    flexible body's contact nearly at rest slips at ~1e-5 m/s, turning every few
    microseconds, and held on sliding it fired that event 551 times in 1.5 ms (two
    icosahedra stacked).  Stopped like a slow slip (its kinetic energy is in the ledger), it
    then sticks or slides from rest as the force LCP decides.  A ground contact solved alone
    (per particle), and in 3D any contact, counts only where its slip was held
    (``slips_held``): else its friction followed the slip through the step."""
    vt = model.friction(y, p, phases.held, phases.push)[0][rows]
    along = np.einsum("kd,kd->k", vt, model.slip_directions(p)[rows])
    # a ground contact the inner model solves alone follows its slip within a step, unless held
    alone = np.zeros(len(rows), bool)
    ground = rows < model.n_ground_contacts
    alone[ground] = model.solved_alone(y, p, phases.held, phases.push)[rows[ground]]
    held_along = (~alone & (model.dim == 2)) | (model.slips_held(p)[rows] != 0)
    return leaving[rows] & (phases.phase[rows] == SLIDING) & held_along & (along <= speed_tolerance)


def coupled_friction_phases(model, t: float, y: np.ndarray, p: np.ndarray, phases, leaving: np.ndarray,
                            was_held: np.ndarray, force_tolerance: np.ndarray, speed_tolerance: float,
                            notes: list[str] | None = None):
    """Coulomb friction of coupled held contacts once their normal forces are settled: stick
    or slip decided jointly (the twin of :func:`flexbody.contact.friction_phases` for
    contacts that couple; ``phases`` is updated in place).

    Frictional held contacts slower than ``speed_tolerance`` (and in 3D those whose slip
    turned back, :func:`_turned_back`) are stopped along their tangents together (every held
    contact's normal velocity kept at 0); the others slide on.  The
    stopped ones then stick unless Coulomb's LCP in accelerations
    (:func:`flexbody.contact_problems.solve_forces_friction`, the sliding ones' friction at
    ``-mu lam``) has them slip (a tangential acceleration beyond round-off, or at the limit
    where their slack event fired).

    Returns
    -------
    y : ndarray, shape (ny,)
    loss : float
        Kinetic energy removed by stopping the slow slips (J).
    events : list of flexbody.contact.Event
        "stick" for sliding contacts that now stick, "slip" for sticking ones that now slide.

    Raises
    ------
    CoupledImpactError
        When no consistent contact force exists (Painlevé's paradox), with the solver's message.
    """
    from .contact import Event  # here: flexbody.contact imports this module

    nq, nu = model.nq, model.nu
    rows = np.flatnonzero(phases.on_ground)
    if not len(rows) or not _frictional(model, rows):
        return y, 0.0, []
    k, mu, dim = len(rows), model.mu[rows], model.dim
    q, u = y[:nq], y[nq : nq + nu]
    J, cols, W, response, bias = _coupling(model, q, u, p, rows, True)
    slip = _slip_rates(J, u[cols], k)
    slow = (mu > 0.0) & (_speeds(slip) <= speed_tolerance)
    if dim == 3:
        slow |= (mu > 0.0) & _turned_back(model, y, p, phases, rows, leaving, speed_tolerance)
    loss = 0.0
    if (slip[slow] != 0.0).any():  # stop the slow slips, holding every normal velocity at 0
        chosen = np.concatenate([np.arange(k), *(k * (j + 1) + np.flatnonzero(slow) for j in range(dim - 1))])
        P = np.zeros(dim * k)
        P[chosen] = contact_solve(W[np.ix_(chosen, chosen)], -(J[chosen] @ u[cols]))
        y = np.array(y, float)
        y[nq : nq + nu] = u + response(P)
        loss = float(model.energies(q, u, p)[0] - model.energies(q, y[nq : nq + nu], p)[0])
        u = y[nq : nq + nu]
        J, cols, W, response, bias = _coupling(model, q, u, p, rows, True)  # the velocity terms are u's
        slip = _slip_rates(J, u[cols], k)
    free, _ = model.rhs(y, p, np.zeros(model.n_contacts, np.intc), phases.push)
    acc = free[nq : nq + nu][cols]
    a_free = _rounded(J @ acc + bias, J, acc)
    moving = (mu > 0.0) & ~slow
    solution = solve_forces_friction(W, a_free, mu, np.where(moving[:, None] if dim == 3 else moving, slip, 0.0),
                                     dim=dim)
    _note_indeterminate(solution, rows, notes)
    _note_unaligned(solution, rows, notes)
    if not (solution.solved or _within_rounding(solution, a_free[:k])):
        raise CoupledImpactError(f"the friction of held contacts {rows.tolist()} has no solution found: "
                                 f"{solution.message}")
    floor = 1e-10 * max(1.0, float(np.abs(a_free).max()))
    slack = mu * solution.normal - _speeds(solution.tangent)
    slips = slow & ((_speeds(solution.tangent_rate) > floor) | (leaving[rows] & (slack <= force_tolerance[rows])))
    before = phases.phase[rows].copy()
    after = np.where(moving | slips, SLIDING, HELD)
    after = np.where(mu > 0.0, after, before)
    phases.phase[rows] = after
    if len(phases.started):
        phases.started[rows[slips & (after == SLIDING)]] = True  # from rest: round-off slips
    events = [Event(t, int(c), "stick") for c in rows[(before == SLIDING) & (after == HELD)]]
    events += [Event(t, int(c), "slip") for c in rows[(before == HELD) & (after == SLIDING) & was_held[rows]]]
    return y, loss, events
