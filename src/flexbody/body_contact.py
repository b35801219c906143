"""Contacts between bodies: a particle of one body against the surface of another.

:class:`BodyContactModel` adds to a scene's model one contact *slot*
per (particle, other body) pair that may touch (the scene's ``[[contacts]]``, ``collide``):
every vertex of the first body's surface against the second body's surface, and the other
way round.  The slots come after the ground contacts, so the phase machine
(:mod:`flexbody.contact`, :mod:`flexbody.events`) runs them as it runs the grounds'.
A run gives slots only to the pairs whose bodies' boxes are in reach of each other
(:meth:`BodyContactModel.with_pairs`; the driver grows the table as pairs come near), so
a pile's table grows with the pairs that touch, not with the square of its bodies; with
self-contact or edge contacts the table is laid out for every pair at once.

* **Free** slot: its gap is the particle's signed distance to the other body's surface
  (:func:`flexbody.surface_contact.closest_features`, over the candidates of the broad
  phase :class:`flexbody.broadphase.CandidateList`), continuous as the closest point moves
  from one segment or triangle to the next, so onset is an exact event on the dense output.
* **At an instant** a touching slot is constrained on one surface *element*: the one its
  closest point lies on, or, at a vertex or edge (or a face's rim), the neighbouring element
  whose normal is closest to the feature's normal (ties: the lowest-numbered), of those
  whose plane has the particle's own body on its outer side where one has (met at a vertex
  to round-off, the direction to it is noise).  Its gap is that element's
  line (2D) or plane (3D) gap, with the generated kernels' Jacobian ``[n, -w_1 n, ...]``
  (w: the projection's weights) and velocity term ``d(J v)/dq . v``
  (:mod:`derivation.elements`).  Impacts and held forces couple through the bodies'
  particles, so they are solved together, with the ground contacts they share particles
  with, as linear complementarity problems (:mod:`flexbody.coupled`).
* **Held** slot: its gap's acceleration is kept at 0 while its force pushes; its event
  fires when the force would pull (lift-off) or when the particle's projection leaves the
  element (a weight reaches 0).  Then :meth:`BodyContactModel.switch_elements` moves it to
  the neighbour across that boundary: it stays held there if it meets it tangentially,
  hits it if it approaches (a concave corner) and is freed if it leaves (a convex one).
* **In a concave corner** a particle can rest on both elements at once.  Each slot has a
  *corner twin* (two in 3D: ``s + n_primary``, ``s + 2 n_primary``), another contact of the
  same particle and body, which only ever holds: where a slot passes onto the next element
  at a concave vertex (edge), a free twin takes over the element it came from, held.  If the slot hits the new element, the
  impact is one LCP over both; if the impact leaves the particle moving away from that
  element faster than a rebound too slow to count (the Zeno threshold, ``min_rebound``),
  the twin lifts off and the particle slides on; slower, both stay held and the particle
  rests in the corner.  If it meets the new element tangentially, the instant's force LCP
  decides whether the twin stays (in a pile, a disc's corner particle in a dent of another
  slipped across the dent's vertex onto the flank lying flush on its own disc, where it is
  redundant and was freed, and without the twin it hit the bent flank again and again:
  "chattering").  Without the twin it
  would be handed from one flank to the other ever faster, each hand-over a plastic impact
  keeping ``cos`` of the corner's angle of its speed (Zeno).  The rows of a corner that
  pins its particle (two in 2D, three in 3D) have no element-boundary event; each leaves by
  its force.  A 3D particle held on the two faces of a concave edge slides along the line
  where their planes meet, and only the ends of the edge bound it (:meth:`_along_edge`).  A
  free twin has no gap (it reads ``margin``), and a held twin always has its slot held too.

**A vertex meeting a vertex** (a box's corner sliding over a floor's vertex, a crease's vertex
passing under a tetrahedron's apex, two corners colliding) is one contact seen from both
sides: both slots touch, and the distance between two points has no normal where they
meet.  Where one of the two is held on an element at the other particle, and the other
body lies on that element's outer side there, the other slot is carried by it (not hit:
its rate is read as 0; :meth:`BodyContactModel._made_from_the_other_side`); where both
are hit at once, the lower-numbered is the contact (:meth:`BodyContactModel.same_contacts`).

**Self-contact** (a body listed with itself): its surface particles have one slot each
against its own surface, which leaves out each particle's neighbourhood (the elements its
links reach within a few element sizes) and reads ``margin`` where the closest feature of
the rest says nothing (:mod:`flexbody.own_surface`); a hand-over onto the neighbourhood
sets the slot free.  Otherwise such a slot is any other.

**Coulomb friction** (the pairs' ``friction``, and the grounds' where contacts couple): a
held contact with friction sticks, its slip rates' accelerations kept at 0 too (the tangent
rows ``[t, -w_1 t, ...]``, 2D: ``t = (-n_y, n_x)``; 3D: ``t1 = (b - a) / |b - a|``,
``t2 = n x t1`` of the element, or a fixed pair of a ground's; and the kernels'
``slip_bias``), or slides, pushed back by ``-mu lam`` along its slip direction; impacts and
the stick/slip decisions at an instant are Coulomb's LCPs (:mod:`flexbody.coupled`; in 3D
on the circular cone, :mod:`flexbody.contact_problems`).

The model inside is the assembled particles formulation (q: the particle positions, M
diagonal) or a whole-scene derived one (the floating formulation: rigid bodies, frames T),
whose particles move with q through ``v = P(q) u``: a contact row on particles is mapped
to q by the derived ``particle_jacobian`` P and ``particle_bias`` (``P' u``), and solved
with the dense mass matrix (such scenes are small).  A scene with a rigid body on a ground
with friction runs here too, without slots.  On the assembled model, ground contacts that
share no particle with a held slot (and are not a frictional corner) keep its per-particle
closed form (its C or NumPy right-hand side); on a derived one, held ground contacts are
solved here with the slots, or where they have friction.  The coupled rows are solved
densely (the held slots of a scene are few).  Segments integrate with SciPy's
explicit or implicit steppers (the compiled loop knows only ground contacts); an implicit
stepper gets the assembled model's Jacobian without the body contacts' coupling, which
slows its Newton iterations, not its answer.
"""

from __future__ import annotations

import copy
import ctypes
import dataclasses
import hashlib
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from . import runtime
from .assembly import AssembledModel, _kernels_module
from .broadphase import CandidateList, slices
from .constants import FREE, HELD, SLIDING, VELOCITY_ROUNDOFF
from .contact import Phases
from .contact_problems import least_squares
from .dynamics import contact_solve
from .edge_contact import EdgeSlots, EdgeTerms
from .held_rows import CompiledHeldRows, LaidOutRows
from .mixed import MixedModel
from .model import GeneratedModel, Model
from .own_surface import OwnSurface
from .scene import Scene
from .surface import (STRICT, closure_problem, cross, crossings, edges, edges_through, piercings, segments_across,
                      signed_measure, winding_numbers)
from .surface_contact import (FACE, CompiledClosestFeatures, CompiledDenseGaps, SurfaceContact, closest_features,
                              segment_normals, thinnest_width, triangle_normals, vertex_elements)

FloatArray = np.ndarray
IntArray = np.ndarray

#: Held rows whose singular value is below this fraction of the largest depend on the others
#: (the least-squares solves of friction's unsymmetric or redundant systems): as
#: :data:`flexbody.dynamics.REDUNDANT` for the symmetric ones, their share is left to the others.
DEPENDENT = 1e-12

#: Particle rows on more than this many coordinates get ``J M^-1 J^T`` term by term
#: (:meth:`BodyContactModel._sparse_gram`), not through the dense rows.
DENSE_WIDTH = 64
#: :func:`_gram` multiplies through sparse matrices only at least this many rows on more than
#: this many coordinates.  Measured (one BLAS thread, rows of 12 nonzeros): the conversions
#: cost ~140 us at any size, and the dense product wins below 250 rows at any width up to
#: 12 000 (20 rows on 64-99 coordinates, a 3D stack's frictional rows: 2.7 us against 138 us,
#: 9 s of a 64 s run); at 250 rows on 1 000 coordinates the sparse one does (1.8 against 2.1 ms).
SPARSE_ROWS, SPARSE_WIDTH = 250, 1000
#: A closest point whose weight on one vertex is within this of 1 is at that vertex (a
#: vertex-to-vertex touch, :meth:`BodyContactModel._made_from_the_other_side`): where the
#: event locates a touch (to ~1e-15 s), the points meet to round-off of the element's size.
AT_VERTEX = 1e-9
#: A free edge contact watches the other body's edges within this fraction of ``margin``
#: (farther it reads ``margin``): only its sign change at 0 is an event, and a crossing is
#: seen from a step's end inside it as from one outside.
EDGE_REACH = 0.25
#: A step moves no particle relative to another by more than this many margins
#: (:meth:`BodyContactModel.step_reach`): within ``margin`` of a surface its gap is exact,
#: so a crossing is seen at a step's end.
STEP_REACH = 0.5
#: A pair of bodies gets its slots (:meth:`BodyContactModel.with_pairs`) where their boxes
#: come within ``margin`` and ``PAIRS_AHEAD`` reach lengths of each other: a step brings no
#: particle nearer another by more than one.  Within ``PAIRS_LATE`` reach lengths at the end
#: of a step taken without them, the step is taken again with them (a particle may have
#: touched within it).
PAIRS_AHEAD, PAIRS_LATE = 4.0, 2.0
#: A free slot's normal rate is read (:meth:`BodyContactModel.gap_rates`) within this fraction
#: of ``margin`` of its surface only: an instant asks the rate of a touching contact (gap at
#: most the gap tolerance, 1e-12 of the scene, or fired 1e-12 s ago), and picking the
#: elements of every slot within ``margin`` cost a pile of discs 15 % of its run.
RATED_REACH = 1e-6
#: Whole surface sweeps kept, by the positions they were made at (:meth:`BodyContactModel._surface_contacts`).
SWEEPS_KEPT = 8
#: Layouts of held rows kept (:meth:`BodyContactModel._layout`).
LAYOUTS_KEPT = 8
#: Answers of the coupled dynamics kept, by the states they were solved at
#: (:meth:`BodyContactModel._dynamics`).
ANSWERS_KEPT = 3
#: A vertex within this fraction of its face's size of the line where two held faces' planes
#: meet lies on it (and planes whose unit normals' cross product is shorter meet nowhere definite).
EDGE_LINE = 1e-6


class BodyContactModel(Model):
    """A scene's model (assembled or derived) with contacts between bodies and coupled friction.

    Parameters
    ----------
    scene : Scene
        With ``scene.contacts`` between bodies (and a body with itself: self-contact).
    inner : AssembledModel or GeneratedModel
        The scene's model with its ground contacts, C or NumPy: assembled (particles
        formulation), or derived whole (floating formulation; rigid bodies).

    Attributes
    ----------
    contacts : ndarray of int, shape (nc, 2)
        The inner model's (particle, ground) rows, then one row per slot: (particle,
        ``n_grounds + body``), the body whose surface it may touch.
    slot_particle, slot_body, slot_pair : ndarray of int, shape (ns,)
        Each slot's particle, the body of the surface, and its index in ``scene.contacts``.
    elements : ndarray of int, shape (m, dim)
        Every body's surface elements, global particle indices (``Scene.surfaces``).
    """

    coupled = True
    compiled_segments = False

    def __init__(self, scene: Scene, inner: AssembledModel | GeneratedModel, pairs: IntArray | None = None) -> None:
        self.inner, self._scene = inner, scene
        self.backend, self.dim, self.formulation = inner.backend, inner.dim, inner.formulation
        self.nq, self.nu, self.ny, self.n_particles = inner.nq, inner.nu, inner.ny, inner.n_particles
        self.masses, self.n_grounds = scene.masses.copy(), len(scene.grounds)
        self._coordinates = (_ParticleCoordinates(inner, self.masses) if isinstance(inner, AssembledModel)
                             else _MixedCoordinates(inner) if isinstance(inner, MixedModel)
                             else _FrameCoordinates(inner))
        self.elements, self.element_body = scene.surfaces()
        counts = [b.n_particles for b in scene.bodies]
        self.particle_body = np.repeat(np.arange(len(counts)), counts)
        #: Whether the table holds only the pairs in reach (:meth:`with_pairs`): not with
        #: self-contact or edge contacts, whose slots and rows are laid out for the whole scene.
        self.grows = not any(c.edges or c.bodies[0] == c.bodies[1] for c in scene.contacts)
        self._pair_bodies = np.array([c.bodies for c in scene.contacts], np.intp).reshape(-1, 2).T  # (2, pairs)
        self._body_starts = np.cumsum([0] + counts[:-1])  # a body's particles are a run
        # each body's surface particles, once (a pair's slots are its bodies' vertices)
        self._on_surface = [np.unique(self.elements[self.element_body == b]) for b in range(len(counts))]
        x0 = scene.initial_positions()
        #: The edge contacts of the pairs with ``edges = true`` (3D) come after
        #: the slots and their twins (see :meth:`_lay_out`).
        self._edge_pairs = np.array([k for k, c in enumerate(scene.contacts) if c.edges], np.intp)
        flexible = {k for k, body in enumerate(scene.bodies) if not body.rigid}
        # The narrow phase runs at every gap evaluation: in C with a C model, its NumPy twin otherwise.
        self._narrow = (CompiledClosestFeatures(self.elements, self.n_particles, self.element_body)
                        if self.backend == "c" else None)
        self._edge_slots = (EdgeSlots(self.elements, self.element_body,
                                      [tuple(scene.contacts[k].bodies) for k in self._edge_pairs], x0, self.backend,
                                      flexible, self._narrow) if len(self._edge_pairs) else None)
        self._body_count = len(counts)
        # particle i's elements: _incident_flat[_incident_start[i] : _incident_start[i + 1]]
        self._incident_start, self._incident_flat = vertex_elements(self.elements, self.n_particles)
        self._body_elements = [np.flatnonzero(self.element_body == b) for b in range(len(counts))]
        self._body_names = [b.name for b in scene.bodies]
        # each body's particles off its surface (a lattice's inside): none may get into another (fold)
        self._inner = [np.setdiff1d(np.flatnonzero(self.particle_body == b), self.elements[self._body_elements[b]])
                       for b in range(len(counts))]
        self._closed: dict[int, bool] = {}  # per body: whether its surface is closed (fold), on first use
        self._neighbour = _neighbours(self.elements)
        # 3D surface edges (global particles), each one's body and an element it borders (crossed_edges)
        self._edges = edges(self.elements) if self.dim == 3 else np.zeros((0, 2), np.intp)
        self._edge_body = self.particle_body[self._edges[:, 0]]
        self._edge_element = _an_element_of(self._edges, self.elements) if self.dim == 3 else np.zeros(0, np.intp)
        lengths = np.linalg.norm(x0[self.elements[:, 1]] - x0[self.elements[:, 0]], axis=1)
        # Within `margin` of a surface the broad phase finds the closest element, so the
        # gap is exact; farther, a slot reads `margin` (positive: nothing can happen there).
        self.margin = float(np.median(lengths)) if len(lengths) else 1.0
        #: No step moves a particle relative to another by more than this (m, see
        #: :meth:`step_reach`): STEP_REACH of ``margin``, or of the thinnest body's width
        #: where that is less (a 5 mm plate flew through a block in one 5 cm step).
        self.reach_length = STEP_REACH * (thinnest_width(x0, self.elements, self.particle_body, self.element_body,
                                                         self.margin) if len(lengths) else self.margin)
        #: Distances (m) of the pairs' boxes within which a pair gets its slots (``PAIRS_AHEAD``,
        #: ``PAIRS_LATE``; see :meth:`pairs_in_reach`).
        self.pairs_ahead = self.margin + PAIRS_AHEAD * self.reach_length
        self.pairs_late = self.margin + PAIRS_LATE * self.reach_length
        own = [pair.bodies[0] for pair in scene.contacts if pair.bodies[0] == pair.bodies[1]]
        self._candidates = CandidateList(self.elements, self.particle_body, self.margin, self.margin,
                                         element_body=self.element_body, self_contact=bool(own))
        #: The self-contact neighbourhoods (:mod:`flexbody.own_surface`), or None without self-contact.
        self.own = (OwnSurface(scene, self.elements, self.element_body, self.particle_body, own, self.margin,
                               self._incident_start, self._incident_flat) if own else None)
        # Free slots' gaps on a step's dense output in C (an impact's instant, a step's
        # samples): on the particles' own coordinates (no rigid frame), where a slot's gap
        # is its body's surface's nearest element (no self-contact).
        self._dense_gaps = (CompiledDenseGaps(self._narrow, self.element_body, self.n_particles, self._body_count)
                            if self._narrow is not None and isinstance(self._coordinates, _ParticleCoordinates)
                            and self.own is None else None)
        ground_laws = [[g.friction, g.restitution] for g in scene.grounds]
        pair_laws = [[c.friction, c.restitution] for c in scene.contacts]
        #: Contact laws (mu, e): the grounds', then the pairs'.
        self.laws = np.array(ground_laws + pair_laws, float).reshape(-1, 2)
        self._ground_mu = np.array(ground_laws, float).reshape(-1, 2)[inner.contacts[:, 1], 0]
        self._pair_mu = np.array(pair_laws, float).reshape(-1, 2)[:, 0]
        self._ground_friction = bool((self._ground_mu > 0.0).any())
        self._element = ElementKernels(self.dim, self.backend)
        # held rows on particles, solved in C with a C model (see _solve and _frictional_rows)
        self._held_rows = (CompiledHeldRows(self.masses, self.dim)
                           if self.backend == "c" and isinstance(self._coordinates, _ParticleCoordinates) else None)
        self._frames_of: tuple[bytes, FloatArray] | None = None  # the grounds' frames at one p (_ground_frames)
        self._lay_out(pairs)

    def _lay_out(self, pairs: IntArray | None) -> None:
        """The table of contacts for the scene's pairs ``pairs`` (None: all), with every
        contact free and nothing kept: all that depends on which pairs have slots."""
        scene, n_pairs = self._scene, self._pair_bodies.shape[1]
        #: The scene's pairs (indices into ``scene.contacts``) that have slots, ascending.
        self.pairs = np.arange(n_pairs) if pairs is None or not self.grows else np.unique(np.asarray(pairs, np.intp))
        #: ... and those that have none yet.
        self.waiting = np.setdiff1d(np.arange(n_pairs), self.pairs)
        particles, bodies, slot_pairs = [np.zeros(0, np.intp)], [np.zeros(0, np.intp)], [np.zeros(0, np.intp)]
        allowed = np.zeros((self._body_count, self._body_count), bool)
        for k in self.pairs:
            first, second = scene.contacts[k].bodies
            allowed[first, second] = allowed[second, first] = True
            for toucher, surface in ((first, second),) if first == second else ((first, second), (second, first)):
                touching = self._on_surface[toucher]
                particles.append(touching)
                bodies.append(np.full(len(touching), surface))
                slot_pairs.append(np.full(len(touching), k))
        #: Slots (each touching particle against each body it may touch), then their corner
        #: twins: one in 2D (two segments make a corner), two in 3D (three faces do).
        self.n_primary = sum(len(a) for a in particles)
        self.slot_particle = np.tile(np.concatenate(particles), self.dim).astype(np.intp)
        self.slot_body = np.tile(np.concatenate(bodies), self.dim).astype(np.intp)
        self.slot_pair = np.tile(np.concatenate(slot_pairs), self.dim).astype(np.intp)
        self.allowed = allowed
        #: Then the edge contacts of the pairs with ``edges = true`` (3D): each
        #: surface edge that may touch of a pair's first body against the second body's edges,
        #: ``EdgeSlots.PER_EDGE`` times, from slot ``first_edge`` on; their particle is the edge's
        #: first end.
        self.first_edge = len(self.slot_particle)
        if self._edge_slots is not None:
            es = self._edge_slots
            self.slot_particle = np.concatenate([self.slot_particle, es.edges[es.own, 0]])
            self.slot_body = np.concatenate([self.slot_body, es.body])
            # es.pair counts the pairs with edges; the laws are the scene's contacts'
            self.slot_pair = np.concatenate([self.slot_pair, self._edge_pairs[es.pair]])
        self.n_slots = len(self.slot_particle)
        self.n_contacts = self.n_ground_contacts + self.n_slots
        self.contacts = np.vstack([self.inner.contacts, np.column_stack([self.slot_particle,
                                                                         self.n_grounds + self.slot_body])])
        # each (particle, other body)'s slot (slots, not twins), -1 where it has none: a lookup
        # per candidate pair, not a search (a pile's sweeps ask for thousands at each check)
        self._slot_at = np.full(self.n_particles * self._body_count, -1, np.intp)
        self._slot_at[(self.slot_particle * self._body_count + self.slot_body)[: self.n_primary]] = \
            np.arange(self.n_primary)
        # each slot's element while constrained; an edge row's edge and side (EdgeSlots.encode):
        # so held_on and the driver's samples restore an edge row's side with its edge
        self.element_of = np.full(self.n_slots, -1, np.intp)
        #: A particle can pass through another body's convex corner (2D; 3D: edge or vertex)
        #: between a step's event checks, however short the step (:meth:`corner_cuts`).
        self.corners = self.n_primary > 0
        # A held slot's element-boundary event fires where its margin falls below this floor
        # (m, <= 0): below 0 where a hand-over left it already past the boundary (a particle
        # a hair inside a concave corner), so that passing back over it is still found.
        self.margin_floor = np.zeros(self.n_slots)
        #: ``mu`` (nc,): each contact's friction coefficient (``laws``).
        self.mu = np.concatenate([self._ground_mu, self._pair_mu[self.slot_pair]])
        self._slip = np.zeros((self.n_contacts, self.dim))
        self._slip_held = np.zeros(self.n_contacts, np.intc)  # 3D: where a slip keeps its step start's direction
        self._frictional = bool((self.mu > 0.0).any())  # else the slip directions change no answer
        self._answers: list[tuple[tuple[np.ndarray, ...], _Solved]] = []  # the last states' answers (see _dynamics)
        self._swept: list[tuple] = []  # (fingerprint, (positions,), the whole surface sweep; see _kept_at)
        self._edges_swept: list[tuple] = []  # (fingerprint, (positions, edges held), every edge row's gap; the same)
        self._layouts: dict[tuple, _Layout] = {}  # held rows -> where their terms go (see _rows)
        self._allowed_pairs: tuple[IntArray, IntArray] | None = None  # (kept pairs, the allowed ones; see _allowed_kept)
        text = f"{self.inner.digest}|{self.slot_particle.tolist()}|{self.slot_body.tolist()}"
        self.digest = hashlib.sha256(f"bodies|{text}".encode()).hexdigest()[:16]

    # ------------------------------------------------------------------ the table of pairs in reach
    def pairs_in_reach(self, q, p, distance: float) -> IntArray:
        """The scene's pairs (indices into ``scene.contacts``, ascending) whose bodies' boxes
        come within ``distance`` (m) of each other at ``q`` (:meth:`pair_separations`): the
        only ones whose particles can be nearer than that (all where the table does not grow)."""
        among = np.arange(self._pair_bodies.shape[1])
        return among[self.pair_separations(q, p, among) <= distance] if self.grows else among

    def pair_separations(self, q, p, pairs: IntArray) -> FloatArray:
        """How far apart (m) the boxes around the particles of the bodies of the scene's pairs
        ``pairs`` (k,) are at ``q``: their widest gap along an axis, <= 0 where they overlap,
        shape (k,).  A particle of one body is no nearer an element of the other."""
        x = self._coordinates.particles(q, None, p)[0]
        lo, hi = np.minimum.reduceat(x, self._body_starts), np.maximum.reduceat(x, self._body_starts)
        first, second = self._pair_bodies[:, pairs]
        return np.maximum(lo[first] - hi[second], lo[second] - hi[first]).max(axis=1, initial=-np.inf)

    def with_pairs(self, pairs: IntArray) -> BodyContactModel:
        """This model with slots for the scene's pairs ``pairs`` (indices into
        ``scene.contacts``) alone, the state of every contact it shares with this one carried
        over (the element a slot is held on, its margin floor, its slip direction); the same
        equations (``digest``), inner model and all else that does not depend on the pairs
        (the surfaces, the broad phase, the compiled kernels: shared, so a new table costs
        ~2 ms).  A pile's table is then as large as the pairs that touch, not the square of
        its bodies."""
        made = copy.copy(self)  # what does not depend on the pairs is shared (the surfaces, the broad phase)
        made._lay_out(pairs)
        made.digest = self.digest
        new = made.contact_map(self)
        kept = new >= 0
        made._slip[new[kept]], made._slip_held[new[kept]] = self._slip[kept], self._slip_held[kept]
        ng = self.n_ground_contacts
        slots = new[ng:] - ng
        made.element_of[slots[kept[ng:]]] = self.element_of[kept[ng:]]
        made.margin_floor[slots[kept[ng:]]] = self.margin_floor[kept[ng:]]
        return made

    def contact_map(self, other: BodyContactModel) -> IntArray:
        """Where each of ``other``'s contacts (a model of the same scene with other pairs) is
        in this one, shape (other's nc,), -1 where this one has no such contact: the grounds'
        in place, a slot by its particle, body and corner twin."""
        if self.first_edge != self.n_slots or other.first_edge != other.n_slots:
            raise ValueError("edge contacts are laid out for the whole scene: their table does not grow")
        ng = self.n_ground_contacts
        twin, primary = np.divmod(np.arange(other.n_slots), max(other.n_primary, 1))
        slot = self._slot_at[other.slot_particle[primary] * self._body_count + other.slot_body[primary]]
        return np.concatenate([np.arange(ng), np.where(slot >= 0, ng + twin * self.n_primary + slot, -1)])

    # ------------------------------------------------------------------ the model interface
    @property
    def n_ground_contacts(self) -> int:
        return self.inner.n_contacts

    @property
    def manifest(self) -> dict:
        """The derived model's manifest (a whole-scene model inside only)."""
        return self.inner.manifest

    def parameters(self, scene: Scene) -> FloatArray:
        return self.inner.parameters(scene)

    def slip_directions(self, p) -> FloatArray:
        """Each sliding contact's slip direction at the start of the step, shape (nc, dim), a
        writable array (the phase machine renews it): past the stop, friction continues along
        it, as for a ground (:meth:`flexbody.assembly.AssembledModel.slip_directions`)."""
        return self._slip

    def slips_held(self, p) -> np.ndarray:
        """Where a sliding contact keeps its friction along its slip direction through the
        step, shape (nc,), int, writable (:meth:`flexbody.assembly.AssembledModel.slips_held`):
        a coupled 3D contact's as a ground's solved alone; a coupled 2D contact's always does
        (its slip does not turn: it reverses, an event)."""
        return self._slip_held

    def solved_alone(self, y, p, held, push) -> np.ndarray:
        """Bool (ng,): the held ground contacts whose laws the inner model applies alone (no
        contact couples to them); their friction follows the slip within a step unless held
        (:meth:`slips_held`), as a coupled 3D row's does; a coupled 2D row keeps the step
        start's direction."""
        return self._dynamics(y, p, np.asarray(held, np.intc), np.asarray(push, float)).fast != 0

    def tangential_pushes(self, p) -> FloatArray:
        return np.zeros((self.n_contacts, self.dim))

    def gaps(self, q, p) -> FloatArray:
        x = self._coordinates.particles(q, None, p)[0]
        return np.concatenate([self.inner.gaps(q, p), self._surface_gaps(x)[0]])

    def deep_inside(self, q, p) -> tuple[IntArray, FloatArray]:
        """The primary slots whose particle lies inside the other body's closed surface, by
        its winding number, however deep, and how far (m) from that surface, (k,) each.  A
        gap reads ``margin`` beyond the margin (the broad phase looks no farther), so a body
        placed wholly inside another reads apart from it: what a scene's start is checked
        with (a run's steps never carry a particle that far: ``step_reach``)."""
        x = self._coordinates.particles(q, None, p)[0]
        primary = np.arange(self.n_primary)
        others = primary[self.slot_body[primary] != self.particle_body[self.slot_particle[primary]]]
        found, depths = [], []
        for body in np.unique(self.slot_body[others]):
            elements = self._body_elements[body]
            corners = x[self.elements[elements].ravel()]
            slots = others[self.slot_body[others] == body]
            near = slots[((x[self.slot_particle[slots]] >= corners.min(axis=0))
                          & (x[self.slot_particle[slots]] <= corners.max(axis=0))).all(axis=1)]  # in its box
            for chunk in np.array_split(near, max(1, -(-len(near) // 256))):  # (k, m, d, d) at a time
                inside = chunk[winding_numbers(x, self.elements[elements], self.slot_particle[chunk]) >= 0.5]
                if not len(inside):
                    continue
                particles = self.slot_particle[inside]
                contact = self._closest_features(x, np.column_stack([np.repeat(particles, len(elements)),
                                                                     np.tile(elements, len(particles))]), read=False)
                distance = np.full(len(x), np.inf)
                np.minimum.at(distance, contact.particle, np.abs(contact.gap))
                found.append(inside)
                depths.append(distance[particles])
        return (np.concatenate(found), np.concatenate(depths)) if found else (np.zeros(0, np.intp), np.zeros(0))

    def point_gaps(self, q, p, gaps: FloatArray) -> FloatArray:
        """As :meth:`flexbody.model.Model.point_gaps`: an edge row read crossed by more than
        ``AT_VERTEX`` of ``margin`` (its lines' distance along their common normal) reads
        how far its edges' closest points lie inside the other body, the deeper
        (:meth:`flexbody.edge_contact.EdgeSlots.crossing_depths`): no deeper, and shallower
        where the edges are nearly parallel (coincident rim edges of boxes side by side
        read 2.6e-7 m crossed along the face between them, their points 2e-9 m inside)."""
        start = self.n_ground_contacts + self.first_edge
        rows = np.flatnonzero(gaps[start:] < -AT_VERTEX * self.margin)
        if not len(rows):
            return gaps
        x = self._coordinates.particles(q, None, p)[0]
        against = self.element_of[self.first_edge :]
        codes = against[rows].copy()
        free = codes < 0
        if free.any():  # a free row's gap is against the edge its search takes
            _, edge, side = self._edge_slots.closest(x, rows[free], against, EDGE_REACH * self.margin)
            codes[free] = np.where(edge >= 0, self._edge_slots.encode(edge, side), -1)
        rows, codes = rows[codes >= 0], codes[codes >= 0]
        out = gaps.copy()
        out[start + rows] = np.maximum(gaps[start + rows], self._edge_slots.crossing_depths(x, rows, codes))
        return out

    def gap(self, q, p, c: int) -> float:
        """Gap of contact ``c`` alone, equal to ``gaps(q, p)[c]``: a slot's is its particle's
        closest feature over the broad phase's kept pairs with the slot's body (a superset
        of the candidates holding its closest element within ``margin``; farther reads
        ``margin``), what locating an impact between bodies evaluates again and again where
        the model has no search of its own on the step's output (:meth:`gap_root`); an
        edge row's, its edge's against the other body's candidate edges (NumPy, the
        triangles' normals of every edge: not O(1))."""
        slot = c - self.n_ground_contacts
        if slot >= self.first_edge:
            return float(self._edge_gaps(self._coordinates.particles(q, None, p)[0], np.array([slot - self.first_edge]))[0][0])
        if not 0 <= slot < self.n_primary:
            return super().gap(q, p, c)
        x = self._coordinates.particles(q, None, p)[0]
        pairs = self._candidates.kept(x, int(self.slot_particle[slot]))
        pairs = self._touchable(pairs[self.element_body[pairs[:, 1]] == self.slot_body[slot]])
        contact = self._closest_features(x, pairs) if len(pairs) else None
        if contact is None or not len(contact.gap):
            return self.margin
        gap = float(contact.gap[0])
        return gap if abs(gap) <= self.margin else self.margin

    def gap_root(self, output: object, c: int, floor: float, ta: float, tb: float, xtol: float) -> float | None:
        """As :meth:`flexbody.model.Model.gap_root`: a primary slot's, in C
        (:class:`flexbody.surface_contact.CompiledDenseGaps`), where the particles are the
        coordinates, without self-contact; None for the others (grounds, twins, edge rows,
        rigid frames), or where it does not apply."""
        slot = c - self.n_ground_contacts
        if self._dense_gaps is None or not 0 <= slot < self.n_primary:
            return None
        return self._dense_gaps.root(output, self.slot_particle[slot], self.slot_body[slot], floor, self.margin, ta,
                                     tb, xtol)

    def dense_gaps(self, output: object, contacts: IntArray, floors: FloatArray, t: float) -> FloatArray | None:
        """As :meth:`flexbody.model.Model.dense_gaps`: of primary slots, in C, as
        :meth:`gap_root`; None if any of ``contacts`` is another contact."""
        slots = np.asarray(contacts, np.intp) - self.n_ground_contacts
        if self._dense_gaps is None or not ((slots >= 0) & (slots < self.n_primary)).all():
            return None
        return self._dense_gaps.at(output, self.slot_particle[slots], self.slot_body[slots], floors, self.margin, t)

    def gaps_of(self, q, p, contacts: IntArray) -> FloatArray:
        """Gaps of ``contacts (k,)`` alone, equal to ``gaps(q, p)[contacts]``: a slot's from its
        own particle's candidates only (an impact between bodies is located at O(1) per
        evaluation; a corner twin has no gap of its own: ``margin``)."""
        contacts, ng = np.asarray(contacts, np.intp), self.n_ground_contacts
        out = np.full(len(contacts), self.margin)
        grounds = contacts < ng
        if grounds.any():
            out[grounds] = self.inner.gaps_of(q, p, contacts[grounds])
        slots = contacts[~grounds] - ng
        slots = slots[(slots < self.n_primary) | (slots >= self.first_edge)]  # a corner twin reads margin
        if len(slots):
            x = self._coordinates.particles(q, None, p)[0]
            gaps = self._surface_gaps(x, slots)[0]
            out[~grounds] = gaps[contacts[~grounds] - ng]
        return out

    def held_gaps(self, q, p, rows) -> FloatArray:
        """Gaps of the held contacts ``rows (k,)``: a slot's to the element it is held on."""
        rows, ng = np.asarray(rows), self.n_ground_contacts
        out = np.empty(len(rows))
        out[rows < ng] = self.inner.gaps(q, p)[rows[rows < ng]]
        slots = rows[rows >= ng] - ng
        if len(slots):
            x = self._coordinates.particles(q, None, p)[0]
            self._constrain_elements(slots, x)
            if self.first_edge == self.n_slots:  # no edge contacts: every slot a particle's (asked at every step)
                gaps = self._element.gaps(x, self._slot_points(slots).T)
            else:
                edge, gaps = slots >= self.first_edge, np.empty(len(slots))
                if (~edge).any():
                    gaps[~edge] = self._element.gaps(x, self._slot_points(slots[~edge]).T)  # _row_terms' gap
                if edge.any():  # the gap kernel alone (this is asked at every step: drift)
                    gaps[edge] = self._edge_slots.gaps(x, slots[edge] - self.first_edge, self.element_of[slots[edge]])
            out[rows >= ng] = gaps
        return out

    def energies(self, q, u, p) -> FloatArray:
        """Kinetic energy (J), shape (1,): what :func:`flexbody.coupled.coupled_impact` needs."""
        v = self._coordinates.particles(q, u, p)[1]
        return np.array([0.5 * float(np.sum(self.masses * np.sum(v * v, axis=1)))])

    def rhs(self, y, p, held, push):
        if not np.any(held):  # every contact free (an instant's free accelerations): the inner model's alone
            ng = self.n_ground_contacts
            self._share_slips(p)
            lam = np.zeros(self.n_contacts)
            ydot, lam[:ng] = self.inner.rhs(y, p, np.zeros(ng, np.intc), np.asarray(push, float)[:ng])
            return ydot, lam
        solved = self._dynamics(y, p, held, push)
        return solved.ydot.copy(), solved.lam.copy()  # new arrays: SciPy keeps references

    def rhs_function(self, p, held, push):
        """As :meth:`flexbody.model.Model.rhs_function`: on particles in C without friction,
        the inner model's C right-hand side and the held rows' forces in C, laid out once for
        the frozen contact set (:class:`_FrozenRows`; a pile's steps evaluate nothing else),
        the same numbers as :meth:`rhs`, bit for bit."""
        held = np.array(held, np.intc)  # frozen: the caller may change its array later
        frozen = self._frozen_rows(p, held)
        general = super().rhs_function(p, held, push)
        if frozen is None:
            return general
        nq, nu, ng = self.nq, self.nu, self.n_ground_contacts
        inner = self.inner.rhs_function(p, frozen.fast, np.asarray(push, float)[:ng])
        if not len(frozen.slots):
            return inner

        def f(t, y):
            if not frozen.current(self.element_of):
                return general(t, y)
            ydot = inner(t, y)
            if frozen.solve(y, ydot[nq : nq + nu]) is None:
                return general(t, y)  # a pivot below the drop threshold: contact_solve's fallback
            return ydot

        return f

    def forces_function(self, p, held, push):
        """As :meth:`flexbody.model.Model.forces_function`, laid out once as :meth:`rhs_function`."""
        held = np.array(held, np.intc)  # frozen: the caller may change its array later
        frozen = self._frozen_rows(p, held)
        if frozen is None:
            return super().forces_function(p, held, push)
        nq, nu, ng = self.nq, self.nu, self.n_ground_contacts
        push = np.asarray(push, float)

        def forces(y):
            if not frozen.current(self.element_of):
                return self.rhs(y, p, held, push)[1]
            lam = np.zeros(self.n_contacts)
            ydot, lam[:ng] = self.inner.rhs(y, p, frozen.fast, push[:ng])
            force = frozen.solve(y, ydot[nq : nq + nu]) if len(frozen.slots) \
                else np.zeros(0)
            if force is None:
                return self.rhs(y, p, held, push)[1]
            lam[frozen.rows] = force
            return lam

        return forces

    def _frozen_rows(self, p, held) -> _FrozenRows | None:
        """What :meth:`_solve` finds for the contact set ``held`` (codes (nc,)) before its
        first number, for C models on particles without friction where every held slot has
        its element; else None."""
        held = np.asarray(held)
        ng = self.n_ground_contacts
        slots = np.flatnonzero(held[ng:] != 0)
        if self._held_rows is None or self._frictional or (self.element_of[slots] < 0).any() \
                or (slots >= self.first_edge).any():  # the C rows are a particle's against an element
            return None
        return self._laid_out(p, held, slots, self._coupled_grounds(held, slots))

    def _laid_out(self, p, held, slots: IntArray, grounds: IntArray) -> _FrozenRows:
        """The held ``slots`` (each with its element) and the ground rows ``grounds`` coupled
        to them (:meth:`_coupled_grounds`), laid out for the C rows (:class:`_FrozenRows`)."""
        ng = self.n_ground_contacts
        fast = np.array(held[:ng], np.intc)
        fast[grounds] = 0
        normals = self._coordinates.ground_normals(p)[self.inner.contacts[grounds, 1]]
        points, at = self._slot_points(slots), self.inner.contacts[grounds, 0]
        return _FrozenRows(slots, self.element_of[slots].copy(), fast, np.concatenate([grounds, ng + slots]), points,
                           at, normals, None if self._held_rows is None else self._held_rows.laid_out(at, normals, points))

    def per_particle(self, y, p, phases: Phases, seeds: np.ndarray, gap_tolerance: float) -> bool:
        """Whether the instant of the contacts ``seeds`` (bool (nc,)) is the inner model's
        alone, solved per particle (:func:`flexbody.contact.resolve` on it): on particles,
        on frictionless, plastic grounds, with no slot held, every seed a ground contact
        and no free slot within ``gap_tolerance`` of its floor (a touch the instant would
        find).  Its ``J M^-1 J^T`` is then diagonal by particle, the coupled LCP's answer the
        same; with e > 0 it would not be: the LCP's Zeno threshold of a rebound counts the
        contact's own pull (:func:`flexbody.coupled.coupled_impact`), the per-particle one
        gravity's alone.  The inner path also sets an impacting particle found up to the gap
        tolerance below a ground onto it (``settle``), as in a scene whose bodies do not
        touch.  Friction between bodies does not enter such an instant (no slot takes part):
        it decides nothing here, so a table with or without its pairs' slots solves the
        instant the same way (a growing table, :meth:`with_pairs`, is bit for bit the whole
        one's)."""
        ng = self.n_ground_contacts
        if not isinstance(self._coordinates, _ParticleCoordinates) or (self.laws[: self.n_grounds] > 0.0).any() \
                or np.asarray(seeds)[ng:].any() or phases.on_ground[ng:].any():
            return False
        x = self._coordinates.particles(y[: self.nq], None, p)[0]
        free = phases.phase[ng:] == FREE
        return not (free & (self._surface_gaps(x)[0] <= phases.floor[ng:] + gap_tolerance)).any()

    def held_forces(self, y, p, held, push) -> FloatArray:
        """As :meth:`flexbody.model.Model.held_forces`: where every held contact couples to a
        held slot (a block of :meth:`coupled_with`), on particles in C without friction, from
        the free accelerations of the particles the rows move and the rows alone (``rhs``'s
        numbers, bit for bit; the C work is the block's, not the scene's, while finding the
        rows still takes a few passes over the contacts); where no slot is held, the inner
        model's per particle (``rhs`` is then the inner model's too)."""
        ng = self.n_ground_contacts
        held = np.asarray(held)
        if self._held_rows is not None and not self._frictional and not held[ng:].any():
            # ground contacts alone (frictionless, on particles): the inner model's, per particle
            lam = np.zeros(self.n_contacts)
            lam[:ng] = self.inner.held_forces(y, p, held[:ng], np.asarray(push, float)[:ng])
            return lam
        frozen = self._frozen_rows(p, held)
        if frozen is None or not len(frozen.slots) or frozen.fast.any():  # fast: a ground contact held alone
            return self.rhs(y, p, held, push)[1]
        y = np.asarray(y, float)
        moved = np.unique(np.concatenate([frozen.at, frozen.points.ravel()]))
        acc = self.inner.free_accelerations(y, p, np.asarray(push, float)[: self.n_ground_contacts], moved)
        force = frozen.solve(y, acc)
        if force is None:  # a pivot below the drop threshold: contact_solve's fallback
            return self.rhs(y, p, held, push)[1]
        lam = np.zeros(self.n_contacts)
        lam[frozen.rows] = force
        return lam

    def friction(self, y, p, held, push) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Each contact's tangential velocity and friction force (nc, dim) and sticking slack
        ``mu lam - |ft|`` (nc,; inf where nothing sticks with friction), as
        :meth:`flexbody.assembly.AssembledModel.friction`: the inner model's for the ground
        contacts it solves alone, the coupled solve's for the others."""
        solved = self._dynamics(y, p, held, push)
        ng, d = self.n_ground_contacts, self.dim
        vt, ft, slack = np.zeros((self.n_contacts, d)), np.zeros((self.n_contacts, d)), np.full(self.n_contacts, np.inf)
        if self.inner.friction is not None and (solved.fast != 0).any():
            self._share_slips(p)
            vt[:ng], ft[:ng], slack[:ng] = self.inner.friction(y, p, solved.fast, np.asarray(push, float)[:ng])
        rows = solved.rows
        if len(rows):
            vt[rows] = np.einsum("km,kmd->kd", solved.slip, solved.tangents)
            ft[rows] = np.einsum("km,kmd->kd", solved.lam_t, solved.tangents)
            stick = solved.stick
            slack[rows[stick]] = (self.mu[rows[stick]] * solved.lam[rows[stick]]
                                  - np.linalg.norm(solved.lam_t[stick], axis=1))
        return vt, ft, slack

    def _share_slips(self, p) -> None:
        """The inner model's ground contacts slide along this model's slip directions (only
        friction reads them)."""
        if not isinstance(self._coordinates, _FrameCoordinates) and self._ground_friction:
            self.inner.slip_directions(p)[:] = self._slip[: self.n_ground_contacts]
            self.inner.slips_held(p)[:] = self._slip_held[: self.n_ground_contacts]

    def _dynamics(self, y, p, held, push) -> _Solved:
        """The right-hand side and contact forces at ``y``: the inner model's alone where no
        contact couples, else its free accelerations plus the coupled rows' forces.  The last
        few answers are kept: the event functions ask for the forces and then the friction of
        the same state (a third of a stack's evaluations), and those at a step's end are asked
        after its midpoint's, for the state of the stepper's last stage (a tenth more of a
        seesaw's), as is the friction that renews the slip directions there."""
        y = np.asarray(y, float)
        held, push = np.asarray(held, np.intc), np.asarray(push, float)
        key = (y, np.asarray(p), held, push, self.element_of) + ((self._slip, self._slip_held) if self._frictional else ())
        probe = (0, len(y) // 2, len(y) - 3)  # coordinates that differ between most states: a cheap first test
        for kept, solved in reversed(self._answers):  # the newest first
            if len(kept[0]) == len(y) and all(kept[0][i] == y[i] for i in probe) \
                    and all(map(np.array_equal, kept, key)):
                return solved
        solved = self._solve(y, p, held, push)
        if len(self._answers) == ANSWERS_KEPT:
            del self._answers[0]
        self._answers.append((tuple(a.copy() for a in key), solved))
        return solved

    def _solve(self, y, p, held, push) -> _Solved:
        """:meth:`_dynamics` without the kept answer."""
        ng = self.n_ground_contacts
        held_slots = np.flatnonzero(held[ng:] != 0)
        lam = np.zeros(self.n_contacts)
        q, u = y[: self.nq], y[self.nq : self.nq + self.nu]
        if len(held_slots):
            self._constrain_elements(held_slots, self._coordinates.particles(q, None, p)[0])
        ground_rows = self._coupled_grounds(held, held_slots)
        fast = held[:ng].copy()
        fast[ground_rows] = 0
        self._share_slips(p)
        ydot, lam[:ng] = self.inner.rhs(y, p, fast, push[:ng])
        rows = np.concatenate([ground_rows, ng + held_slots]).astype(np.intp)
        m = self.dim - 1  # tangent rows per contact
        if not len(rows):
            return _Solved(ydot, lam, fast, rows, np.zeros((0, m)), np.zeros((0, m)), np.zeros((0, m, self.dim)),
                           np.zeros(0, bool))
        acc = ydot[self.nq : self.nq + self.nu]
        k, mu, codes = len(rows), self.mu[rows], held[rows]
        stick = (mu > 0.0) & (codes == HELD)
        sliding = (mu > 0.0) & (codes == SLIDING)
        none = np.zeros((k, m))
        if self._held_rows is not None and not (mu > 0.0).any() and not (held_slots >= self.first_edge).any():
            force = self._laid_out(p, held, held_slots, ground_rows).solve(y, acc)
            if force is not None:  # else a pivot fell below the drop threshold: contact_solve's fallback below
                lam[rows] = force
                return _Solved(ydot, lam, fast, rows, none, none, np.zeros((k, m, self.dim)), stick)
        if not (stick | sliding).any():  # frictionless: no tangent rows, a symmetric system
            r = self._rows(ground_rows, held_slots, q, u, p, tangents=bool((mu > 0.0).any()))
            force = contact_solve(r.W, -(r.J @ acc[r.columns] + r.bias))
            acc[r.columns] += r.scaled.T @ force
            lam[rows] = force
            return _Solved(ydot, lam, fast, rows, none, none, r.tangents, stick)
        slip, tangents, fastest, forces = self._frictional_rows(ground_rows, held_slots, q, u, p, mu)
        # a sliding contact's friction is -mu lam_n along its slip direction (the step start's,
        # continued past a stop, as for a ground, taken into the contact's tangent plane now),
        # or from rest (a slip at round-off of the velocities counts as none) against the pull
        # that slips it
        along = _unit_rows(np.einsum("kd,kmd->km", self._slip[rows], tangents))
        moving = np.linalg.norm(slip, axis=1) > VELOCITY_ROUNDOFF * max(1.0, fastest)
        if self.dim == 3:
            # A 3D slip turns within a step: its friction follows it, as a ground contact's
            # solved alone does, unless the phase machine holds it along the step start's
            # direction (a slow slip, or one friction stops within the step: slips_held).
            # Kept through a step, the direction was an error the stepper did not see: a
            # sliding, turning rigid base's corner force read -0.62 N from the law at a
            # sample where the step had pushed with +0.11 N (a fuzzed scene).
            follow = sliding & moving & (self._slip_held[rows] == 0)
            along[follow] = _unit_rows(slip[follow])
        none_yet = ~along.any(axis=1)
        along[none_yet & moving] = _unit_rows(slip[none_yet & moving])
        none_yet = ~along.any(axis=1)
        if (sliding & none_yet).any():
            held_t = forces(stick | sliding, np.zeros((k, m)), acc.copy())[1]
            along[none_yet] = -_unit_rows(held_t[none_yet])
        drag = np.where(sliding[:, None], -mu[:, None] * along, 0.0)
        lam_n, lam_t = forces(stick, drag, acc)
        lam[rows] = lam_n
        # the power sliding friction dissipates (>= 0): the contact work entry of the state, as a ground's
        ydot[self.nq + self.nu + 1] -= float(np.sum(np.where(sliding[:, None], lam_t * slip, 0.0)))
        return _Solved(ydot, lam, fast, rows, slip, lam_t, tangents, stick)

    def _frictional_rows(self, ground_rows: IntArray, slots: IntArray, q, u, p, mu: FloatArray):
        """The held rows of :meth:`_solve` with their tangent rows: each contact's slip rates
        (k, dim - 1) along its tangents (k, dim - 1, dim), the largest speed of the
        coordinates they move, and ``forces(stick, drag, acc) -> (lam_n (k,), lam_t (k, dim -
        1))``, which adds the rows' accelerations to ``acc`` (:meth:`_coupled_forces`).  In C
        on particles (:meth:`flexbody.held_rows.CompiledHeldRows.friction`; edge rows and
        frames keep NumPy), where (nearly) dependent rows fall back to the NumPy rows."""
        k, m = len(ground_rows) + len(slots), self.dim - 1
        numpy_rows = []

        def solved(stick, drag, acc):  # the NumPy rows', built once
            if not numpy_rows:
                numpy_rows.append(self._rows(ground_rows, slots, q, u, p, tangents=True))
            r = numpy_rows[0]
            lam_n, lam_t, delta = self._coupled_forces(r, acc, k, mu, stick, drag)
            acc[r.columns] += delta
            return lam_n, lam_t

        if self._held_rows is None or (np.asarray(slots) >= self.first_edge).any():
            r = self._rows(ground_rows, slots, q, u, p, tangents=True)
            numpy_rows.append(r)
            return ((r.J[k:] @ u[r.columns]).reshape(m, k).T, r.tangents,
                    float(np.abs(u[r.columns]).max(initial=0.0)), solved)
        d = self.dim
        x, v = q.reshape(-1, d), u.reshape(-1, d)
        at, points = self.inner.contacts[ground_rows, 0], self._slot_points(slots)
        frames = self._ground_frames(p, ground_rows)
        slip, tangents = self._held_rows.slips(x, v, at, frames, points)

        def forces(stick, drag, acc):
            answer = self._held_rows.friction(x, v, acc, at, frames, points, mu, stick, drag)
            return solved(stick, drag, acc) if answer is None else answer

        fastest = max(float(np.abs(v[at]).max(initial=0.0)), float(np.abs(v[points]).max(initial=0.0)))
        return slip, tangents, fastest, forces

    def _ground_frames(self, p, ground_rows: IntArray) -> FloatArray:
        """Each ground row's frame (k_g, dim, dim): its ground's unit normal, then its
        tangents (2D: t = (-n_y, n_x); 3D: the ``ground_3d`` kernel's pair, as :meth:`_rows`
        takes them), each ground's made once per parameter vector."""
        grounds = self.inner.contacts[ground_rows, 1]
        key = np.asarray(p).tobytes()
        if self._frames_of is None or self._frames_of[0] != key:
            normals = self._coordinates.ground_normals(p)
            if self.dim == 2:
                axes = np.column_stack([-normals[:, 1], normals[:, 0]])[:, None, :]
            else:
                zeros = np.zeros((3, len(normals)))
                axes = self._element.numpy.ground_3d(zeros, zeros, normals.T)[3].transpose(2, 0, 1)
            self._frames_of = (key, np.concatenate([normals[:, None, :], axes], axis=1))
        return self._frames_of[1][grounds]

    def _coupled_grounds(self, held: np.ndarray, held_slots: IntArray) -> IntArray:
        """The held ground contacts :meth:`_solve` solves with the held slots ``held_slots``
        (each with its element), ascending: those of the particles the slots move (on frames
        T, every held one; only those with friction need this solve there), and of a
        particle held on two grounds at once (a corner: its friction couples them); none
        where no slot is held and nothing has friction."""
        ng = self.n_ground_contacts
        held_g = held[:ng] != 0
        moved = np.bincount(self.inner.contacts[held_g, 0], minlength=self.n_particles) > 1
        moved[self._slot_points(held_slots).ravel()] = True
        ground_rows = np.flatnonzero(self._coordinates.coupled_grounds(held_g, moved))
        if not len(held_slots) and not (self.mu[ground_rows] > 0.0).any():
            ground_rows = ground_rows[:0]
        return ground_rows

    def _coupled_forces(self, r: _Rows, acc, k: int, mu: np.ndarray, stick: np.ndarray, drag: np.ndarray):
        """Normal forces (k,), tangential ones (k, dim - 1) and the acceleration change on
        ``r.columns`` of held rows (friction ``mu`` (k,)): sticking contacts keep their slip
        rates' accelerations at 0 too, sliding ones are pushed back by ``drag * lam_n``
        (``drag`` (k, dim - 1)) along their tangents.

        With sliding friction the system is not symmetric: solved directly (a Painlevé
        configuration makes it singular: least squares, and the LCP at the instants reports
        it).  Sticking rows can depend on each other (two corners of a box on a face): their
        tangential forces are then not unique, and are split as ``mu lam_n``, so that every
        such contact is equally near its limit and their slack events fire together (the
        least-squares answer in tangential forces scaled by ``sqrt(mu lam_n)``).
        """
        m = drag.shape[1]
        blocks = [slice(k * (j + 1), k * (j + 2)) for j in range(m)]  # each tangent direction's k rows
        Jn, Sn = r.J[:k], r.scaled[:k]
        C = np.vstack([Jn, *(r.J[t][stick] for t in blocks)])  # the constrained rates
        pushed = Sn + sum(drag[:, j, None] * r.scaled[t] for j, t in enumerate(blocks))
        G = np.vstack([pushed, *(r.scaled[t][stick] for t in blocks)])  # G M^-1: the forces' directions, M^-1
        b = -(C @ acc[r.columns] + np.concatenate([r.bias[:k], *(r.bias[t][stick] for t in blocks)]))
        A = _gram(C, G)
        if not (np.all(np.isfinite(A)) and np.all(np.isfinite(b))):  # the driver reports a blow-up
            raise FloatingPointError("the held contacts' forces are not finite (the state diverged)")
        x = contact_solve(A, b) if not drag.any() else _least_squares(A, b)
        if stick.any():
            limit = mu[stick] * x[:k][stick]
            weight = np.maximum(limit, 1e-12 * max(float(limit.max()), 1e-300))
            scale = np.concatenate([np.ones(k), *([np.sqrt(weight)] * m)])
            x = scale * _least_squares(A * scale, b)
        lam_t = drag * x[:k, None]
        lam_t[stick] = x[k:].reshape(m, -1).T
        return x[:k], lam_t, G.T @ x

    def coupled_with(self, q, p, seeds: np.ndarray, among: np.ndarray, jumped: np.ndarray | None = None) -> np.ndarray:
        """As :meth:`flexbody.model.Model.coupled_with`: on particle coordinates (M diagonal)
        two contacts' rows act on each other only through a particle both move (a slot's:
        its own and its element's), so the answer is the seeds' connected components in
        the graph of contacts and the particles they move (a pile's instant: a few
        contacts, not every held one); the particles of ``jumped`` coordinates are seeds."""
        seeds, among = np.asarray(seeds, bool), np.asarray(among, bool)
        if isinstance(self._coordinates, _FrameCoordinates) or not seeds.any():
            return super().coupled_with(q, p, seeds, among)  # a frame moves every particle
        if jumped is not None and jumped.any():
            seeds = seeds | (among & self._moves(self._coordinates.touched(jumped)))
        ng = self.n_ground_contacts
        nodes = np.flatnonzero(seeds | among)
        grounds, slots = nodes[nodes < ng], nodes[nodes >= ng] - ng
        self._constrain_elements(slots, self._coordinates.particles(q, None, p)[0])  # a seed just hit
        moved = self._slot_points(slots)
        if self._held_rows is not None:
            label = self._held_rows.blocks(self.inner.contacts[grounds, 0], moved)
        else:
            from scipy.sparse import csr_matrix
            from scipy.sparse.csgraph import connected_components

            node = np.concatenate([np.arange(len(grounds)),
                                   len(grounds) + np.repeat(np.arange(len(slots)), moved.shape[1])])
            # a rigid body's particles are one node: its frame moves them all
            particle = self._coordinates.representative[np.concatenate([self.inner.contacts[grounds, 0],
                                                                        moved.ravel()])]
            # contacts and particles, one graph: a contact's edges go to the particles it moves
            graph = csr_matrix((np.ones(len(node)), (node, len(nodes) + particle)),
                               shape=(len(nodes) + self.n_particles,) * 2)
            label = connected_components(graph, directed=False)[1][: len(nodes)]
        order = np.concatenate([grounds, ng + slots])
        out = np.zeros(self.n_contacts, bool)
        # the blocks (labels 0, 1, ...) holding a seed, by table: np.isin would sort both
        seeded = np.zeros(int(label.max(initial=-1)) + 1, bool)
        seeded[label[seeds[order]]] = True
        out[order] = seeded[label]
        return out

    def _moves(self, particles: np.ndarray) -> np.ndarray:
        """Which contacts (bool (nc,)) move one of ``particles`` (bool (n,)): a ground
        contact its particle, a slot its particle and (if chosen) its element's."""
        ng = self.n_ground_contacts
        particles = self._coordinates.expand(particles)
        out = particles[self.contacts[:, 0]].copy()
        chosen = np.flatnonzero(self.element_of >= 0)
        out[ng + chosen] = particles[self._slot_points(chosen)].any(axis=1)
        return out

    def contact_state(self, y, p, held, push):
        return *self.gap_rates(y, p, held), self.rhs(y, p, held, push)[1]

    def gap_rates(self, y, p, held) -> tuple[FloatArray, FloatArray]:
        """As :meth:`flexbody.model.Model.gap_rates`; a free slot's rate is read within
        :data:`RATED_REACH` of ``margin`` of its surface only, a held slot's not at all (0:
        an instant asks the rates of free contacts that touch, to find which it hits; a
        pile's held rows are most of those touching)."""
        y = np.asarray(y, float)
        x, v = self._state(y, p)
        ng = self.n_ground_contacts
        gaps_g, vn_g, _ = self.inner.contact_state(y, p, np.zeros(ng, np.intc), np.zeros(ng))
        gaps_s, near, found = self._surface_contacts(x)
        vn_s = np.zeros(self.n_slots)
        held = np.asarray(held)
        rated = np.flatnonzero(near & (gaps_s <= RATED_REACH * self.margin) & (held[ng:] == 0))
        if len(rated):
            self._constrain_elements(rated, x, found)
            vn_s[rated] = self._row_terms(rated, x, v).rate
        if found is not None:  # a vertex-to-vertex touch is one contact: the other side's
            vn_s[self._made_from_the_other_side(*found, held, x)] = 0.0
        return np.concatenate([gaps_g, gaps_s]), np.concatenate([vn_g, vn_s])

    def contact_coupling(self, q, u, p, rows: IntArray, tangents: bool = False):
        """The contact rows ``rows`` (contact indices) as :mod:`flexbody.coupled` needs them;
        with ``tangents``, the normal rows then each tangent block (one in 2D, two in 3D), stacked.

        Returns
        -------
        J : ndarray, shape (m, c)
            On the coordinates ``columns`` of the particles the rows move; m = k rows, or
            dim k with ``tangents`` (normal rows, then the tangent blocks).
        columns : ndarray of int, shape (c,)
        W : ndarray, shape (m, m)
            ``J M^-1 J^T``.
        response : callable
            ``P (m,) -> M^-1 J^T P``, shape (nu,).
        bias : ndarray, shape (m,)
            The gap (and slip) accelerations' velocity terms.
        """
        x = self._coordinates.particles(q, None, p)[0]
        rows = np.asarray(rows)
        ng = self.n_ground_contacts
        slots = rows[rows >= ng] - ng
        self._constrain_elements(slots, x)
        r = self._rows(rows[rows < ng], slots, q, u, p, tangents)

        def response(P):
            out = np.zeros(self.nu)
            out[r.columns] = r.scaled.T @ np.asarray(P, float)
            return out

        return r.J, r.columns, r.W, response, r.bias

    def impact(self, y, p, stop):  # pragma: no cover - coupled models resolve with flexbody.coupled
        raise NotImplementedError("contacts between bodies couple: flexbody.coupled.coupled_impact resolves them")

    def trajectory(self, Y, p, held, push, elements: IntArray | None = None):
        """As :meth:`flexbody.model.Model.trajectory`; ``elements (nt, ns)``: the element each
        slot was held on at each sample (the driver records them), without which held slots'
        forces are taken on their elements now."""
        ng = self.n_ground_contacts
        X, V, E, lam_g = self.inner.trajectory(Y, p, np.asarray(held)[:, :ng], np.asarray(push)[:, :ng])
        lam = np.zeros((len(Y), self.n_contacts))
        lam[:, :ng] = lam_g
        held = np.asarray(held)
        # where the coupled rows were solved here (held slots; friction at a rigid body's or a
        # corner's ground contacts), the inner model's forces are not the answer
        again = np.any(held[:, ng:] != 0, axis=1)
        if (self.mu > 0.0).any():
            again |= np.any(held != 0, axis=1)
        for k in np.flatnonzero(again):
            with self.held_on(None if elements is None else elements[k]):
                lam[k] = self.rhs(Y[k], p, held[k], push[k])[1]
        return X, V, E, lam

    @contextmanager
    def held_on(self, elements: IntArray | None) -> Iterator[None]:
        """Within the block, each slot is held on ``elements (ns,)`` (a sample's, as the driver
        recorded them; None: the present ones); afterwards on its present element again."""
        now = self.element_of.copy()
        if elements is not None:
            self.element_of[:] = elements
        try:
            yield
        finally:
            self.element_of[:] = now

    def jacobian_function(self, p, held):
        return self.inner.jacobian_function(p, np.asarray(held)[: self.n_ground_contacts])

    # ------------------------------------------------------------------ for the phase machine
    def particle_forces(self, lam: FloatArray, positions: FloatArray | None = None,
                        elements: IntArray | None = None) -> FloatArray:
        """Normal contact force on each particle (N), shape (nt, n), from the contact forces
        ``lam (nt, nc)``: its grounds' and those of the slots it is the particle of (the
        reactions on the other body's element vertices are not counted there).  An edge
        contact's force is its edge's: split between the edge's two ends as (1 - s) and s
        (its closest point's parameter) where the samples' ``positions`` (nt, n, 3) and the
        slots' held ``elements`` (nt, ns) are given, else all on its first end."""
        lam = np.atleast_2d(lam)
        out = super().particle_forces(lam)
        ng, first = self.n_ground_contacts, self.first_edge
        np.add.at(out.T, self.slot_particle, lam[:, ng:].T)
        if positions is None or elements is None or self._edge_slots is None:
            return out
        sample, row = np.nonzero((lam[:, ng + first :] != 0.0) & (np.asarray(elements)[:, first:] >= 0))
        if len(sample):
            es, force = self._edge_slots, lam[sample, ng + first + row]
            s = es.parameters(np.asarray(positions), sample, row, np.asarray(elements)[sample, first + row])
            ends = es.edges[es.own[row]]
            np.add.at(out, (sample, ends[:, 0]), -s * force)  # its first end had it all
            np.add.at(out, (sample, ends[:, 1]), s * force)
        return out

    def fold(self, y, p, contacts: IntArray | None = None, depth: float = 0.0) -> tuple[int, str] | None:
        """A body whose surface slot contacts ``contacts`` touch (default, the whole check
        the driver makes at output samples: every surface a free slot is within ``margin``
        of, and every body with self-contact) and how
        it has folded (its index and a description), or None.  Folded: two of its 2D
        segments cross, an edge of its 3D surface passes through one of its triangles, its
        closed surface encloses no positive area or volume, or (the whole check) one of its
        particles off its surface lies inside another body (:meth:`_inside_through`).  On a folded surface inside and outside
        are not defined, so a gap's sign against it is not either: another body's particle
        can read "inside" far from any contact.  With self-contact, two segments of a body
        crossing beyond each other's neighbourhoods by at most ``depth`` (m) are two parts
        touching (a vertex held on a vertex crosses the other's flank by rounding), as two
        bodies' would be; deeper they are a contact missed, a fold too.  (A fold's onset,
        before anything crosses: :meth:`fold_onset`.)"""
        x = self._state(y, p)[0]
        slots = (np.asarray(contacts, np.intp) - self.n_ground_contacts if contacts is not None
                 else np.flatnonzero(self._surface_gaps(x)[1]))
        bodies = np.unique(self.slot_body[slots])
        if contacts is None and self.own is not None:  # a body touching itself is always near its own surface
            bodies = np.union1d(bodies, np.flatnonzero(np.diag(self.allowed)))
        for body in bodies:
            mine = self.elements[self._body_elements[body]]
            if self.dim == 2:  # a 2D crossing is a particle inside: self-contact or not, a fold
                crossed = crossings(x, mine)
                if len(crossed) and self.allowed[body, body]:  # but two parts touching, to rounding
                    ids, a, b = self._body_elements[body], mine[crossed[:, 0]], mine[crossed[:, 1]]
                    apart = ~(self.own.near(a, ids[crossed[:, 1]]) | self.own.near(b, ids[crossed[:, 0]]))
                    crossed = crossed[~(apart & (_crossing_depth(x, a, b) <= depth))]
                if len(crossed):
                    a, b = mine[crossed[0]].tolist()
                    return int(body), f"its segments {a} and {b} cross"
            else:
                pierced = piercings(x, mine)
                if self.allowed[body, body]:  # beyond a neighbourhood: edges passing, as two bodies' (crossed_edges)
                    pierced = pierced[self.own.near(edges(mine)[pierced[:, 1]], self._body_elements[body][pierced[:, 0]])]
                if len(pierced):
                    return int(body), (f"its edge {edges(mine)[pierced[0, 1]].tolist()} passes through its "
                                       f"triangle {mine[pierced[0, 0]].tolist()}")
            if self._is_closed(body) and signed_measure(x, mine) <= 0.0:
                return int(body), f"it encloses no positive {'area' if self.dim == 2 else 'volume'} (turned inside out)"
        if contacts is None:
            return self._inside_through(x, slots)
        return None

    def fold_onset(self, y, p, fired: IntArray, floors: FloatArray, depth: float) -> tuple[int, str] | None:
        """A body folding where a free contact's event fired: the body and how, or None.

        A particle's gap to a closed surface is continuous until the surface turns back on
        itself, so a free contact whose event fired reads its floor at its instant, to the
        root's tolerance.  Reading deeper than ``depth`` (m) below its floor, its gap changed
        sign at a distance from the surface: the feature's pseudo-normal flipped as the
        surface folded there, an instant before its segments cross (a soft disc folding at a
        vertex 2.8 cm from a particle of another body, which then read 2.8 cm inside at its
        impact; the segments crossed 1e-6 s later).

        Parameters
        ----------
        y : ndarray, shape (ny,)
            The state at the instant.
        fired : ndarray of int, shape (k,)
            The contacts whose gap events fired there (free just before it).
        floors : ndarray, shape (k,)
            Their floors then (m).
        depth : float
        """
        fired, floors = np.asarray(fired, np.intp), np.asarray(floors, float)
        slot = fired - self.n_ground_contacts
        # a particle's against a surface (a corner twin reads margin; an edge row's gap is an edge's)
        primary = (slot >= 0) & (slot < self.n_primary)
        slots, floors = slot[primary], floors[primary]
        if not len(slots):
            return None
        # the whole sweep at y: the instant's resolve left it kept (a few slots' own would be a new one)
        below = self._surface_gaps(self._state(np.asarray(y, float), p)[0])[0][slots] - floors
        if not (below < -depth).any():
            return None
        k = int(np.argmin(below))
        return int(self.slot_body[slots[k]]), (
            f"the gap of particle {int(self.slot_particle[slots[k]])} against it changed sign {-below[k]:.2g} m "
            "from its surface at this instant's event: its boundary turned back on itself there")

    def _is_closed(self, body: int) -> bool:
        """Whether ``body``'s surface is closed (has an inside), found on first use."""
        if body not in self._closed:
            self._closed[body] = closure_problem(self.elements[self._body_elements[body]]) == ""
        return self._closed[body]

    def _inside_through(self, x, slots: IntArray) -> tuple[int, str] | None:
        """A body one of whose particles off its surface (a lattice's inside) lies inside
        another body near it (the bodies of ``slots``' particles and those slots' bodies,
        each against the other), and how, or None.  Only surface particles make contacts: such a particle
        came through its own surface, which turned inside out (a 7-particle disc's centre
        went 2.4 cm into a block it hit at 3 m/s, unseen)."""
        x = np.asarray(x, float)
        pairs = np.column_stack([self.particle_body[self.slot_particle[slots]], self.slot_body[slots]])
        near = np.unique(np.vstack([pairs, pairs[:, ::-1]]), axis=0)  # either way: a big body can engulf a small one
        for mine, other in near[near[:, 0] != near[:, 1]].tolist():
            inner, theirs = self._inner[mine], self.elements[self._body_elements[other]]
            if not len(inner) or not self._is_closed(other):
                continue
            low, high = x[theirs].min(axis=(0, 1)), x[theirs].max(axis=(0, 1))
            inner = inner[((x[inner] >= low) & (x[inner] <= high)).all(axis=1)]
            inside = inner[winding_numbers(x, theirs, inner) >= 0.5] if len(inner) else inner
            if len(inside):
                return int(mine), (f"its particle {int(inside[0])}, off its surface, is inside body "
                                   f"{self._body_names[other]!r}: it came through its own surface, which turned "
                                   "inside out")
        return None

    def crossed_edges(self, y, p, depth: float) -> tuple[float, int, int, str] | None:
        """The deepest crossing of two bodies that may touch whose surfaces cross along
        edges, by more than ``depth`` m: its depth (m), the first body, the second and a
        description; None where none does.  Only elements inside the overlap of two bodies'
        bounding boxes are tested, in one search.

        3D: an edge of one passes through a triangle of the other
        (:func:`flexbody.surface.edges_through`; the edge's body first).  Without edge
        contacts two edges meeting (boxes crossed edge on edge, coarse polyhedra colliding)
        is no contact: the edges pass through each other with no particle inside the other
        body.  Edge contacts (``edges = true``, :mod:`flexbody.edge_contact`) keep a pair's
        edges from this; elsewhere it is the measure of what they would catch.

        2D: a segment of one crosses a segment of the other
        (:func:`flexbody.surface.segments_across`): two tips through each other, no particle
        inside, which the event location's corner cuts are there to stop.  A body's own
        segments crossing are a fold (:meth:`fold`)."""
        if not self.n_slots:
            return None
        x = self._state(y, p)[0]
        if self.dim == 2:
            return self._crossed_segments(x, depth)
        low, high = x[self.elements].min(axis=1), x[self.elements].max(axis=1)
        bodies = [b for b in range(len(self._body_elements)) if len(self._body_elements[b])]
        box = {b: (low[self._body_elements[b]].min(axis=0), high[self._body_elements[b]].max(axis=0)) for b in bodies}
        near = np.zeros(len(self.elements), bool)
        for first in bodies:
            for second in bodies:
                if second < first or not self.allowed[first, second]:
                    continue
                lo, hi = np.maximum(box[first][0], box[second][0]), np.minimum(box[first][1], box[second][1])
                if (lo <= hi).all():  # the two bodies' elements in the overlap
                    mine = np.concatenate([self._body_elements[first], self._body_elements[second]])
                    near[mine[((high[mine] >= lo) & (low[mine] <= hi)).all(axis=1)]] = True
        if not near.any():
            return None
        triangles = np.flatnonzero(near)
        segments = np.flatnonzero(near[self._edge_element])  # an edge is tested where an element of it is
        rows, depths = edges_through(x, self._edges[segments], self.elements[triangles], depth)
        edge_body, triangle_body = self._edge_body[segments[rows[:, 1]]], self.element_body[triangles[rows[:, 0]]]
        between = (edge_body != triangle_body) & self.allowed[edge_body, triangle_body]
        if self.own is not None:  # a self-contact body's edge through its own far triangle: the same
            own = (edge_body == triangle_body) & self.allowed[edge_body, triangle_body]
            own[own] = ~self.own.near(self._edges[segments[rows[own, 1]]], triangles[rows[own, 0]])
            between |= own
        if not between.any():
            return None
        k = int(np.flatnonzero(between)[np.argmax(depths[between])])
        edge, triangle = self._edges[segments[rows[k, 1]]].tolist(), self.elements[triangles[rows[k, 0]]].tolist()
        return (float(depths[k]), int(edge_body[k]), int(triangle_body[k]),
                f"its edge {edge} through the other's triangle {triangle}, {depths[k]:.2g} m deep")

    def _crossed_segments(self, x: FloatArray, depth: float) -> tuple[float, int, int, str] | None:
        """:meth:`crossed_edges` in 2D at the positions ``x`` (n, 2)."""
        rows, depths = segments_across(x, self.elements, depth)
        first, second = self.element_body[rows[:, 0]], self.element_body[rows[:, 1]]
        between = (first != second) & self.allowed[first, second]
        if not between.any():
            return None
        k = int(np.flatnonzero(between)[np.argmax(depths[between])])
        one, other = self.elements[rows[k]].tolist()
        return (float(depths[k]), int(first[k]), int(second[k]),
                f"its segment {one} across the other's segment {other}, {depths[k]:.2g} m deep")

    def start_segment(self, free: np.ndarray, q, p) -> None:
        """A segment starts at ``q``: free slots (``free`` (nc,) bool) pick their element
        afresh at their next instant, and the edge contacts watch the edges that may touch
        there through it (:meth:`flexbody.edge_contact.EdgeSlots.start_segment`)."""
        free = np.asarray(free)[self.n_ground_contacts :]
        self.element_of[free] = -1
        self.margin_floor[free] = 0.0
        if self._edge_slots is not None:
            self._edge_slots.start_segment(self._coordinates.particles(q, None, p)[0])

    def forget_twins(self, twins: IntArray) -> None:
        """The corner twins ``twins`` (contact indices, (k,)) are left without an element or
        margin floor (they lift off, or their slots took them over)."""
        self._forget(np.asarray(twins, np.intp) - self.n_ground_contacts)

    def _forget(self, rows: IntArray) -> None:
        """The rows ``rows`` (slot numbering, (k,)) are left without an element or margin
        floor: free, each picks its element anew."""
        self.element_of[rows], self.margin_floor[rows] = -1, 0.0

    def primary(self, c: IntArray) -> IntArray:
        """The slot's contact index of corner twins ``c`` (and of slots: themselves)."""
        ng = self.n_ground_contacts
        return ng + (np.asarray(c) - ng) % self.n_primary

    def _group_rows(self, slots: IntArray) -> IntArray:
        """The rows of each of ``slots``' groups (the slot, then its twins), slot numbering, (k, dim)."""
        return (np.asarray(slots) % self.n_primary)[:, None] + self.n_primary * np.arange(self.dim)

    def hand_to_slots(self, twins: IntArray) -> None:
        """The held corner twins ``twins`` (contact indices, one per slot) whose slots were
        released: each slot takes over its twin's element, margin floor and slip direction;
        the twin is left without an element (the caller swaps their phases)."""
        ng = self.n_ground_contacts
        twin_slots = np.asarray(twins, np.intp) - ng
        slots = twin_slots % self.n_primary
        self.element_of[slots] = self.element_of[twin_slots]
        self.margin_floor[slots] = self.margin_floor[twin_slots]
        self._slip[ng + slots] = self._slip[ng + twin_slots]
        self.forget_twins(twins)

    def _bounded(self, held, slots) -> np.ndarray:
        """Which held ``slots`` have an element-boundary event: not the rows of a corner that
        pins its particle (two in 2D, three in 3D)."""
        held = np.asarray(held)[self.n_ground_contacts :] != 0
        return held[self._group_rows(slots)].sum(axis=1) < self.dim

    def _margins(self, slots, x, v, held) -> tuple[ElementTerms, FloatArray, FloatArray]:
        """Held ``slots`` against their elements (:class:`ElementTerms`), how far inside them
        their particles project (m, (k,): the smallest bounding weight times the element's
        size) and the bounding weights (k, dim; ``inf`` for the others, see :meth:`_along_edge`)."""
        terms = self._element_terms(slots, x, v)
        return terms, *self._bounding(slots, terms.weights, x, held)

    def _bounding(self, slots, weights, x, held) -> tuple[FloatArray, FloatArray]:
        """How far inside their elements held ``slots`` project (m, (k,)), from their
        particles' ``weights`` (k, dim) on them, and the bounding weights (see :meth:`_margins`)."""
        weights = self._along_edge(slots, weights, x, held)
        return weights.min(axis=1) * self._sizes(slots, x), weights

    def _along_edge(self, slots, weights, x, held) -> FloatArray:
        """``weights`` (k, dim) of held ``slots`` with ``inf`` where they bound nothing: a 3D
        particle held on two faces of a concave edge moves along the line where their planes
        meet, and a face with an edge on that line keeps the weight of its third vertex at 0
        (up to round-off) all along it: only the edge's ends bound the particle there."""
        if self.dim == 2:
            return weights
        groups = self._group_rows(slots)
        on = (np.asarray(held)[self.n_ground_contacts :] != 0)[groups]
        pairs = np.flatnonzero(on.sum(axis=1) == 2)
        if not len(pairs):
            return weights
        rows, group = np.asarray(slots)[pairs], groups[pairs]
        other = np.where(on[pairs] & (group != rows[:, None]), group, -1).max(axis=1)
        faces = self.elements[self.element_of[rows]]
        line = cross(triangle_normals(x, faces), triangle_normals(x, self.elements[self.element_of[other]]))
        length = np.linalg.norm(line, axis=1)
        line /= np.maximum(length, np.finfo(float).tiny)[:, None]
        offset = x[faces] - x[self.slot_particle[rows]][:, None, :]
        distance = np.linalg.norm(cross(offset, line[:, None, :]), axis=2)  # of each vertex to the line
        on_line = distance <= EDGE_LINE * self._sizes(rows, x)[:, None]
        # nearly parallel planes (a flat crease) meet nowhere definite: all three weights bound
        edge = (on_line.sum(axis=1) == 2) & (length > EDGE_LINE)
        weights = weights.copy()
        weights[pairs[edge]] = np.where(on_line[edge], weights[pairs[edge]], np.inf)
        return weights

    def element_margins(self, y, p, held) -> FloatArray:
        """How far each held slot's particle projects inside its element (m), shape (nc,):
        its smallest bounding weight times the element's size, above the slot's
        ``margin_floor``; ``inf`` for the other contacts and the rows of a pinning corner.
        It reaches 0 where the particle passes onto a neighbour (an event)."""
        out = np.full(self.n_contacts, np.inf)
        contacts, margins = self.held_margins(y, p, held)
        out[contacts] = margins
        return out

    def held_margins(self, y, p, held, rows: tuple[IntArray, IntArray] | None = None
                     ) -> tuple[IntArray, FloatArray]:
        """:meth:`element_margins` of the contacts that have one, shape (k,) each: those
        contacts and their margins (the others' are ``inf``).  Event location asks for them
        thousands of times, a few contacts of many: no array of every contact.  ``rows``:
        :meth:`margin_rows` of ``held``, if kept (a segment's held codes are fixed)."""
        ng = self.n_ground_contacts
        slots, edges = self.margin_rows(held) if rows is None else rows
        margins = [np.zeros(0), np.zeros(0)]
        if len(slots) or len(edges):
            x, v = self._state(np.asarray(y, float), p)
        if len(slots):
            self._constrain_elements(slots, x)
            # where the particles are on their elements, not how fast: the position kernel alone
            weights = self._element.weights(x, self._slot_points(slots).T)
            margins[0] = self._bounding(slots, weights, x, held)[0] - self.margin_floor[slots]
        if len(edges):  # an edge contact's closest points reaching an end of either edge
            self._constrain_edges(edges, x)
            margins[1] = self._edge_terms(edges, x, v).margin - self.margin_floor[edges]
        return ng + np.concatenate([slots, edges]), np.concatenate(margins)

    def margin_rows(self, held) -> tuple[IntArray, IntArray]:
        """The held slots of the held codes ``held`` (nc,) with an element-boundary event
        (:meth:`_bounded`) and the held edge rows, slot indices, shape (k,) and (e,): the
        rows :meth:`held_margins` reads (two passes over every contact to find)."""
        slots = np.flatnonzero(np.asarray(held)[self.n_ground_contacts :] != 0)
        edges, slots = slots[slots >= self.first_edge], slots[slots < self.first_edge]
        return slots[self._bounded(held, slots)], edges

    def floor_margins(self, y, p, held: np.ndarray, changed: np.ndarray, gap_tolerance: float) -> None:
        """Held rows of the groups of the contacts ``changed`` at this instant (bool (nc,):
        held or released there) that start within ``gap_tolerance`` of their element's
        boundary or a hair past it: lower their margin floors below where they start, as a
        hand-over does, so that passing the boundary is an event (a margin that starts below
        its floor never crosses it, and the particle would slide on along the element's line
        or plane).  Such a row is newly held where it landed on an edge or a vertex, or was
        held before in a corner that pinned its particle (no boundary event: each row leaves
        by its force) until another row of the corner lifted off (measured: a disc's particle
        resting in a dent of another went 2.3e-7 m through the dent's other flank)."""
        ng = self.n_ground_contacts
        changed = np.flatnonzero(np.asarray(changed)[ng:])
        groups = self._group_rows(np.unique(changed[changed < self.first_edge] % self.n_primary)).ravel()
        slots = groups[np.asarray(held)[ng + groups] != 0]
        slots = slots[self._bounded(held, slots)]
        edges = changed[(changed >= self.first_edge) & (np.asarray(held)[ng + changed] != 0)]
        if not len(slots) and not len(edges):
            return
        x, v = self._state(np.asarray(y, float), p)
        margin = np.empty(0)
        if len(slots):
            self._constrain_elements(slots, x)
            margin = self._margins(slots, x, v, held)[1]
        if len(edges):  # an edge contact held a hair from an end of an edge
            self._constrain_edges(edges, x)
            slots, margin = np.concatenate([slots, edges]), np.concatenate([margin, self._edge_terms(edges, x, v).margin])
        low = margin - self.margin_floor[slots] < gap_tolerance
        self.margin_floor[slots[low]] = np.minimum(self.margin_floor[slots[low]], margin[low] - gap_tolerance)

    def switch_elements(self, y, p, held: np.ndarray, gap_tolerance: float, speed_tolerance: float) -> HandOvers:
        """Move each held slot whose projection left its element onto the neighbour across
        that boundary (the rows of a pinning corner stay; of a 3D edge's two rows, the one
        farther past its boundary: the other follows at its own event).

        Returns
        -------
        HandOvers
        """
        ng = self.n_ground_contacts
        slots = np.flatnonzero(np.asarray(held)[ng:] != 0)
        edges, slots = slots[slots >= self.first_edge], slots[slots < self.first_edge]
        slots = slots[self._bounded(held, slots)]
        empty = np.zeros(0, np.intp)
        ended = empty
        if len(slots) or len(edges):
            x, v = self._state(np.asarray(y, float), p)
        if len(edges):  # past an end of either edge the contact is a vertex's: the edge contact is set free
            ended = edges[self._edge_terms(edges, x, v).margin - self.margin_floor[edges] <= gap_tolerance]
            self._forget(ended)
        if not len(slots):
            return HandOvers(empty, empty, ng + ended, empty, empty, empty.reshape(0, 2))
        terms, margins, weights = self._margins(slots, x, v, held)
        past = margins - self.margin_floor[slots]
        passed = np.flatnonzero(past <= gap_tolerance)
        # one row of a group moves at an instant (a 3D edge's two reach its end together)
        order = passed[np.lexsort((past[passed], slots[passed] % self.n_primary))]
        group = slots[order] % self.n_primary
        first = np.ones(len(group), bool)
        first[1:] = group[1:] != group[:-1]
        waiting = slots[order[~first]]
        self.margin_floor[waiting] = margins[order[~first]] - 2.0 * gap_tolerance
        moving = np.sort(order[first])
        out = slots[moving]
        if not len(out):
            return HandOvers(empty, empty, ng + ended, empty, empty, empty.reshape(0, 2))
        # The slot is the group's row that moves (only a slot has a gap to hit): a twin that
        # is to move swaps rows with its slot, which is held too.
        relabel = out[out >= self.n_primary]
        if len(relabel):
            self._swap(relabel % self.n_primary, relabel)
            out = out % self.n_primary
        came_from = self.element_of[out].copy()
        corner = np.argmin(weights[moving], axis=1)
        self.element_of[out] = self._neighbour[came_from, corner]
        if self.own is not None:  # onto its own neighbourhood, which it does not watch: it is set free
            home = self.own.left_out(self.slot_particle[out], self.element_of[out])
            self._forget(out[home])
            ended, out, came_from = np.concatenate([ended, out[home]]), out[~home], came_from[~home]
            if not len(out):
                return HandOvers(empty, empty, ng + ended, empty, empty,
                                 ng + np.column_stack([relabel % self.n_primary, relabel]))
        terms, margin, _ = self._margins(out, x, v, held)
        # a hand-over a hair past the boundary (a particle a hair inside a corner) starts
        # below 0 on the new element too: its floor keeps its next pass findable
        self.margin_floor[out] = np.where(margin < gap_tolerance, margin - gap_tolerance, 0.0)
        rate = terms.rate
        approach, tangential = rate < -speed_tolerance, np.abs(rate) <= speed_tolerance
        # At rest on the other body, handed over a convex edge onto a face whose plane has
        # the particle's own body on its inner side though the face it came from had it
        # outside: no contact of its there (two boxes side by side, corners coincident: a
        # corner held on the other box's side face at its corner was handed to that box's
        # back face, opposite the other corner's row on this box's back face).  It is set
        # free, as one leaving.  (Moving along the new face, it slides over the edge onto it.)
        unfit = np.zeros(len(out), bool)
        met = np.flatnonzero(tangential)
        if len(met):
            particle, onto = self.slot_particle[out[met]], self.elements[self.element_of[out[met]]]
            relative = v[particle] - np.einsum("kj,kjd->kd", terms.weights[met], v[onto])
            normals = (segment_normals if self.dim == 2 else triangle_normals)
            unfit[met] = ((np.linalg.norm(relative, axis=1) <= speed_tolerance)
                          & ~self._beside(particle, normals(x, onto), x)
                          & self._beside(particle, normals(x, self.elements[came_from[met]]), x))
        tangential &= ~unfit
        self._forget(out[unfit])  # held again, it picks anew
        # At a concave vertex (edge) the particle is in a corner, on both elements, whether it
        # hits the new one or meets it tangentially (it rests there): a free twin keeps the old
        # one, held as the slot was (the next instant's LCP decides whether it stays).  Met
        # tangentially, concave by more than rounding: across a flat face's diagonal the
        # particle slides on, and a twin left on the old triangle a hair past its boundary
        # never saw that boundary again (a fuzzed flexible box's corner slid 0.08 m past a
        # rigid box's rim held on the old triangle's plane, its force down to -7 N).
        cornered = approach.copy()
        cornered[tangential] = self._concave(came_from[tangential], self.element_of[out[tangential]], x, strict=True)
        # But a 3D crease flatter than EDGE_LINE has no line for a twin to hold the particle
        # on (the two planes meet nowhere definite: :meth:`_along_edge`): the particle is on
        # one face or the other, and one crossing the crease onto the new face (faster than
        # the speed tolerance: a slide, not rounding; more across the crease than along it:
        # not a slide along the crease that a vibration or rounding takes a hair across),
        # approaching it beyond round-off, approaches it at its slide times the crease's
        # angle, a sign the geometry gives, however slowly: an impact, and no twin (past the
        # crease the old plane runs under the new face, inside the body).  A twin there took
        # the load, its row and the slot's parallel to 3e-13, and the slot, released still
        # approaching, was handed it back past the old face's end every 3.7e-12 s (a fuzzed
        # stack's corner crossing a face diagonal creased by 5e-7 rad at 0.19 m/s, 1e-7 m/s
        # onto the new triangle).  At a crease with a line the held pair slides along it: a
        # particle sliding along one, dithering across it (1e-11 m at 2e-6 m/s, a crease of
        # 8e-4 rad), keeps its twin, as every slower crossing does.
        if self.dim == 3:
            roundoff = VELOCITY_ROUNDOFF * max(1.0, float(np.abs(v).max(initial=0.0)))
            creased = np.flatnonzero(tangential & cornered & (rate < -roundoff))
            if len(creased):
                across, along, sine = self._across_crease(came_from[creased], out[creased], terms.weights[creased],
                                                          x, v)
                hit = creased[(sine < EDGE_LINE) & (across > speed_tolerance) & (across > np.abs(along))]
                cornered[hit], approach[hit], tangential[hit] = False, True, False
        rows = self._group_rows(out[cornered])
        free = np.asarray(held)[ng + rows] == 0  # a moving row's group always has one (it is bounded)
        twins = rows[np.arange(len(rows)), free.argmax(axis=1)]
        self.element_of[twins] = came_from[cornered]
        self.margin_floor[twins] = 0.0
        self._slip[ng + twins] = self._slip[ng + out[cornered]]
        return HandOvers(ng + out[tangential], ng + out[approach],
                         ng + np.concatenate([out[(rate > speed_tolerance) | unfit], ended]),
                         ng + twins, ng + out[cornered], ng + np.column_stack([relabel % self.n_primary, relabel]))

    def _swap(self, first: IntArray, second: IntArray) -> None:
        """Exchange the elements, margin floors and slip directions of rows ``first`` and
        ``second`` (slot numbering, (k,) each)."""
        ng = self.n_ground_contacts
        for a in (self.element_of, self.margin_floor):
            a[first], a[second] = a[second], a[first].copy()
        self._slip[ng + first], self._slip[ng + second] = self._slip[ng + second], self._slip[ng + first].copy()

    # ------------------------------------------------------------------ geometry
    def _concave(self, first: IntArray, second: IntArray, x: FloatArray, strict: bool = False) -> np.ndarray:
        """Whether neighbouring elements ``first`` and ``second`` (k,) meet at a concave
        vertex or edge, bool (k,): a vertex of ``second`` off the shared feature lies
        above ``first``'s line or plane (outside its body); with ``strict``, by more than
        :data:`flexbody.surface.STRICT` of its distance (not flat by rounding)."""
        a, b = self.elements[first], self.elements[second]
        off = np.array([row_b[~np.isin(row_b, row_a)][0] for row_a, row_b in zip(a, b)], np.intp)
        normals = (segment_normals if self.dim == 2 else triangle_normals)(x, a)
        reach = x[off] - x[a[:, 0]]
        return np.einsum("ij,ij->i", normals, reach) > (STRICT * np.linalg.norm(reach, axis=1) if strict else 0.0)

    def _across_crease(self, first: IntArray, slots: IntArray, weights: FloatArray, x: FloatArray,
                       v: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """3D: how each of ``slots``' particles crosses the edge its triangle shares with the
        neighbouring triangle ``first`` (k,).

        Parameters
        ----------
        first, slots : ndarray of int, shape (k,)
            The triangle each slot left and the slots, each now on its new triangle.
        weights : ndarray, shape (k, 3)
            Each particle's projection on its new triangle.
        x, v : ndarray, shape (n, 3)
            Particle positions and velocities.

        Returns
        -------
        across : ndarray, shape (k,)
            The particle's velocity relative to the triangle's point under it, in the
            triangle's plane square to the shared edge, towards the triangle's third vertex
            (m/s: > 0 onto the new triangle).
        along : ndarray, shape (k,)
            That velocity along the shared edge (m/s).
        sine : ndarray, shape (k,)
            The sine of the angle between the two triangles' planes.
        """
        left, now = self.elements[first], self.elements[self.element_of[slots]]
        shared = np.isin(now, left)
        ends = now[shared].reshape(len(now), 2)  # a neighbour across an edge shares two vertices
        third = now[~shared]
        edge = _unit_rows(x[ends[:, 1]] - x[ends[:, 0]])
        normal = triangle_normals(x, now)
        inward = cross(normal, edge)
        inward *= np.sign(np.einsum("kd,kd->k", inward, x[third] - x[ends[:, 0]]))[:, None]
        relative = v[self.slot_particle[slots]] - np.einsum("kj,kjd->kd", weights, v[now])
        sine = np.linalg.norm(cross(triangle_normals(x, left), normal), axis=1)
        return np.einsum("kd,kd->k", relative, inward), np.einsum("kd,kd->k", relative, edge), sine

    def concave_hand_backs(self, twins: IntArray, y, p) -> np.ndarray:
        """Of the held corner twins ``twins`` (contact indices) about to hand their elements
        back to their released slots (:meth:`hand_to_slots`), those whose slot was released
        from an element that meets the twin's at a strictly concave vertex or edge, bool
        (k,): the particle sits in a dent, and past the twin's element's end it would be
        inside the body (flat, it may slide on along the element's line)."""
        ng = self.n_ground_contacts
        twin_slots = np.asarray(twins, np.intp) - ng
        left, kept = self.element_of[twin_slots % self.n_primary], self.element_of[twin_slots]
        out = np.zeros(len(twin_slots), bool)
        both = (left >= 0) & (kept >= 0) & (left != kept)
        if both.any():
            out[both] = self._concave(kept[both], left[both], self._state(np.asarray(y, float), p)[0], strict=True)
        return out

    def crossing_hand_backs(self, twins: IntArray, y, p, speed_tolerance: float) -> np.ndarray:
        """Which held corner twins' released slots are crossing onto their new triangles.

        The slot was handed, across a 3D crease, from the twin's triangle onto the
        neighbour it holds now, and its particle crosses onto that neighbour faster than
        ``speed_tolerance`` (:meth:`_across_crease`): it is leaving the twin's triangle past
        its end, not resting in the corner.  Handed that triangle back, the slot would pass
        its end again one gap tolerance later, every time (a fuzzed row's top rim midpoint
        crossing a crease of 1.4e-5 rad at 3.3e-3 m/s, 0.0116 m/s along it: every
        2.6e-10 s).

        Parameters
        ----------
        twins : ndarray of int, shape (k,)
            Held corner twins (contact indices) whose slots the force LCP released.
        y : ndarray, shape (ny,)
        p : ndarray
            The state and the parameters.
        speed_tolerance : float
            Crossing speeds up to this are rest (m/s).

        Returns
        -------
        ndarray of bool, shape (k,)
        """
        ng = self.n_ground_contacts
        twin_slots = np.asarray(twins, np.intp) - ng
        slots = twin_slots % self.n_primary
        now, behind = self.element_of[slots], self.element_of[twin_slots]
        out = np.zeros(len(twin_slots), bool)
        both = np.flatnonzero((now >= 0) & (behind >= 0) & (now != behind))
        if self.dim != 3 or not len(both):
            return out
        both = both[(self._neighbour[behind[both]] == now[both, None]).any(axis=1)]  # across an edge (a crease)
        if not len(both):
            return out
        x, v = self._state(np.asarray(y, float), p)
        weights = self._element_terms(slots[both], x, v).weights
        across = self._across_crease(behind[both], slots[both], weights, x, v)[0]
        out[both] = across > speed_tolerance
        return out

    def _state(self, y, p) -> tuple[FloatArray, FloatArray]:
        """Particle positions and velocities (n, dim) each at state ``y``."""
        return self._coordinates.particles(y[: self.nq], y[self.nq : self.nq + self.nu], p)

    def _sizes(self, slots, x) -> FloatArray:
        e = self.elements[self.element_of[slots]]
        return np.linalg.norm(x[e[:, 1]] - x[e[:, 0]], axis=1)

    def _surface_gaps(self, x, slots: IntArray | None = None) -> tuple[FloatArray, np.ndarray]:
        """Each slot's signed distance to its body's surface (``margin`` where it is farther
        than that), and whether it is within ``margin``, shape (ns,) each; with ``slots``
        (primary slots and edge rows), their entries only (the others read ``margin``, not
        near)."""
        gaps, near, _ = self._surface_contacts(x, slots)
        return gaps, near

    def _surface_contacts(self, x, slots: IntArray | None = None) \
            -> tuple[FloatArray, np.ndarray, tuple[SurfaceContact, IntArray] | None]:
        """:meth:`_surface_gaps`, and the closest features found with the slot of each of
        their rows (-1: farther than ``margin``), or None where there are none."""
        if slots is not None:
            slots = np.asarray(slots, np.intp)
            gaps, near, found = self._sweep(x, slots[slots < self.first_edge])
            rows = slots[slots >= self.first_edge] - self.first_edge
        else:
            gaps, near, found = self._whole_sweep(x)
            rows = np.arange(self.n_slots - self.first_edge)
        if len(rows):  # the edge contacts': an edge held against another reads that pair's gap
            gaps, near = gaps.copy(), near.copy()
            if slots is None:  # all of them: x and the edges held decide them (asked again as the sweep is)
                edge_gaps = _kept_at(self._edges_swept, (x, self.element_of[self.first_edge :]),
                                     lambda: _read_only(self._edge_gaps(x, rows)), SWEEPS_KEPT)
            else:
                edge_gaps = self._edge_gaps(x, rows)
            gaps[self.first_edge + rows], near[self.first_edge + rows] = edge_gaps
        return gaps, near, found

    def _whole_sweep(self, x) -> tuple[FloatArray, np.ndarray, tuple[SurfaceContact, IntArray] | None]:
        """:meth:`_sweep` of every slot at positions ``x`` (n, dim), kept: it depends on x
        alone, and an instant asks for it at the same state several times (the step's end,
        the instant's resolve, the next segment's start); the last few answers are kept,
        read-only."""
        return _kept_at(self._swept, (x,), lambda: _read_only(self._sweep(x)), SWEEPS_KEPT)

    def _sweep(self, x, slots: IntArray | None = None) \
            -> tuple[FloatArray, np.ndarray, tuple[SurfaceContact, IntArray] | None]:
        """:meth:`_surface_contacts` without the kept answers."""
        gaps = np.full(self.n_slots, self.margin)
        near = np.zeros(self.n_slots, bool)
        contact = self._closest(x, slots) if self.n_slots else None
        if contact is None:
            return gaps, near, None
        slots, found = self._slots_of(contact.particle, self.element_body[contact.element])
        # Farther than `margin` the nearest candidate need not be the nearest element, and
        # its side (the gap's sign) says nothing: such a slot reads `margin`, as one without any.
        found &= np.abs(contact.gap) <= self.margin
        gaps[slots[found]] = contact.gap[found]
        near[slots[found]] = True
        return gaps, near, (contact, np.where(found, slots, -1))

    def _made_from_the_other_side(self, contact: SurfaceContact, slot_of: IntArray, held: np.ndarray,
                                  x: FloatArray) -> IntArray:
        """The slots whose closest point is a vertex of the other body at which that contact
        is made from the other side, shape (k,).

        A particle ``s`` touching another body ``B`` at its vertex ``w`` is the point where
        ``w`` touches ``s``'s body ``A``: one contact seen from both sides.  Its distance gap
        has no normal there (``|x_s - x_w|`` is not differentiable at 0; its rate along the
        relative motion is no contact normal: a box's corner sliding over a flat floor's
        vertex was stopped by it).  So ``s``'s slot is *carried* (its rate is read as 0: it
        is not hit) where ``w``'s slot against ``A`` is held on an element ``e`` with ``s``
        for a vertex, and ``B`` lies on the outer side of ``e``'s line or plane around ``w``
        (every surface edge from ``w`` points there, and ``B``'s outward normal at ``w`` away
        from it): then every motion that takes ``s`` into ``B`` takes ``w`` through ``e``,
        which its row forbids.  ``held`` (nc,): the held codes; ``x`` (n, dim) the positions.
        """
        touching = contact.gap <= AT_VERTEX * self.margin  # the others' rates decide nothing
        if not touching.any():
            return np.zeros(0, np.intp)
        rows, at, mirror = self._mirrors(contact, np.where(touching, slot_of, -1))
        if not len(rows):
            return np.zeros(0, np.intp)
        # each (row, element) where the mirror's slot or a corner twin of it is held on an
        # element with the row's particle for a vertex
        groups = self._group_rows(mirror)
        row, member = np.nonzero(np.asarray(held)[self.n_ground_contacts + groups] != 0)
        element = self.element_of[groups[row, member]]
        # a held slot has its element; one without (-1) would read the last element
        own = (element >= 0) & (self.elements[element] == contact.particle[rows][row, None]).any(axis=1)
        row, element = row[own], element[own]
        normals = (segment_normals if self.dim == 2 else triangle_normals)(x, self.elements[element])
        carried = np.zeros(len(rows), bool)
        carried[row[self._beside(at[row], normals, x)]] = True
        return slot_of[rows[carried]]

    def same_contacts(self, y, p, hit: np.ndarray) -> np.ndarray:
        """Of the contacts ``hit`` (bool (nc,)), those hit where another of them is, bool
        (nc,): two particles of two bodies meeting each at the other's vertex fire both
        slots, one contact, whose distance gaps have no normal there; its lower-numbered
        slot is the contact (its element and normal as for any touch at a vertex), and the
        other, left free, is carried by it once it holds (:meth:`_made_from_the_other_side`)."""
        out = np.zeros(self.n_contacts, bool)
        ng = self.n_ground_contacts
        slots = np.flatnonzero(np.asarray(hit)[ng : ng + self.n_primary])
        if len(slots) < 2:
            return out
        contact = self._closest(self._state(np.asarray(y, float), p)[0], slots)
        if contact is None:
            return out
        slot_of, found = self._slots_of(contact.particle, self.element_body[contact.element])
        rows, _, mirror = self._mirrors(contact, np.where(found, slot_of, -1))
        mirror_of = dict(zip(slot_of[rows].tolist(), mirror.tolist()))
        for slot, other in mirror_of.items():
            if other < slot and mirror_of.get(other) == slot:  # each at the other's vertex
                out[ng + slot] = True
        return out

    def corner_cuts(self, ya, yb, p, watched: np.ndarray) -> tuple[IntArray, IntArray, IntArray]:
        """The free contacts of ``watched`` (bool (nc,)) whose particle went round a convex
        corner of the other body between the states ``ya`` and ``yb``, shape (k,); each
        with the corner, (k, 3): a vertex ``w`` and two of its elements (:meth:`corner_lines`),
        and the one of those two (0 or 1) whose line or plane it crossed inward, (k,).

        Near a convex vertex (2D) or edge (3D) the body is the wedge inside both of its
        elements' lines or planes (near a 3D vertex, inside all of its triangles' planes),
        whose tip is as thin as one likes: a particle passing ``w`` by 1e-5 m can go into
        the tip through one element and out through the other within a step, its signed
        distance positive at each of the step's checks (two
        flexible squares whose corners had met passed each other's, the impact missed; the
        bodies then overlapped along a whole side; in 3D a box's corner through another's
        edge, 7e-6 m deep).  Each line's or plane's gap is smooth, as a ground's: a particle
        within ``margin`` at both states, its closest feature holding ``w`` at both, inside
        the first and outside the second at ``ya`` and the other way round at ``yb``, went
        round the corner outside or through the tip, as the second's crossing comes before
        or after the first's (:func:`flexbody.events.locate` roots them).  Every pair of
        ``w``'s elements is a candidate (2D: its two segments; 3D: its triangles, among them
        the two at each of its edges); the event location keeps those whose particle was
        inside the body where the two gaps are equal.
        """
        none = (np.zeros(0, np.intp), np.zeros((0, 3), np.intp), np.zeros(0, np.intp))
        ng = self.n_ground_contacts
        slots = np.flatnonzero(np.asarray(watched)[ng : ng + self.n_primary]) if self.corners else none[0]
        if not len(slots):
            return none
        found = []
        for y in (ya, yb):  # each state's closest features (the whole sweep, kept from its gaps; no edge rows')
            swept = self._whole_sweep(self._state(np.asarray(y, float), p)[0])[2]
            if swept is None:
                return none
            contact, slot_rows = swept
            found.append((contact, self._rows_of(slot_rows, slot_rows >= 0)[slots]))
        (ca, ra), (cb, rb) = found
        near = (ra >= 0) & (rb >= 0)
        slots, ra, rb = slots[near], ra[near], rb[near]
        fa, fb = ca.feature[ra], cb.feature[rb]
        moved = (fa != fb).any(axis=1)  # on one face at both: not round a vertex
        slots, fa, fb = slots[moved], fa[moved], fb[moved]
        # each (slot, w) with w a vertex of both features
        row, col = np.nonzero((fa >= 0) & (fa[:, :, None] == fb[:, None, :]).any(axis=2))
        if not len(row):
            return none
        contacts, corners = self._corner_pairs(ng + slots[row], fa[row, col])
        if not len(contacts):
            return none
        a, b = self.corner_lines(ya, p, contacts, corners), self.corner_lines(yb, p, contacts, corners)
        inward = [(a[:, j] > 0.0) & (b[:, j] <= 0.0) & (a[:, 1 - j] < 0.0) & (b[:, 1 - j] > 0.0) for j in (0, 1)]
        cut = inward[0] | inward[1]
        return contacts[cut], corners[cut], np.where(inward[0], 0, 1)[cut]

    def _corner_pairs(self, contacts: IntArray, w: IntArray) -> tuple[IntArray, IntArray]:
        """Each of ``contacts`` (k,) with each pair of the elements at its vertex ``w`` (k,)
        (a closed surface's vertex: two or more), as rows (contact) and (w, element,
        element), shapes (r,) and (r, 3); a contact's pair found at two of its vertices (the
        two triangles at an edge) once."""
        start, count = self._incident_start[w], self._incident_start[w + 1] - self._incident_start[w]
        if self.dim == 2:  # a closed outline's vertex: one pair, which no other vertex holds
            two = count == 2
            at = start[two]
            return contacts[two], np.column_stack([w[two], self._incident_flat[at], self._incident_flat[at + 1]])
        rows = []
        for m in np.unique(count[count >= 2]).tolist():  # vertices of m elements: m (m - 1) / 2 pairs each
            at = np.flatnonzero(count == m)
            i, j = np.triu_indices(m, 1)
            first = self._incident_flat[start[at][:, None] + i].ravel()
            second = self._incident_flat[start[at][:, None] + j].ravel()
            rows.append(np.column_stack([np.repeat(contacts[at], len(i)), np.repeat(w[at], len(i)), first, second]))
        if not rows:
            return np.zeros(0, np.intp), np.zeros((0, 3), np.intp)
        rows = np.concatenate(rows)
        # one row per (contact, pair): the pair's lowest shared vertex stands for it
        rows = rows[np.lexsort((rows[:, 1], rows[:, 3], rows[:, 2], rows[:, 0]))]
        first = np.ones(len(rows), bool)
        first[1:] = (rows[1:, [0, 2, 3]] != rows[:-1, [0, 2, 3]]).any(axis=1)
        return rows[first, 0], rows[first, 1:]

    def corner_lines(self, y, p, contacts: IntArray, corners: IntArray) -> FloatArray:
        """Each contact's particle's gap to the lines (2D) or planes (3D) of its corner's two
        elements, through its vertex ``w`` (``corners`` (k, 3): w and the elements, as
        :meth:`corner_cuts`), shape (k, 2) (m, negative on the body's side)."""
        x = self._state(np.asarray(y, float), p)[0]
        corners = np.asarray(corners, np.intp).reshape(-1, 3)
        w, elements = corners[:, 0], self.elements[corners[:, 1:].ravel()]
        normals = (segment_normals if self.dim == 2 else triangle_normals)(x, elements).reshape(len(w), 2, self.dim)
        particle = self.slot_particle[np.asarray(contacts, np.intp) - self.n_ground_contacts]
        return np.einsum("kjd,kd->kj", normals, x[particle] - x[w])

    def _mirrors(self, contact: SurfaceContact, slot_of: IntArray) -> tuple[IntArray, IntArray, IntArray]:
        """The rows of ``contact`` whose slot (``slot_of`` (k,), -1: none) touches at a
        vertex ``w`` of the other body, that vertex, and ``w``'s slot against the touching
        particle's body, shape (r,) each."""
        vertex, at_vertex = _touched_vertex(contact)
        rows = np.flatnonzero((slot_of >= 0) & at_vertex)
        mirror, known = self._slots_of(vertex[rows], self.particle_body[contact.particle[rows]])
        return rows[known], vertex[rows][known], mirror[known]

    def _beside(self, w: IntArray, normal: FloatArray, x: FloatArray) -> np.ndarray:
        """Whether the body of each surface vertex ``w`` (k,) lies on the outer side of a
        plane through ``x[w]`` with unit ``normal`` (k, dim), near ``w``, bool (k,): its
        surface edges from ``w`` all point there (to rounding) and its outward normal there
        points away from it."""
        start, stop = self._incident_start[w], self._incident_start[w + 1]
        owner = np.repeat(np.arange(len(w)), stop - start)
        elements = self.elements[self._incident_flat[slices(start, stop)]]  # each w's, end to end
        others = elements != w[owner, None]  # each element's other d - 1 vertices: its edges from w
        edge_owner = np.repeat(owner, self.dim - 1)
        edges = x[elements[others]] - x[w[edge_owner]]
        falling = ~(np.einsum("kd,kd->k", edges, normal[edge_owner]) >= -AT_VERTEX * np.linalg.norm(edges, axis=1))
        normals = (segment_normals if self.dim == 2 else triangle_normals)(x, elements)
        # summed per vertex in the order of its elements, as np.add.at would (bincount: a tenth of its cost)
        outward = np.column_stack([np.bincount(owner, normals[:, k], minlength=len(w)) for k in range(self.dim)])
        return (np.bincount(edge_owner[falling], minlength=len(w)) == 0) & (np.einsum("kd,kd->k", outward, normal) < 0.0)

    def _closest(self, x, slots: IntArray | None = None, read: bool = True):
        """The closest features at ``x`` of every slot within reach (or of ``slots``'s), as
        read or, with ``read`` false, as measured (:meth:`_closest_features`); None if none."""
        if slots is None and self._narrow is not None:
            # the whole sweep in C: the allowed kept pairs, boxed there (no NumPy pass over them)
            contact = self._narrow(x, x, self._allowed_kept(x), reach=self._candidates.margin)
            contact = self._readable(contact) if read else contact
            return contact if len(contact.particle) else None
        pairs = self._candidates.pairs(x, None if slots is None else np.unique(self.slot_particle[slots]))
        keep = self.allowed[self.particle_body[pairs[:, 0]], self.element_body[pairs[:, 1]]]
        if self.own is not None:
            keep &= self.own.touchable(pairs)
        if slots is not None:  # only the asked slots' bodies
            wanted = np.zeros(self.n_slots, bool)
            wanted[slots] = True
            slot, found = self._slots_of(pairs[:, 0], self.element_body[pairs[:, 1]])
            keep &= found & wanted[slot]
        pairs = pairs[keep]
        if not len(pairs):
            return None
        contact = self._closest_features(x, pairs, read)
        return contact if len(contact.particle) else None

    def _allowed_kept(self, x) -> IntArray:
        """The broad phase's kept pairs at x between bodies that may touch, shape (k, 2):
        filtered once per rebuild of its list."""
        kept = self._candidates.all_kept(x)
        if self._allowed_pairs is None or self._allowed_pairs[0] is not kept:
            allowed = self.allowed[self.particle_body[kept[:, 0]], self.element_body[kept[:, 1]]]
            if self.own is not None:
                allowed &= self.own.touchable(kept)
            self._allowed_pairs = (kept, np.ascontiguousarray(kept[allowed], np.intc))
        return self._allowed_pairs[1]

    def _closest_features(self, x, pairs, read: bool = True) -> SurfaceContact:
        """Each particle's closest feature per body over ``pairs`` (k, 2); with ``read``, as
        read (:meth:`_readable`), else as measured."""
        if self._narrow is not None:
            contact = self._narrow(x, x, pairs)
        else:
            contact = closest_features(x, x, self.elements, pairs, self.element_body)
        return self._readable(contact) if read else contact

    def _touchable(self, pairs: IntArray) -> IntArray:
        """``pairs`` (k, 2) without those in a particle's own neighbourhood (self-contact)."""
        return pairs if self.own is None else pairs[self.own.touchable(pairs)]

    def _readable(self, contact: SurfaceContact) -> SurfaceContact:
        """``contact`` as read (self-contact, :meth:`flexbody.own_surface.OwnSurface.read`):
        without the rows whose gap says nothing (their slots read ``margin``), and with the
        gaps of particles deep inside their own bodies reflected."""
        if self.own is None:
            return contact
        keep, gap = self.own.read(contact)
        if keep.all() and gap is contact.gap:
            return contact
        return dataclasses.replace(contact, gap=gap) if keep.all() else SurfaceContact(
            *((gap if f.name == "gap" else getattr(contact, f.name))[keep] for f in dataclasses.fields(SurfaceContact)))

    def step_reach(self, y, p, ydot=None) -> float:
        """The longest step (s) in which no particle moves relative to another by more than
        :attr:`reach_length` at the velocities of ``y`` and, given the state's rate ``ydot``
        (ny,), its accelerations: a step carrying a particle through a surface would otherwise
        see it beyond reach on both sides (``margin``), or through a thin body and out, and
        no event (two blocks flying at each other at 3 m/s passed through each other in one
        step at rtol 1e-6: free flight is exact for RK45, its steps unbounded; a bar released
        at rest 1 cm above a block resting on the ground fell through it in one step: no
        relative velocity at its start, only gravity against the ground's hold)."""
        y = np.asarray(y, float)
        v = self._state(y, p)[1]
        spread_v = _spread(v)
        spread_a = 0.0
        if ydot is not None:  # the particles' accelerations along the flow (a frame's too)
            dt = 1e-7
            spread_a = _spread((self._state(y + dt * np.asarray(ydot, float), p)[1] - v) / dt)
        if spread_a > 0.0:  # the root of spread_v h + spread_a h^2 / 2 = reach_length, without cancellation
            return 2.0 * self.reach_length / (spread_v + np.sqrt(spread_v**2 + 2.0 * spread_a * self.reach_length))
        return self.reach_length / spread_v if spread_v > 0.0 else np.inf

    def step_motion(self, states, p) -> float:
        """How far (m) a particle moved relative to another between consecutive ``states``
        (each (ny,); the event checks of a step, in order) at most: what :meth:`step_reach`
        bounds ahead, measured after the step."""
        x = [self._coordinates.particles(np.asarray(y, float)[: self.nq], None, p)[0] for y in states]
        return max(_spread(b - a) for a, b in zip(x, x[1:]))

    def from_inside(self, y, p, touching: np.ndarray) -> tuple[int, int, float] | None:
        """Where a touching contact (bool (nc,)) is a particle come at its own surface from
        inside (:meth:`flexbody.own_surface.OwnSurface.inside`): the particle, its body and
        how far (m) behind its surface it is; else None."""
        if self.own is None:
            return None
        slots = np.flatnonzero(np.asarray(touching)[self.n_ground_contacts : self.n_ground_contacts + self.n_primary])
        slots = slots[self.slot_body[slots] == self.particle_body[self.slot_particle[slots]]]
        contact = self._closest(self._state(np.asarray(y, float), p)[0], slots, read=False) if len(slots) else None
        deep = np.flatnonzero(self.own.inside(contact)) if contact is not None else ()
        if not len(deep):
            return None
        particle = int(contact.particle[deep[0]])
        return particle, int(self.particle_body[particle]), float(-contact.gap[deep[0]])

    def _slots_of(self, particle, body) -> tuple[IntArray, np.ndarray]:
        """The slot of each particle against each body (k,) (-1 where there is none) and
        whether there is one, bool (k,)."""
        slot = self._slot_at[np.asarray(particle) * self._body_count + np.asarray(body)]
        return slot, slot >= 0

    def _constrain_elements(self, slots, x, swept: tuple[SurfaceContact, IntArray] | None = None) -> None:
        """Pick an element for each of ``slots`` that has none (see the module docstring).
        ``swept``: the whole sweep's closest features at ``x`` with their slots
        (:meth:`_surface_contacts`), if at hand: a slot within ``margin`` has its closest
        feature over the whole surface there (what is not a candidate is farther)."""
        slots = np.asarray(slots, np.intp)
        if self.first_edge != self.n_slots and (slots >= self.first_edge).any():
            self._constrain_edges(slots[slots >= self.first_edge], x)
            slots = slots[slots < self.first_edge]
        missing = slots[self.element_of[slots] < 0]
        if not len(missing):
            return
        rows = None
        if swept is not None:
            contact, slot_rows = swept
            rows = self._rows_of(slot_rows, slot_rows >= 0)[missing % self.n_primary]  # a twin: its slot's answer
        if rows is None or (rows < 0).any():  # not all of them swept: theirs, over their bodies' surfaces
            contact = self._closest_features(x, self._pairs_with_body(missing))
            slot_rows, found = self._slots_of(contact.particle, self.element_body[contact.element])
            rows = self._rows_of(slot_rows, found)[missing % self.n_primary]
        if (rows < 0).any():
            raise KeyError(f"slots {missing[rows < 0].tolist()} have no closest feature on their bodies")
        # on a face, inside it: that face (a face's closest point on its rim is its edge's or
        # vertex's, whose elements all hold it)
        on_face = (contact.kind[rows] == FACE) & (contact.weights[rows] > AT_VERTEX).all(axis=1)
        self.element_of[missing[on_face]] = contact.element[rows[on_face]]
        if on_face.all():
            return
        at_rim, rows = missing[~on_face].tolist(), rows[~on_face].tolist()
        candidates = []  # each slot's elements of its body that hold its closest feature
        for slot, r in zip(at_rim, rows):
            feature = contact.feature[r][(contact.feature[r] >= 0) & (contact.weights[r] > AT_VERTEX)]
            around = self._elements_at(feature[0])
            for other in feature[1:]:
                around = np.intersect1d(around, self._elements_at(other))
            candidates.append(around[self.element_body[around] == self.slot_body[slot]])
        # of those whose plane has the particle's own body on its outer side, if any: at a
        # vertex met to round-off the direction to it is noise (two boxes side by side,
        # corners coincident: a corner was held on the other's top face, the other corner on
        # this one's, two rows opposite each other and no force problem's answer); one test
        # for all the slots' candidates
        every = np.concatenate(candidates)
        counts = [len(a) for a in candidates]
        ends = np.cumsum(counts)[:-1]
        # the candidates' normals alone (each element's own: the same numbers as of all of them)
        normals = np.split((segment_normals if self.dim == 2 else triangle_normals)(x, self.elements[every]), ends)
        apart = np.split(self._beside(np.repeat(self.slot_particle[at_rim], counts), np.concatenate(normals), x), ends)
        for slot, r, around, facing, beside in zip(at_rim, rows, candidates, normals, apart):
            if beside.any():
                around, facing = around[beside], facing[beside]
            self.element_of[slot] = around[np.argmax(facing @ contact.normal[r])]

    def _rows_of(self, slot_rows: IntArray, found: np.ndarray) -> IntArray:
        """Each primary slot's row among closest features whose slots are ``slot_rows`` (k,),
        those ``found`` (bool (k,)) only; -1 for a slot with none, shape (n_primary,)."""
        row_of = np.full(self.n_primary, -1, np.intp)
        row_of[slot_rows[found]] = np.flatnonzero(found)
        return row_of

    def _elements_at(self, vertex: int) -> IntArray:
        """The elements ``vertex`` is a corner of, ascending."""
        return self._incident_flat[self._incident_start[vertex] : self._incident_start[vertex + 1]]

    def _pairs_with_body(self, slots) -> IntArray:
        """Every (particle, element) pair of these slots with their bodies' whole surfaces."""
        surfaces = [self._body_elements[b] for b in self.slot_body[slots]]
        counts = [len(k) for k in surfaces]
        return self._touchable(np.column_stack([np.repeat(self.slot_particle[slots], counts), np.concatenate(surfaces)]))

    def _element_terms(self, slots, x, v):
        """Each slot's particle against its element (:class:`ElementTerms`)."""
        return self._element(x, v, self._slot_points(slots).T)

    def _slot_points(self, slots) -> IntArray:
        """The particles each constrained slot moves, shape (k, 1 + dim): its own, then its
        element's; an edge contact's, its edge's two ends, then the other edge's."""
        slots = np.asarray(slots, np.intp)
        # no masks where there are no edge contacts (asked ~20 times an instant)
        edge = slots >= self.first_edge if self.first_edge < self.n_slots else None
        particle = slots if edge is None else slots[~edge]  # (concatenate: column_stack's checks cost a pile 1 %)
        points = np.concatenate([self.slot_particle[particle][:, None], self.elements[self.element_of[particle]]], axis=1)
        if edge is None or not edge.any():
            return points
        out = np.empty((len(slots), 1 + self.dim), np.intp)
        out[~edge] = points
        out[edge] = self._edge_slots.points(slots[edge] - self.first_edge, self.element_of[slots[edge]])
        return out

    # ------------------------------------------------------------------ edge contacts (3D)
    def _row_terms(self, slots, x, v) -> RowTerms:
        """Each constrained slot's row (:class:`RowTerms`): a particle against its element
        (the element kernels) or an edge against the edge it is held on (the edge kernels)."""
        slots = np.asarray(slots, np.intp)
        edge = slots >= self.first_edge
        if not edge.any():  # particles alone (every scene without edge contacts)
            terms = self._element_terms(slots, x, v)
            return RowTerms(terms.gap, np.column_stack([np.ones(len(slots)), -terms.weights]), terms.normal,
                            terms.rate, terms.bias, terms.slip_bias)
        k = len(slots)
        out = RowTerms(np.empty(k), np.empty((k, 1 + self.dim)), np.empty((k, self.dim)), np.empty(k), np.empty(k),
                       np.zeros(k) if self.dim == 2 else None)
        if (~edge).any():
            terms = self._element_terms(slots[~edge], x, v)
            for name in ("gap", "normal", "rate", "bias"):
                getattr(out, name)[~edge] = getattr(terms, name)
            out.coefficients[~edge] = np.column_stack([np.ones(len(terms.gap)), -terms.weights])
            if self.dim == 2:
                out.slip_bias[~edge] = terms.slip_bias
        if edge.any():
            terms = self._edge_terms(slots[edge], x, v)
            for name in ("gap", "coefficients", "normal", "rate", "bias"):
                getattr(out, name)[edge] = getattr(terms, name)
        return out

    def _edge_terms(self, slots, x, v) -> EdgeTerms:
        """Constrained edge contacts ``slots`` (slot numbering) against their edges."""
        rows = np.asarray(slots, np.intp) - self.first_edge
        return self._edge_slots.terms(x, v, rows, self.element_of[self.first_edge + rows])

    def _edge_gaps(self, x, rows) -> tuple[FloatArray, np.ndarray]:
        """Gaps of edge contacts ``rows`` (rows of the edge slots, (k,)) and whether each is
        within ``margin``: one held against an edge, that pair's (its side kept); a free one,
        its edge's least gap to the other body's edges where both closest points lie on
        both edges (its siblings' edges left out, see :meth:`EdgeSlots.closest`), else ``margin``."""
        rows = np.asarray(rows, np.intp)
        against = self.element_of[self.first_edge :]
        gaps = np.full(len(rows), self.margin)
        on = against[rows] >= 0
        if on.any():
            gaps[on] = self._edge_slots.gaps(x, rows[on], against[rows[on]])
        if (~on).any():
            gap, edge, _ = self._edge_slots.closest(x, rows[~on], against, EDGE_REACH * self.margin)
            gaps[~on] = np.where(edge >= 0, gap, self.margin)
        return gaps, np.abs(gaps) < self.margin

    def _constrain_edges(self, slots, x) -> None:
        """Hold each of the edge contacts ``slots`` that has no edge against the other
        body's edge its edge is closest to (:meth:`flexbody.edge_contact.EdgeSlots.closest`),
        on the side it is on now."""
        missing = np.asarray(slots, np.intp)
        missing = missing[self.element_of[missing] < 0]
        if not len(missing):
            return
        rows = missing - self.first_edge
        against = self.element_of[self.first_edge :]
        # by rank: of an edge's free rows, the first takes the closest edge, the next the next
        rank = rows // self._edge_slots.n_primary
        for part in (rows[rank == r] for r in range(self._edge_slots.PER_EDGE)):
            if not len(part):
                continue
            _, edge, side = self._edge_slots.closest(x, part, against, EDGE_REACH * self.margin)
            lost = edge < 0
            if lost.any():  # fired, yet the strict search misses it now: a twin's choice, the inside test's rounding
                _, edge[lost], side[lost] = self._edge_slots.closest(x, part[lost], against, self.margin, loose=True)
            lost = edge < 0
            if lost.any():  # an instant's seed within the gap tolerance whose pair is no edge contact any more
                edge[lost], side[lost] = self._edge_slots.nearest(x, part[lost], against)
            against[part] = self._edge_slots.encode(edge, side)

    def _rows(self, ground_rows, slots, q, u, p, tangents: bool = False) -> _Rows:
        """Constraint rows (ground rows, then slots) on the coordinates they move: their
        normal rows, and with ``tangents`` their tangent rows after them (2D: one block
        along t = (-n_y, n_x); 3D: two, along a ground's ``ground_3d`` kernel basis or an
        element's t1 = (b - a) / |b - a|, t2 = n x t1, the slip kernel's)."""
        d = self.dim
        x, v = self._coordinates.particles(q, u, p)
        k_g, k = len(ground_rows), len(ground_rows) + len(slots)
        layout = self._layout(ground_rows, slots, tangents)
        frames = self._ground_frames(p, ground_rows)  # each ground row's normal, then its tangents
        normals = frames[:, 0]
        axes = frames[:, 1:] if tangents and d == 3 else np.zeros((k_g, 2, d))
        weights = [np.ones((k_g, 1))]
        bias, slip_bias = np.zeros(k), np.zeros((k, d - 1))
        if len(slots):
            terms = self._row_terms(slots, x, v)
            bias[k_g:] = terms.bias
            weights.append(terms.coefficients)
            normals = np.vstack([normals, terms.normal])
            if tangents and d == 2:
                slip_bias[k_g:, 0] = terms.slip_bias
            elif tangents:
                # a particle's along its triangle's tangents, an edge row's along its own edge's
                slots = np.asarray(slots, np.intp)
                on, edge = np.flatnonzero(slots < self.first_edge), np.flatnonzero(slots >= self.first_edge)
                element_axes = np.zeros((len(slots), 2, d))
                if len(on):
                    slip_bias[k_g + on], element_axes[on] = self._element.slip_terms(
                        x, v, self._slot_points(slots[on]).T)
                if len(edge):
                    slip_bias[k_g + edge], element_axes[edge] = self._edge_slots.slip_terms(
                        x, v, slots[edge] - self.first_edge, self.element_of[slots[edge]])
                axes = np.concatenate([axes, element_axes])
        if not tangents:
            directions = [normals]
        elif d == 2:
            directions = [normals, np.column_stack([-normals[:, 1], normals[:, 0]])]
        else:
            directions = [normals, axes[:, 0], axes[:, 1]]
        # every term (row, particle, coefficient (d,)): ground rows, then slots, per direction
        coefficients = []
        for direction in directions:
            offset = 0
            for w in weights:
                coefficients.append((w[:, :, None] * direction[offset : offset + len(w), None, :]).reshape(-1, d))
                offset += len(w)
        coefficients = np.concatenate(coefficients)
        J = np.zeros((len(directions) * k, len(layout.particles), d))
        if layout.distinct:  # each term its own entry (np.add.at costs ~0.1 ms a call)
            J[layout.rows, layout.at] = coefficients
        else:
            np.add.at(J, (layout.rows, layout.at), coefficients)
        bias = np.concatenate([bias, *slip_bias.T]) if tangents else bias
        columns, J, scaled, bias = self._coordinates.rows(layout.particles, J.reshape(len(J), -1), bias, q, u, p)
        if isinstance(self._coordinates, _ParticleCoordinates) and J.shape[1] > DENSE_WIDTH:
            W = self._sparse_gram(layout, coefficients, len(J))
        else:
            W = _gram(scaled, J)
        unit = np.stack(directions[1:], axis=1) if tangents else np.zeros((k, d - 1, d))
        return _Rows(columns, J, scaled, bias, unit, W)

    def _layout(self, ground_rows, slots, tangents: bool) -> _Layout:
        """Where the terms of :meth:`_rows` go (:class:`_Layout`): fixed by the rows, their
        elements and ``tangents``, so kept for the last few such sets (a segment's held rows
        are the same at every evaluation)."""
        key = (np.asarray(ground_rows).tobytes(), np.asarray(slots).tobytes(),
               self.element_of[slots].tobytes(), tangents)
        return _kept(self._layouts, key, lambda: self._new_layout(ground_rows, slots, tangents), LAYOUTS_KEPT)

    def _new_layout(self, ground_rows, slots, tangents: bool) -> _Layout:
        """:meth:`_layout` without the kept ones."""
        k = len(ground_rows) + len(slots)
        points = [self.inner.contacts[ground_rows, :1]] + ([self._slot_points(slots)] if len(slots) else [])
        particles = np.unique(np.concatenate([z.ravel() for z in points]))
        rows, at = [], []
        for block in range(self.dim if tangents else 1):  # normal rows, then dim - 1 tangent blocks
            offset = 0
            for z in points:
                rows.append(block * k + np.repeat(np.arange(offset, offset + len(z)), z.shape[1]))
                at.append(np.searchsorted(particles, z.ravel()))
                offset += len(z)
        rows, at = np.concatenate(rows), np.concatenate(at)
        # W's entries (sparse, see _sparse_gram): pairs of terms on the same particle,
        # found as neighbours `offset` apart in the terms sorted by particle
        order = np.argsort(at, kind="stable")
        sorted_rows, sorted_at = rows[order], at[order]
        m = (self.dim if tangents else 1) * k
        pairs, index = [], []
        distinct = True  # no two terms on one particle in one row: each pair of terms on a particle differs in row
        for offset in range(len(sorted_at)):
            same = np.flatnonzero(sorted_at[offset:] == sorted_at[: len(sorted_at) - offset])
            if not same.size:
                break
            a, b = sorted_rows[same], sorted_rows[same + offset]
            pairs.append((same, same + offset, offset > 0))
            index += [a * m + b] + ([b * m + a] if offset else [])
            distinct = distinct and (offset == 0 or not (a == b).any())
        masses = self.masses[particles[sorted_at]][:, None] if isinstance(self._coordinates, _ParticleCoordinates) \
            else None
        return _Layout(particles, rows, at, order, masses, pairs, np.concatenate(index), distinct)

    @staticmethod
    def _sparse_gram(layout: _Layout, coefficients: FloatArray, m: int) -> FloatArray:
        """``J M^-1 J^T`` (m, m) of particle rows given as their terms' ``coefficients``
        (t, d) in ``layout`` (a pile's held rows: each moves a few particles): ``W_ab`` sums
        ``c . c' / m_p`` over the pairs of terms of rows a and b on the same particle p,
        never through the dense rows."""
        coefficients = coefficients[layout.order]
        scaled = coefficients / layout.masses
        weight = []
        for first, second, mirrored in layout.pairs:
            w = np.einsum("kd,kd->k", scaled[first], coefficients[second])
            weight += [w] + ([w] if mirrored else [])
        return np.bincount(layout.index, np.concatenate(weight), minlength=m * m).reshape(m, m)


class _FrozenRows(NamedTuple):
    """The coupled rows of one contact set, as :meth:`BodyContactModel._solve` finds them:
    the held ``slots`` (k_s,) with their ``elements`` then, the inner model's codes
    ``fast`` (ng,) with the coupled ground rows cleared, every coupled row ``rows`` (ground
    rows, then slots; contact indices), the slots' points (k_s, 1 + dim), the ground
    rows' particles ``at`` and ``normals`` (k_g, dim), and these rows laid out for the C
    rows (:meth:`flexbody.held_rows.CompiledHeldRows.laid_out`; None without them)."""

    slots: IntArray
    elements: IntArray
    fast: IntArray
    rows: IntArray
    points: IntArray
    at: IntArray
    normals: FloatArray
    compiled: LaidOutRows | None

    def current(self, element_of: IntArray) -> bool:
        """Whether the held slots are still on these elements."""
        return bool((element_of[self.slots] == self.elements).all())  # (np.array_equal's checks: 2 µs a call)

    def solve(self, y: FloatArray, acc: FloatArray) -> FloatArray | None:
        """The rows' forces at state ``y`` (on particles: positions, then velocities), their
        accelerations added to ``acc`` (see :class:`flexbody.held_rows.LaidOutRows`)."""
        return self.compiled(y, acc)


class _Layout(NamedTuple):
    """Where the terms of :meth:`BodyContactModel._rows` go, for one set of rows.

    ``particles (c,)``: the particles they move, ascending; term t (ground rows, then slots,
    per direction) adds its coefficient to row ``rows[t]`` on particle ``particles[at[t]]``.
    For the sparse ``J M^-1 J^T``: ``order`` sorts the terms by particle, ``masses`` (t, 1)
    are the sorted terms' particles' masses, ``pairs`` the index pairs (first, second,
    mirrored) of sorted terms on the same particle, and ``index`` their entries' flat
    positions in W (a pair's, then its mirror's).  ``distinct``: no two terms share a row
    and a particle (a row's particle and its element's vertices are different particles)."""

    particles: IntArray
    rows: IntArray
    at: IntArray
    order: IntArray
    masses: FloatArray | None
    pairs: list
    index: IntArray
    distinct: bool


class _Rows(NamedTuple):
    """Contact rows on the coordinates ``columns (c,)`` they move: ``J (m, c)``, ``J M^-1
    (m, c)`` and the velocity terms ``bias (m,)`` of their accelerations (m = k normal rows,
    then dim - 1 blocks of k tangent rows if asked), each contact's unit tangents (k, dim - 1,
    dim) (zeros if not), and ``W = J M^-1 J^T``."""

    columns: IntArray
    J: FloatArray
    scaled: FloatArray
    bias: FloatArray
    tangents: FloatArray
    W: FloatArray  # J M^-1 J^T, (m, m)


@dataclass
class _Solved:
    """One evaluation of :meth:`BodyContactModel._dynamics`: the right-hand side, every
    contact's normal force, the ground contacts the inner model held alone (its codes), and
    for the coupled contacts ``rows (k,)``: slip rates and tangential forces along their
    unit tangents (k, dim - 1), the tangents (k, dim - 1, dim) and which stick with friction."""

    ydot: FloatArray
    lam: FloatArray
    fast: IntArray
    rows: IntArray
    slip: FloatArray
    lam_t: FloatArray
    tangents: FloatArray
    stick: np.ndarray


class _ParticleCoordinates:
    """q are the particle positions (the assembled model): a row on particles is a row on
    their coordinates, and M is diagonal (the particle masses)."""

    def __init__(self, inner: AssembledModel, masses: FloatArray) -> None:
        self.inner, self.masses = inner, masses
        #: Each particle is its own block of the mass matrix.
        self.representative = np.arange(inner.n_particles)

    def expand(self, particles: np.ndarray) -> np.ndarray:
        """The particles (bool (n,)) that move with ``particles``: the same ones."""
        return particles

    def touched(self, columns: np.ndarray) -> np.ndarray:
        """The particles (bool (n,)) whose velocities are the coordinates ``columns`` (bool (nu,))."""
        return columns.reshape(-1, self.inner.dim).any(axis=1)

    def particles(self, q, u, p) -> tuple[FloatArray, FloatArray | None]:
        """Positions and velocities (n, dim) each (velocities None without ``u``)."""
        d = self.inner.dim
        x = np.asarray(q, float)[: self.inner.nq].reshape(-1, d)
        return x, None if u is None else np.asarray(u, float)[: self.inner.nu].reshape(-1, d)

    def ground_normals(self, p) -> FloatArray:
        """Each ground's unit normal, shape (n_grounds, dim)."""
        return self.inner.ground_normals(p)

    def coupled_grounds(self, held: np.ndarray, moved: np.ndarray) -> np.ndarray:
        """Which held ground contacts (bool (ng,)) couple with rows moving particles ``moved``
        (bool (n,)): those of the same particles."""
        return held & moved[self.inner.contacts[:, 0]]

    def rows(self, particles: IntArray, J: FloatArray, bias: FloatArray, q, u, p):
        """``columns, J, J M^-1, bias`` of rows ``J (k, m * dim)`` on ``particles (m,)``."""
        d = self.inner.dim
        columns = (particles[:, None] * d + np.arange(d)).ravel()
        return columns, J, J / np.repeat(self.masses[particles], d), bias


class _MixedCoordinates:
    """Flexible bodies on particle coordinates beside rigid frames (:class:`flexbody.mixed.MixedModel`):
    a row on flexible particles is a row on their coordinates with their masses, as
    :class:`_ParticleCoordinates`; on a rigid body's particles it maps through its frame
    (``v = P(q) u``) and the frames' mass matrix, as :class:`_FrameCoordinates`."""

    def __init__(self, inner: MixedModel) -> None:
        self.inner = inner
        self.masses = inner.masses
        #: A flexible particle is its own block of the mass matrix; a rigid body's particles are
        #: one, named by its first particle.
        self.representative = inner.representative
        self._positions: tuple | None = None  # (q, p, x) of the last positions asked
        self._velocities: tuple | None = None  # (q, u, p, v) of the last velocities asked

    def particles(self, q, u, p) -> tuple[FloatArray, FloatArray | None]:
        """Positions and velocities (n, dim) each (velocities None without ``u``), read-only.
        The last state's are kept: a right-hand side asks for them about five times (its
        rows' elements at q alone, then the rows at q and u), each the frames' state in C
        and a gather of every particle (17 % of a disc landing on a rigid block); comparing
        the coordinates costs a tenth of that."""
        inner = self.inner
        q = np.ascontiguousarray(np.asarray(q, float)[: inner.nq])
        p = np.ascontiguousarray(p, float)
        kept = self._positions
        same = runtime.same_as_kept
        if kept is None or not (same(kept[0], q) and same(kept[1], p)):
            kept = self._positions = (q.copy(), runtime.kept_copy(p), _read_only(inner.particle_positions(q, p)))
        if u is None:
            return kept[2], None
        u = np.ascontiguousarray(np.asarray(u, float)[: inner.nu])
        known = self._velocities
        if known is None or not (same(known[1], u) and same(known[0], q) and same(known[2], p)):
            known = self._velocities = (q.copy(), u.copy(), runtime.kept_copy(p),
                                        _read_only(inner.particle_velocities(q, u, p)))
        return kept[2], known[3]

    def ground_normals(self, p) -> FloatArray:
        """Each ground's unit normal, shape (n_grounds, dim)."""
        return self.inner.ground_normals(p)

    def expand(self, particles: np.ndarray) -> np.ndarray:
        """The particles (bool (n,)) that move with ``particles``: a rigid body's all together."""
        block = np.zeros(len(particles), bool)
        block[self.representative[particles]] = True
        return block[self.representative]

    def touched(self, columns: np.ndarray) -> np.ndarray:
        """The particles (bool (n,)) whose velocities depend on the coordinates ``columns`` (bool (nu,)):
        a flexible particle's own, every rigid particle for a frame's (a frame moves its body's)."""
        inner, d = self.inner, self.inner.dim
        out = np.zeros(inner.n_particles, bool)
        out[inner.flexible_part.particles] = columns[: inner.flexible.nu].reshape(-1, d).any(axis=1)
        out[inner.rigid_particle] |= bool(columns[inner.flexible.nu :].any())
        return out

    def coupled_grounds(self, held: np.ndarray, moved: np.ndarray) -> np.ndarray:
        """Which held ground contacts (bool (ng,)) couple with rows moving particles ``moved``
        (bool (n,)): those of the same particles or rigid bodies, and every one of a rigid body
        (its contacts couple through its frame)."""
        return held & (self.expand(moved) | self.inner.rigid_particle)[self.inner.contacts[:, 0]]

    def rows(self, particles: IntArray, J: FloatArray, bias: FloatArray, q, u, p):
        """``columns, J, J M^-1, bias`` of rows ``J (k, m * dim)`` on ``particles (m,)``: the
        flexible particles' coordinates, then every rigid frame's."""
        d, k = self.inner.dim, len(J)
        on_frame = self.inner.rigid_particle[particles]
        per_particle = J.reshape(k, len(particles), d)
        flexible = particles[~on_frame]
        columns = (self.inner.local[flexible][:, None] * d + np.arange(d)).ravel()
        J_f = per_particle[:, ~on_frame].reshape(k, -1)
        scaled_f = J_f / np.repeat(self.masses[flexible], d)
        if not on_frame.any():
            return columns, J_f, scaled_f, bias
        # the rigid particles' rows on the frames' velocities, after the flexible coordinates
        on = (self.inner.local[particles[on_frame]][:, None] * d + np.arange(d)).ravel()
        J_r, scaled_r, bias = _through_frames(self.inner.rigid, on, per_particle[:, on_frame].reshape(k, -1), bias,
                                              *self.inner.rigid_state(q, u, p))
        frames = self.inner.flexible.nu + np.arange(self.inner.rigid.nu)
        return (np.concatenate([columns, frames]), np.hstack([J_f, J_r]), np.hstack([scaled_f, scaled_r]), bias)


class _FrameCoordinates:
    """A whole-scene derived model (frames T, rigid bodies): its particles move with q as
    ``v = P(q) u``, ``a = P u' + P' u``, and M is dense; every coordinate may take part."""

    def __init__(self, inner: GeneratedModel) -> None:
        self.inner = inner
        k = inner.n_contacts // max(inner.n_particles, 1)
        self._normals = [[inner.p_names.index(f"n{g}_{a}") for a in "xyz"[: inner.dim]] for g in range(k)]

    def ground_normals(self, p) -> FloatArray:
        """Each ground's unit normal, shape (n_grounds, dim): the derived model's parameters
        ``n<g>_<axis>``."""
        return np.asarray(p, float)[np.array(self._normals, np.intp).reshape(-1, self.inner.dim)]

    def particles(self, q, u, p) -> tuple[FloatArray, FloatArray | None]:
        """Positions and velocities (n, dim) each (velocities None without ``u``)."""
        q = np.asarray(q, float)[: self.inner.nq]
        x = self.inner.positions(q, p)
        return x, None if u is None else self.inner.velocities(q, np.asarray(u, float)[: self.inner.nu], p)

    def coupled_grounds(self, held: np.ndarray, moved: np.ndarray) -> np.ndarray:
        """Every held ground contact: the dense mass matrix couples them all."""
        return held

    def rows(self, particles: IntArray, J: FloatArray, bias: FloatArray, q, u, p):
        """``columns, J, J M^-1, bias`` of rows ``J (k, m * dim)`` on ``particles (m,)``,
        mapped to every coordinate."""
        d, inner = self.inner.dim, self.inner
        on = (particles[:, None] * d + np.arange(d)).ravel()
        Jq, scaled, bias = _through_frames(inner, on, J, bias, np.asarray(q, float)[: inner.nq],
                                           np.asarray(u, float)[: inner.nu], p)
        return np.arange(inner.nu), Jq, scaled, bias


def _through_frames(model: GeneratedModel, on: IntArray, J: FloatArray, bias: FloatArray, q, u, p):
    """Rows ``J (k, len(on))`` on the particle velocity components ``on`` of a derived model
    (``v = P(q) u``) as rows on its ``u``: ``J P (k, nu)``, ``J P M^-1`` and the bias with
    ``J P' u`` added."""
    Jq = J @ model.particle_jacobian(q, p)[on]
    bias = bias + J @ model.particle_bias(q, u, p).reshape(-1)[on]
    scaled = np.linalg.solve(model.mass_matrix(q, p), Jq.T).T  # M symmetric
    return Jq, scaled, bias


class HandOvers(NamedTuple):
    """What :meth:`BodyContactModel.switch_elements` did, contact indices.

    Attributes
    ----------
    stay, approach, leave : ndarray of int
        The moved slots that meet their new element tangentially (normal speed within the
        speed tolerance: still held), approach it (an impact) and leave it; ``leave`` also
        holds the edge contacts set free where their closest points reached an edge's end,
        the self-contact slots whose new element is in their particle's neighbourhood, and
        those met tangentially on a face over a convex edge whose plane has their own body
        on its inner side (the face they left had it outside).
    corners, sources : ndarray of int
        The free corner twins now on the elements that ``sources`` (those of the moved that
        passed a concave vertex or edge: all of ``approach``, and those of ``stay`` there)
        came from: the caller holds each as its source was (the impact or the force LCP
        decides whether they stay).
    relabelled : ndarray of int, shape (k, 2)
        Held slots and twins that exchanged rows (a 3D edge's twin that was to move): the
        caller exchanges their phases.
    """

    stay: IntArray
    approach: IntArray
    leave: IntArray
    corners: IntArray
    sources: IntArray
    relabelled: IntArray


class RowTerms(NamedTuple):
    """Constrained slots' rows, k of them: gap (k,), the row's coefficients on its points
    (k, 1 + dim; a particle's ``[1, -w_1, ...]``, an edge's ``[1 - s, s, -(1 - t), -t]``),
    times the unit normal (k, dim), gap rate (k,), the gap acceleration's velocity term
    (k,) and, 2D, the slip's (k,; None in 3D)."""

    gap: FloatArray
    coefficients: FloatArray
    normal: FloatArray
    rate: FloatArray
    bias: FloatArray
    slip_bias: FloatArray | None


class ElementTerms(NamedTuple):
    """A particle against an element, k contacts: gap (k,), weights (k, dim), outward normal
    (k, dim), gap rate (k,), the gap acceleration's velocity term (k,), and in 2D the slip
    rate along t = (-n_y, n_x) (k,) and its acceleration's velocity term (k,) (None in 3D:
    :meth:`ElementKernels.slip_bias` gives those, only where friction asks)."""

    gap: FloatArray
    weights: FloatArray
    normal: FloatArray
    rate: FloatArray
    bias: FloatArray
    slip: FloatArray | None
    slip_bias: FloatArray | None


class ElementKernels:
    """The generated segment (2D) or triangle (3D) kernels on k contacts at once: the compiled
    ones with the C backend (the triangle's velocity kernel is 2565 operations: NumPy spends
    ~1 ms a call on that many small arrays), else their NumPy twins.

    Call with ``points`` (the particle, then the element's vertices; each (k, dim)) and their
    velocities ``rates``; returns :class:`ElementTerms`.
    """

    def __init__(self, dim: int, backend: str) -> None:
        self.dim = dim
        self.name = "segment_2d" if dim == 2 else "triangle_3d"
        self.numpy = _kernels_module()
        self.c = None
        self.velocity_outputs = 5 if dim == 2 else 3  # 2D adds the slip rate and its velocity term
        if backend == "c":
            from .runtime import library

            lib = library()
            self.c = [getattr(lib, f"fb_kb_{self.name}"), getattr(lib, f"fb_kb_{self.name}_velocity")]
            self.c[0].argtypes = [ctypes.c_long] + [ctypes.c_void_p] * (dim + 1 + 4)
            self.c[1].argtypes = [ctypes.c_long] + [ctypes.c_void_p] * (2 * (dim + 1) + self.velocity_outputs)
            if dim == 3:
                self._slip_c = lib.fb_kb_triangle_3d_slip
                self._slip_c.argtypes = [ctypes.c_long] + [ctypes.c_void_p] * (2 * (dim + 1) + 3)
            self._grow(16)

    def _grow(self, k: int) -> None:
        """Buffers for ``k`` contacts, kept between calls with their addresses: a held row's
        event function calls the kernels with one or two contacts thousands of times, and
        each array's address costs microseconds to take."""
        d = self.dim
        # inputs: the points, then their rates; outputs in the kernel manifest's order: the
        # gap, s (2D) or the 3 barycentrics (3D), normal, Jacobian; rate, tangential, bias(, slip)
        self._inputs = np.empty((2 * (d + 1), k, d))
        widths = (1, 1 if d == 2 else 3, d, (d + 1) * d, 1, d, 1) + (1,) * (self.velocity_outputs - 3)
        self._outputs = [np.empty((k, n)) for n in widths]
        self._addresses = ([self._inputs[j].ctypes.data for j in range(2 * (d + 1))],
                           [z.ctypes.data for z in self._outputs])

    def __call__(self, x: FloatArray, v: FloatArray, points: IntArray) -> ElementTerms:
        """The terms of k contacts whose particle and element vertices are the rows ``points``
        (1 + dim, k) of the positions ``x`` and velocities ``v`` (n, dim)."""
        d, k = self.dim, points.shape[1]
        if self.c is not None:
            inputs, outputs = self._gathered(x, v, points)
            self.c[0](k, *inputs[: d + 1], *outputs[:4])
            self.c[1](k, *inputs, *outputs[4:])
            gap, weight, normal, _, rate, _, bias, *slip = (z[:k] for z in self._outputs)
            weights = self._as_weights(weight.copy())
            slip_terms = (slip[0][:, 0].copy(), slip[1][:, 0].copy()) if d == 2 else (None, None)
            return ElementTerms(gap[:, 0].copy(), weights, normal.copy(), rate[:, 0].copy(), bias[:, 0].copy(),
                                *slip_terms)
        at, rates = x[points], v[points]
        gap, weight, normal, _ = getattr(self.numpy, self.name)(*(z.T for z in at))
        rate, _, bias, *slip = getattr(self.numpy, f"{self.name}_velocity")(*(z.T for z in (*at, *rates)))
        weights = self._as_weights(weight.T)
        slip_terms = (slip[0][0], slip[1][0]) if d == 2 else (None, None)
        return ElementTerms(gap[0], weights, normal.T, rate[0], bias[0], *slip_terms)

    def gaps(self, x: FloatArray, points: IntArray) -> FloatArray:
        """The gaps (k,) alone of :meth:`__call__`'s contacts: the position kernel only (the
        held rows' drift is asked at every step, their velocities need not be gathered)."""
        return self._positions(x, points)[0]

    def weights(self, x: FloatArray, points: IntArray) -> FloatArray:
        """The weights (k, dim) alone of :meth:`__call__`'s contacts (the particle's closest
        point on the element's line or plane): the position kernel only (a held row's
        event function asks where its particle is on its element, not how fast)."""
        return self._as_weights(self._positions(x, points)[1])

    def _as_weights(self, weight: FloatArray) -> FloatArray:
        """The kernel's s (k, 1; 2D) or barycentrics (k, 3; 3D) as the weights (k, dim) of the
        element's vertices: 2D (1 - s, s)."""
        return np.column_stack([1.0 - weight[:, 0], weight[:, 0]]) if self.dim == 2 else weight

    def _positions(self, x: FloatArray, points: IntArray) -> tuple[FloatArray, FloatArray]:
        """The position kernel's gap (k,) and s (k, 1; 2D) or barycentrics (k, 3; 3D) of
        :meth:`__call__`'s contacts, copies."""
        if self.c is not None:
            k = points.shape[1]
            inputs, outputs = self._gathered(x, None, points)
            self.c[0](k, *inputs[: self.dim + 1], *outputs[:4])
            return self._outputs[0][:k, 0].copy(), self._outputs[1][:k].copy()
        gap, weight, _, _ = getattr(self.numpy, self.name)(*(z.T for z in x[points]))
        return gap[0], weight.T

    def _gathered(self, x: FloatArray, v: FloatArray | None, points: IntArray) -> tuple[list[int], list[int]]:
        """Rows ``points`` (1 + dim, k) of ``x`` (and ``v`` if given) copied into the input
        buffers, one gather each, not one per vertex; the inputs' and outputs' addresses."""
        d, k = self.dim, points.shape[1]
        if k > self._inputs.shape[1]:
            self._grow(max(k, 2 * self._inputs.shape[1]))
        self._inputs[: d + 1, :k] = x[points]
        if v is not None:
            self._inputs[d + 1 :, :k] = v[points]
        # each buffer's first k rows are contiguous: the addresses stand for any k up to its size
        return self._addresses

    def slip_terms(self, x: FloatArray, v: FloatArray, points: IntArray) -> tuple[FloatArray, FloatArray]:
        """3D: the velocity terms (k, 2) of the slip rates' accelerations along the
        triangle's t1 = (b - a) / |b - a| and t2 = n x t1, and those tangents (k, 2, 3) (the
        ``triangle_3d_slip`` kernel; only friction asks for them), of :meth:`__call__`'s
        contacts (rows ``points`` (1 + dim, k) of ``x`` and ``v``)."""
        k, columns = points.shape[1], [*x[points], *v[points]]
        if self.c is not None:
            _, bias, tangents = runtime.batched_call(self._slip_c, columns, [(2,), (2,), (2, 3)])
            return bias, tangents
        _, bias, tangents = self.numpy.triangle_3d_slip(*(z.T for z in columns))
        return bias.T, tangents.T.reshape(k, 2, 3)


def _kept(store: dict, key, make, size: int):
    """``store[key]``, made by ``make()`` if missing; ``store`` keeps the last ``size`` made
    (the oldest goes first)."""
    if key not in store:
        if len(store) == size:
            del store[next(iter(store))]
        store[key] = make()
    return store[key]


def _kept_at(store: list, state: tuple[np.ndarray, ...], make, size: int):
    """As :func:`_kept` for answers that depend on the arrays ``state`` alone (positions
    (n, dim), the edges held), ``store`` a list of (fingerprint, state, answer), newest
    last: the arrays are compared bit for bit, as their bytes, not hashed (hashing every
    coordinate's bytes cost more than the comparison), and only where a few of their items
    already agree (:func:`_fingerprint`; a pile asks ~25 000 times, half of them misses
    that a whole comparison with each of the kept states made ~3 % of its run)."""
    state = tuple(np.ascontiguousarray(a) for a in state)
    key = _fingerprint(state)
    for known, at, answer in reversed(store):  # the newest first: most asks are for a state just swept
        if known == key and all(runtime.same_bits(a, b) for a, b in zip(at, state)):
            return answer
    if len(store) == size:
        del store[0]
    store.append((key, tuple(a.copy() for a in state), make()))
    return store[-1][2]


def _fingerprint(state: tuple[np.ndarray, ...]) -> tuple:
    """The dtypes and shapes of the arrays ``state`` (8-byte items, C-contiguous) and the
    bits of their first, middle and last items: equal for equal states, and for two states
    of a run nearly always different (they differ in nearly every coordinate)."""
    key = []
    for a in state:
        bits = a.reshape(-1).view(np.int64)
        key += [a.dtype.str, a.shape, *(bits[[0, len(bits) // 2, -1]].tolist() if len(bits) else ())]
    return tuple(key)


def _read_only(answer):
    """``answer`` (arrays in tuples and dataclasses, nested) with every array made
    read-only, in place: a kept answer handed out again must not be changed by whoever got
    it first."""
    if isinstance(answer, np.ndarray):
        answer.flags.writeable = False
    elif isinstance(answer, tuple):
        for part in answer:
            _read_only(part)
    elif dataclasses.is_dataclass(answer):
        for field in dataclasses.fields(answer):
            _read_only(getattr(answer, field.name))
    return answer


def _spread(rows: FloatArray) -> float:
    """The largest difference between two rows of ``rows`` (n, dim) at most (m or m/s): the
    length of their bounding box's diagonal (0 for none)."""
    # column by column: NumPy reduces an (n, 2) array along its long axis ~18 times slower
    # (170 us against 10 us for a pile's 3 980 particles, twice a step)
    return float(np.linalg.norm([column.max() - column.min() for column in rows.T])) if len(rows) else 0.0


def _unit_rows(a: FloatArray) -> FloatArray:
    """Each row of ``a`` (k, m) scaled to length 1; zero rows stay 0 (in 1D: its sign)."""
    norm = np.linalg.norm(a, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(norm[:, None] > 0.0, a / norm[:, None], 0.0)


def _gram(A: FloatArray, B: FloatArray) -> FloatArray:
    """``A @ B.T``, shape (m, m), of contact rows ``A, B`` (m, c): through sparse matrices when
    there are many and they are wide (:data:`SPARSE_ROWS`), since each row moves a few
    particles (O(m c) work to convert, not O(m^2 c) to multiply densely)."""
    if A.shape[0] < SPARSE_ROWS or A.shape[1] <= SPARSE_WIDTH:
        return A @ B.T
    from scipy.sparse import csr_matrix

    return (csr_matrix(A) @ csr_matrix(B).T).toarray()


def _least_squares(A: FloatArray, b: FloatArray) -> FloatArray:
    """The least-norm ``x`` with ``A x = b`` (k, k), rows below :data:`DEPENDENT` dropped."""
    try:
        return least_squares(A, b, rcond=DEPENDENT)
    except np.linalg.LinAlgError as exc:  # the driver reports a blow-up
        raise FloatingPointError(f"the held contacts' forces: {exc}") from None


def _touched_vertex(contact: SurfaceContact) -> tuple[IntArray, np.ndarray]:
    """Each closest point's vertex of largest weight (k,), and whether the point is at it
    (a face's or an edge's closest point can be its vertex), bool (k,)."""
    rows = np.arange(len(contact.particle))
    corner = np.argmax(contact.weights, axis=1)
    return contact.feature[rows, corner], contact.weights[rows, corner] >= 1.0 - AT_VERTEX


def _crossing_depth(x: FloatArray, a: IntArray, b: IntArray) -> FloatArray:
    """How deep 2D segments ``a`` and ``b`` (k, 2 particles each; crossing) cross, shape (k,):
    the nearest of their four ends to the other's line (m)."""
    def to_line(ends, line):
        t = x[line[:, 1]] - x[line[:, 0]]
        normal = np.column_stack([t[:, 1], -t[:, 0]]) / np.linalg.norm(t, axis=1, keepdims=True)
        return np.abs(np.einsum("kjd,kd->kj", x[ends] - x[line[:, 0]][:, None], normal)).min(axis=1)

    return np.minimum(to_line(b, a), to_line(a, b))


def _an_element_of(segments: IntArray, elements: IntArray) -> IntArray:
    """For each edge ``segments (e, 2)`` (sorted pairs) of triangles ``elements (m, 3)``, the
    index of one triangle it borders, shape (e,)."""
    pairs = np.concatenate([np.sort(elements[:, [i, j]], axis=1) for i, j in ((0, 1), (1, 2), (2, 0))])
    owner = np.tile(np.arange(len(elements)), 3)
    base = int(elements.max(initial=0)) + 1  # a pair (a, b) as the one number a * base + b
    key = pairs[:, 0] * base + pairs[:, 1]
    order = np.argsort(key, kind="stable")
    wanted = segments[:, 0] * base + segments[:, 1]
    return owner[order][np.searchsorted(key[order], wanted)]


def _neighbours(elements: IntArray) -> IntArray:
    """``out[e, k]``: the element sharing element e's facet opposite its vertex k (2D: the
    segment beyond vertex 1 - k; 3D: the triangle across the edge opposite vertex k)."""
    m, d = elements.shape
    facets: dict[tuple[int, ...], list[int]] = {}
    for e, vertices in enumerate(elements.tolist()):
        for k in range(d):
            facets.setdefault(tuple(sorted(vertices[:k] + vertices[k + 1 :])), []).append(e)
    out = np.full((m, d), -1, np.intp)
    for e, vertices in enumerate(elements.tolist()):
        for k in range(d):
            sharing = [f for f in facets[tuple(sorted(vertices[:k] + vertices[k + 1 :]))] if f != e]
            out[e, k] = sharing[0] if sharing else e
    return out
