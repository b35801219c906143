"""Contacts between bodies: a particle of one body against the surface of another.

:class:`BodyContactModel` adds to the assembled particles formulation one contact *slot*
per (particle, other body) pair that may touch (the scene's ``[[contacts]]``, ``collide``):
every vertex of the first body's surface against the second body's surface, and the other
way round.  The slots come after the ground contacts, so the phase machine
(:mod:`flexbody.contact`, :mod:`flexbody.events`) runs them as it runs the grounds':

* **Free** slot: its gap is the particle's signed distance to the other body's surface
  (:func:`flexbody.surface_contact.closest_features`, over the candidates of the broad
  phase :class:`flexbody.broadphase.CandidateList`), continuous as the closest point moves
  from one segment or triangle to the next, so onset is an exact event on the dense output.
* **At an instant** a touching slot is constrained on one surface *element*: the one its
  closest point lies on, or, at a vertex or edge, the neighbouring element whose normal is
  closest to the feature's normal (ties: the lowest-numbered).  Its gap is that element's
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

Ground contacts that share no particle with a held slot keep the per-particle closed form
of the assembled model (its C or NumPy right-hand side); only the coupled ones are solved
here, densely (the held slots of a scene are few).  Segments integrate with SciPy's
explicit or implicit steppers (the compiled loop knows only ground contacts); an implicit
stepper gets the assembled model's Jacobian without the body contacts' coupling, which
slows its Newton iterations, not its answer.
"""

from __future__ import annotations

import hashlib

import numpy as np
import scipy.sparse

from .assembly import AssembledModel, _kernels_module
from .broadphase import CandidateList
from .dynamics import contact_solve
from .model import Model
from .scene import Scene
from .surface_contact import FACE, closest_features, segment_normals, triangle_normals

FloatArray = np.ndarray
IntArray = np.ndarray


class BodyContactModel(Model):
    """The assembled particles formulation with contacts between bodies.

    Parameters
    ----------
    scene : Scene
        With ``scene.contacts`` between flexible bodies (no self-contact).
    inner : AssembledModel
        The scene's assembled model (ground contacts), C or NumPy.

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
    formulation = "particles"

    def __init__(self, scene: Scene, inner: AssembledModel) -> None:
        self.inner = inner
        self.backend, self.dim = inner.backend, inner.dim
        self.nq, self.nu, self.ny, self.n_particles = inner.nq, inner.nu, inner.ny, inner.n_particles
        self.masses, self.laws, self.n_grounds = inner.masses, inner.laws, inner.n_grounds
        self.n_ground_contacts = inner.n_contacts
        self.elements, self.element_body = scene.surfaces()
        counts = [b.n_particles for b in scene.bodies]
        self.particle_body = np.repeat(np.arange(len(counts)), counts)
        particles, bodies, pairs = [], [], []
        allowed = np.zeros((len(counts), len(counts)), bool)
        for k, pair in enumerate(scene.contacts):
            first, second = pair.bodies
            allowed[first, second] = allowed[second, first] = True
            for toucher, surface in ((first, second), (second, first)):
                touching = np.unique(self.elements[self.element_body == toucher])
                particles.append(touching)
                bodies.append(np.full(len(touching), surface))
                pairs.append(np.full(len(touching), k))
        self.slot_particle = np.concatenate(particles).astype(np.intp)
        self.slot_body = np.concatenate(bodies).astype(np.intp)
        self.slot_pair = np.concatenate(pairs).astype(np.intp)
        self.allowed = allowed
        self.n_slots = len(self.slot_particle)
        self.n_contacts = self.n_ground_contacts + self.n_slots
        self.contacts = np.vstack([inner.contacts, np.column_stack([self.slot_particle,
                                                                    self.n_grounds + self.slot_body])])
        self._key = self.slot_particle * len(counts) + self.slot_body
        self._order = np.argsort(self._key)
        self._body_count = len(counts)
        self._incident = _incidence(self.elements, self.n_particles)
        self._neighbour = _neighbours(self.elements)
        x0 = scene.initial_positions()
        lengths = np.linalg.norm(x0[self.elements[:, 1]] - x0[self.elements[:, 0]], axis=1)
        # Within `margin` of a surface the broad phase finds the closest element, so the
        # gap is exact; farther, a slot reads `margin` (positive: nothing can happen there).
        self.margin = float(np.median(lengths))
        self._candidates = CandidateList(self.elements, self.particle_body, self.margin, self.margin,
                                         element_body=self.element_body)
        self.element_of = np.full(self.n_slots, -1, np.intp)  # each slot's element while constrained
        self._kernels = _kernels_module()
        self._tag = "segment_2d" if self.dim == 2 else "triangle_3d"
        text = f"{inner.digest}|{self.slot_particle.tolist()}|{self.slot_body.tolist()}"
        self.digest = hashlib.sha256(f"bodies|{text}".encode()).hexdigest()[:16]

    # ------------------------------------------------------------------ the model interface
    def parameters(self, scene: Scene) -> FloatArray:
        return self.inner.parameters(scene)

    def slip_directions(self, p) -> FloatArray:
        return np.zeros((self.n_contacts, self.dim))

    def tangential_pushes(self, p) -> FloatArray:
        return np.zeros((self.n_contacts, self.dim))

    def gaps(self, q, p) -> FloatArray:
        x = np.asarray(q, float)[: self.nq].reshape(-1, self.dim)
        return np.concatenate([self.inner.gaps(q, p), self._surface_gaps(x)[0]])

    def energies(self, q, u, p) -> FloatArray:
        """Kinetic energy (J), shape (1,): what :func:`flexbody.coupled.coupled_impact` needs."""
        v = np.asarray(u, float).reshape(-1, self.dim)
        return np.array([0.5 * float(np.sum(self.masses * np.sum(v * v, axis=1)))])

    def rhs(self, y, p, held, push):
        y = np.asarray(y, float)
        held, push = np.asarray(held, np.intc), np.asarray(push, float)
        ng = self.n_ground_contacts
        held_slots = np.flatnonzero(held[ng:] != 0)
        lam = np.zeros(self.n_contacts)
        if not len(held_slots):
            ydot, lam[:ng] = self.inner.rhs(y, p, held[:ng], push[:ng])
            return ydot, lam
        x, v = self._split(y)
        self._constrain_elements(held_slots, x)
        # Ground contacts of the particles these slots move couple with them: solved here.
        moved = np.zeros(self.n_particles, bool)
        moved[self.slot_particle[held_slots]] = True
        moved[self.elements[self.element_of[held_slots]].ravel()] = True
        ground_rows = np.flatnonzero((held[:ng] != 0) & moved[self.inner.contacts[:, 0]])
        fast = held[:ng].copy()
        fast[ground_rows] = 0
        ydot, lam[:ng] = self.inner.rhs(y, p, fast, push[:ng])
        acc = ydot[self.nq : 2 * self.nq]
        J, bias = self._rows(ground_rows, held_slots, x, v, p)
        scaled = J.multiply(np.repeat(1.0 / self.masses, self.dim)[None, :]).tocsr()
        W = (scaled @ J.T).toarray()
        force = contact_solve(W, -(J @ acc + bias))
        acc += scaled.T @ force
        rows = np.concatenate([ground_rows, ng + held_slots])
        lam[rows] = force
        return ydot, lam

    def contact_state(self, y, p, held, push):
        y = np.asarray(y, float)
        x, v = self._split(y)
        ng = self.n_ground_contacts
        gaps_g, vn_g, _ = self.inner.contact_state(y, p, np.zeros(ng, np.intc), np.zeros(ng))
        gaps_s, near = self._surface_gaps(x)
        vn_s = np.zeros(self.n_slots)
        held = np.asarray(held)
        rated = np.flatnonzero(near | (held[ng:] != 0))
        if len(rated):
            self._constrain_elements(rated, x)
            vn_s[rated] = self._element_terms(rated, x, v)[3]
        return np.concatenate([gaps_g, gaps_s]), np.concatenate([vn_g, vn_s]), self.rhs(y, p, held, push)[1]

    def contact_coupling(self, q, u, p, rows: IntArray):
        """The contact rows ``rows`` (contact indices) as :mod:`flexbody.coupled` needs them.

        Returns
        -------
        J : scipy.sparse.csr_matrix, shape (k, nu)
        W : ndarray, shape (k, k)
            ``J M^-1 J^T`` (M diagonal: the particle masses).
        response : callable
            ``P (k,) -> M^-1 J^T P``, shape (nu,).
        bias : ndarray, shape (k,)
            The gap accelerations' velocity terms.
        """
        x = np.asarray(q, float)[: self.nq].reshape(-1, self.dim)
        v = np.asarray(u, float)[: self.nu].reshape(-1, self.dim)
        rows = np.asarray(rows)
        ng = self.n_ground_contacts
        slots = rows[rows >= ng] - ng
        self._constrain_elements(slots, x)
        J, bias = self._rows(rows[rows < ng], slots, x, v, p)
        scaled = J.multiply(np.repeat(1.0 / self.masses, self.dim)[None, :]).tocsr()
        return J, (scaled @ J.T).toarray(), lambda P: scaled.T @ np.asarray(P, float), bias

    def impact(self, y, p, stop):  # pragma: no cover - coupled models resolve with flexbody.coupled
        raise NotImplementedError("contacts between bodies couple: flexbody.coupled.coupled_impact resolves them")

    def trajectory(self, Y, p, held, push):
        ng = self.n_ground_contacts
        X, V, E, lam_g = self.inner.trajectory(Y, p, np.asarray(held)[:, :ng], np.asarray(push)[:, :ng])
        lam = np.zeros((len(Y), self.n_contacts))
        lam[:, :ng] = lam_g
        for k in np.flatnonzero(np.any(np.asarray(held)[:, ng:], axis=1)):
            lam[k] = self.rhs(Y[k], p, held[k], push[k])[1]
        return X, V, E, lam

    def jacobian_function(self, p, held):
        return self.inner.jacobian_function(p, np.asarray(held)[: self.n_ground_contacts])

    # ------------------------------------------------------------------ for the phase machine
    def particle_forces(self, lam: FloatArray) -> FloatArray:
        """Normal contact force on each particle (N), shape (nt, n), from the contact forces
        ``lam (nt, nc)``: its grounds' and those of the slots it is the particle of (the
        reactions on the other body's element vertices are not counted there)."""
        lam = np.atleast_2d(lam)
        ng, n = self.n_ground_contacts, self.n_particles
        out = lam[:, :ng].reshape(len(lam), n, -1).sum(axis=2) if self.n_grounds else np.zeros((len(lam), n))
        np.add.at(out.T, self.slot_particle, lam[:, ng:].T)
        return out

    def forget_free(self, free: np.ndarray) -> None:
        """Let free slots pick their element afresh at their next instant (``free`` (nc,) bool)."""
        self.element_of[np.asarray(free)[self.n_ground_contacts :]] = -1

    def element_margins(self, y, p, held) -> FloatArray:
        """How far each held slot's particle projects inside its element (m), shape (nc,):
        its smallest weight times the element's size; ``inf`` for the other contacts.  It
        reaches 0 where the particle passes onto a neighbour (an event)."""
        out = np.full(self.n_contacts, np.inf)
        ng = self.n_ground_contacts
        slots = np.flatnonzero(np.asarray(held)[ng:] != 0)
        if len(slots):
            x, v = self._split(np.asarray(y, float))
            self._constrain_elements(slots, x)
            weights = self._element_terms(slots, x, v)[1]
            out[ng + slots] = weights.min(axis=1) * self._sizes(slots, x)
        return out

    def switch_elements(self, y, p, held: np.ndarray, gap_tolerance: float, speed_tolerance: float
                        ) -> tuple[IntArray, IntArray, IntArray]:
        """Move each held slot whose projection left its element onto the neighbour across
        that boundary.

        Returns
        -------
        stay, approach, leave : ndarray of int
            Contact indices of those slots that meet their new element tangentially (normal
            speed within ``speed_tolerance``: still held), approach it (an impact) and leave it.
        """
        ng = self.n_ground_contacts
        slots = np.flatnonzero(np.asarray(held)[ng:] != 0)
        empty = np.zeros(0, np.intp)
        if not len(slots):
            return empty, empty, empty
        x, v = self._split(np.asarray(y, float))
        weights = self._element_terms(slots, x, v)[1]
        out = slots[weights.min(axis=1) * self._sizes(slots, x) <= gap_tolerance]
        if not len(out):
            return empty, empty, empty
        corner = np.argmin(self._element_terms(out, x, v)[1], axis=1)
        self.element_of[out] = self._neighbour[self.element_of[out], corner]
        rate = self._element_terms(out, x, v)[3]
        return ng + out[np.abs(rate) <= speed_tolerance], ng + out[rate < -speed_tolerance], \
            ng + out[rate > speed_tolerance]

    # ------------------------------------------------------------------ geometry
    def _split(self, y):
        return y[: self.nq].reshape(-1, self.dim), y[self.nq : 2 * self.nq].reshape(-1, self.dim)

    def _sizes(self, slots, x) -> FloatArray:
        e = self.elements[self.element_of[slots]]
        return np.linalg.norm(x[e[:, 1]] - x[e[:, 0]], axis=1)

    def _surface_gaps(self, x) -> tuple[FloatArray, np.ndarray]:
        """Each slot's signed distance to its body's surface (``margin`` where it is farther
        than that), and whether it is within ``margin``, shape (ns,) each."""
        gaps = np.full(self.n_slots, self.margin)
        near = np.zeros(self.n_slots, bool)
        contact = self._closest(x)
        if contact is not None:
            slots, found = self._slots_of(contact.particle, self.element_body[contact.element])
            # Farther than `margin` the nearest candidate need not be the nearest element, and
            # its side (the gap's sign) says nothing: such a slot reads `margin`, as one without any.
            found &= np.abs(contact.gap) <= self.margin
            gaps[slots[found]] = contact.gap[found]
            near[slots[found]] = True
        return gaps, near

    def _closest(self, x):
        pairs = self._candidates.pairs(x)
        keep = self.allowed[self.particle_body[pairs[:, 0]], self.element_body[pairs[:, 1]]]
        pairs = pairs[keep]
        if not len(pairs):
            return None
        return closest_features(x, x, self.elements, pairs, self.element_body)

    def _slots_of(self, particle, body) -> tuple[IntArray, np.ndarray]:
        key = np.asarray(particle) * self._body_count + np.asarray(body)
        at = np.minimum(np.searchsorted(self._key[self._order], key), self.n_slots - 1)
        return self._order[at], self._key[self._order][at] == key

    def _constrain_elements(self, slots, x) -> None:
        """Pick an element for each of ``slots`` that has none (see the module docstring)."""
        missing = np.asarray(slots)[self.element_of[slots] < 0]
        if not len(missing):
            return
        contact = closest_features(x, x, self.elements, self._pairs_with_body(missing), self.element_body)
        slot_rows, found = self._slots_of(contact.particle, self.element_body[contact.element])
        row_of = dict(zip(slot_rows[found].tolist(), np.flatnonzero(found).tolist()))
        normals = (segment_normals if self.dim == 2 else triangle_normals)(x, self.elements)
        for slot in missing.tolist():
            r = row_of[slot]
            if contact.kind[r] == FACE:
                self.element_of[slot] = contact.element[r]
                continue
            feature = contact.feature[r][contact.feature[r] >= 0]
            around = self._incident[feature[0]]
            for other in feature[1:]:
                around = np.intersect1d(around, self._incident[other])
            around = around[self.element_body[around] == self.slot_body[slot]]
            self.element_of[slot] = around[np.argmax(normals[around] @ contact.normal[r])]

    def _pairs_with_body(self, slots) -> IntArray:
        """Every (particle, element) pair of these slots with their bodies' whole surfaces."""
        rows = [np.column_stack([np.full(k.size, self.slot_particle[s]), k])
                for s in slots for k in [np.flatnonzero(self.element_body == self.slot_body[s])]]
        return np.vstack(rows)

    def _element_terms(self, slots, x, v):
        """Gap (k,), weights (k, dim), normal (k, dim), gap rate (k,) and velocity term (k,) of
        each slot's particle against its element."""
        e = self.elements[self.element_of[slots]]
        points = [x[self.slot_particle[slots]].T] + [x[e[:, k]].T for k in range(self.dim)]
        rates = [v[self.slot_particle[slots]].T] + [v[e[:, k]].T for k in range(self.dim)]
        gap, projection, normal, _ = getattr(self._kernels, self._tag)(*points)
        rate, _, bias = getattr(self._kernels, f"{self._tag}_velocity")(*points, *rates)
        if self.dim == 2:
            weights = np.column_stack([1.0 - projection[0], projection[0]])
        else:
            weights = projection.T
        return gap[0], weights, normal.T, rate[0], bias[0]

    def _rows(self, ground_rows, slots, x, v, p) -> tuple[scipy.sparse.csr_matrix, FloatArray]:
        """Constraint rows (ground rows, then slots) as a sparse (k, nu) Jacobian, and their
        velocity terms (k,): 0 for a flat ground."""
        d = self.dim
        grounds = np.asarray(p, float)[-self.n_grounds * 2 * d :].reshape(self.n_grounds, 2, d) \
            if self.n_grounds else np.zeros((0, 2, d))
        particle, ground = self.inner.contacts[ground_rows, 0], self.inner.contacts[ground_rows, 1]
        cols = [(particle[:, None] * d + np.arange(d))]
        vals = [grounds[ground, 1, :]]
        bias = np.zeros(0)
        if len(slots):
            _, weights, normal, _, bias = self._element_terms(slots, x, v)
            points = np.column_stack([self.slot_particle[slots], self.elements[self.element_of[slots]]])
            scale = np.column_stack([np.ones(len(slots)), -weights])
            cols.append((points[:, :, None] * d + np.arange(d)).reshape(len(slots), -1))
            vals.append((scale[:, :, None] * normal[:, None, :]).reshape(len(slots), -1))
        k_g = len(ground_rows)
        rows = np.concatenate([np.repeat(np.arange(k_g), d), np.repeat(k_g + np.arange(len(slots)), (1 + d) * d)])
        J = scipy.sparse.csr_matrix((np.concatenate([a.ravel() for a in vals]),
                                     (rows, np.concatenate([c.ravel() for c in cols]))),
                                    shape=(k_g + len(slots), self.nu))
        return J, np.concatenate([np.zeros(k_g), bias])


def _incidence(elements: IntArray, n: int) -> list[IntArray]:
    """The elements each particle is a vertex of, ascending."""
    out: list[list[int]] = [[] for _ in range(n)]
    for e, vertices in enumerate(elements.tolist()):
        for i in vertices:
            out[i].append(e)
    return [np.array(sorted(set(x)), np.intp) for x in out]


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


def body_contact_model(scene: Scene, inner: AssembledModel) -> BodyContactModel:
    """The model of a scene whose bodies may touch each other (see :class:`BodyContactModel`)."""
    return BodyContactModel(scene, inner)
