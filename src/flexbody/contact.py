"""Contact phases and what happens at an event instant (thesis ch. 4, DESIGN §1).

Each contact (a particle against a ground) is in one phase:

* ``FREE``: no constraint force; its event is the gap reaching the ground while approaching.
* ``HELD`` (contact): the constraint force ``lam >= 0`` keeps its gap acceleration zero
  (eq. 4.8-4.9); its event is ``lam`` turning negative (it would pull): lift-off.
* ``PUSHED`` (thesis impact mode only): the estimated impact force ``-m v_n / dT``
  (eq. 4.6) acts for ``dT``; then the contact is resolved like a fresh touch.

:func:`resolve` is the fixed point applied at an event instant: impacts (``v_n < 0``
strictly), then the constraint forces are recomputed (the dampers see the velocity jump),
contacts whose force would pull are released, and this repeats until nothing changes.
Contact forces of point masses on flat grounds decouple (``J M^-1 J^T`` is diagonal), so
this is the exact solution of the contact complementarity problem, in any order.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .model import Model

FREE, HELD, PUSHED = 0, 1, 2


@dataclass
class Phases:
    """Per-contact state of the phase machine, arrays of shape (nc,)."""

    phase: np.ndarray  # FREE / HELD / PUSHED
    floor: np.ndarray  # a FREE contact's event fires when its gap falls to this level (m): 0, or
    # a hair below where the contact was released on the ground
    push: np.ndarray  # normal force of PUSHED contacts (N), 0 elsewhere
    push_until: np.ndarray  # end of each PUSHED window (s), inf elsewhere

    @classmethod
    def all_free(cls, nc: int) -> Phases:
        """Every contact free and armed at the ground itself (floor 0)."""
        return cls(np.zeros(nc, int), np.zeros(nc), np.zeros(nc), np.full(nc, np.inf))

    @property
    def held(self) -> np.ndarray:
        """1 where held, as the C ABI wants it (int array)."""
        return (self.phase == HELD).astype(np.intc)

    def copy(self) -> Phases:
        return Phases(self.phase.copy(), self.floor.copy(), self.push.copy(), self.push_until.copy())


@dataclass
class Event:
    t: float
    contact: int
    kind: str  # "impact" or "liftoff"
    normal_velocity: float = 0.0  # before the impact (m/s, < 0)
    held: bool = True  # False: released right after its impact ("not held")


@dataclass
class Resolution:
    """What :func:`resolve` did at one instant."""

    y: np.ndarray
    phases: Phases
    events: list[Event] = field(default_factory=list)
    not_held: np.ndarray | None = None  # bool (nc,): stopped at this instant, then released at once
    impact_loss: float = 0.0  # kinetic energy removed by instant impacts (J)
    iterations: int = 0


def kinetic_energy(model: Model, y: np.ndarray, p: np.ndarray) -> float:
    q, u = y[: model.nq], y[model.nq : model.nq + model.nu]
    return 0.5 * float(u @ model.mass_matrix(q, p) @ u)


def apply_impacts(model: Model, y: np.ndarray, p: np.ndarray, hit: np.ndarray, keep: np.ndarray) -> np.ndarray:
    """Plastic impacts: zero the normal velocity of contacts ``hit`` (eq. 4.4-4.5).

    The impulses act along the gap Jacobian rows and also keep the already held contacts
    ``keep`` at zero normal velocity: ``u+ = u + M^-1 J_S^T L`` with ``J_S u+ = 0``.
    Tangential velocity is kept (no friction).

    Returns
    -------
    ndarray, shape (ny,)
        The state after the impulses.
    """
    nq, nu = model.nq, model.nu
    q, u = y[:nq], y[nq : nq + nu]
    S = np.flatnonzero(hit | keep)
    J = model.gap_jacobian(q, p)[S]
    M = model.mass_matrix(q, p)
    X = np.linalg.solve(M, J.T)
    impulses = np.linalg.solve(J @ X, -(J @ u))
    out = y.copy()
    out[nq : nq + nu] = u + X @ impulses
    return out


def effective_masses(model: Model, q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """``1 / (J M^-1 J^T)_cc`` for every contact, shape (nc,): the particle's mass."""
    J = model.gap_jacobian(q, p)
    X = np.linalg.solve(model.mass_matrix(q, p), J.T)
    return 1.0 / np.einsum("ij,ji->i", J, X)


def resolve(
    model: Model,
    t: float,
    y: np.ndarray,
    p: np.ndarray,
    phases: Phases,
    touching: np.ndarray,
    leaving: np.ndarray,
    *,
    gap_tolerance: float,
    force_tolerance: np.ndarray,
    impact: str = "instant",
    impact_dt: float | None = None,
) -> Resolution:
    """Apply the event fixed point at instant ``t``.

    Parameters
    ----------
    y : ndarray, shape (ny,)
        State just before the instant.
    phases : Phases
        Phases just before the instant (not modified).
    touching : ndarray of bool, shape (nc,)
        Contacts whose gap event fired (or whose impact window ended) at ``t``.
    leaving : ndarray of bool, shape (nc,)
        Held contacts whose force event fired at ``t``.
    gap_tolerance : float
        A free contact at or below ``floor + gap_tolerance`` counts as touching (m).
    force_tolerance : ndarray, shape (nc,)
        A held contact in ``leaving`` is released when its force is below this (N).
    impact : {"instant", "thesis"}
    impact_dt : float, optional
        The thesis mode's ΔT (s).

    Returns
    -------
    Resolution
    """
    phases = phases.copy()
    y = y.copy()
    touching = touching.copy()
    nq, nu = model.nq, model.nu
    events: list[Event] = []
    loss = 0.0
    impacted = np.zeros(model.n_contacts, bool)
    settled = np.zeros(model.n_contacts, bool)
    not_held = np.zeros(model.n_contacts, bool)
    was_held = phases.phase == HELD  # on the ground before this instant, so v_n = 0
    iterations = 0
    for iterations in range(1, 2 * model.n_contacts + 3):
        changed = False
        q, u = y[:nq], y[nq : nq + nu]
        gaps = model.gaps(q, p)
        vn = model.gap_jacobian(q, p) @ u
        near = (phases.phase == FREE) & (touching | (gaps <= phases.floor + gap_tolerance))
        # Strictly approaching (<= 0 would flip-flop forever); a contact stopped or released
        # at this instant has v_n = 0 up to round-off (1e-16 m/s) and is not hit again.
        hit = near & (vn < 0.0) & ~impacted & ~was_held
        ending = (phases.phase == PUSHED) & touching  # thesis windows that end now
        touching &= ~(ending | near)  # each touch is handled once
        events += [Event(t, int(c), "impact", float(vn[c])) for c in np.flatnonzero(hit)]
        impacted |= hit
        settled |= ending | (hit & (impact == "instant"))  # stopped on the ground at this instant
        if impact == "thesis" and hit.any():
            # eq. 4.6: the impulse -m v_n spread as a force over dT; no velocity jump now.
            m_eff = effective_masses(model, q, p)
            phases.phase[hit] = PUSHED
            phases.push[hit] = -m_eff[hit] * vn[hit] / impact_dt
            phases.push_until[hit] = t + impact_dt
            hit = np.zeros_like(hit)
            changed = True
        # After a window, what velocity is left towards the ground is stopped instantly.
        instant = hit | (ending & (vn < 0.0))
        if instant.any():
            before = kinetic_energy(model, y, p)
            y = apply_impacts(model, y, p, instant, phases.phase == HELD)
            loss += before - kinetic_energy(model, y, p)
            phases.phase[instant] = HELD
            changed = True
        away = ending & (vn >= 0.0)
        if away.any():
            phases.phase[away] = FREE
            phases.floor[away] = np.minimum(0.0, gaps[away]) - gap_tolerance
            changed = True
        held = phases.held
        if held.any():
            # The dampers saw the velocity jump: recompute the forces before holding anyone.
            _, lam = model.rhs(y, p, held, phases.push)
            pulling = (phases.phase == HELD) & ((lam < 0.0) | (leaving & (lam <= force_tolerance)))
            if pulling.any():
                # Release the most pulling contact, then recompute: exact also for coupled contacts.
                c = int(np.flatnonzero(pulling)[np.argmin(lam[pulling])])
                phases.phase[c] = FREE
                phases.floor[c] = min(0.0, gaps[c]) - gap_tolerance
                if settled[c]:
                    not_held[c] = True  # its (latest) impact did not hold it: it leaves at once
                else:
                    events.append(Event(t, c, "liftoff"))
                changed = True
        if not changed:
            break
    else:
        raise RuntimeError(f"contact resolution at t = {t:.17g} s did not settle after {iterations} passes")
    # A free contact too close to its floor to be armed (released on the ground, or left at
    # -1e-16 by round-off) gets a floor a hair below: its next event is a real approach.
    gaps = model.gaps(y[:nq], p)
    unarmed = (phases.phase == FREE) & (gaps - phases.floor <= gap_tolerance)
    phases.floor[unarmed] = np.minimum(0.0, gaps[unarmed]) - gap_tolerance
    phases.push[phases.phase != PUSHED] = 0.0
    phases.push_until[phases.phase != PUSHED] = np.inf
    return Resolution(y=y, phases=phases, events=events, not_held=not_held, impact_loss=loss, iterations=iterations)
