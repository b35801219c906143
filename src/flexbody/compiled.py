"""The compiled path: smooth segments (``fb_integrate``) and event instants (``fb_resolve``) in C.

Both live in the runtime library (compiled once per install) and reach the model as an
FbSystem, so any C model runs on them: the assembled particles formulation or a
whole-scene derived one.  They work on buffers that live as long as one run: the state, the phases,
the output samples.  Their addresses are taken once, so a call costs a few microseconds
of ctypes instead of the ~30 us of converting a dozen arrays, and the fixed point at an
instant costs ~5 us instead of the ~100 us of :func:`flexbody.contact.resolve` (its
reference twin, which the tests hold it to).  The Python driver keeps the phase
machine's loop: it decides what to call, records the events and applies the guards.
"""

from __future__ import annotations

import ctypes

import numpy as np

from . import runtime
from .constants import IMPACT, LIFTOFF, SLIP, STICK  # noqa: F401  (event kinds as fb_resolve reports them)
from .contact import Phases, UnsettledInstant
from .model import Model, singular_matrix_error


def _address(a: np.ndarray, dtype=np.float64) -> int:
    """The address of a buffer C will read or write: it must have C's layout."""
    if a.dtype != dtype or not a.flags.c_contiguous:
        raise TypeError(f"a buffer handed to C must be contiguous {np.dtype(dtype)}, not {a.dtype} "
                        f"(contiguous: {a.flags.c_contiguous})")
    return a.ctypes.data


class CompiledPath:
    """Persistent buffers of one run and the two C calls on them.

    Parameters
    ----------
    model : Model
        A C model: it has ``system(p)``.
    p : ndarray, shape (np,)
    y : ndarray, shape (ny,)
        The state; both calls update it in place.
    phases : Phases
        Updated in place by :meth:`resolve` (``phase`` must be ``np.intc``) and, for
        re-armed floors, by :meth:`integrate`.
    grid : ndarray, shape (k,)
        Output times.
    samples : ndarray, shape (k, ny)
        Receives the states at the grid times.
    force_tolerance, masses : ndarray, shape (nc,)
    gap_tolerance : float
    restitution, min_rebound, friction : ndarray, shape (nc,), optional
        Each contact's Newton e, slowest rebound and Coulomb mu (see :func:`flexbody.contact.resolve`);
        0 by default.
    speed_tolerance : float
        A sliding contact slower than this (m/s) has come to rest.
    """

    def __init__(self, model: Model, p: np.ndarray, y: np.ndarray, phases: Phases, grid: np.ndarray,
                 samples: np.ndarray, force_tolerance: np.ndarray, masses: np.ndarray, gap_tolerance: float,
                 restitution: np.ndarray | None = None, min_rebound: np.ndarray | None = None,
                 speed_tolerance: float = 0.0, friction: np.ndarray | None = None) -> None:
        nc = model.n_contacts
        self.model, self.gap_tolerance, self.n_grid = model, gap_tolerance, len(grid)
        self.lib = runtime.library()
        self.system = model.system(p)
        self.work = runtime.Work(model.ny, nc)
        self._system, self._work = ctypes.addressof(self.system), self.work.address
        self.touching, self.leaving = np.zeros(nc, np.intc), np.zeros(nc, np.intc)  # events at a stop
        self.not_held = np.zeros(nc, np.intc)
        # At most an impact or lift-off, and a stick or slip, per contact and instant (and a lift-off after its impact).
        self.event_contact, self.event_kind = np.zeros(3 * nc, np.intc), np.zeros(3 * nc, np.intc)
        self.event_speed = np.zeros(3 * nc)
        self.speed_tolerance = speed_tolerance
        self.counters = np.zeros(4, ctypes.c_long)  # C long: nfev, steps, rejected steps, event evaluations
        self.n_sampled, self.n_events, self.iterations = ctypes.c_int(0), ctypes.c_int(0), ctypes.c_int(0)
        self.t_stop, self.loss, self.h_next = ctypes.c_double(0.0), ctypes.c_double(0.0), ctypes.c_double(0.0)
        self.min_gap = ctypes.c_double(np.inf)
        # The buffers (kept alive as long as C holds their addresses):
        self.p, self.y, self.phases, self.grid, self.samples = p, y, phases, grid, samples
        self.force_tolerance, self.masses = force_tolerance, masses
        self.restitution = np.zeros(nc) if restitution is None else np.ascontiguousarray(restitution, float)
        self.min_rebound = np.zeros(nc) if min_rebound is None else np.ascontiguousarray(min_rebound, float)
        self.friction = np.zeros(nc) if friction is None else np.ascontiguousarray(friction, float)
        self._laws = (_address(self.restitution), _address(self.min_rebound), _address(self.friction))
        self._y = _address(y)
        self._phase, self._floor = _address(phases.phase, np.intc), _address(phases.floor)
        self._push, self._push_until = _address(phases.push), _address(phases.push_until)
        self._grid, self._samples, self._row = _address(grid), _address(samples), samples.strides[0]
        self._force_tol, self._masses = _address(force_tolerance), _address(masses)
        self._touching, self._leaving = _address(self.touching, np.intc), _address(self.leaving, np.intc)
        self._events = (_address(self.event_contact, np.intc), _address(self.event_kind, np.intc),
                        _address(self.event_speed))
        self._not_held = _address(self.not_held, np.intc)
        self._counters = _address(self.counters, np.dtype(ctypes.c_long))
        self._integrate_out = tuple(map(ctypes.addressof, (self.n_sampled, self.t_stop)))
        self._integrate_tail = (self._touching, self._leaving, self._counters, ctypes.addressof(self.min_gap),
                                ctypes.addressof(self.h_next))
        self._resolve_out = (ctypes.addressof(self.n_events), self._not_held, ctypes.addressof(self.loss),
                             ctypes.addressof(self.iterations))

    def integrate(self, method: int, t0: float, t_bound: float, rtol: float, atol: float,
                  first_sample: int, max_seconds: float = float("inf")) -> tuple[int, float, int]:
        """One smooth segment from ``t0`` until the first event or ``t_bound``.

        The state ``y`` becomes the state at the stop; ``touching`` and ``leaving`` mark the
        gap events of free contacts and the force events of held ones that fired there.
        Grid samples are written from row ``first_sample`` on; after ``max_seconds`` of wall
        time the segment stops with status TOO_SLOW.

        Returns
        -------
        status : int
            A status of :mod:`flexbody.constants`: REACHED, EVENT, STEP_COLLAPSE, NON_FINITE,
            SINGULAR or TOO_SLOW.
        t_stop : float
        n_samples : int
            Rows of ``samples`` written.
        """
        status = self.lib.fb_integrate(
            self._work, self._system, method, t0, self._y, t_bound, self._phase, self._push, self._floor, self._force_tol,
            self._masses, self.gap_tolerance, self.speed_tolerance, rtol, atol, self._grid + 8 * first_sample,
            self.n_grid - first_sample,
            self._samples + self._row * first_sample, *self._integrate_out, self._y, *self._integrate_tail,
            max_seconds,
        )
        return status, self.t_stop.value, self.n_sampled.value

    def resolve(self, t: float, touching: np.ndarray, leaving: np.ndarray, thesis: bool,
                impact_dt: float) -> tuple[list[tuple[int, int, float]], np.ndarray, float]:
        """The fixed point at instant ``t`` on ``y`` and the phases (see ``fb_resolve``).

        Returns
        -------
        events : list of (contact, kind, normal velocity)
            kind is IMPACT, LIFTOFF, STICK or SLIP, in the order :func:`flexbody.contact.resolve` gives.
        not_held : ndarray of int, shape (nc,)
        loss : float
            Kinetic energy removed by instant impacts (J).
        """
        if touching is not self.touching:  # the integrator's own buffers need no copy
            self.touching[:] = touching
        if leaving is not self.leaving:
            self.leaving[:] = leaving
        status = self.lib.fb_resolve(
            self._work, self._system, t, self._y, self._phase, self._floor, self._push, self._push_until, self._touching,
            self._leaving, self.gap_tolerance, self._force_tol, self._masses, *self._laws, self.speed_tolerance, int(thesis),
            impact_dt or 0.0,
            *self._events, *self._resolve_out,
        )
        if status == -1:
            raise singular_matrix_error()
        if status == -2:
            raise UnsettledInstant(t, self.iterations.value)
        n = self.n_events.value
        events = list(zip(self.event_contact[:n].tolist(), self.event_kind[:n].tolist(),
                          self.event_speed[:n].tolist()))
        return events, self.not_held, self.loss.value
