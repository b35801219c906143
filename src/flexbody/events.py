"""Event functions of the phase machine and their location on a step's dense output.

One event function per contact, positive while nothing happens:

* ``FREE``: ``gap - floor`` (``floor`` is a hair below the ground, so a particle released
  at gap -1e-16 is still armed and a restart never starts on a root);
* ``HELD``: ``lam + force_tolerance`` (the constraint force, lift-off when it would pull);
  with friction the smaller of that and ``mu lam - |ft| + force_tolerance`` (it slips at 0);
  on another body's element, also how far inside the element the particle projects (m; it
  passes onto the neighbour at 0, :mod:`flexbody.body_contact`);
* ``SLIDING``: the smaller of ``lam + force_tolerance`` and the tangential velocity along the
  slip direction at the start of the step (it stops at 0; the direction is renewed after
  every step because in 3D it turns, see ``friction_event`` in integrator.c);
* ``PUSHED``: none (its window ends at a known time).

SciPy's ``solve_ivp`` keeps only the first of several terminal events falling at the same
time, so events are located here: every function that changed sign in a step (checked
at the step's end and midpoint) gets its root on the dense output by Chandrupatla's
bracketing method (:func:`first_fired`; the compiled loop's is Brent's, bracketed the
same way), the earliest root wins, and every root within ``GROUP_TIME`` of it belongs to
the same instant.  The result does not depend on the order of the contacts.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .constants import FREE, GROUP_TIME, HELD, SLIDING
from .contact import Phases
from .model import Model

#: The tolerance (s) of a root's time, besides the rounding of t (:func:`first_fired`).
ROOT_TIME = 1e-15


class EventFunctions:
    """The vector of event functions, shape (nc,), for one contact configuration."""

    def __init__(self, model: Model, p: np.ndarray, phases: Phases, force_tolerance: np.ndarray,
                 gap_tolerance: float = 0.0, speed_tolerance: float = 0.0,
                 masses: np.ndarray | None = None) -> None:
        self.model, self.p, self.phases = model, p, phases
        self.force_tolerance, self.gap_tolerance = force_tolerance, gap_tolerance
        # slow 3D slips keep their direction through a step (renew) with explicit steppers, given
        # each contact's particle mass; an implicit one (masses None) follows their fast turn
        self.speed_tolerance, self.masses = speed_tolerance, masses
        self.hold_slips = masses is not None and model.dim == 3
        self.free = phases.phase == FREE
        self._not_free = np.flatnonzero(~self.free)
        self.held_mask = phases.on_ground
        self._held_rows = np.flatnonzero(self.held_mask)
        self.held = phases.held
        # held slots' element margins, by contact (None where the segment holds no slot), and
        # the rows they are read on (found once: two passes over every contact)
        self.margins = model.held_margins if phases.on_ground[model.n_ground_contacts :].any() else None
        self._margin_rows = self._rows_with_margins(self.held)
        # Contacts between bodies (past the grounds'): a just released one is checked more densely.
        self.between_bodies = np.arange(model.n_contacts) >= model.n_ground_contacts
        self.friction = bool(self.held_mask.any() and model.laws[:, 0].any())
        # Each sliding contact's direction at the step's start: the model's own (FbSystem.slip), whose
        # right-hand side continues a slip past its stop along it; one from an earlier slide is stale.
        self.direction = model.slip_directions(p) if self.friction else np.zeros((model.n_contacts, model.dim))
        # A slide from rest starts its first step at 0, which no sign change leaves, hiding its
        # lift-off: in 2D it has no stop there, in 3D it is armed a speed tolerance below (see
        # friction_event in integrator.c).
        self.from_rest = np.zeros(model.n_contacts, bool)
        self.started = np.zeros(model.n_contacts, bool)  # taken from the phases, for the first step
        self._first: np.ndarray | None = None  # where the first step starts (a retake starts there too)
        if len(phases.started) == model.n_contacts:
            self.started[:] = phases.started
            phases.started[:] = False
        if self.friction:  # a direction or hold from an earlier slide is stale: the law follows v_t
            self.direction[phases.phase == SLIDING] = 0.0
            if self.hold_slips:
                model.slips_held(p)[:] = 0
        self._coupled: dict[int, tuple] = {}  # each held contact's block (see one, _block)
        self._forces = model.forces_function(p, self.held, phases.push)  # the segment's contact set, laid out once

    def renew(self, y: np.ndarray, step: float = 0.0) -> bool:
        """Take each sliding contact's slip direction at ``y`` (the start of the next step,
        ``step`` long if known, else 0): along its tangential velocity, or from rest along its
        pull (-ft).  A 3D slip slower than the speed tolerance, or one inside its cone that
        friction alone would stop within the step, or one that its present slowing
        (:meth:`slowing`) stops within the step, keeps its friction along it through the
        step: near its stop it turns faster than the step can follow (see ``friction_event``
        in integrator.c).  Where contacts couple, so does one outside its cone within
        ``SLOW_SLIP`` speed tolerances of rest that friction alone would reverse within the
        step: pulled and held back nearly equally through the coupled rows, such a slip can
        creep at a speed tolerance or two for milliseconds, neither growing nor stopping,
        and followed it holds an explicit step at its stiffness limit (mu lam / (m |v|)
        rad/s: 2e-8 s in a fuzzed row).  A faster slip outside its cone is followed: held
        over the long steps its smooth law allows, it would turn late
        (tests/test_friction.py).  A lone particle's slow slip outside its cone speeds up
        and is followed in a few steps, as the compiled loop does.  A contact the last
        instant set sliding from rest (``Phases.started``) slides from rest in its first
        step whatever round-off slip it has, also where that step is taken again from its
        start, shorter (else the round-off slip's direction holds its friction there: along
        the pull, measured, which stopped it at once, an instant at one time again and
        again).  Returns whether a slip is or was
        held: then the right-hand side at ``y`` changed (a stepper's first stage, kept from
        the last step, is stale)."""
        if not self.friction:
            return False
        vt, ft, slack = self.model.friction(y, self.p, self.held, self.phases.push)
        speed, pull = np.linalg.norm(vt, axis=1), np.linalg.norm(ft, axis=1)
        sliding = self.phases.phase == SLIDING
        if self.started.any():
            if self._first is None:
                self._first = np.array(y, float)
            elif not np.array_equal(y, self._first):
                self.started = np.zeros_like(self.started)  # the first step's only, and its retakes'
        self.from_rest = sliding & ((speed == 0.0) | self.started)
        hold = ft
        if (self.from_rest & (speed > 0.0)).any():
            # Its pull is what would hold it there, reversed: the law's own force follows a
            # round-off slip (measured in a fuzz: 6.8e-49 m/s against the pull, so friction
            # pushed the slide on, 12 N for 0.35 ms, and the ledger's friction work fell).
            codes = np.where(self.from_rest, HELD, self.held).astype(self.held.dtype)
            hold = np.where(self.from_rest[:, None], self.model.friction(y, self.p, codes, self.phases.push)[1], ft)
        size = np.linalg.norm(hold, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            direction = np.where((~self.from_rest)[:, None], vt / speed[:, None],
                                 np.where((size > 0.0)[:, None], -hold / size[:, None], 0.0))
        self.direction[sliding] = direction[sliding]
        if not self.hold_slips:
            return False
        held = self.model.slips_held(self.p)
        was = bool(held.any())
        # inside its cone (sliding, its slack is the one it would have sticking) friction alone
        # takes |ft| / m = mu lam / m off the slip per second; outside it, only a slip near rest
        # is judged so, where contacts couple (what the hold gets wrong is that slip, which
        # the stop takes)
        creeping = self.model.coupled & (speed <= SLOW_SLIP * self.speed_tolerance)
        reach = np.where((slack >= 0.0) | creeping, pull / self.masses * step, 0.0)
        beyond = sliding & ~self.from_rest & (speed > np.maximum(self.speed_tolerance, reach))
        if step > 0.0 and beyond.any():
            # A contact between bodies slips against another body's element, which moves
            # too: its slip can slow far faster than friction alone slows its particle
            # (measured: 1.9e-6 m/s slowed at 76 m/s^2, friction on the particle 17 m/s^2;
            # followed, it whirled past its step's direction every 1.6e-8 s, each instant
            # sliding on).  A slip its present slowing stops within the step is held along
            # it, as a slow one: its event is then its stop, and the instant stops it.
            reach = np.where(beyond, np.maximum(reach, self.slowing(y, vt, speed, step) * step), reach)
        held[:] = sliding & (speed <= np.maximum(self.speed_tolerance, reach))
        return was or bool(held.any())

    def slowing(self, y: np.ndarray, vt: np.ndarray, speed: np.ndarray, step: float) -> np.ndarray:
        """How fast each contact's slip ``vt`` (nc, dim; ``speed`` its length) is slowed at
        ``y`` (m/s^2, < 0 where it speeds up), shape (nc,): its tangential acceleration against
        it, on the right-hand side's path over a thousandth of ``step``."""
        m, held, push = self.model, self.held, self.phases.push
        ydot = m.rhs(y, self.p, held, push)[0]
        dt = 1e-3 * step
        ahead = m.friction(y + dt * ydot, self.p, held, push)[0]
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(speed > 0.0, -np.sum((ahead - vt) * vt, axis=1) / (dt * speed), 0.0)

    def rearm(self, g_mid: np.ndarray, g_new: np.ndarray) -> None:
        """Arm at the ground (floor 0) each free contact armed a hair below it (just released
        or rebounded) that is 2 gap tolerances above it at the step's midpoint, as at a step's
        end, for the step's second half; ``g_mid`` and ``g_new`` are moved to it in place.
        Else a bounce within one step would be caught only at the lower floor."""
        floor = self.phases.floor
        lifted = self.free & (floor < 0.0) & (g_mid + floor >= 2.0 * self.gap_tolerance)
        g_mid[lifted] += floor[lifted]
        g_new[lifted] += floor[lifted]
        floor[lifted] = 0.0

    def free_gaps(self, y: np.ndarray, only: np.ndarray | None = None) -> np.ndarray:
        """The free contacts' event functions at ``y`` (their gaps above their floors), ``inf``
        for the others, shape (nc,): all that locating impacts needs (no right-hand side);
        with ``only`` (bool (nc,)), those of these contacts alone."""
        m = self.model
        if only is None and self.free.any():  # one pass over every contact: no masked copies
            g = m.gaps(y[: m.nq], self.p) - self.phases.floor
            g[self._not_free] = np.inf  # the held and pushed ones: a few of many
            return g
        g = np.full(m.n_contacts, np.inf)
        if only is not None:
            watched = np.flatnonzero(self.free & only)
            g[watched] = m.gaps_of(y[: m.nq], self.p, watched) - self.phases.floor[watched]
        return g

    def __call__(self, y: np.ndarray) -> np.ndarray:
        # the held contacts' functions written over the free gaps' inf (their minimum, without
        # two more passes over every contact)
        return self._held_functions(y, self.held_mask, self._held_rows, self.held, self._margin_rows, False,
                                    self.free_gaps(y))

    def held_functions(self, y: np.ndarray, among: np.ndarray | None = None) -> np.ndarray:
        """The held contacts' event functions at ``y``, ``inf`` for the others, shape (nc,):
        all that locating a lift-off, slip or hand-over needs (no gaps); with ``among`` (bool
        (nc,), a block of contacts that couple to no other held one), theirs alone, solved as
        if no other were held."""
        if among is None:
            return self._held_functions(y, self.held_mask, self._held_rows, self.held, self._margin_rows, False)
        return self._held_functions(y, *self._block(among), True)

    def _block(self, among: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple | None]:
        """The held contacts of ``among`` (bool (nc,)) as a mask and as indices, the held
        codes with them alone held (read-only: :meth:`one` keeps them) and the rows of their
        margins (:meth:`_rows_with_margins`)."""
        mask = self.held_mask & among
        held = np.where(mask, self.held, 0).astype(self.held.dtype)
        held.flags.writeable = False
        return mask, np.flatnonzero(mask), held, self._rows_with_margins(held)

    def _rows_with_margins(self, held: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """The rows whose element margins are read with the held codes ``held``
        (:meth:`flexbody.body_contact.BodyContactModel.margin_rows`); None where the segment
        reads no margins."""
        return None if self.margins is None else self.model.margin_rows(held)

    def _held_functions(self, y: np.ndarray, mask: np.ndarray, rows: np.ndarray, held: np.ndarray,
                        margin_rows: tuple | None, block: bool, out: np.ndarray | None = None) -> np.ndarray:
        """:meth:`held_functions` of the held contacts ``mask`` (bool (nc,)), ``rows`` (their
        indices: a few of many contacts, indexed without passing over the mask again) with
        the held codes ``held`` and their margins' rows ``margin_rows``; with ``block``, from
        their own rows' forces.  ``out``: an array (nc,) that is ``inf`` at ``rows``, taken as
        the others' functions and written (else they are ``inf``)."""
        m = self.model
        g = np.full(m.n_contacts, np.inf) if out is None else out
        if len(rows):
            # a block's forces from its own rows (a lift-off's root evaluates nothing else)
            lam = m.held_forces(y, self.p, held, self.phases.push) if block else self._forces(y)
            g[rows] = lam[rows] + self.force_tolerance[rows]
            if self.margins is not None:  # a contact held on another body's element passes onto the next
                bounded, margins = self.margins(y, self.p, held, margin_rows)  # among rows
                g[bounded] = np.minimum(g[bounded], margins)
            if self.friction:
                vt, _, slack = m.friction(y, self.p, held, self.phases.push)
                sticking, sliding = mask & (self.phases.phase == HELD), mask & (self.phases.phase == SLIDING)
                g[sticking] = np.minimum(g[sticking], slack[sticking] + self.force_tolerance[sticking])
                along = np.sum(vt * self.direction, axis=1)
                along = np.where(self.from_rest, np.inf if m.dim != 3 else along + self.speed_tolerance, along)
                g[sliding] = np.minimum(g[sliding], along[sliding])
        return g

    def one(self, y: np.ndarray, c: int) -> float:
        """Event function ``c`` alone at ``y``, equal to ``self(y)[c]``: a free contact's needs
        only the gaps, not the right-hand side (what locating an impact costs), and a held
        one's no gaps, only the forces of the held contacts coupled to it (what locating a
        lift-off costs; :meth:`flexbody.model.Model.coupled_with`)."""
        if self.free[c]:
            return self.model.gap(y[: self.model.nq], self.p, c) - float(self.phases.floor[c])
        if self.friction:  # slips couple through the slip directions the model keeps: all of them
            return float(self.held_functions(y)[c])
        if c not in self._coupled:  # the held contacts coupled to c: its force is theirs to solve
            seed = np.zeros(self.model.n_contacts, bool)
            seed[c] = True
            self._coupled[c] = self._block(self.model.coupled_with(y[: self.model.nq], self.p, seed, self.held_mask))
        return float(self._held_functions(y, *self._coupled[c], True)[c])


#: Where contacts couple, a 3D slip outside its cone within this many speed tolerances of
#: rest is held like a stopping one inside it (see :meth:`EventFunctions.renew`).
SLOW_SLIP = 10.0


@dataclass
class Crossing:
    """The earliest event instant inside a step."""

    t: float
    contacts: np.ndarray  # bool (nc,): every contact whose event fired at t


def locate(
    events: EventFunctions,
    dense: Callable[[float], np.ndarray],
    t_old: float,
    t_new: float,
    g_old: np.ndarray,
    g_new: np.ndarray | Callable[[], np.ndarray],
) -> Crossing | None:
    """Find the earliest sign change (positive to non-positive) in ``[t_old, t_new]``.

    The midpoint is checked too, so a particle that dips below the ground and comes back
    within one step is not missed; a contact between bodies released at the last instant is
    checked at ``DIP_SAMPLES`` points (:func:`_first_dip`).

    Parameters
    ----------
    dense : callable
        The step's dense output, ``t -> y (ny,)``.
    g_old : ndarray, shape (nc,)
    g_new : ndarray, shape (nc,), or callable () -> ndarray
        Event functions at the step's ends (``g_new`` follows a contact armed at the ground
        at the midpoint, see :meth:`EventFunctions.rearm`); ``g_new`` may be a function that
        evaluates them, called only where needed (a dip found first ends the step before).
    """
    dip = _first_dip(events, dense, t_old, t_new, g_old)
    if dip is None:
        g_new = g_new() if callable(g_new) else g_new
        crossing = _unmissed(events, dense, t_old, g_old, _sign_change(events, dense, t_old, t_new, g_old, g_new))
        return _corner_cut(events, dense, t_old, t_new, g_old, crossing)
    # the step as if it ended at the dip: an earlier crossing of another contact wins, and
    # the corners are checked between its checks (start, midpoint, dip), whose gaps are known
    crossing = _sign_change(events, dense, t_old, dip.t, g_old, events(dense(dip.t)))
    if crossing is not None and crossing.t < dip.t - GROUP_TIME:
        return _corner_cut(events, dense, t_old, dip.t, g_old, _unmissed(events, dense, t_old, g_old, crossing))
    if crossing is not None:
        dip.contacts |= crossing.contacts
    return _corner_cut(events, dense, t_old, dip.t, g_old, _unmissed(events, dense, t_old, g_old, dip))


def _corner_cut(events: EventFunctions, dense: Callable[[float], np.ndarray], t_old: float, t_new: float,
                g_old: np.ndarray, crossing: Crossing | None) -> Crossing | None:
    """``crossing``, or an earlier one of a free contact between bodies that went into
    another body's convex corner (2D; 3D: edge or vertex) and out again between two of the step's
    checks (its start, midpoint and end ``t_new``: where a dip shortened the step, its end
    is the dip's, as :func:`_sign_change` checks it), positive at both
    (:meth:`flexbody.model.Model.corner_cuts`).

    Each such contact's two lines (3D: planes) are rooted on the dense output: where it crossed the
    second's inward before the first's outward, it was inside both in between, deepest
    (for a straight passage) where their gaps are equal.  Its event function there, below
    minus the gap tolerance (a graze, two corners meeting to a rounding, is no dip, as in
    :func:`_unmissed`), brackets its crossing from the check before it.
    """
    model = events.model
    if not model.corners:
        return crossing
    t_end = crossing.t if crossing is not None else t_new
    t_mid = 0.5 * (t_old + t_new)
    watched = events.free & events.between_bodies
    gaps = {t_old: g_old}

    def free_gaps(t: float) -> np.ndarray:  # at a check, once: most steps need none
        if t not in gaps:
            gaps[t] = events.free_gaps(dense(t))
        return gaps[t]

    for ta, tb in ((t_old, t_mid), (t_mid, t_new)):
        if ta >= t_end:
            break
        y_a, y_b = dense(ta), dense(tb)
        # each contact is judged alone, so those above their floors at both checks are picked after
        contacts, corners, inward = model.corner_cuts(y_a, y_b, events.p, watched)
        roots = {}
        if len(contacts):
            g_a, g_b = free_gaps(ta), free_gaps(tb)
            positive = (g_a[contacts] > 0.0) & (g_b[contacts] > 0.0)
            contacts, corners, inward = contacts[positive], corners[positive], inward[positive]
        if len(contacts):
            lines_a = model.corner_lines(y_a, events.p, contacts, corners)
            lines_b = model.corner_lines(y_b, events.p, contacts, corners)
        for k, (c, corner, j) in enumerate(zip(contacts.tolist(), corners.tolist(), inward.tolist())):
            def lines(t: float, c: int = c, corner: list = corner) -> np.ndarray:
                return model.corner_lines(dense(t), events.p, np.array([c]), np.array([corner]))[0]

            if c in roots:  # found at another pair of the same corner's elements
                continue
            if t_end < tb and lines(t_end)[j] > 0.0:  # not in before the step's event: nothing to miss
                continue
            t_in = first_fired(lambda t: lines(t)[j], ta, tb, lines_a[k, j], lines_b[k, j], xtol=ROOT_TIME)
            t_out = first_fired(lambda t: -lines(t)[1 - j], ta, tb, -lines_a[k, 1 - j], -lines_b[k, 1 - j],
                                xtol=ROOT_TIME)
            if t_in >= t_out:  # round the vertex outside
                continue
            d_in, d_out = (float(g[j] - g[1 - j]) for g in (lines(t_in), lines(t_out)))
            t_deep = (first_fired(lambda t: float(np.subtract(*lines(t)[[j, 1 - j]])), t_in, t_out, d_in, d_out,
                                  xtol=ROOT_TIME) if d_in > 0.0 >= d_out else 0.5 * (t_in + t_out))
            if events.one(dense(t_deep), c) < -events.gap_tolerance:
                roots[c] = _root(events, dense, c, ta, t_deep, float(g_a[c]))
        if roots:
            t_cut = min(roots.values())
            if crossing is not None and t_cut >= crossing.t - GROUP_TIME:  # the same instant
                crossing.contacts[[c for c, t in roots.items() if t <= crossing.t + GROUP_TIME]] = True
                return crossing
            cut = np.zeros(len(g_old), bool)
            cut[[c for c, t in roots.items() if t <= t_cut + GROUP_TIME]] = True
            return _unmissed(events, dense, t_old, g_old, Crossing(t_cut, cut))
    return crossing


def _unmissed(events: EventFunctions, dense: Callable[[float], np.ndarray], t_old: float, g_old: np.ndarray,
              crossing: Crossing | None) -> Crossing | None:
    """``crossing``, or an earlier one of a free contact found below its floor at its time:
    a contact between bodies can dip through a moving surface and back between the points
    checked (measured: 2.9e-9 m deep, a dip shorter than a pile's step / ``DIP_SAMPLES``,
    at the instant another contact's event ended that step).  Then the state the step stops
    at would start the next one past that contact's surface, unseen.  Inside by more than
    the gap tolerance only: one grazing its surface (a rounding below it) is not a dip."""
    while crossing is not None:
        g_at = events.free_gaps(dense(crossing.t))
        missed = (g_old > 0.0) & (g_at < -events.gap_tolerance) & ~crossing.contacts
        if not missed.any():
            return crossing
        # A floor re-armed since (EventFunctions.rearm, at a midpoint) may leave it below at
        # t_old: it is sampled all the same, its crossing bracketed by the first point above
        # its floor before one below (measured: a slot released a hair inside a box's face,
        # re-armed at 0, in through that face and out through the box's bottom within 5.5e-6 s
        # of a 6.6e-4 s step, 3.3e-9 m deep at the instant another contact ended the step,
        # dropped here as starting below its floor).
        g_start = _free_gaps_at(events, dense, t_old, missed)
        # the first of DIP_SAMPLES points where one is inside brackets its first crossing
        earlier = _sampled(events, dense, missed, t_old, crossing.t, g_start, g_at)
        if earlier is None:
            return crossing
        if earlier.t >= crossing.t - GROUP_TIME:
            crossing.contacts |= earlier.contacts
            return crossing
        crossing = earlier
    return crossing


#: Points per step at which a just released contact between bodies is checked.
DIP_SAMPLES = 8
#: ... and what "just released" means: armed below the surface, or within this many gap
#: tolerances above it (1e-6 of the scene's size) at the step's start.
DIP_BAND = 1e6


def _first_dip(events: EventFunctions, dense: Callable[[float], np.ndarray], t_old: float, t_new: float,
               g_old: np.ndarray) -> Crossing | None:
    """The earliest crossing of a contact between bodies released at the last instant (still
    armed a hair below the surface, or within ``DIP_BAND`` gap tolerances of it), found on
    ``DIP_SAMPLES`` points of the step.  Such a particle starts on the other body's surface, and the surface can catch it
    up and let it go again within half a step (measured: 6.5e-6 m deep between the checks
    at a step's ends and midpoint in a pile of discs); a ground does not move."""
    near = (events.phases.floor < 0.0) | (g_old < DIP_BAND * events.gap_tolerance)
    fresh = events.free & events.between_bodies & near
    if not fresh.any():
        return None
    return _sampled(events, dense, fresh, t_old, t_new, g_old)


def _sampled(events: EventFunctions, dense: Callable[[float], np.ndarray], watched: np.ndarray, ta: float,
             tb: float, g_a: np.ndarray, g_b: np.ndarray | None = None) -> Crossing | None:
    """The earliest crossing of the free contacts ``watched`` (bool (nc,)) found on
    ``DIP_SAMPLES`` points of ``[ta, tb]`` (only these are evaluated there), their values
    at ``ta`` ``g_a``; the point ``tb`` is checked only with its values ``g_b`` given."""
    t_prev, g_prev = ta, g_a
    for k in range(1, DIP_SAMPLES + 1):
        if k == DIP_SAMPLES and g_b is None:
            return None
        t = ta + (tb - ta) * k / DIP_SAMPLES
        g = g_b if k == DIP_SAMPLES else _free_gaps_at(events, dense, t, watched)
        fired = np.flatnonzero(watched & (g_prev > 0.0) & (g <= 0.0))
        if fired.size:
            return _earliest(events, dense, fired, t_prev, t, g_prev, g)
        t_prev, g_prev = t, g
    return None


def _free_gaps_at(events: EventFunctions, dense: Callable[[float], np.ndarray], t: float,
                  only: np.ndarray) -> np.ndarray:
    """``events.free_gaps(dense(t), only)``, from the model's own evaluation on the
    stepper's dense output where it has one (:meth:`flexbody.model.Model.dense_gaps`: a few
    contacts' gaps without interpolating the whole state)."""
    output = getattr(dense, "output", None)  # the stepper's own (flexbody.driver._remembered)
    if output is not None:
        watched = np.flatnonzero(events.free & only)
        gaps = events.model.dense_gaps(output, watched, events.phases.floor[watched], t)
        if gaps is not None:
            g = np.full(len(only), np.inf)
            g[watched] = gaps
            return g
    return events.free_gaps(dense(t), only)


def _sign_change(events: EventFunctions, dense: Callable[[float], np.ndarray], t_old: float, t_new: float,
                 g_old: np.ndarray, g_new: np.ndarray) -> Crossing | None:
    """The earliest sign change at the step's ends and midpoint (see :func:`locate`)."""
    t_mid = 0.5 * (t_old + t_new)
    g_mid = events(dense(t_mid))
    if not (((g_old > 0.0) & (g_mid <= 0.0)) | ((g_mid > 0.0) & (g_new <= 0.0))).any():
        return None  # the common case: nothing happened in this step
    for half, ((ta, ga), (tb, gb)) in enumerate((((t_old, g_old), (t_mid, g_mid)), ((t_mid, g_mid), (t_new, g_new)))):
        if half == 1:  # nothing in the first half (the step may end there: not before)
            events.rearm(g_mid, g_new)
        fired = np.flatnonzero((ga > 0.0) & (gb <= 0.0))
        if fired.size == 0:
            continue
        return _earliest(events, dense, fired, ta, tb, ga, gb)
    return None


def _earliest(events: EventFunctions, dense: Callable[[float], np.ndarray], fired: np.ndarray, ta: float,
              tb: float, ga: np.ndarray, gb: np.ndarray) -> Crossing:
    """The earliest root in ``[ta, tb]`` of the ``fired`` contacts, with every root within
    ``GROUP_TIME`` of it (the same instant).

    The contact whose chord crosses first is rooted first; the event functions at its root
    say which others fired before it, and only those are rooted next (usually none), so an
    instant costs one root search, not one per fired contact.  A contact belongs to the
    instant if its function has fired ``GROUP_TIME`` after the earliest root.
    """
    # impacts alone need no forces, and only the fired contacts' gaps; lift-offs alone no gaps
    if events.free[fired].all():
        among = np.zeros(len(ga), bool)
        among[fired] = True

        def evaluate(t: float) -> np.ndarray:
            return _free_gaps_at(events, dense, t, among)
    else:
        functions = events.held_functions if not events.free[fired].any() else events

        def evaluate(t: float) -> np.ndarray:
            return functions(dense(t))
    hi, g_hi = tb, gb
    rooted = np.zeros(len(ga), bool)
    candidates = fired
    while candidates.size:
        chord = ga[candidates] / (ga[candidates] - g_hi[candidates])  # where each one's chord crosses, in (0, 1]
        earliest = int(candidates[np.argmin(chord)])
        hi = _root(events, dense, earliest, ta, hi, float(ga[earliest]))
        rooted[earliest] = True
        if fired.size == 1:  # nothing else fired: the instant is its root (no function evaluated again)
            return Crossing(hi, rooted)
        g_hi = evaluate(hi)
        candidates = fired[(g_hi[fired] <= 0.0) & ~rooted[fired]]  # fired by then: their roots are not later
    group = np.zeros(len(ga), bool)
    t_group = min(hi + GROUP_TIME, tb)
    g_group = gb if t_group == tb else evaluate(t_group)
    group[fired[g_group[fired] <= 0.0]] = True
    group[earliest] = True
    return Crossing(hi, group)


def _root(events: EventFunctions, dense: Callable[[float], np.ndarray], c: int, ta: float, tb: float,
          start: float = np.inf) -> float:
    """Root of event function ``c`` in ``[ta, tb]`` on the dense output; ``start``: its
    value at ``ta`` from the whole vector (:meth:`EventFunctions.__call__`), if known.

    The bracket is evaluated on the dense output itself: an interpolant need not pass
    exactly through the step's end state (LSODA's does not), so its sign there decides.
    A free contact's search runs in the model where it has its own (contacts between
    bodies on SciPy's Runge-Kutta output: :meth:`flexbody.model.Model.gap_root`, the same
    steps in C on the few coordinates the gap reads, not the whole state at each try).
    """
    output = getattr(dense, "output", None)  # the stepper's own (flexbody.driver._remembered)
    if output is not None and events.free[c]:  # the model's own search on it, where it has one
        root = events.model.gap_root(output, c, float(events.phases.floor[c]), ta, tb, ROOT_TIME)
        if root is not None:
            return root

    def g(t: float) -> float:
        return events.one(dense(t), c)

    fa, fb = g(ta), g(tb)
    if fa <= 0.0 and start > 0.0 and np.isfinite(start):
        # A held contact's force from its block alone (:meth:`EventFunctions.one`) pulls
        # where the whole problem's pushes: redundant rows share a force differently.  The
        # instant's resolve, which keeps it, agrees with the whole: root the whole's (else
        # the event fires again at every restart, a stall: measured in a pile, 1e-10 N).
        def g(t: float) -> float:
            return float(events(dense(t))[c])

        fa, fb = start, g(tb)
    if fa <= 0.0:
        return ta
    if fb > 0.0:  # the interpolant stays positive: the crossing is at the step's end
        return tb
    # a free contact's gap reads exactly 0 on a plateau where a particle lies in a coplanar
    # face's plane; a held one's function is 0 at its root only
    return first_fired(g, ta, tb, fa, fb, xtol=ROOT_TIME, plateaus=bool(events.free[c]))


def first_fired(g: Callable[[float], float], lo: float, hi: float, g_lo: float, g_hi: float,
                xtol: float, plateaus: bool = False) -> float:
    """The time where ``g`` fires (``g <= 0``; a NaN counts as fired) in ``[lo, hi]``, given
    ``g(lo) = g_lo > 0`` and ``g(hi) = g_hi <= 0``, within ``2 (xtol + 4 eps |t|)`` after
    the crossing (eps: the machine epsilon; the first one, if ``g`` crosses once):
    Chandrupatla's bracketing method (inverse quadratic interpolation where it is safe,
    else bisection).  Each new point lies at least the tolerance inside the bracket, so the
    search ends; the interpolation's acceptance test keeps it from creeping (a guard that
    bisects where the bracket has not halved in two steps, as Brent's, changed no count on
    random roots of ``|t - r|^q``, q = 0.25 to 9, and added evaluations in a pile).

    The bracket's fired end is returned, never an estimate on the side where nothing has
    happened yet (a contact force changing at 1e7 N/s moves 1e-8 N in 1e-15 s): a restart
    there would find the same event again.  The ends' values are reused, not evaluated
    again, and the search stops when the bracket is within the tolerance, not below the
    noise of ``g``'s round-off (measured in a pile: SciPy's ``brentq`` took 19.7 evaluations
    per impact root, with its ends evaluated again and a bisection after its estimate to
    reach the fired side; this takes 9.9).  A value of exactly 0 is a root; with
    ``plateaus``, where one is met, a point 2 tol toward the unfired end tells an isolated
    root from the inside of a plateau of zeros (a particle on a coplanar face's plane reads
    a gap of exactly 0 from where it met it on), which is bisected to its start.
    """
    eps = float(np.finfo(float).eps)
    a, g_a = float(hi), float(g_hi)  # the newest point
    b, g_b = float(lo), float(g_lo)  # the bracket's other end
    c, g_c = b, g_b  # the point dropped last (for the interpolation)
    t = 0.5
    while True:
        width, tol = abs(b - a), xtol + 4 * eps * max(abs(a), abs(b))
        if width <= 2 * tol or (not plateaus and (g_a == 0.0 or g_b == 0.0)):
            break
        if g_a == 0.0 and g_b > 0.0:
            # Exactly 0 is fired, and may be a plateau's inside (a particle on a coplanar
            # face's plane reads 0 from where it met it on; the root taken at the step's end,
            # whose value was 0 too, held it 1e-4 m past the face it met): one point 2 tol
            # toward the unfired end tells an isolated root (fired within the tolerance)
            # from a plateau, which is then bisected.
            x = a + 2.0 * tol / width * (b - a)
            g_x = g(x)
            if g_x > 0.0:
                return a
            a, g_a, t = x, g_x, 0.5
            width = abs(b - a)
            if width <= 2 * tol:
                break
        limit = tol / width  # at least tol from either end
        x = a + min(1.0 - limit, max(limit, t)) * (b - a)
        if x == a or x == b:  # the bracket holds no float between its ends (a tolerance of 0)
            break
        g_x = g(x)
        if (g_x > 0.0) == (g_a > 0.0):  # x replaces a: the bracket is [x, b]
            c, g_c = a, g_a
        else:  # x and a bracket: b is dropped
            c, g_c = b, g_b
            b, g_b = a, g_a
        a, g_a = x, g_x
        # inverse quadratic interpolation through a, b, c where it stays monotone (not off a
        # plateau of zeros: bisection)
        if 0.0 in (g_a, g_b, g_c) or g_c == g_b:
            t = 0.5
            continue
        xi, phi = (a - b) / (c - b), (g_a - g_b) / (g_c - g_b)
        if phi * phi < xi and (1.0 - phi) ** 2 < 1.0 - xi:
            t = g_a / (g_b - g_a) * g_c / (g_b - g_c) + (c - a) / (b - a) * g_a / (g_c - g_a) * g_b / (g_c - g_b)
        else:
            t = 0.5
    return b if g_a > 0.0 else a  # the fired end (a NaN counts as fired, as in the bookkeeping)
