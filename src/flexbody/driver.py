"""The simulation driver: integrate smooth segments, stop at events, apply the phase machine.

``simulate`` integrates the generated model from event instant to event instant, either
with the generated C integrator (``dopri5``, ``dop853``: one C call per smooth segment) or
with one of SciPy's ``solve_ivp`` methods (their stepper classes, driven step by step so
that co-timed events are all found).  At each instant the fixed point of
:func:`flexbody.contact.resolve` applies impacts, contact and lift-off (with the C backend
its compiled twin ``fb_resolve`` does), then a fresh segment starts.  The loop, the events
and the guards stay here, whichever path integrates.
"""

from __future__ import annotations

import numbers
import os
import time
from collections import defaultdict, deque
from collections.abc import Callable
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass

import numpy as np

from . import __version__
from .compiled import CompiledPath
from .constants import (EVENT, IMPACT, LIFTOFF, NON_FINITE, SINGULAR, SLIDING, SLIP, STEP_COLLAPSE, STICK,
                        TOO_SLOW, VELOCITY_ROUNDOFF, ZENO_RISE)
from .assembly import AssembledModel
from .choices import CASCADE_FALL, CHATTER_WINDOW
from .contact import FREE, HELD, PUSHED, Event, Phases, UnsettledInstant, resolve
from .contact_problems import UNALIGNED
from .coupled import POISSON, CoupledImpactError, project_held
from .edge_contact import EdgeSlots
from .events import EventFunctions, locate
from .model import MADE_FOR, Model, couples_contacts, load_model, made_for, resolved_formulation
from .result import STATUSES, SimulationResult
from .samples import ContactSamples
from .scene import (
    COMPILED_METHODS,
    IMPACT_MODES,
    METHODS,
    Scene,
    SceneError,
    SimulationSettings,
    load_scene,
)
from .state import initial_coordinates

#: SciPy's stepper classes by method name (scipy.integrate is imported only when one is used:
#: it takes ~0.6 s, and the default compiled path does not need it).
SCIPY_METHODS = ("RK45", "RK23", "DOP853", "Radau", "BDF", "LSODA")
IMPLICIT = ("Radau", "BDF", "LSODA")

#: Above these a run is flagged in ``stats["warnings"]``: relative energy drift, and rtol
#: (looser tolerances can change the event sequence).
DRIFT_WARNING, LOOSE_RTOL = 1e-3, 1e-4
#: A particle with more impacts than ``simulation.chatter_impacts`` (default CHATTER_IMPACTS)
#: within CHATTER_WINDOW seconds is chattering: in a row without being held (an
#: accumulation the Zeno threshold does not end), or held each time and released again.  A
#: cascade of rebounds that ends held counts as its hold: a flexible sphere landing on
#: another with e = 0.5 restarted its cascade (7 impacts, the last held) 4 times within 1 ms
#: as its neighbours' impacts released it, 26 impacts.  Within the window a burst that ends
#: looks like one that does not: where a scene's bursts end (a pile settling), the scene
#: raises its bound.
#: A contact switching between stick and slip more than this within CHATTER_WINDOW is chattering.
CHATTER_FRICTION = 25
#: A sliding contact slower than this times sqrt(|g| size) has come to rest (m/s).
SPEED_TOLERANCE = 1e-7
#: A held contact of a coupled model this many gap tolerances off its surface is put back on
#: it (its gap is not linear in the coordinates: the integrator's error drifts it).
PROJECT_GAPS = 2.0
#: A step that leaves a held contact of a coupled model more than this many gap tolerances
#: off its surface is taken again at half its length (and no longer until the contact set
#: changes): put back after the step, it would have sunk that deep within it.  RK45 at atol
#: 1e-9 accepted a 20 ms step of two rigid bodies resting on each other that sank 3.9e-9 m.
SINK_GAPS = 100.0
#: ... checked there at the step's end and at these fractions of it on its dense output.
SINK_POINTS = (0.5, 0.25, 0.75)
#: A held contact that sank deeper than this many gap tolerances is warned of: deeper than a
#: step lets it sink (one that could not be shortened).
SINK_WARNING = 100.0
#: ... and one put back from farther off its surface than this many: the move shifts the
#: bodies by that much (the held contacts of 3D piles are put back from 1.5e-10 m at most,
#: ~300 gap tolerances; a row held on the wrong edge, 2e-3 m apart, was put back unflagged).
PUT_BACK_WARNING = 1e4
#: Names of the compiled fixed point's event kinds.
EVENT_KINDS = {IMPACT: "impact", LIFTOFF: "liftoff", STICK: "stick", SLIP: "slip"}
#: An instant whose impacts add more than this fraction of the energy is warned of (an
#: impact law's gain, not rounding: a frictionless plastic or elastic one adds ~1e-16).
IMPACT_GAIN = 1e-9
#: A step shorter than this (s) is not shortened again for a held contact's sink.
STALL_TIME = 1e-12
#: Event instants closer than this (s) count as no progress; STALL_COUNT in a row is a
#: failure (``no_progress``).  Not the root finder's resolution (1e-15 s): a corner handed
#: between a slot and its corner twin lifted off every 3.7e-12 s, 4 000 instants of it until
#: the wall time ran out (``too_slow``, 90 s after the loop began; fixed since, see
#: :meth:`flexbody.body_contact.BodyContactModel.switch_elements`).
#: 200 instants within 2e-7 s are none a run can afford either way; a pile's come 1e-4 s
#: apart on average.
PROGRESS_TIME, STALL_COUNT = 1e-9, 200

Progress = Callable[[float, float, int], None]


class SimulationFailed(Exception):
    def __init__(self, status: str, message: str) -> None:
        super().__init__(message)
        self.status, self.message = status, message


def _unending(recent: deque[tuple[float, float, bool]], in_a_row: int) -> int:
    """Of the last ``in_a_row`` impacts of ``recent`` (time, normal velocity, held), the
    first and those that came in no slower than :data:`CASCADE_FALL` of the one before:
    the rebounds a converging cascade does not explain."""
    speeds = [abs(v) for _, v, _ in list(recent)[len(recent) - in_a_row :]]
    return min(len(speeds), 1) + sum(b > CASCADE_FALL * a for a, b in zip(speeds, speeds[1:]))


def _non_finite(t: float) -> tuple[str, str]:
    return "blow_up", f"the state became non-finite at t = {t:.9g} s; tighten --rtol/--atol or use an implicit method."


#: Two 3D bodies' surfaces crossing edge through face by more than this many gap tolerances
#: are measured and warned of (:meth:`_Run.track_edges`): 1e-9 of the scene's size, the
#: penetration the tests allow a particle, so that a face resting on a face (edges in the
#: other's plane to round-off, held contacts drifting by up to 2 gap tolerances) is not one;
#: two far parts of a 2D body with self-contact crossing no deeper are no fold either.
EDGE_DEPTH = 1e3
#: A free contact between bodies found inside the other body by more than this many gap
#: tolerances at a step's end has its surfaces checked for a fold at once (not only at the
#: next output sample): a surface that folded over turns a gap's sign, and a particle that
#: was outside reads deep inside, or an integrator stalls against it (seen in a fuzz: an
#: unbraced ring collapsing beside a box ended `success` 0.086 m "inside" it, and another
#: stopped `too_slow` at one instant).
FOLD_PROBE = 1e3
#: ... checked this many times per output interval (at the steps' ends: see _Run.track_edges).
EDGE_CHECKS = 4

#: A step collapse or a singular M with a floating 3D body's angle beta this close to
#: +-90 deg (its X-Y-Z angles' gimbal lock) is that singularity, reported as such (deg).
GIMBAL_LOCK_DEG = 1.0


def _gimbal_lock(scene: Scene, model: Model, y: np.ndarray, t: float) -> tuple[str, str] | None:
    """``blow_up`` naming the body whose frame T reached its angles' gimbal lock in state ``y``,
    or None.  Whether the integrator's trial state there fails the mass matrix's
    factorisation or its steps shrink first (a step collapse) depends on rounding, so on the
    machine: both are the same singularity."""
    names = getattr(getattr(model, "inner", model), "q_names", ())  # a body-contact model wraps it
    for k, name in enumerate(names):
        # |cos beta| small: within GIMBAL_LOCK_DEG of +-90 deg (or of any odd multiple of it)
        if name.startswith("beta") and abs(np.cos(y[k])) < np.sin(np.radians(GIMBAL_LOCK_DEG)):
            body = scene.bodies[int(name[4:])].name
            return "blow_up", (f"at t = {t:.9g} s body {body!r} reached its frame T's gimbal lock (beta = "
                               f"{np.degrees(y[k]):.4f} deg), where the mass matrix of its X-Y-Z angles is singular; a body "
                               "that tumbles freely needs the particles formulation.")
    return None


def _model_kind(model: Model) -> str:
    """How a run's model was made: "assembled" (element kernels), "derived" (whole by Kane) or
    "mixed" (flexible bodies assembled, rigid frames derived beside them)."""
    from .mixed import MixedModel

    return "assembled" if isinstance(model, AssembledModel) else "mixed" if isinstance(model, MixedModel) else "derived"


def _scipy_version() -> str:
    from importlib.metadata import version

    return version("scipy")


def _surface_of(model: Model, contact: int) -> int:
    """The body whose surface ``contact`` touches (its index in the scene's bodies), or -1 for a ground."""
    if contact < model.n_ground_contacts:
        return -1
    return int(model.contacts[contact][1]) - model.n_grounds


def _lowest_gaps(positions: np.ndarray, grounds, held: np.ndarray) -> tuple[float, float]:
    """The lowest gap of any particle to any ground over samples ``positions (nt, n, dim)``,
    of the contacts free there and of those held there (``held (nt, n * n_grounds)``, the
    ground contacts' codes, particle-major)."""
    if not (positions.size and grounds):
        return np.inf, np.inf
    gaps = np.stack([(positions - np.asarray(g.point)) @ np.asarray(g.normal) for g in grounds], axis=2)
    on = held.reshape(gaps.shape) != 0
    return float(gaps[~on].min(initial=np.inf)), float(gaps[on].min(initial=np.inf))


#: How two bodies' surfaces cross with no particle inside the other, by dimension
#: (:meth:`flexbody.body_contact.BodyContactModel.crossed_edges`).
_CROSSED = {2: "segment across segment", 3: "edge on edge"}


def _dense(matrix) -> np.ndarray:
    return matrix.toarray() if hasattr(matrix, "toarray") else matrix


def _remembered(dense: Callable[[float], np.ndarray]) -> Callable[[float], np.ndarray]:
    """A step's dense output ``t -> y (ny,)`` that evaluates each time once: event location
    asks for the same points again (a root's bracket ends, the instant found, the step's
    midpoint), each a pass over the whole state.  The states are handed out read-only: each
    is kept for whoever asks for that time next.  ``at.output`` is ``dense`` itself, for a
    model that evaluates a few coordinates of it (:meth:`flexbody.model.Model.gap_root`,
    :meth:`flexbody.model.Model.dense_gaps`)."""
    states: dict[float, np.ndarray] = {}

    def at(t: float) -> np.ndarray:
        key = float(t)
        if key not in states:
            states[key] = dense(t)
            states[key].flags.writeable = False
        return states[key]

    at.output = dense
    return at


def _settings(scene: Scene, overrides: dict) -> SimulationSettings:
    """The scene's settings with the given overrides, each validated.

    Raises
    ------
    flexbody.errors.InputError
        Listing every bad option (name, value, rule), as for a scene file.
    """
    from .errors import InputError, shown  # here, not at the top: this function is the validation's only user
    from .scene import timing_problems

    s = scene.simulation
    values = {k: getattr(s, k) for k in s.__dataclass_fields__}
    for key, value in overrides.items():
        if value is not None:
            values[key] = value
    problems = []
    if values["formulation"] in ("particles", "floating"):  # a scene of rigid bodies alone is its frames T (DESIGN §6)
        values["formulation"] = resolved_formulation(scene, values["formulation"])
    coupled = couples_contacts(scene, values["formulation"])
    if values["method"] is None:
        values["method"] = "dopri5" if values["backend"] == "c" and not coupled else "RK45"
    if values["method"] in COMPILED_METHODS and values["backend"] != "c":
        problems.append(f"`method` = {values['method']!r}: is compiled C and needs backend 'c'; with backend "
                        f"{values['backend']!r} use a SciPy method ({', '.join(METHODS[len(COMPILED_METHODS):])})")
    if values["method"] not in METHODS:
        problems.append(f"`method` = {shown(values['method'])}: must be one of {list(METHODS)}")
    for key, inside, rule in (("rtol", lambda x: 1e-14 <= x < 1, "[1e-14, 1)"), ("atol", lambda x: 0 < x < 1, "(0, 1)")):
        value = values[key]  # a string would not compare (a bare TypeError); nan fails every comparison
        if not isinstance(value, numbers.Real) or isinstance(value, bool):
            problems.append(f"`{key}` = {shown(value)}: must be a number in {rule}")
        elif not inside(value):
            problems.append(f"`{key}` = {value!r}: must be in {rule}")
    bound = values["chatter_impacts"]
    if not isinstance(bound, numbers.Integral) or isinstance(bound, bool) or bound < 1:
        problems.append(f"`chatter_impacts` = {shown(bound)}: must be an integer >= 1 (impacts of one particle "
                        f"within {CHATTER_WINDOW * 1e3:g} ms)")
    else:
        values["chatter_impacts"] = int(bound)
    if values["impact"] not in IMPACT_MODES:
        problems.append(f"`impact` = {shown(values['impact'])}: must be one of {list(IMPACT_MODES)}")
    if values["impact"] == "instant":
        # The scene's ΔT is unused when the mode is switched to instant; a ΔT given as an option is a mistake.
        values["impact_dt"] = overrides.get("impact_dt")
    problems += [f"`{key}` = {value!r}: {rule}" for key, value, rule in
                 timing_problems(values["t_end"], values["output_dt"], values["impact"], values["impact_dt"])]
    problems += _contact_law_problems(scene, values) + _body_contact_problems(scene, values)
    if problems:
        raise InputError("invalid simulation options:\n" + "\n".join(f"  - {p}" for p in problems))
    return SimulationSettings(**values)


# ----------------------------------------------------------------------------------------------
# Contact between bodies (flexbody.body_contact) runs between flexible and rigid bodies, with
# friction in 2D and instant impacts; what it cannot run with yet is refused here, naming the
# bodies, never ignored.


def _body_contact_problems(scene: Scene, values: dict) -> list[str]:
    """What the scene's contacts between bodies cannot run with yet (one sentence each)."""
    if not scene.contacts:
        if couples_contacts(scene, values["formulation"]) and values["method"] in COMPILED_METHODS:
            why = ("a rigid body on a ground with friction runs with SciPy's steppers (the compiled loop does not know "
                   "coupled sticking and sliding)" if any(g.friction > 0.0 for g in scene.grounds) else
                   "rigid bodies beside flexible ones on the particles formulation run with SciPy's steppers (the "
                   "compiled loop knows one model, not the two side by side)")
            return [_scipy_only(values["method"], why)]
        return []
    out = []
    if values["impact"] == "thesis":
        out.append("`impact` = 'thesis' with bodies that may touch each other: the window force -m v_n / dT "
                   "(eq. 4.6) takes one particle's mass, not a contact between bodies' effective mass; use "
                   "impact = 'instant' (the default)")
    if values["method"] in COMPILED_METHODS:
        out.append(_scipy_only(values["method"], "bodies that may touch each other run with SciPy's steppers (the "
                               "compiled loop knows the grounds only)"))
    return out


def _check_apart(scene: Scene, model: Model, q: np.ndarray, p: np.ndarray) -> None:
    """Refuse bodies that may touch each other but start inside one another (checked on the
    built model, so after the scene's fields are valid).

    Raises
    ------
    flexbody.scene.SceneError
        One problem per pair of bodies, at the position of a body whose particles are inside
        the other: the particles of each inside the other's surface and how deep, or the
        edges that cross.
    """
    if not model.n_slots:
        return
    size = max(1.0, float(np.abs(scene.initial_positions()).max()))
    gaps = model.gaps(q, p)[model.n_ground_contacts :]
    inside = gaps < -1e-9 * size
    inside[model.first_edge :] = False  # edges crossed, not particles inside: crossed_edges below names them
    depth = -gaps
    deep, how_deep = model.deep_inside(q, p)  # beyond the margin too (a gap reads `margin` there)
    deep, how_deep = deep[how_deep > 1e-9 * size], how_deep[how_deep > 1e-9 * size]  # not a touch's rounding
    inside[deep] = True
    depth[deep] = np.maximum(depth[deep], how_deep)
    names = [b.name for b in scene.bodies]
    rule = "bodies that may touch must start apart (or touching)"

    def at(body: int) -> str:
        return f"`bodies[{body}].position` = {list(scene.bodies[body].position)}"

    if not inside.any():  # EDGE_DEPTH gap tolerances (1e-12 of the size) deep, as in a run
        crossed = model.crossed_edges(np.concatenate([q, np.zeros(model.nu + 2)]), p, EDGE_DEPTH * 1e-12 * size)
        if crossed is not None:  # no particle inside, and yet two surfaces cross
            _, first, second, how = crossed
            raise SceneError(scene.source, [f"{at(first)}: bodies {names[first]!r} and {names[second]!r} start crossed "
                                            f"{_CROSSED[model.dim]} ({names[first]!r}: {how}); {rule}"])
        return
    pairs: dict[tuple[int, int], list] = {}  # each pair of bodies once, whichever is inside which
    for toucher in sorted(set(zip(model.particle_body[model.slot_particle[inside]], model.slot_body[inside]))):
        rows = inside & (model.particle_body[model.slot_particle] == toucher[0]) & (model.slot_body == toucher[1])
        found = pairs.setdefault(tuple(sorted(toucher)), [int(toucher[0])])  # at the position of a body inside
        found.append(f"body {names[toucher[0]]!r} starts inside body {names[toucher[1]]!r}: its particles "
                     f"{model.slot_particle[rows].tolist()} (scene numbering) are up to {depth[rows].max():.3g} m "
                     "inside its surface")
    raise SceneError(scene.source, [f"{at(inner)}: {', and '.join(found)}; {rule}" for inner, *found in pairs.values()])


def _scipy_only(method: str, why: str) -> str:
    """The refusal of a compiled ``method`` for a scene that runs with SciPy's steppers."""
    others = ", ".join(m for m in METHODS[len(COMPILED_METHODS):] if m != "RK45")
    return f"`method` = {method!r}: {why}; use RK45 (the same Dormand-Prince pair, the default here) or {others}"


# ----------------------------------------------------------------------------------------------


def _contact_law_problems(scene: Scene, values: dict) -> list[str]:
    """What the grounds' friction and restitution cannot run with (one sentence each)."""
    friction = [j for j, g in enumerate(scene.grounds) if g.friction > 0.0]
    restitution = [j for j, g in enumerate(scene.grounds) if g.restitution > 0.0]
    out = []
    rigid = scene.rigid_bodies
    if rigid and values["impact"] == "thesis":
        out.append(f"`impact` = 'thesis': bodies {rigid} are rigid, and the thesis's window force -m v_n / dT "
                   "(eq. 4.6) takes the particle's own mass, not the effective mass 1 / (J M^-1 J^T) of a rigid "
                   "body's coupled contact; use impact = 'instant' (the default)")
    elif (friction or restitution) and values["formulation"] == "floating" and not rigid:
        out.append(f"`formulation` = 'floating': grounds {sorted(set(friction + restitution))} have friction or "
                   "restitution, which only the particles formulation (the default) applies")
    return out


def _rebound_laws(scene: Scene, model: Model, size: float) -> tuple[np.ndarray, np.ndarray]:
    """Each contact's Newton e and slowest rebound speed, shape (nc,) each.

    A rebound at ``v`` against gravity's pull ``a = -g . n`` rises ``v^2 / (2 a)``; below
    ``ZENO_RISE * size`` it is plastic (DESIGN §6), so a bouncing particle comes to rest at
    its Zeno time t1 (1 + e) / (1 - e) instead of bouncing ever faster.  Grounds gravity does
    not pull towards never stop a rebound this way (0).  Between bodies (contacts past the
    grounds': ``model.slot_pair``) e is the pair's, and the pull ``max(|g|, 1 m/s^2)``.
    """
    grounds = scene.grounds
    ground = model.contacts[: model.n_ground_contacts, 1]
    e = np.array([g.restitution for g in grounds])[ground]
    pull = np.array([max(0.0, -float(np.dot(scene.gravity, g.normal))) for g in grounds])[ground]
    pairs = model.slot_pair
    e = np.concatenate([e, np.array([c.restitution for c in scene.contacts])[pairs]])
    # between bodies: no gravity direction to rise against; |g|, at least 1 m/s^2 (as the speed
    # tolerance), so two bodies in free space end a rocking accumulation of impacts too
    pull = np.concatenate([pull, np.full(len(pairs), max(float(np.linalg.norm(scene.gravity)), 1.0))])
    return e, np.sqrt(2.0 * pull * ZENO_RISE * size)


@dataclass
class _Window:
    """A thesis-mode impact window with friction: its constant force on its particle."""

    contact: int
    particle: int
    t_start: float
    force: np.ndarray  # (dim,) N: the normal push along the ground's normal plus the tangential one
    x_start: np.ndarray  # (dim,) the particle's position when it started
    t_end: float = np.inf
    x_end: np.ndarray | None = None


@dataclass
class _Stop:
    t: float
    touching: np.ndarray  # (nc,), nonzero: free contacts whose gap event fired
    leaving: np.ndarray  # (nc,), nonzero: held contacts whose force event fired
    fired: bool  # whether any did
    grow: np.ndarray | None = None  # the scene's pairs that need slots from here on (_Run.grow)


class _Run:
    """State of one simulation: model, state and phases, samples, counters.

    ``y`` and ``phases`` are updated in place from instant to instant, and the output
    samples are written into preallocated arrays, so the compiled path can hand C their
    addresses once (:class:`flexbody.compiled.CompiledPath`).
    """

    def __init__(self, scene: Scene, model: Model, settings: SimulationSettings, progress: Progress | None,
                 max_events: int, max_wall_time: float = np.inf) -> None:
        self.scene, self.model, self.settings = scene, model, settings
        self.progress, self.max_events = progress, max_events
        self.deadline = time.perf_counter() + max_wall_time
        self.p = model.parameters(scene)
        self.p.flags.writeable = False  # fixed for the run: C calls know it unchanged (runtime.SystemModel.system)
        q, u = initial_coordinates(scene, model)
        size = self.size = float(np.abs(scene.initial_positions()).max()) if scene.n_particles else 1.0
        self.contact_laws()
        self.friction = bool(np.any(self.mu > 0.0))  # anywhere in the scene: in slots to come too
        self.digest = model.digest
        self.retaken = 0  # steps taken again with the slots of a pair that came near within them
        near = model.pairs_in_reach(q, self.p, model.pairs_ahead) if getattr(model, "grows", False) else None
        if near is not None and not np.array_equal(near, model.pairs):  # slots for the pairs in reach (see grow)
            model = self.model = model.with_pairs(near)
            self.contact_laws()
        _check_apart(scene, model, q, self.p)
        self.y = np.concatenate([q, u, [0.0, 0.0]])
        self.phases = Phases.all_free(model.n_contacts)
        self.gap_tolerance = 1e-12 * max(size, 1.0)
        self.max_edge_crossing, self.edge_crossing = 0.0, None  # 3D edges through faces (see track_edges)
        self.t_edges = -np.inf  # the last check of crossed edges (see track_edges)
        self.zeno_rise = ZENO_RISE * size
        # A sliding contact slower than this has come to rest (a stop's root is ~1e-15 s wide).
        self.speed_tolerance = SPEED_TOLERANCE * np.sqrt(max(float(np.linalg.norm(scene.gravity)), 1.0) * max(size, 1.0))
        # The thesis mode's windows with friction: their constant forces (normal and tangential)
        # and the samples' tangential ones, to split the integrated contact work (see result).
        thesis_friction = self.friction and settings.impact == "thesis"
        self.windows: list[_Window] | None = [] if thesis_friction else None
        self.grid = np.linspace(0.0, settings.t_end, int(round(settings.t_end / settings.output_dt)) + 1)
        n = len(self.grid)
        self.Y = np.empty((n, model.ny))  # samples at the grid times, the first n_samples of them taken
        # each sample's contact-law codes (Phases.held), pushes, the windows' tangential pushes and,
        # between bodies, the element each slot was held on (its force's row), kept sparse
        self.samples = ContactSamples(model.n_contacts, model.n_slots, model.dim, thesis_friction)
        # with friction, the law each sample's step integrated (SciPy's steppers; see record)
        self.sample_slips: list[tuple[np.ndarray, np.ndarray, np.ndarray] | None] | None = \
            [None] * n if self.friction else None
        self.n_samples = 0
        self.events: list[Event] = []
        # for the chatter guard: each contact's impacts (time, normal speed, held)
        self.impact_times: dict[int, deque[tuple[float, float, bool]]] = defaultdict(deque)
        self.friction_times: dict[int, deque[float]] = defaultdict(deque)  # stick and slip events, likewise
        self.losses: list[tuple[float, float]] = []
        self.indeterminate: list[tuple[float, str]] = []  # instants whose contact forces may not be unique or Coulomb's
        self.projections = 0  # held contacts put back on their surfaces (coupled models, SciPy's steppers)
        self.max_put_back = 0.0  # ... the farthest one was off its surface then (m)
        self.shortened = 0  # steps taken again shorter: a held contact sank too deep within them, or a
        # particle moved too far relative to another (BodyContactModel.step_reach)
        self.nfev = self.njev = self.steps = self.segments = 0
        self.h_next = 0.0  # the step an explicit stepper proposed where the last segment ended (s)
        # A segment's bound on its steps (a step that sank was taken again shorter: the rest
        # of the segment keeps that bound), carried over a stop that only gave pairs their
        # slots, which is no event: the run goes on as without that stop (s; None: none).
        self.step_cap: float | None = None
        self.segment_log: list | None = None  # set to [] to log (RHS evaluations, y0, held, push) per segment
        self.min_gap = np.inf  # lowest gap of a free contact (an impact missed between event checks)
        self.min_held_gap = np.inf  # ... and of a held one (its constraint drifted)
        self.y_started: np.ndarray | None = None  # the state right after the instant at t = 0 (see result)
        # the lowest gaps before the last step's end was tracked, and that step's start: a
        # surface found folded there has no inside, its gaps measure nothing (refuse_fold)
        self.gaps_before, self.step_start = (np.inf, np.inf), 0.0
        self.folded_from = np.inf  # samples after this time are of a folding step (see refuse_fold)
        self.stalled = 0
        self.compiled = None
        if model.backend == "c" and model.compiled_segments:
            self.compiled = CompiledPath(model, self.p, self.y, self.phases, self.grid, self.Y,
                                         self.force_tolerance, self.contact_masses, self.gap_tolerance,
                                         self.restitution, self.min_rebound, self.speed_tolerance, self.mu)

    def contact_laws(self) -> None:
        """Each contact's effective mass, force tolerance, restitution, slowest rebound and
        friction coefficient, shape (nc,) each, from the model's table."""
        scene, model = self.scene, self.model
        # For point masses on flat grounds a contact's effective mass 1 / (J M^-1 J^T) is its particle's.
        self.contact_masses = scene.masses[model.contacts[:, 0]]
        self.force_tolerance = 1e-10 * self.contact_masses * max(float(np.linalg.norm(scene.gravity)), 1.0)
        self.restitution, self.min_rebound = _rebound_laws(scene, model, self.size)
        if model.mu is not None:  # contacts between bodies: the grounds', then the pairs'
            self.mu = model.mu.copy()
        else:
            self.mu = np.array([g.friction for g in scene.grounds], float)[model.contacts[:, 1]] \
                if model.n_contacts else np.zeros(0)

    def pairs_near(self, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The scene's pairs without slots yet (indices into ``scene.contacts``) whose bodies'
        boxes lie within the model's ``pairs_late`` and within its ``pairs_ahead`` of each
        other at ``y``, shape (k,) and (j,); none where the table does not grow (:meth:`grow`)."""
        model = self.model
        if not getattr(model, "grows", False) or not len(model.waiting):
            return np.zeros(0, np.intp), np.zeros(0, np.intp)
        apart = model.pair_separations(y[: model.nq], self.p, model.waiting)
        return model.waiting[apart <= model.pairs_late], model.waiting[apart <= model.pairs_ahead]

    def grow(self, pairs: np.ndarray) -> None:
        """Give the scene's pairs ``pairs`` their slots from here on: the model's table grows
        (:meth:`flexbody.body_contact.BodyContactModel.with_pairs`), and every contact's
        phase, samples, events and counts move to its place in the new table; the new slots
        start free, armed at their surfaces."""
        old = self.model
        self.model = old.with_pairs(np.union1d(old.pairs, pairs))
        new = self.model.contact_map(old)
        self.phases = self.phases.moved(new, self.model.n_contacts)
        ng = old.n_ground_contacts
        self.samples.move(new, self.model.n_contacts, new[ng:] - ng, self.model.n_slots)
        if self.sample_slips is not None:
            self.sample_slips = [law if law is None else (new[law[0]], *law[1:]) for law in self.sample_slips]
        for e in self.events:
            e.contact = int(new[e.contact])
        self.impact_times = defaultdict(deque, {int(new[c]): v for c, v in self.impact_times.items()})
        self.friction_times = defaultdict(deque, {int(new[c]): v for c, v in self.friction_times.items()})
        self.contact_laws()

    @property
    def counters(self) -> np.ndarray:
        """Compiled-path counters: RHS evaluations, steps, rejected steps, event evaluations."""
        return self.compiled.counters if self.compiled else np.zeros(4, np.int64)

    @property
    def evaluations(self) -> int:
        """RHS evaluations so far, by either path, including those for event location."""
        return self.nfev + int(self.counters[0] + self.counters[3])

    def keep_samples(self, start: int, stop: int) -> None:
        """Tag samples ``start:stop`` with the current contact set."""
        if stop == start:
            return
        samples = self.samples
        samples.keep(start, stop, self.phases.held, self.phases.push,
                     self.model.tangential_pushes(self.p) if samples.has_tangential else None,
                     self.model.element_of if samples.n_slots else None)
        self.n_samples = stop

    # ------------------------------------------------------------------ one smooth segment
    def segment(self, t0: float, t_bound: float) -> _Stop:
        """Integrate with a fixed contact set from ``t0`` until an event or ``t_bound``; ``y`` becomes
        the state there."""
        if self.segment_log is not None:
            before = self.evaluations
            y0, held, push = self.y.copy(), self.phases.on_ground, self.phases.push.copy()
        self.segments += 1
        if self.settings.method in COMPILED_METHODS:
            stop = self.segment_compiled(t0, t_bound)
        else:
            stop = self.segment_scipy(t0, t_bound)
        if self.segment_log is not None:  # what the segment's work cost, for the benchmark's RHS limit
            self.segment_log.append((self.evaluations - before, y0, held, push))
        if self.progress:
            self.progress(stop.t, self.settings.t_end, len(self.events))
        return stop

    def segment_compiled(self, t0: float, t_bound: float) -> _Stop:
        """The same as :meth:`segment_scipy`, in one call of the generated C integrator."""
        s, c = self.settings, self.compiled
        start = self.n_samples
        budget = max(0.0, self.deadline - time.perf_counter())
        status, t_stop, n_new = c.integrate(COMPILED_METHODS.index(s.method), t0, t_bound, s.rtol, s.atol, start,
                                            budget)
        self.keep_samples(start, start + n_new)
        self.min_gap = c.min_gap.value
        if status < 0:
            if status == TOO_SLOW:
                raise SimulationFailed(*self.too_slow(t_stop))
            lock = _gimbal_lock(self.scene, self.model, self.y, t_stop) if status in (STEP_COLLAPSE, SINGULAR) else None
            raise SimulationFailed(*(lock or self.COMPILED_FAILURES[status](s.method, t_stop)))
        return _Stop(t_stop, c.touching, c.leaving, status == EVENT)

    COMPILED_FAILURES = {
        STEP_COLLAPSE: lambda m, t: (
            "step_size_collapse", f"{m} failed at t = {t:.9g} s: the step size collapsed. The model is too stiff for "
            "this method or tolerance: try --method Radau or BDF, or a looser --rtol."),
        NON_FINITE: lambda m, t: _non_finite(t),
        SINGULAR: lambda m, t: ("blow_up", f"at t = {t:.9g} s: mass or contact matrix not positive definite."),
    }

    def segment_scipy(self, t0: float, t_bound: float) -> _Stop:
        """Integrate with one of SciPy's steppers, locating events on its dense output."""
        model, s, phases = self.model, self.settings, self.phases
        options = {"rtol": s.rtol, "atol": s.atol}
        if s.method in IMPLICIT:
            options["jac"] = jacobian = model.jacobian_function(self.p, phases.held)
            if s.method == "LSODA":  # Radau and BDF take the sparse Jacobian; LSODA only a dense one
                options["jac"] = lambda t, y: _dense(jacobian(t, y))
        elif self.h_next > 0.0:  # as the compiled path: a restart does not guess the step size again
            options["first_step"] = min(self.h_next, t_bound - t0)
        if self.step_cap is not None:  # the segment before ended where pairs got their slots: its bound goes on
            options["max_step"], self.step_cap = self.step_cap, None
        import scipy.integrate

        # a free contact between bodies picks its element at its next instant
        model.start_segment(phases.phase == FREE, self.y[: model.nq], self.p)
        # also at a segment's start: a pile's segments are often one step long, each ending at an event
        if not self.put_back() and model.n_slots > model.first_edge:
            # A free edge contact read its gap on the edge the instant held it to; free, it
            # reads the closest edge by its rules, which can start at or below its floor
            # (a pile: -1e-16 m, then 1.6e-7 m through unseen): armed below it again.
            phases.arm(model.gaps(self.y[: model.nq], self.p), self.gap_tolerance)
        # first: it clears the directions of earlier slides, which the stepper's first stage must not see
        events = EventFunctions(model, self.p, phases, self.force_tolerance, self.gap_tolerance, self.speed_tolerance,
                                None if s.method in IMPLICIT else self.contact_masses)
        stepper, rhs = getattr(scipy.integrate, s.method), model.rhs_function(self.p, phases.held, phases.push)
        solver = stepper(rhs, t0, self.y.copy(), t_bound, **options)

        def renew_slips() -> None:
            """The next step's slip directions at the stepper's state; where they hold a slip
            (or held one) the law changed there, and so the stepper's first stage."""
            if events.renew(solver.y, 0.0 if s.method in IMPLICIT else solver.h_abs):
                solver.f = solver.fun(solver.t, solver.y)

        renew_slips()
        g_old = events(self.y)
        held_rows = self.held_rows()  # the segment's (its steps change no phase)
        # bodies that may touch (slots, or pairs waiting for theirs: see grow); LSODA fixes it at its start
        reach = model.step_reach if (model.n_slots or len(getattr(model, "waiting", ()))) and s.method != "LSODA" \
            else None
        retry = np.inf  # a step taken again after it moved particles too far: its bound
        try:
            while True:
                t_start, y_start = solver.t, solver.y.copy()
                if reach is not None:  # bodies may touch: no step carries a particle through a surface unseen
                    solver.max_step = min(options.get("max_step", np.inf), retry,
                                          reach(solver.y, self.p, getattr(solver, "f", None)))
                    retry = np.inf
                message = solver.step()
                self.steps += 1
                if solver.status == "failed":
                    failure = _gimbal_lock(self.scene, model, solver.y, solver.t) or (
                        "step_size_collapse",
                        f"{s.method} failed at t = {solver.t:.9g} s: {message} The model is too stiff for this "
                        "method or tolerance: try an implicit method (--method Radau or BDF) or a looser --rtol.")
                    raise SimulationFailed(*failure)
                if not np.all(np.isfinite(solver.y)):
                    raise SimulationFailed(*_non_finite(solver.t))
                dense = _remembered(solver.dense_output())
                if reach is not None:
                    # Measured, as the event checks see it (the step's ends and midpoint): its
                    # bound ahead was a forecast, and the accelerations change within it.
                    moved = model.step_motion((y_start, dense(0.5 * (solver.t_old + solver.t)), solver.y), self.p)
                    if moved > model.reach_length:  # again from its start, shorter, before anything changes
                        self.nfev += solver.nfev
                        self.shortened += 1
                        retry = 0.9 * (solver.t - t_start) * model.reach_length / moved
                        solver = stepper(rhs, t_start, y_start, t_bound, **dict(options, first_step=retry))
                        renew_slips()
                        continue
                drift = self.held_drift(solver.y, held_rows)
                if len(held_rows) and solver.t - t_start > STALL_TIME and self.sank(drift, dense, t_start, solver.t,
                                                                                     held_rows):
                    # too long for the held contacts' constraints (at its end, or within it on
                    # the dense output, which is less accurate): again from its start, shorter,
                    # before event location changes anything (it re-arms floors)
                    self.nfev += solver.nfev
                    self.shortened += 1
                    options["first_step"] = options["max_step"] = 0.5 * (solver.t - t_start)
                    solver = stepper(rhs, t_start, y_start, t_bound, **options)
                    renew_slips()
                    continue
                late, ahead = self.pairs_near(solver.y)
                if len(late):  # a particle may have touched a body it had no slot for: again, with them
                    self.retaken += 1
                    self.y[:] = y_start
                    self.step_cap = options.get("max_step")
                    return _Stop(t_start, np.zeros_like(events.free), np.zeros_like(events.free), False, late)
                at_end: list[np.ndarray] = []  # the step end's event functions, once asked for

                def end_functions() -> np.ndarray:
                    if not at_end:
                        at_end.append(events(solver.y))
                    return at_end[0]

                hit = locate(events, dense, solver.t_old, solver.t, g_old, end_functions)
                t_stop = hit.t if hit else solver.t
                self.y[:] = dense(t_stop) if hit else solver.y
                self.record(dense, t_stop, solver.t_old)
                if hit:
                    return _Stop(t_stop, hit.contacts & events.free, hit.contacts & events.held_mask, True)
                g_new = end_functions()  # (a step without an event has them: locate asked)
                if events.friction:  # the next step's slip directions
                    renew_slips()
                    g_new = events(solver.y)
                    renewed = events.held_mask & (g_new <= 0.0)
                    if renewed.any():
                        # Positive at the step's end (nothing fired), an event function of a held
                        # contact is not after the renewal: a slow slip's new direction moved the
                        # coupled rows' forces (measured: a rigid base's corner from +3.8 to -0.5 N,
                        # which pulled unseen through the next step, its event starting below 0).
                        # An instant here, as if it fired: the LCPs decide.
                        return _Stop(solver.t, np.zeros_like(events.free), renewed, True)
                if solver.status == "finished":
                    return _Stop(solver.t, np.zeros_like(events.free), np.zeros_like(events.free), False)
                lowered = events.free & (phases.floor < 0.0)
                if lowered.any():  # a particle clearly back above the ground is armed at the ground again
                    above = lowered & (model.gaps(solver.y[: model.nq], self.p) >= 2 * self.gap_tolerance)
                    if above.any():
                        phases.floor[above] = 0.0
                        g_new = events(solver.y)
                if self.put_back(drift):  # held contacts put back on their surfaces: the stepper restarts there
                    self.nfev += solver.nfev
                    if s.method not in IMPLICIT:
                        options["first_step"] = min(solver.h_abs, t_bound - solver.t)
                    solver = stepper(rhs, solver.t, self.y.copy(), t_bound, **options)
                    renew_slips()
                    g_new = events(self.y)
                g_old = g_new
                if self.progress:
                    self.progress(solver.t, s.t_end, len(self.events))
                self.check_deadline(solver.t)
                if len(ahead):  # a pair came near (at the step's end; a put-back moves nothing that far):
                    # the next segment has its slots
                    self.step_cap = options.get("max_step")
                    return _Stop(solver.t, np.zeros_like(events.free), np.zeros_like(events.free), False, ahead)
        except FloatingPointError as exc:
            failure = _gimbal_lock(self.scene, model, solver.y, solver.t) or ("blow_up", f"at t = {solver.t:.9g} s: {exc}")
            raise SimulationFailed(*failure) from None
        finally:
            self.nfev += solver.nfev
            self.njev += getattr(solver, "njev", 0)
            if s.method not in IMPLICIT:
                self.h_next = solver.h_abs

    def put_back(self, drift: float | None = None) -> bool:
        """Put the held contacts back on their surfaces where they have drifted off them by
        more than :data:`PROJECT_GAPS` gap tolerances (the state ``y`` changes; ``drift``:
        :meth:`held_drift` at ``y`` where known); whether they had."""
        drift = self.held_drift(self.y) if drift is None else drift
        if drift <= PROJECT_GAPS * self.gap_tolerance:
            return False
        model, phases = self.model, self.phases
        self.y[:] = project_held(model, self.y, self.p, np.flatnonzero(phases.on_ground))
        self.projections += 1
        self.max_put_back = max(self.max_put_back, drift)
        # A free contact the move left at or below its floor (one just released against a
        # surface that moved) would start its segment unarmed, its next approach missed.
        phases.arm(model.gaps(self.y[: model.nq], self.p), self.gap_tolerance)
        return True

    def held_rows(self) -> np.ndarray:
        """The held contacts of a coupled model, shape (k,) (none for one that is not):
        those :meth:`held_drift` reads."""
        return np.flatnonzero(self.phases.on_ground) if self.model.coupled else np.zeros(0, np.intp)

    def held_drift(self, y: np.ndarray, rows: np.ndarray | None = None) -> float:
        """How far (m) the held contacts of a coupled model are off their surfaces at ``y``,
        the largest (0 where none is held): their gaps are kept on accelerations, and where
        they are not linear in the coordinates the integrator's error drifts them (see
        :func:`flexbody.coupled.project_held`).  ``rows``: :meth:`held_rows`, if known."""
        rows = self.held_rows() if rows is None else rows
        if not len(rows):
            return 0.0
        return float(np.abs(self.model.held_gaps(y[: self.model.nq], self.p, rows)).max())

    def sank(self, drift: float, dense, t_start: float, t_end: float, rows: np.ndarray | None = None) -> bool:
        """Whether a held contact of a coupled model is deeper than ``SINK_GAPS`` gap
        tolerances off its surface at the step's end (``drift``, :meth:`held_drift`) or at
        one of ``SINK_POINTS`` on its dense output ``dense`` over ``[t_start, t_end]``: inside
        a step the interpolant is less accurate than at its ends, and an event there starts
        the next segment from it (measured: 1.2e-9 m at 3/8 of a step whose ends and midpoint
        read 3e-11 m, in a fuzzed 3D pile)."""
        limit = SINK_GAPS * self.gap_tolerance
        return drift > limit or any(self.held_drift(dense(t_start + f * (t_end - t_start)), rows) > limit
                                    for f in SINK_POINTS)

    def record(self, dense, t_stop: float, t_start: float) -> None:
        """Keep the output-grid samples up to ``t_stop`` and track penetration (of particles,
        and in 3D of edges crossing: :meth:`track_edges`, on the step from ``t_start``)."""
        start = self.n_samples
        stop = max(start, int(np.searchsorted(self.grid, t_stop, side="right")))
        for k in range(start, stop):
            self.Y[k] = dense(self.grid[k])
        self.keep_samples(start, stop)
        if self.sample_slips is not None and stop > start:
            # the step's friction law: each sliding contact's kept direction, and whether its
            # friction was held along it (its outputs are the forces that moved the bodies)
            sliding = np.flatnonzero(self.phases.phase == SLIDING)
            law = (sliding, self.model.slip_directions(self.p)[sliding].copy(),
                   self.model.slips_held(self.p)[sliding].copy())
            self.sample_slips[start:stop] = [law] * (stop - start)
        self.gaps_before, self.step_start = (self.min_gap, self.min_held_gap), t_start
        lowest = self.track_gaps(self.y)
        if self.model.n_slots and (stop > start or lowest < -FOLD_PROBE * self.gap_tolerance):
            self.check_surfaces(t_stop)  # at the step's end: its surfaces' sweep is kept (the event functions')
        self.track_edges(dense, t_start, t_stop)

    def track_edges(self, dense, t_start: float, t: float) -> None:
        """Where two 3D bodies' surfaces cross edge through face (:meth:`flexbody.body_contact.
        BodyContactModel.crossed_edges`, deeper than ``EDGE_DEPTH`` gap tolerances): their
        edges met, a contact the model does not have, and passed through each other.
        Checked at the end ``t`` of a step (dense output ``dense`` from ``t_start``) once per
        ``EDGE_CHECKS`` of an output interval (a check costs milliseconds in a pile, its
        steps are many), so crossings shorter than that can go unseen.  The deepest crossing
        checked and the first are kept for the run's stats and warnings, the first's time
        found by bisection to 1e-12 s where the last check lies within this step, else
        between the two checks."""
        crossed = getattr(self.model, "crossed_edges", None)
        if crossed is None or t < self.t_edges + self.settings.output_dt / EDGE_CHECKS and t < self.settings.t_end:
            return
        depth = EDGE_DEPTH * self.gap_tolerance
        found = crossed(self.y, self.p, depth)
        t_before, self.t_edges = self.t_edges, t
        if found is None:
            return
        self.max_edge_crossing = max(self.max_edge_crossing, found[0])
        if self.edge_crossing is not None:
            return
        lo, hi, first = max(t_before, t_start), t, found  # clear at t_before, crossed at hi
        if lo > t_before and crossed(dense(lo), self.p, depth) is not None:
            lo, hi = t_before, lo  # crossed at the step's start already: it began between the last check and it
        else:
            while hi - lo > 1e-12 * max(1.0, abs(hi)):
                mid = 0.5 * (lo + hi)
                at_mid = crossed(dense(mid), self.p, depth)
                lo, hi, first = (mid, hi, first) if at_mid is None else (lo, mid, at_mid)
        _, a, b, how = first
        self.edge_crossing = (lo, hi, self.scene.bodies[a].name, self.scene.bodies[b].name, how)

    def track_gaps(self, y: np.ndarray, held: np.ndarray | None = None) -> float:
        """Lower the lowest gaps of free and held contacts to those at state ``y`` (``held``:
        bool (nc,), the contacts held there, default the present ones); return the lowest
        free contact's between bodies there (inf if none)."""
        q = y[: self.model.nq]
        gaps = self.model.point_gaps(q, self.p, self.model.gaps(q, self.p))
        if held is None:  # the present phases: a free contact still above its floor went there held
            held = self.phases.on_ground
            # (released at that gap, armed a tolerance below it; or set there by an impact):
            # a held contact's sink, which SINK_WARNING judges, not an impact missed, which
            # would be below its floor (measured: a row released 1.4e-11 m inside, 13 gap
            # tolerances, warned of as a missed impact at the next step's end)
            sunk = held | ((gaps >= self.phases.floor) & (gaps < 0.0))
        else:
            sunk = held
        self.min_gap = min(self.min_gap, float(gaps[~sunk].min(initial=np.inf)))
        self.min_held_gap = min(self.min_held_gap, float(gaps[sunk].min(initial=np.inf)))
        ng = self.model.n_ground_contacts
        return float(gaps[ng:][~held[ng:]].min(initial=np.inf))

    # ------------------------------------------------------------------ the phase machine
    def resolve_at(self, t: float, touching: np.ndarray, leaving: np.ndarray) -> list[Event]:
        """Apply the fixed point at instant ``t`` to ``y`` and the phases; return the new events."""
        s = self.settings
        was_pushed = self.phases.phase == PUSHED if self.windows is not None else None  # O(nc): only if needed
        if self.compiled and not self.model.coupled:  # the compiled twin of contact.resolve
            found, not_held, loss = self.compiled.resolve(t, touching, leaving, s.impact == "thesis", s.impact_dt)
            new = [Event(t, c, EVENT_KINDS[kind], speed) for c, kind, speed in found]
        elif self.per_particle(touching | leaving):
            new, not_held, loss = self.resolve_per_particle(t, touching, leaving)
        else:
            renewed = held_before = None
            if self.model.n_slots:
                inside = self.model.from_inside(self.y, self.p, touching)
                if inside:  # no contact to resolve: a particle inside its own body reached its far side
                    particle, body, depth = inside
                    raise SimulationFailed(
                        "unsupported",
                        f"at t = {t:.9g} s particle {particle} of body {self.scene.bodies[body].name!r} came at its own "
                        f"surface from inside, {depth:.3g} m behind it (a hollow body crushed flat, a body pressed "
                        "through its thickness, or a part of it that passed through another): self-contact is between "
                        "the outer sides of a surface, and its inside is taken for material.")
                held_before = self.phases.on_ground.copy()
                touching, leaving, renewed = self.switch_elements(t, touching, leaving)
            res = resolve(self.model, t, self.y, self.p, self.phases, touching, leaving,
                          gap_tolerance=self.gap_tolerance, force_tolerance=self.force_tolerance,
                          masses=self.contact_masses, impact=s.impact, impact_dt=s.impact_dt,
                          restitution=self.restitution, min_rebound=self.min_rebound,
                          speed_tolerance=self.speed_tolerance, friction=self.mu, zeno_rise=self.zeno_rise,
                          renewed=renewed)
            self.y[:] = res.y
            self.phases.assign(res.phases)
            new, not_held, loss = res.events, res.not_held, res.impact_loss
            if self.model.n_slots:
                dented = self.settle_corners(new)
                changed = self.phases.on_ground ^ held_before  # held or released here
                changed[dented] = True  # or handed back, in a dent, the element its twin held
                self.model.floor_margins(self.y, self.p, self.phases.held, changed, self.gap_tolerance)
            self.indeterminate += [(t, note) for note in res.notes]
        self.events += new
        if self.windows is not None:
            self.track_windows(t, was_pushed)
        if any(e.kind == "impact" and self.restitution[e.contact] > 0.0 for e in new):
            # A rebound reverses a velocity: the step proposed before it says nothing about the
            # flight after it (a bounce much shorter than that step would be located only at
            # the floor a hair below the ground); the next step is estimated afresh.
            self.h_next = 0.0
            if self.compiled:
                self.compiled.h_next.value = 0.0
        if not_held.any():
            for c in np.flatnonzero(not_held):
                latest = next(e for e in reversed(self.events) if e.contact == c and e.kind == "impact")
                latest.held = False
        if loss:
            self.losses.append((t, loss))
        return new

    def per_particle(self, seeds: np.ndarray) -> bool:
        """Whether the instant of the contacts ``seeds`` (bool (nc,)) of a coupled model is its
        inner model's, per particle (:meth:`flexbody.model.Model.per_particle`)."""
        return (self.model.coupled and self.settings.impact == "instant"
                and self.model.per_particle(self.y, self.p, self.phases, seeds, self.gap_tolerance))

    def resolve_per_particle(self, t: float, touching: np.ndarray, leaving: np.ndarray
                             ) -> tuple[list[Event], np.ndarray, float]:
        """:func:`flexbody.contact.resolve` on the inner model's ground contacts alone (the
        first ``n_ground_contacts``; the slots, all free and out of reach, keep their
        phases).  Returns the new events, the contacts not held after their impact (bool
        (nc,)) and the kinetic energy the impacts removed (J)."""
        ng, s = self.model.n_ground_contacts, self.settings
        grounds = self.phases.first(ng)
        res = resolve(self.model.inner, t, self.y, self.p, grounds, np.asarray(touching)[:ng],
                      np.asarray(leaving)[:ng], gap_tolerance=self.gap_tolerance,
                      force_tolerance=self.force_tolerance[:ng], masses=self.contact_masses[:ng], impact=s.impact,
                      impact_dt=s.impact_dt, restitution=self.restitution[:ng], min_rebound=self.min_rebound[:ng],
                      speed_tolerance=self.speed_tolerance, friction=None, zeno_rise=self.zeno_rise)
        settled = not np.array_equal(res.y[: self.model.nq], self.y[: self.model.nq])
        self.y[:] = res.y
        grounds.assign(res.phases)  # into self.phases
        if settled:  # a particle set onto a ground moves the slots it carries: re-arm them (as resolve does)
            self.phases.arm(self.model.gaps(self.y[: self.model.nq], self.p), self.gap_tolerance)
        self.indeterminate += [(t, note) for note in res.notes]
        not_held = np.zeros(self.model.n_contacts, bool)
        not_held[:ng] = res.not_held
        return res.events, not_held, res.impact_loss

    def switch_elements(self, t: float, touching: np.ndarray, leaving: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Contacts held on another body's element whose particle passed onto the neighbour
        (:meth:`flexbody.body_contact.BodyContactModel.switch_elements`): held on it if they
        meet it tangentially, else freed at the instant (an approach is then an impact, a
        separation a lift-off).  Returns ``touching, leaving`` and the contacts handed over
        without an event of their own (bool (nc,) each)."""
        phases = self.phases
        stay, approach, leave, corners, sources, relabelled = self.model.switch_elements(
            self.y, self.p, phases.held, self.gap_tolerance, self.speed_tolerance)
        for state in (phases.phase, phases.floor):
            state[relabelled] = state[relabelled[:, ::-1]]
        touching, leaving = np.array(touching, bool), np.array(leaving, bool)
        moved = np.concatenate([stay, approach, leave])
        leaving[moved] = False
        # At a concave corner the contact on the element left behind goes on as the slot's
        # twin, held as the slot was: the impact on the new element (or, met tangentially,
        # the instant's force LCP) decides if it stays.
        phases.phase[corners] = phases.phase[sources]
        for c in np.concatenate([approach, leave]).tolist():
            phases.phase[c] = FREE
            phases.floor[c] = -self.gap_tolerance
        touching[approach] = True
        self.events += [Event(t, int(c), "liftoff") for c in leave]
        model = self.model
        first_edge = model.n_ground_contacts + model.first_edge
        if len(leave) and (leave >= first_edge).any():
            # A free edge row watches, by rank, the edge its free siblings leave it: with one
            # released here (past an end) the row that fired watches the next closest edge,
            # apart; held on it, it was put back onto it by moving two bodies (measured:
            # 2e-3 m, in a pile of boxes). The released sibling, earlier in rank, now watches
            # the edge the row fired on, and its own event takes it.
            rows = first_edge + np.flatnonzero(touching[first_edge:] & (phases.phase[first_edge:] == FREE))
            if len(rows):
                gaps = model.gaps_of(self.y[: model.nq], self.p, rows)
                touching[rows[gaps > phases.floor[rows] + self.gap_tolerance]] = False
        renewed = np.zeros(len(touching), bool)
        renewed[np.concatenate([stay, corners, leave])] = True  # the released one's force is gone
        return touching, leaving, renewed

    def settle_corners(self, new: list[Event]) -> np.ndarray:
        """Keep a held corner twin's slot held: where the slot was released and its twin
        holds on, the slot takes the twin's element and phase, and the lift-off just
        recorded is the twin's (the particle left the slot's element, not the body); where
        the slot's particle is crossing onto its new element, the slot keeps that instead
        and the twin lifts off (:meth:`twins_left_behind`).
        Returns those slots (contact indices) released from an element that meets the one
        handed back at a strictly concave vertex: each is held in the dent, at or a hair
        past its element's end, which :meth:`flexbody.body_contact.BodyContactModel.
        floor_margins` must see (a twin has no boundary event, and with the twin's floor the
        slot slid on along the element's line, 1.5 mm into the other body in a fuzz's
        pile).  Where the elements are flat, sliding on along the line is right: there the
        released row was redundant, and re-armed at the end it was handed on and back every
        1e-12 s."""
        model, phases = self.model, self.phases
        first_twin = model.n_ground_contacts + model.n_primary
        twins = first_twin + np.flatnonzero(phases.on_ground[first_twin : model.n_ground_contacts + model.first_edge])
        orphans = twins[~phases.on_ground[model.primary(twins)]]
        if not len(orphans):
            return np.zeros(0, np.intp)
        # one per slot: a second held twin (3D) stays the twin of the slot it now has
        orphans = orphans[np.sort(np.unique(model.primary(orphans), return_index=True)[1])]
        slots = model.primary(orphans)
        left_behind = self.twins_left_behind(orphans)
        handed = orphans[~left_behind]
        dented = model.concave_hand_backs(handed, self.y, self.p)
        model.hand_to_slots(handed)
        model.forget_twins(orphans[left_behind])
        phases.phase[slots], phases.phase[orphans] = phases.phase[orphans], FREE
        phases.floor[orphans] = -self.gap_tolerance
        twin_of = dict(zip(slots.tolist(), orphans.tolist()))
        for e in new:  # handed back or kept, the slot's particle left an element, not the body
            if e.kind == "liftoff" and e.contact in twin_of:
                e.contact = twin_of[e.contact]
        return model.primary(handed)[dented]

    def twins_left_behind(self, orphans: np.ndarray) -> np.ndarray:
        """Of the held corner twins ``orphans`` (contact indices, one per slot, (k,)) whose
        slots the force LCP released, those whose slot keeps the element it was just handed
        and holds on it alone, bool (k,): the slot was handed across a 3D crease onto a
        triangle its particle crosses onto faster than the speed tolerance
        (:meth:`flexbody.body_contact.BodyContactModel.crossing_hand_backs`), and held there
        in place of the twin it would not pull (:meth:`slots_hold_alone`).  The particle is
        leaving the twin's triangle past its end, not resting in the corner: handed that
        triangle back, the slot passed its end again one gap tolerance later, every time (a
        fuzzed row's rim midpoint: a lift-off every 2.56e-10 s).  Such a slot is held with
        its twin's phase, as a slot handed its twin's element is, and the twin lifts off
        without an element (:meth:`settle_corners`)."""
        slots = self.model.primary(orphans)
        lifted = self.model.crossing_hand_backs(orphans, self.y, self.p, self.speed_tolerance)
        while lifted.any():  # forces are coupled: judge the survivors again without the ones dropped
            holds = self.slots_hold_alone(slots[lifted], orphans[lifted])
            if holds.all():
                break
            lifted[np.flatnonzero(lifted)[~holds]] = False
        return lifted

    def slots_hold_alone(self, slots: np.ndarray, twins: np.ndarray) -> np.ndarray:
        """Whether the released ``slots`` (contact indices, (k,)), held on the elements they
        have in place of their corner twins ``twins`` (k,), which are set free, would push,
        bool (k,): each one's force as the segment's right-hand side takes it (every held
        row's acceleration at 0, :meth:`flexbody.model.Model.held_forces`) above
        ``-force_tolerance``, so that its lift-off event starts above 0 (one starting below
        never fires: the slot would be held pulling)."""
        trial = self.phases.copy()
        trial.phase[slots], trial.phase[twins] = trial.phase[twins], FREE
        lam = self.model.held_forces(self.y, self.p, trial.held, trial.push)
        return lam[slots] + self.force_tolerance[slots] > 0.0

    def track_windows(self, t: float, was_pushed: np.ndarray) -> None:
        """Record the thesis-mode windows that start or end at ``t`` (positions, constant force)."""
        model, d = self.model, self.model.dim
        pushed = self.phases.phase == PUSHED
        for c in np.flatnonzero(was_pushed & ~pushed):
            window = next(w for w in reversed(self.windows) if w.contact == c)
            window.t_end, window.x_end = t, self.y[d * window.particle : d * window.particle + d].copy()
        if not np.any(pushed & ~was_pushed):
            return
        tangential = model.tangential_pushes(self.p)
        for c in np.flatnonzero(pushed & ~was_pushed):
            i, g = (int(k) for k in model.contacts[c])
            force = self.phases.push[c] * np.asarray(self.scene.grounds[g].normal, float) + tangential[c]
            self.windows.append(_Window(int(c), i, t, force, self.y[d * i : d * i + d].copy()))

    def window_work(self, T: np.ndarray, X: np.ndarray) -> np.ndarray:
        """Energy the thesis-mode windows took by each sample time, shape (nt,) (J): a window's
        force F is constant, so its work up to a time is F . (x - x_start), exactly."""
        taken = np.zeros(len(T))
        for w in self.windows:
            inside = (T > w.t_start) & (T < w.t_end)
            taken[inside] -= (X[inside, w.particle] - w.x_start) @ w.force
            if w.x_end is not None:
                taken[T >= w.t_end] -= float((w.x_end - w.x_start) @ w.force)
        return taken

    def run(self) -> tuple[str, str]:
        s, model, phases = self.settings, self.model, self.phases
        t = 0.0
        # Particles starting on a ground at rest are held if the ground has to push them; at
        # rest to round-off: a rigid body's spin leaves its corners' normal speeds at 1e-17 m/s
        # (measured: a spinning tripod on the ground left the corner moving off it by 1e-17
        # free, which then fell 1e-12 m in 0.5 us until it hit).
        gaps, vn, _ = model.contact_state(self.y, self.p, np.zeros(model.n_contacts, np.intc), np.zeros(model.n_contacts))
        roundoff = VELOCITY_ROUNDOFF * max(1.0, float(np.abs(self.y[model.nq : model.nq + model.nu]).max(initial=0.0)))
        resting = (gaps <= self.gap_tolerance) & (np.abs(vn) <= roundoff)
        phases.phase[resting] = HELD
        # Sample 0 is the initial state as given; what the instant at t = 0 does (a particle
        # starting on the ground while approaching it is stopped) is in the ledger from there on.
        self.Y[0] = self.y
        self.keep_samples(0, 1)
        none = np.zeros(model.n_contacts, bool)
        try:
            self.resolve_at(0.0, none, none)
            self.keep_samples(0, 1)  # its contact set is the instant's outcome (a slide starting at once)
            self.y_started = self.y.copy()
            while t < s.t_end:
                ahead = self.pairs_near(self.y)[1]  # after an instant: its step's end was not checked
                if len(ahead):
                    self.grow(ahead)
                    phases = self.phases
                t_bound = min(s.t_end, float(phases.push_until.min()))  # a thesis-mode window ends a segment
                stop = self.segment(t, t_bound)
                if stop.grow is not None:  # from the stop, with the slots of the pairs come near
                    self.grow(stop.grow)
                    phases, t = self.phases, stop.t
                    continue
                touching, leaving = stop.touching, stop.leaving
                if not stop.fired:
                    if stop.t >= s.t_end:
                        break
                    touching = (phases.phase == PUSHED) & (phases.push_until <= stop.t * (1 + 1e-15) + 1e-300)
                self.stalled = self.stalled + 1 if stop.t - t < PROGRESS_TIME else 0
                t = stop.t
                fired = np.flatnonzero(touching)
                armed = phases.floor[fired]  # where they fired: the instant re-arms or holds them
                self.check_guards(t, self.resolve_at(t, touching, leaving), (fired, armed))
        except SimulationFailed as failure:
            return failure.status, failure.message
        except FloatingPointError as exc:  # a singular mass or contact matrix at an event instant
            return "blow_up", f"at t = {t:.9g} s: {exc}; the contacts at this instant are not independent."
        except UnsettledInstant as exc:
            return "no_progress", str(exc)
        except CoupledImpactError as exc:
            return "unsupported", f"at t = {t:.9g} s: {exc}"
        return "success", STATUSES["success"]

    def check_deadline(self, t: float) -> None:
        if time.perf_counter() > self.deadline:
            raise SimulationFailed(*self.too_slow(t))

    def too_slow(self, t: float) -> tuple[str, str]:
        """The status and message of this run stopped by its wall-time budget at ``t`` (s),
        with its steps and events so far: tiny steps, or many events."""
        steps = self.steps + int(self.counters[1])  # SciPy's and the compiled loop's
        return "too_slow", (f"stopped at t = {t:.6g} s: the run exceeded its max_wall_time ({steps} steps, "
                            f"{t / max(steps, 1):.2g} s each on average, and {len(self.events)} events). If the "
                            "scene is very stiff (tiny steps), try an implicit method (--method Radau or BDF) or a "
                            "softer body.")

    def check_guards(self, t: float, new_events: list[Event],
                     fired: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """Stop the run where an instant at ``t`` (its ``new_events``; ``fired``: the contacts
        whose gap events fired there (k,) and their floors then (k,)) went past a bound or a
        surface folded."""
        self.check_deadline(t)
        if len(self.events) >= self.max_events:
            raise SimulationFailed("max_events", f"{len(self.events)} events by t = {t:.9g} s (max_events = "
                                   f"{self.max_events}); raise max_events if the scene really has that many.")
        if self.stalled >= STALL_COUNT:
            raise SimulationFailed("no_progress", f"{self.stalled} event instants in a row within {PROGRESS_TIME:g} s "
                                   f"of each other at t = {t:.12g} s; tighten --rtol/--atol, or please report the "
                                   "scene (a contact handed back and forth at one place).")
        if self.friction:
            self.check_corners(t)
        if self.model.n_slots:
            self.check_folds(t, new_events, fired)
        # An impact's friction impulse can stop a sliding contact of its body that the forces
        # set sliding again at once: such switches end with the impacts, whose own bound
        # watches them (a rigid ring sliding while the corners of its body rattled: 26 in 1 ms)
        impacted = any(e.kind == "impact" for e in new_events)
        for e in new_events:
            if e.kind in ("stick", "slip") and not impacted:
                self.check_stick_slip(t, e)
            if e.kind != "impact":
                continue
            recent = self.impact_times[e.contact]
            recent.append((e.t, e.normal_velocity, e.held))
            while recent[0][0] <= t - CHATTER_WINDOW:
                recent.popleft()
            held = [h for _, _, h in recent]
            in_a_row = held[::-1].index(True) if True in held else len(held)  # since the last hold
            bound = self.settings.chatter_impacts
            unending = _unending(recent, in_a_row)
            if max(unending, sum(held)) > bound:
                particle = int(self.model.contacts[e.contact][0])
                speed = max(abs(v) for _, v, _ in list(recent)[-5:])
                how = (f"{in_a_row} in a row, none held, {unending} of them no slower than {CASCADE_FALL:g} of the "
                       "one before" if unending > bound else f"held and released again {sum(held)} times")
                e_here = float(self.restitution[e.contact])
                advice = ("tighten --rtol/--atol, or add damping so the body settles; if its impacts come in a burst "
                          "that ends (a pile settling, its contacts taking turns), raise the bound: "
                          f"simulation.chatter_impacts (--chatter-impacts), now {bound}")
                if unending > bound and e_here >= CASCADE_FALL:  # an elastic rattle: no cascade ends it
                    how += f"; e = {e_here:g} at this contact takes too little of each rebound for it to die out"
                elif unending > bound and e_here > 0.0 and e.contact < self.model.n_ground_contacts:
                    # a flexible body's particle pushed back by its neighbours at once: a rebound is plastic
                    # only below the speed that would rise ZENO_RISE against gravity alone (_rebound_laws)
                    how += (f"; with e = {e_here:g} every rebound faster than {self.min_rebound[e.contact]:.2g} m/s "
                            "(the speed that rises 1e-9 of the scene against gravity) leaves, and the body's "
                            "springs push the particle back at once, so its bounces keep pace with the body's "
                            "vibration (a lattice disc landing with e >= 0.7)")
                    advice = "lower this ground's restitution (tolerances and damping do not end such bounces)"
                raise SimulationFailed(
                    "chattering",
                    f"particle {particle} impacted {len(recent)} times within {CHATTER_WINDOW * 1e3:g} ms up to "
                    f"t = {t:.9g} s at normal speeds up to {speed:.3g} m/s (an accumulation of impacts: {how}); "
                    f"{advice}.",
                )

    def check_folds(self, t: float, new_events: list[Event],
                    fired: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """Refuse to go on where a contact decided at this instant, or whose gap event fired
        there (``fired``: those contacts and their floors then), is against a surface that
        crosses itself, or where a fired one reads deep below its floor (a body folded over,
        or folding: :meth:`flexbody.body_contact.BodyContactModel.fold`, ``fold_onset``)."""
        ng, depth = self.model.n_ground_contacts, EDGE_DEPTH * self.gap_tolerance
        contacts, floors = fired if fired is not None else (np.zeros(0, np.intp), np.zeros(0))
        touched = sorted({e.contact for e in new_events if e.contact >= ng} | set(contacts[contacts >= ng].tolist()))
        fold = self.model.fold(self.y, self.p, touched, depth) if touched else None
        if fold is None and (contacts >= ng).any():
            fold = self.model.fold_onset(self.y, self.p, contacts, floors, depth)
        self.refuse_fold(t, fold)

    def check_surfaces(self, t: float) -> None:
        """:meth:`check_folds` for every surface a free contact is within reach of at the
        end ``t`` of a step that passed an output sample, or where a contact between bodies
        reads deep inside: a body can fold with no contact against it decided, and then a
        particle beside it reads inside."""
        self.refuse_fold(t, self.model.fold(self.y, self.p, depth=EDGE_DEPTH * self.gap_tolerance))

    def refuse_fold(self, t: float, fold: tuple[int, str] | None) -> None:
        """Stop with ``unsupported`` at ``t`` if ``fold`` (a body and how it folded) is one.
        The gaps read at the folded state, and on the samples of the step it folded in, are
        left out of the penetration (a particle beside a folded surface reads deep inside
        it: measured, 1.7e-3 m in a run whose states before the fold read none)."""
        if fold is not None:
            self.min_gap, self.min_held_gap = self.gaps_before
            self.folded_from = self.step_start
            body, how = fold
            raise SimulationFailed(
                "unsupported",
                f"at t = {t:.9g} s body {self.scene.bodies[body].name!r} has folded over ({how}): inside and outside of it "
                "are not defined and contacts against it would be wrong (with self_contact = true a body's outer "
                "surface stops at itself, except near each particle: see the README's self-contact); stiffen the "
                "body, give it more particles, or soften what hits it.",
            )

    def check_stick_slip(self, t: float, e: Event) -> None:
        """Stick-slip chattering: a contact switching more than CHATTER_FRICTION times within CHATTER_WINDOW."""
        recent = self.friction_times[e.contact]
        recent.append(e.t)
        while recent[0] <= t - CHATTER_WINDOW:
            recent.popleft()
        if len(recent) > CHATTER_FRICTION:
            particle = int(self.model.contacts[e.contact][0])
            raise SimulationFailed(
                "chattering",
                f"particle {particle} switched between stick and slip {len(recent)} times within "
                f"{CHATTER_WINDOW * 1e3:g} ms up to t = {t:.9g} s (stick-slip chattering: its tangential pull stays "
                "at the friction limit); tighten --rtol/--atol, or change the friction coefficient.",
            )

    def check_corners(self, t: float) -> None:
        """Refuse a particle held on two grounds at once where one has friction (a frictional corner):
        its tangential problem couples the grounds, which the per-particle path does not solve
        (coupled models solve it with the others, as one LCP)."""
        if self.model.coupled:
            return
        held = self.phases.on_ground.reshape(self.model.n_particles, -1)
        corner = np.flatnonzero(held.sum(axis=1) > 1)
        mu = np.array([g.friction for g in self.scene.grounds])
        for i in corner:
            if (mu[held[i]] > 0.0).any():
                grounds = np.flatnonzero(held[i]).tolist()
                raise SimulationFailed(
                    "unsupported",
                    f"particle {i} is held on grounds {grounds} at once at t = {t:.9g} s and one of them has friction: "
                    "frictional corners are not solved (refused rather than approximated); make the grounds "
                    "frictionless where they meet, or keep the body away from the corner.",
                )

    # ------------------------------------------------------------------ results
    def impact_gains(self, energy: float) -> list[str]:
        """The instants whose impacts added energy, more than IMPACT_GAIN of ``energy`` (J),
        one sentence (empty when none): Newton's restitution with Coulomb friction, or with
        several coupled contacts, can (a spinning bar's rough corner with e = 1 gained 8.6 %
        in a fuzz, unwarned).  A property of the impact law, not an error: the ledger's
        impact work counts it, so the energy drift does not show it."""
        gains = [(t, -loss) for t, loss in self.losses if -loss > IMPACT_GAIN * energy]
        if not gains:
            return []
        (t, first), total = gains[0], sum(gain for _, gain in gains)
        later = f" and at {len(gains) - 1} later instants" if len(gains) > 1 else ""
        return [f"at t = {t:.9g} s{later}, impacts added energy ({first:.3g} J; {total:.3g} J in all, "
                f"{total / energy:.2g} of the energy): Newton's restitution with Coulomb friction or with several "
                "contacts at once can (the impact law, not an error; the ledger's impact work counts it)"]

    def untrustworthy(self, relative_drift: float, penetration: float, min_force: float, sink: float = 0.0
                      ) -> list[str]:
        """What makes this run's numbers untrustworthy, one sentence each (empty when nothing):
        ``penetration`` (m) of free contacts, ``sink`` (m) of held ones."""
        s, out = self.settings, []
        if relative_drift > DRIFT_WARNING:
            out.append(f"the energy ledger drifted by {relative_drift:.2g} of the energy (more than {DRIFT_WARNING:g}): "
                       "tighten --rtol/--atol")
        if penetration > 10 * self.gap_tolerance:
            into = " or into another body" if self.scene.contacts else ""
            out.append(f"a particle went {penetration:.2g} m below a ground{into} between event checks (an impact was "
                       "missed at this tolerance): tighten --rtol/--atol")
        if sink > SINK_WARNING * self.gap_tolerance:
            out.append(f"a held contact sank {sink:.2g} m into what holds it: its constraint is kept on accelerations, "
                       "and where its gap is not linear in the coordinates (a rigid body's or a floating frame's) the "
                       "integrator's error drifts it: tighten --rtol/--atol")
        if self.max_put_back > PUT_BACK_WARNING * self.gap_tolerance:
            out.append(f"held contacts were put back onto their surfaces from up to {self.max_put_back:.2g} m off "
                       "them, which moved the bodies by about that: a held contact drifted that far (tighten "
                       "--rtol/--atol) or was held where it did not touch (please report the scene)")
        if min_force < -float(self.force_tolerance.max(initial=0.0)):
            out.append(f"a held contact's force turned negative ({min_force:.2g} N) between event checks (a lift-off "
                       "was missed at this tolerance): tighten --rtol/--atol")
        unaligned = [(t, note) for t, note in self.indeterminate if UNALIGNED in note]
        poisson = [(t, note) for t, note in self.indeterminate if POISSON in note]
        painleve = [(t, note) for t, note in self.indeterminate if UNALIGNED not in note and POISSON not in note]
        for notes, why in ((painleve, "another would be as consistent (Painlevé's indeterminate case)"),
                           (unaligned, "its friction lies within Coulomb's disc (an inscribed square's) but is not "
                                       "exactly against the slip"),
                           (poisson, "there the rebounds follow Poisson's law, not Newton's, which would have a "
                                     "body held between others leave both (restitution differing between them)")):
            if notes:
                (t, note), more = notes[0], len({t for t, _ in notes}) - 1
                also = f" (and at {more} later instant{'s' if more > 1 else ''})" if more else ""
                out.append(f"at t = {t:.9g} s{also}, {note.rstrip('.')}: the run went on with the answer found, and {why}")
        if self.edge_crossing is not None:
            lo, hi, first, second, how = self.edge_crossing
            when = f"from t = {hi:.9g} s" if hi - lo <= 1e-12 * max(1.0, abs(hi)) else \
                f"from between t = {lo:.9g} and {hi:.9g} s"
            why = ("two corners passed through each other with no particle inside the other body, which no "
                   "contact sees (the event location watches a particle passing another body's corner, and this one "
                   "went unseen); a tighter --rtol or more particles on the bodies make it rarer"
                   if self.model.dim == 2 else
                   "two edges meeting are a contact only between bodies whose [[contacts]] entry has edges = true "
                   f"(3D; at most {EdgeSlots.PER_EDGE} edges of the second body under one edge of "
                   "the first at once), so here edges passed through each other unseen; finer surfaces make it rarer "
                   "(a vertex meets a face first more often)")
            out.append(f"bodies {first!r} and {second!r} crossed {_CROSSED[self.model.dim]} {when} ({first!r}: {how}), "
                       f"up to {self.max_edge_crossing:.2g} m deep where checked ({EDGE_CHECKS} times per output "
                       f"interval): {why}")
        if s.rtol > LOOSE_RTOL:
            out.append(f"rtol = {s.rtol:g} is loose: impacts and lift-offs can differ from a tight run's; check the "
                       "event count against a run with a tighter --rtol")
        return out

    @contextmanager
    def as_sampled(self, k: int, elements: np.ndarray | None):
        """A context in which the model's contacts between bodies are held on ``elements``
        (ns,), those they were held on at sample ``k`` (each slot on its element then; None
        without slots), and with friction its sliding contacts follow the law its step
        integrated (:meth:`record`); afterwards as before."""
        law = None if self.sample_slips is None else self.sample_slips[k]
        with nullcontext() if elements is None else self.model.held_on(elements):
            if law is None:
                yield
                return
            rows, directions, held = law
            slip, slip_held = self.model.slip_directions(self.p), self.model.slips_held(self.p)  # writable views
            before = slip[rows].copy(), slip_held[rows].copy()
            slip[rows], slip_held[rows] = directions, held
            try:
                yield
            finally:
                slip[rows], slip_held[rows] = before

    def result(self, status: str, message: str, wall: float) -> SimulationResult:
        model, p, s = self.model, self.p, self.settings
        nq, nu = model.nq, model.nu
        k = self.n_samples
        T, Y = self.grid[:k], self.Y[:k]
        n = model.n_particles
        if self.friction:  # outputs: the physical law, or the law a sample's step integrated (as_sampled)
            model.slip_directions(p)[:] = 0.0
            model.slips_held(p)[:] = 0
        # Sample 0 is the state as given, its contact set the instant at t = 0's outcome; where
        # that instant was an impact (the velocities jumped), its forces are those right after
        # it: read at the given velocities, under the laws set for the new ones, two rigid
        # boxes side by side, one pushed into the other, showed held forces of -1 N there
        forces_at = list(Y)
        jumped_at_start = bool(k and self.y_started is not None and not np.array_equal(self.y_started, Y[0]))
        if jumped_at_start:
            forces_at[0] = self.y_started
        # a few samples at a time: their contact arrays are (samples, contacts), and a pile's
        # contacts grow with the square of its bodies
        outputs: dict[str, np.ndarray] = {}  # each made whole at the first chunk, then filled
        lowest_free = lowest_held = np.inf
        min_force = np.inf
        for rows in self.samples.chunks(k):
            contacts = self.samples.dense(rows)
            held, push, elements = contacts.held, contacts.push, contacts.elements
            if elements is None:
                X, V, E, lam = model.trajectory(Y[rows], p, held, push)
            else:
                X, V, E, lam = model.trajectory(Y[rows], p, held, push, elements=elements)
            if rows.start == 0 and jumped_at_start:
                with self.as_sampled(0, None if elements is None else elements[0]):
                    lam[0] = model.held_forces(forces_at[0], p, held[0], push[0])
            friction_force = np.zeros_like(V)
            if self.friction:
                for i in np.flatnonzero(held.any(axis=1)):
                    j = rows.start + i
                    with self.as_sampled(j, None if elements is None else elements[i]):
                        law = self.sample_slips[j]
                        if law is not None and len(law[0]):
                            # a sliding contact whose step kept its direction (a coupled 2D slip, a
                            # slow 3D one) pushed along that: measured, a rigid base's corner read
                            # 0.11 N from the law at the sample's own slip where the step pushed 0.41 N
                            lam[i] = model.held_forces(forces_at[j], p, held[i], push[i])
                        ft = model.friction(forces_at[j], p, held[i], push[i])[1]
                    friction_force[i] = model.particle_forces(ft.T).T
                if contacts.tangential is not None:  # the windows' tangential forces
                    friction_force += contacts.tangential.reshape(len(X), n, model.n_contacts // n, -1).sum(axis=2)
            force = model.particle_forces(lam + push, X, elements)
            for name, value in (("X", X), ("V", V), ("E", E), ("force", force), ("friction", friction_force)):
                outputs.setdefault(name, np.empty((k, *value.shape[1:]), value.dtype))[rows] = value
            free_gap, held_gap = _lowest_gaps(X, self.scene.grounds, held[:, : model.n_ground_contacts])
            lowest_free, lowest_held = min(lowest_free, free_gap), min(lowest_held, held_gap)
            min_force = min(min_force, float(lam[held != 0].min(initial=np.inf)))
        X, V, E, force, friction_force = (outputs[name] for name in ("X", "V", "E", "force", "friction"))
        min_force = 0.0 if min_force == np.inf else min_force
        if len(Y) and T[-1] <= self.folded_from:
            # the last sample (the last chunk's last) as it was: its contacts held and their
            # elements then (a free edge contact read against the edge it was held on at the
            # stop is no crossing: measured, 3e-4 m in a pile stopped `chattering`)
            with self.as_sampled(k - 1, None if elements is None else elements[-1]):
                self.track_gaps(Y[-1], held[-1] != 0)
        # Energy taken by instant impacts strictly before each sample time (losses come in time order).
        loss_t = np.array([x[0] for x in self.losses], dtype=float)
        lost = np.concatenate([[0.0], np.cumsum([x[1] for x in self.losses])])
        instant = lost[np.searchsorted(loss_t, T, side="left")]
        ev = self.events
        # The last state entry integrates the power of the thesis mode's impact forces and of
        # sliding friction; where both act, the windows' exact work splits them.
        contact_work = Y[:, nq + nu + 1]
        window_work = self.window_work(T, X) if self.windows is not None else None
        if window_work is not None:
            impact_work, friction_work = window_work, contact_work - window_work
        elif self.friction:
            impact_work, friction_work = 0.0, contact_work
        else:
            impact_work, friction_work = contact_work, np.zeros(len(T))
        result = SimulationResult(
            t=T.copy(), positions=X, velocities=V, contact_force=force,
            kinetic=E[:, 0], spring=E[:, 1], gravity=E[:, 2],
            damping_work=Y[:, nq + nu], impact_loss=instant + impact_work,
            friction_force=friction_force, friction_work=friction_work,
            events_time=np.array([e.t for e in ev], dtype=float),
            events_particle=np.array([model.contacts[e.contact][0] for e in ev], dtype=int),
            events_kind=np.array([e.kind for e in ev], dtype="<U7"),
            events_held=np.array([e.held for e in ev], dtype=bool),
            events_surface=np.array([_surface_of(model, e.contact) for e in ev], dtype=int),
            masses=self.scene.masses.copy(), links=self.scene.links(), status=status, message=message,
        )
        total = result.total_energy
        drift = float(np.abs(total - total[0]).max()) if len(total) else 0.0
        relative_drift = drift / max(abs(float(total[0])), float(result.kinetic.max()), 1e-300) if len(total) else 0.0
        # Penetration is also measured on the samples: between event checks a loose
        # tolerance can let a particle dip below a ground with no event.
        self.min_gap, self.min_held_gap = min(self.min_gap, lowest_free), min(self.min_held_gap, lowest_held)
        impacts = [e for e in ev if e.kind == "impact"]
        warnings = self.untrustworthy(relative_drift, max(0.0, -self.min_gap), min_force, max(0.0, -self.min_held_gap))
        warnings += self.impact_gains(max(abs(float(total[0])), float(result.kinetic.max())) if len(total) else 0.0)
        result.stats = {
            "scene": self.scene.name, "source": self.scene.source,
            "method": s.method, "rtol": s.rtol, "atol": s.atol, "backend": model.backend,
            "formulation": model.formulation, "model": _model_kind(getattr(model, "inner", model)),
            "threads": getattr(model, "inner", model).threads,
            "impact": s.impact, "impact_dt": s.impact_dt, "chatter_impacts": s.chatter_impacts,
            "t_end": s.t_end, "t_reached": float(T[-1]) if len(T) else 0.0,
            "wall_time_s": wall, "rhs_evaluations": self.nfev + int(self.counters[0]),
            "jacobian_evaluations": self.njev, "steps": self.steps + int(self.counters[1]),
            "rejected_steps": int(self.counters[2]), "event_rhs_evaluations": int(self.counters[3]),
            "segments": self.segments, "projections": self.projections, "max_put_back_m": self.max_put_back,
            "steps_shortened": self.shortened, "steps_retaken_for_pairs": self.retaken,
            "contacts": model.n_contacts,  # the table's at the end: it grows with the pairs in reach
            "contact_pairs": len(getattr(model, "pairs", ())), "contact_pairs_in_scene": len(self.scene.contacts),
            "events": len(ev), "impacts": len(impacts), "not_held": sum(not e.held for e in impacts),
            "liftoffs": sum(e.kind == "liftoff" for e in ev),
            "sticks": sum(e.kind == "stick" for e in ev), "slips": sum(e.kind == "slip" for e in ev),
            "friction_work_J": float(result.friction_work[-1]) if len(T) else 0.0,
            "max_penetration_m": max(0.0, -self.min_gap, -self.min_held_gap),
            "max_edge_crossing_m": self.max_edge_crossing,
            "energy_initial_J": float(total[0]) if len(total) else 0.0,
            "energy_drift_J": drift,
            "energy_drift_relative": relative_drift,
            "min_held_contact_force_N": min_force,
            "warnings": warnings,
            "model_digest": self.digest,
            "versions": {"flexbody": __version__, "numpy": np.__version__, "scipy": _scipy_version()},
        }
        return result


def simulate(
    scene: Scene | str,
    *,
    model: Model | None = None,
    method: str | None = None,
    rtol: float | None = None,
    atol: float | None = None,
    t_end: float | None = None,
    output_dt: float | None = None,
    backend: str | None = None,
    formulation: str | None = None,
    impact: str | None = None,
    impact_dt: float | None = None,
    chatter_impacts: int | None = None,
    max_events: int = 100_000,
    max_wall_time: float = np.inf,
    progress: Progress | None = None,
) -> SimulationResult:
    """Simulate a scene: free flight, impacts, contact and lift-off of every particle.

    Parameters
    ----------
    scene : Scene, path or bundled scene name
    model : Model, optional
        A loaded model (skips loading); otherwise ``load_model(scene, backend, formulation)``.
    method, rtol, atol, t_end, output_dt, backend, formulation, impact, impact_dt, chatter_impacts
        Override the scene's ``[simulation]`` settings.
    max_events : int
        Stop with status ``max_events`` after this many events (>= 1).
    max_wall_time : float
        Stop with status ``too_slow`` after this many seconds (> 0; inf: no limit; checked
        between steps).
    progress : callable, optional
        ``progress(t, t_end, n_events)``, called after each stretch of steps between events
        (SciPy's steppers, or the compiled loop, which runs such a stretch whole) and at the end.

    Raises
    ------
    flexbody.errors.InputError
        A bad scene or option (naming it, its value and the rule), or a ``model`` loaded for
        another scene, backend or formulation than the one asked for; nothing is run.

    Returns
    -------
    SimulationResult
        ``status`` says whether it reached ``t_end``; if not, ``message`` says why and
        what to change, and the arrays hold what was computed until then.
    """
    from .errors import InputError, shown

    if not isinstance(scene, (Scene, str, os.PathLike)):
        raise InputError(f"`scene` = {shown(scene)}: must be a Scene, a scene file's path or a bundled scene's name")
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    _check_run_options(max_events, max_wall_time, progress)
    if model is not None:  # the model decides what it is; an option asking for another is a mistake
        # (a scene of rigid bodies alone runs on its frames T whichever formulation is asked)
        asked = {"backend": backend, "formulation": None if formulation is None else resolved_formulation(scene, formulation)}
        for name, value in asked.items():
            own = getattr(model, name)
            if value is not None and value != own:
                raise InputError(f"`{name}` = {shown(value)}: the model given is {name} {own!r}; load one with "
                                 f"load_model(scene, {name}={value!r}), or leave {name} out")
        backend, formulation = model.backend, model.formulation
    settings = _settings(scene, dict(method=method, rtol=rtol, atol=atol, t_end=t_end, output_dt=output_dt,
                                     backend=backend, formulation=formulation, impact=impact, impact_dt=impact_dt,
                                     chatter_impacts=chatter_impacts))
    if model is None:
        model = load_model(scene, backend=settings.backend, formulation=settings.formulation)
    elif getattr(model, "made_for", None) is not None and model.made_for != (this := made_for(scene)):
        differ = [name for name, a, b in zip(MADE_FOR, model.made_for, this) if a != b]
        raise InputError(f"`model`: loaded for a scene with other {', '.join(differ)} than {scene.name!r}, which it "
                         "keeps from when it was made; load_model(scene) makes this scene's")
    settings = _settings(scene, dict(vars(settings), backend=model.backend, formulation=model.formulation))
    with _one_rhs_thread(model, settings.method not in COMPILED_METHODS):
        run = _Run(scene, model, settings, progress, max_events, max_wall_time)
        start = time.perf_counter()
        status, message = run.run()
        wall = time.perf_counter() - start
        return run.result(status, message, wall)


def _check_run_options(max_events, max_wall_time, progress) -> None:
    """:func:`simulate`'s run limits and progress callback, checked before any work.

    Raises
    ------
    flexbody.errors.InputError
        Naming the option, its value and the rule.
    """
    from .errors import InputError, shown

    if not isinstance(max_events, numbers.Integral) or isinstance(max_events, bool) or max_events < 1:
        raise InputError(f"`max_events` = {shown(max_events)}: must be an integer >= 1")
    if not isinstance(max_wall_time, numbers.Real) or isinstance(max_wall_time, bool) or not max_wall_time > 0:
        raise InputError(f"`max_wall_time` = {shown(max_wall_time)}: must be a number of seconds > 0 (inf: no limit)")
    if progress is not None and not callable(progress):
        raise InputError(f"`progress` = {shown(progress)}: must be a callable progress(t, t_end, n_events), or None")


@contextmanager
def _one_rhs_thread(model: Model, scipy_stepper: bool):
    """With one of SciPy's steppers, the right-hand side of the model's assembled C part runs
    on one thread for the run (the values are the same, bit for bit); afterwards its limit
    is as before.  Between two of its calls from Python the second OpenMP thread falls
    asleep, and waking it costs more than the half it takes (measured on a 2-core VM: a
    pile of 20 discs, 10 920 links, 66 us a call on one thread against 86-120 us on two,
    its run 11 % slower; a 10 000-particle disc, 29 628 links, 170 against 155-215 us).
    The compiled loop calls it back to back and keeps both."""
    inner = getattr(model, "inner", model)  # contacts between bodies wrap the scene's model
    assembly = getattr(inner, "flexible", inner)  # rigid frames beside it: its flexible part
    if not scipy_stepper or not hasattr(assembly, "use_threads"):
        yield
        return
    before = assembly.use_threads(1)
    try:
        yield
    finally:
        assembly.use_threads(before)


__all__ = ["simulate", "SimulationFailed"]
