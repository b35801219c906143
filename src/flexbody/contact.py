"""Contact phases and what happens at an event instant (thesis ch. 4, DESIGN §1).

Each contact (a particle against a ground) is in one phase:

* ``FREE``: no constraint force; its event is the gap reaching the ground while approaching.
* ``HELD`` (contact): the constraint force ``lam >= 0`` keeps its gap acceleration zero
  (eq. 4.8-4.9); its event is ``lam`` turning negative (it would pull): lift-off.  On a
  ground with friction it also sticks: the tangential force ``ft = -(tangential pull)``
  holds it while ``|ft| <= mu lam``; its event "slip" is that slack reaching 0.
* ``SLIDING`` (ground with friction): held along the normal, slipping along the ground
  against ``ft = -mu lam v_t / |v_t|``; its event "stick" is ``v_t`` reaching 0 (located
  along the slip direction of the step's start, renewed every step: in 3D it turns).
* ``PUSHED`` (thesis impact mode only): the estimated impact force ``-m v_n / dT``
  (eq. 4.6) acts for ``dT``; then the contact is resolved like a fresh touch.

:func:`resolve` is the fixed point applied at an event instant: impacts (``v_n < 0``
strictly), then the constraint forces are recomputed (the dampers see the velocity jump),
contacts whose force would pull are released, and this repeats until nothing changes.
Contact forces of point masses on flat grounds decouple (``J M^-1 J^T`` is diagonal), so
this is the exact solution of the contact complementarity problem, in any order.

Impacts follow the ground's laws (DESIGN §6): ``v_n+ = -e v_n-`` (a rebound that would not
rise ``ZENO_RISE`` of the scene is plastic, which ends Zeno's accumulation of bounces) and a
tangential impulse ``min(m |v_t|, mu P_n)`` against ``v_t``.  Once the normal forces are
settled, :func:`friction_phases` decides stick and slip, per particle (exact for point
masses on flat grounds).  A particle held on two grounds at once where one has friction (a
frictional corner) is refused by the driver (status ``unsupported``), not approximated.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .constants import FREE, HELD, KEEP, PUSHED, REBOUND, SETTLE, SLIDING, STOP
from .coupled import coupled_friction_phases, coupled_impact, coupled_release
from .model import Model

__all__ = ["FREE", "HELD", "PUSHED", "SLIDING", "Event", "Phases", "Resolution", "UnsettledInstant", "friction_phases",
           "resolve"]


@dataclass
class Phases:
    """Per-contact state of the phase machine, arrays of shape (nc,)."""

    phase: np.ndarray  # FREE / HELD / PUSHED, np.intc (the C ABI's int)
    floor: np.ndarray  # a FREE contact's event fires when its gap falls to this level (m): 0, or
    # a hair below where the contact was released on the ground
    push: np.ndarray  # normal force of PUSHED contacts (N), 0 elsewhere
    push_until: np.ndarray  # end of each PUSHED window (s), inf elsewhere
    # coupled contacts the last instant set sliding from rest: their slip is round-off, and the
    # next segment's first step slides them along their pull (EventFunctions, which resets it)
    started: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    # coupled contacts set free at gap 0 because the others' rows imply theirs (redundant and
    # unloaded): still touching, so a later impact of their block takes them in its LCP
    implied: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))

    def __post_init__(self) -> None:
        if len(self.implied) != len(self.phase):  # made without the field: none implied yet
            self.implied = np.zeros(len(self.phase), bool)

    @classmethod
    def all_free(cls, nc: int) -> Phases:
        """Every contact free and armed at the ground itself (floor 0)."""
        return cls(np.zeros(nc, np.intc), np.zeros(nc), np.zeros(nc), np.full(nc, np.inf), np.zeros(nc, bool),
                   np.zeros(nc, bool))

    @property
    def held(self) -> np.ndarray:
        """The contact-law code of each held contact (HELD, or SLIDING), 0 elsewhere: the
        ``held`` array of the right-hand side (np.intc, as the C ABI wants it)."""
        # HELD and SLIDING are the odd codes: one product, a new np.intc array (5.6 us over a
        # pile's 40 460 contacts; 13.7 us through the bool mask; np.where took more)
        return self.phase * (self.phase & 1)

    @property
    def on_ground(self) -> np.ndarray:
        """Bool (nc,): held along the normal (sticking, frictionless or sliding)."""
        return (self.phase & 1) != 0  # HELD and SLIDING are the odd codes (as in held)

    def arm(self, gaps: np.ndarray, gap_tolerance: float) -> None:
        """Give each free contact too close to its floor to be armed (released on a surface,
        left at -1e-16 by round-off, or moved there) a floor a hair below its gap ``gaps``
        (nc,): its next event is then a real approach, not a function that starts at 0."""
        unarmed = (self.phase == FREE) & (gaps - self.floor <= gap_tolerance)
        self.floor[unarmed] = np.minimum(0.0, gaps[unarmed]) - gap_tolerance

    def moved(self, index: np.ndarray, nc: int) -> Phases:
        """These phases in a table of ``nc`` contacts where contact ``i`` is ``index[i]``
        (every ``index`` >= 0, distinct); the others all free (:meth:`all_free`)."""
        out = Phases.all_free(nc)
        for name in ("phase", "floor", "push", "push_until", "started", "implied"):
            getattr(out, name)[index] = getattr(self, name)
        return out

    def copy(self) -> Phases:
        return Phases(self.phase.copy(), self.floor.copy(), self.push.copy(), self.push_until.copy(),
                      self.started.copy(), self.implied.copy())

    def first(self, n: int) -> Phases:
        """The first ``n`` contacts' phases, views of these arrays: what is assigned to them
        (:meth:`assign`) lands here."""
        return Phases(self.phase[:n], self.floor[:n], self.push[:n], self.push_until[:n], self.started[:n],
                      self.implied[:n])

    def assign(self, other: Phases) -> None:
        """Take ``other``'s values into these arrays (whose addresses C may hold)."""
        for name in ("phase", "floor", "push", "push_until", "started", "implied"):
            getattr(self, name)[:] = getattr(other, name)


class UnsettledInstant(RuntimeError):
    """The fixed point at an event instant did not settle (contacts kept changing phase)."""

    def __init__(self, t: float, passes: int) -> None:
        super().__init__(f"contact resolution at t = {t:.17g} s did not settle after {passes} passes: contacts kept "
                         "impacting and releasing at the same instant; tighten --rtol/--atol.")


@dataclass
class Event:
    t: float
    contact: int
    kind: str  # "impact", "liftoff", "stick" or "slip"
    normal_velocity: float = 0.0  # before the impact (m/s, < 0)
    held: bool = True  # False: released right after its impact ("not held")


@dataclass
class Resolution:
    """What :func:`resolve` did at one instant."""

    y: np.ndarray
    phases: Phases
    events: list[Event] = field(default_factory=list)
    not_held: np.ndarray | None = None  # bool (nc,): stopped at this instant, then released at once (or rebounded)
    impact_loss: float = 0.0  # kinetic energy removed by instant impacts (J)
    iterations: int = 0
    notes: list[str] = field(default_factory=list)  # ill-posed but solved problems (Painlevé's indeterminate case)


def friction_phases(model: Model, t: float, y: np.ndarray, p: np.ndarray, phases: Phases, leaving: np.ndarray,
                    was_held: np.ndarray, force_tolerance: np.ndarray,
                    speed_tolerance: float) -> tuple[np.ndarray, float, list[Event]]:
    """Coulomb friction of the held contacts once their normal forces are settled (the twin
    of ``friction_phases`` in phases.c; ``phases`` is updated in place).

    For point masses on flat grounds each particle's tangential problem is its own, so the
    order does not matter.  A sliding contact slower than ``speed_tolerance`` (in 3D also one
    held along its step's direction whose event fired with no more than that left along it:
    its slip passed by 0, see :func:`flexbody.coupled._turned_back`) comes to rest
    (its tangential velocity is zeroed, SETTLE) and sticks if its ground can hold it
    ("stick"), or slides on along its pull; a sticking contact whose slack ``mu lam - |ft|``
    is negative, or within its tolerance where its event fired, slides ("slip"); a contact
    that landed with tangential velocity left slides.

    Returns
    -------
    y : ndarray, shape (ny,)
    loss : float
        Kinetic energy removed by zeroing the last tangential velocities (J).
    events : list of Event
    """
    held = phases.held
    vt, ft, slack = model.friction(y, p, held, phases.push)
    speed = np.linalg.norm(vt, axis=1)
    on = held != 0
    stopping = on & (phases.phase == SLIDING) & (speed <= speed_tolerance)
    if model.dim == 3:  # a held slip whose event fired with nothing left along its step's direction: it stopped
        along = np.einsum("cd,cd->c", vt, model.slip_directions(p))
        held_along = model.slips_held(p) != 0
        stopping |= on & (phases.phase == SLIDING) & leaving & held_along & (along <= speed_tolerance)
    sticking = on & (phases.phase == HELD) & np.isfinite(slack)
    landed = sticking & (speed > speed_tolerance)
    slips = sticking & ~landed & ((slack < 0.0) | (leaving & (slack <= force_tolerance)))
    residue = sticking & ~landed & ~slips & (speed > 0.0)  # sticking holds the acceleration: zero the rest
    phases.phase[landed | slips] = SLIDING
    events = [Event(t, int(c), "slip") for c in np.flatnonzero(slips & was_held)]
    settle = stopping | residue
    if not settle.any():
        return y, 0.0, events
    y, loss = model.impact(y, p, np.where(settle, SETTLE, KEEP).astype(np.intc))
    held = np.where(settle, HELD, held).astype(np.intc)
    slack = model.friction(y, p, held, phases.push)[2]
    events += [Event(t, int(c), "stick") for c in np.flatnonzero(settle & (slack >= 0.0) & (phases.phase == SLIDING))]
    phases.phase[settle] = np.where(slack[settle] >= 0.0, HELD, SLIDING)
    return y, loss, events


def window_friction(model: Model, y: np.ndarray, p: np.ndarray, phases: Phases, started: np.ndarray,
                    masses: np.ndarray, friction: np.ndarray, impact_dt: float) -> None:
    """The thesis mode's frictional impact (DESIGN §6, spread like eq. 4.6): each ``started``
    contact, pushed with ``phases.push = P_n / impact_dt``, also gets the constant tangential
    force of Coulomb's impulse ``min(m |v_t|, mu P_n)`` against its tangential velocity, spread
    over the same window (written into ``model.tangential_pushes(p)``, shape (nc, dim)).  As
    ``impact_dt -> 0`` it tends to the instant mode's impulse (the twin of ``window_friction``
    in phases.c)."""
    vt = model.friction(y, p, phases.held, phases.push)[0][started]  # free contacts: their v_t
    speed = np.linalg.norm(vt, axis=1)
    size = np.minimum(masses[started] * speed / impact_dt, friction[started] * phases.push[started])
    with np.errstate(divide="ignore", invalid="ignore"):
        force = np.where((speed > 0.0)[:, None], -size[:, None] * vt / speed[:, None], 0.0)
    model.tangential_pushes(p)[started] = force


def _free_accelerations(model: Model, y: np.ndarray, p: np.ndarray, push: np.ndarray) -> np.ndarray:
    """``u'`` (nu,) at ``y`` with every contact free (pushes kept)."""
    ydot, _ = model.rhs(y, p, np.zeros(model.n_contacts, np.intc), push)
    return ydot[model.nq : model.nq + model.nu]


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
    masses: np.ndarray,
    impact: str = "instant",
    impact_dt: float | None = None,
    restitution: np.ndarray | None = None,
    min_rebound: np.ndarray | None = None,
    speed_tolerance: float = 0.0,
    friction: np.ndarray | None = None,
    zeno_rise: float = 0.0,
    renewed: np.ndarray | None = None,
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
    masses : ndarray, shape (nc,)
        Mass of each contact's particle (the impact force of eq. 4.6 is ``-m v_n / dT``).
    impact : {"instant", "thesis"}
    impact_dt : float, optional
        The thesis mode's ΔT (s).
    restitution : ndarray, shape (nc,), optional
        Newton's e of each contact's ground (default 0: plastic).  A contact hit at speed
        ``|v_n|`` leaves at ``e |v_n|`` (instant mode), or is pushed with ``(1 + e)`` times
        the plastic force (thesis mode), unless ``e |v_n| < min_rebound``.
    min_rebound : ndarray, shape (nc,), optional
        Rebound speeds below this are plastic: the rebound would not rise
        :data:`~flexbody.constants.ZENO_RISE` of the scene's size (default 0).
    speed_tolerance : float
        A sliding contact slower than this (m/s) has come to rest (see :func:`friction_phases`).
    friction : ndarray, shape (nc,), optional
        Coulomb's mu of each contact's ground (default 0).  In the thesis mode a window also
        pushes against the tangential velocity (:func:`window_friction`).
    zeno_rise : float, optional
        The rise (m) below which a rebound is plastic (``min_rebound``'s, against its pull);
        coupled contacts pulled back harder than by gravity stop at their own pull's speed
        (:func:`flexbody.coupled.coupled_impact`).
    renewed : ndarray of bool, shape (nc,), optional
        Held contacts whose constraint changed at ``t`` without an event of their own (handed
        onto another element): checked with the instant's contacts.

    Coupled contacts are solved over the instant's own: those coupled
    (:meth:`flexbody.model.Model.coupled_with`) to the contacts that fired, were renewed or
    were hit, or that move a particle whose free acceleration an impact changed (its
    dampers' neighbours).  The other held contacts' rows are separate blocks of the whole
    problem, which nothing at this instant changed: each keeps its force, and its own event
    finds its lift-off.

    Returns
    -------
    Resolution
    """
    phases = phases.copy()
    touching = np.array(touching, bool)  # the compiled path hands its int buffers
    leaving = np.asarray(leaving, bool)
    nc = model.n_contacts
    e = np.zeros(nc) if restitution is None else np.asarray(restitution, float)
    slowest = np.zeros(nc) if min_rebound is None else np.asarray(min_rebound, float)
    bouncy = e > 0.0
    events: list[Event] = []
    notes: list[str] = []
    loss = 0.0
    impacted, settled, not_held = np.zeros(nc, bool), np.zeros(nc, bool), np.zeros(nc, bool)
    was_held = phases.on_ground.copy()  # on the ground before this instant, so v_n = 0
    # coupled contacts: the instant's own (its seeds), and the coordinates an impact's velocity
    # jump gave another free acceleration
    seeds = touching | leaving | (np.zeros(nc, bool) if renewed is None else np.asarray(renewed, bool))
    jumped = np.zeros(model.nu, bool)
    for iterations in range(1, 2 * nc + 3):
        if model.coupled:  # its held contacts' forces come from coupled_release's LCP
            (gaps, vn), lam = model.gap_rates(y, p, phases.held), None
        else:
            gaps, vn, lam = model.contact_state(y, p, phases.held, phases.push)
        near = (phases.phase == FREE) & (touching | (gaps <= phases.floor + gap_tolerance))
        # Strictly approaching (<= 0 would flip-flop forever); a contact stopped or released
        # at this instant has v_n = 0 up to round-off (1e-16 m/s) and is not hit again.
        hit = near & (vn < 0.0) & ~impacted & ~was_held
        if model.coupled and np.count_nonzero(hit) > 1:  # two bodies' vertices meeting: one contact
            hit &= ~model.same_contacts(y, p, hit)
        ending = (phases.phase == PUSHED) & touching  # thesis windows that end now
        touching &= ~(ending | near)  # each touch is handled once
        phases.push[ending] = 0.0  # its force ends with it: a held contact's force is eq. 4.8's
        if ending.any() and friction is not None and friction.any():
            model.tangential_pushes(p)[ending] = 0.0
        events += [Event(t, int(c), "impact", float(vn[c])) for c in np.flatnonzero(hit)]
        impacted |= hit
        settled |= ending | (hit & (impact == "instant"))  # stopped on the ground at this instant
        # A rebound too slow to rise ZENO_RISE of the scene is plastic: no endless bouncing.
        rebounds = hit & bouncy
        if rebounds.any():
            rebounds &= -e * vn >= slowest
        started = hit if impact == "thesis" else np.zeros_like(hit)
        if started.any():
            # eq. 4.6: the impulse -(1 + e) m v_n spread as a force over dT; no velocity jump now.
            phases.phase[started] = PUSHED
            phases.push[started] = -masses[started] * vn[started] * (1.0 + np.where(rebounds, e, 0.0)[started]) / impact_dt
            phases.push_until[started] = t + impact_dt
            if friction is not None and friction[started].any():
                window_friction(model, y, p, phases, started, masses, friction, impact_dt)
            hit = np.zeros_like(hit)
        # After a window, what velocity is left towards the ground is stopped instantly.
        instant = hit | (ending & (vn < 0.0))
        if instant.any() and model.coupled:
            # Coupled contacts (a rigid body's, between bodies): one LCP over the touching
            # contacts coupled to the hit ones, those held and those the others held implied at
            # gap 0 (without them a box resting on 3 of its 4 corners tipped about 2 of them
            # when hit, its fourth corner going down and rocking it)
            resting = phases.on_ground | (phases.implied & (phases.phase == FREE) & (gaps <= gap_tolerance))
            touching_now = instant | (resting & model.coupled_with(y[: model.nq], p, instant, resting))
            phases.implied[touching_now] = False
            before = _free_accelerations(model, y, p, phases.push)
            out = coupled_impact(model, y, p, touching_now, np.where(hit & rebounds, e, 0.0), slowest, zeno_rise,
                                 notes)
            y, loss = out.y, loss + out.loss
            seeds |= touching_now
            jumped |= _free_accelerations(model, y, p, phases.push) != before
            gaps = model.gaps(y[: model.nq], p)
            left = out.leaving
            events += [Event(t, int(c), "liftoff") for c in np.flatnonzero(left & phases.on_ground & ~settled)]
            phases.phase[touching_now & ~left] = HELD
            phases.phase[left] = FREE
            phases.floor[left] = np.minimum(0.0, gaps[left]) - gap_tolerance
            not_held |= left & impacted
        elif instant.any():
            stop = np.where(instant | phases.on_ground, STOP, KEEP)
            stop[hit & rebounds] = REBOUND
            y, lost = model.impact(y, p, stop.astype(np.intc))
            loss += lost
            if impact == "instant" and model.settle is not None:
                # found by event location up to the gap tolerance below the ground: set onto it
                # (not the thesis mode's windows, whose penetration is the model's)
                y = model.settle(y, p, stop.astype(np.intc))
            gaps = model.gaps(y[: model.nq], p)
            bounced = stop == REBOUND  # it leaves the ground at once
            phases.phase[instant & ~bounced] = HELD
            # armed a hair below where the impact left it: below where it was found, each
            # bounce within one step would arm the next a hair lower
            phases.floor[bounced] = np.minimum(0.0, gaps[bounced]) - gap_tolerance
            not_held |= bounced
        away = ending & (vn >= 0.0)
        phases.phase[away] = FREE
        phases.floor[away] = np.minimum(0.0, gaps[away]) - gap_tolerance
        if (started | instant | away).any():
            continue  # the dampers saw the velocity jump: recompute the forces before holding anyone
        if model.coupled:  # Signorini's law over the held contacts coupled to the instant's, at once
            checked = phases.on_ground & model.coupled_with(y[: model.nq], p, seeds, phases.on_ground, jumped)
            pulling, implied = coupled_release(model, y, p, checked, phases.push, leaving,
                                               force_tolerance, phases.held, notes, speed_tolerance)
            phases.phase[implied] = FREE  # redundant and unloaded: the others hold it at gap 0
            phases.implied[implied] = True
            # armed a band lower than a lift-off: it stays at its gap (the others imply it),
            # and one tolerance down it would count as touching at every later instant, its
            # round-off approach (1e-13 m/s) an impact each time (Zeno-like, "chattering")
            phases.floor[implied] = np.minimum(0.0, gaps[implied]) - 2.0 * gap_tolerance
            released = np.flatnonzero(pulling)
            if implied.any() and not len(released):
                continue  # recompute the forces of the independent held contacts
        else:
            pulling = phases.on_ground & ((lam < 0.0) | (leaving & (lam <= force_tolerance)))
            # Release the most pulling contact, then recompute.
            released = np.flatnonzero(pulling)[np.argmin(lam[pulling])][None] if pulling.any() else []
        if not len(released):
            break
        for c in map(int, released):
            phases.phase[c] = FREE
            phases.implied[c] = False
            phases.floor[c] = min(0.0, gaps[c]) - gap_tolerance
            if settled[c]:
                not_held[c] = True  # its (latest) impact did not hold it: it leaves at once
            else:
                events.append(Event(t, c, "liftoff"))
    else:
        raise UnsettledInstant(t, iterations)
    if model.friction is not None and model.laws[:, 0].any():
        # coupled contacts (between bodies, a rigid body's): stick and slip decided jointly
        if model.coupled:
            y, lost, found = coupled_friction_phases(model, t, y, p, phases, leaving, was_held, force_tolerance,
                                                     speed_tolerance, notes)
        else:
            y, lost, found = friction_phases(model, t, y, p, phases, leaving, was_held, force_tolerance,
                                             speed_tolerance)
        loss += lost
        events += found
    phases.arm(model.gaps(y[: model.nq], p), gap_tolerance)
    unpushed = phases.phase != PUSHED
    if friction is not None and friction.any():
        model.tangential_pushes(p)[unpushed] = 0.0
    phases.push[unpushed] = 0.0
    phases.push_until[unpushed] = np.inf
    return Resolution(y=y, phases=phases, events=events, not_held=not_held, impact_loss=loss, iterations=iterations,
                      notes=notes)
