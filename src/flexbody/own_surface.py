"""Self-contact: which of its own body's elements a surface particle may touch.

A particle of a body's surface lies on its own elements, and its signed distance to its
own surface is 0 there and says nothing about a contact.  So a body with
``self_contact = true`` watches each of its surface particles against its own elements
except a *neighbourhood*: the elements with a vertex it reaches through the body's
links within ``NEIGHBOURHOOD`` times the larger of the contact margin and the body's
median element size (shortest paths along the links' rest lengths: its own elements, their
neighbours, and the far side of a body thinner than that; two parts of a body that no
links join are never each other's neighbourhood).  What is left can be reached from outside only where the body has
bent far: two parts of its outer surface meeting (a dent closing, a bent strip's ends).
Such a contact is one between two bodies, with the same gaps, events, LCPs and friction
(:mod:`flexbody.body_contact`).

Two closest features of the rest read otherwise:

* one on the rim of the neighbourhood (a vertex one of whose elements is in it, or a 3D
  edge one of whose two triangles is) reads ``margin``, as a surface farther than anything
  that can happen in a step: its gap's sign comes from a pseudo-normal that leans over the
  left-out elements, so it does not say on which side of the rest the particle is;
* one the particle lies more than ``INSIDE`` margins behind is inside its own body, under
  its far surface (a body pressed through its thickness), not at a contact.  Its gap is
  reflected there, ``-2 INSIDE margin - gap``: continuous, negative only within
  ``2 INSIDE`` margins behind the surface, and positive deeper.  So a particle that comes
  at its own surface from inside (a hollow ring crushed flat: its inside is not material,
  but the surface's orientation says it is) makes its gap cross 0 at ``2 INSIDE`` margins
  deep, an event located as any other, which :meth:`OwnSurface.inside` recognises:
  the run stops there (``unsupported``) instead of resolving a contact that is not one.
  (Without the reflection its gap would jump from ``margin`` to that depth where it comes
  within reach, and an event on a jump is located on either side of it by rounding.)
"""

from __future__ import annotations

import numpy as np

from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from .broadphase import slices
from .constants import FACE

FloatArray = np.ndarray
IntArray = np.ndarray

#: A particle's neighbourhood on its own surface reaches this many times the larger of the
#: contact margin and its body's median element size (a box test at the start: see the docstring).
NEIGHBOURHOOD = 2.0
#: A particle more than this many margins behind its own surface is inside its body, not at
#: a contact: its gap is reflected there (see the module docstring).  Below 1/2, so that the
#: reflected gap's 0, at twice this depth, lies within the broad phase's reach (``margin``).
INSIDE = 0.25
#: Surface particles whose neighbourhoods are searched at once (a dense (CHUNK, n) table of distances).
CHUNK = 256


class OwnSurface:
    """The self-contact neighbourhoods of the bodies that may touch themselves.

    Parameters
    ----------
    scene : Scene
        Its bodies' links and rest lengths give the distances through the material.
    elements : ndarray of int, shape (m, dim)
        Every body's surface elements, global particle indices.
    element_body, particle_body : ndarray of int, shape (m,) and (n,)
    bodies : sequence of int
        The bodies with self-contact.
    margin : float
        The contact margin (m): a gap farther than it reads ``margin``.
    incident_start, incident : ndarray of int
        Each particle's elements, CSR (:func:`flexbody.surface_contact.vertex_elements`).
    """

    def __init__(self, scene, elements: IntArray, element_body: IntArray, particle_body: IntArray,
                 bodies, margin: float, incident_start: IntArray, incident: IntArray) -> None:
        self.n_elements = len(elements)
        self.element_body, self.particle_body = element_body, particle_body
        self.margin = margin
        self._elements = elements
        self._start, self._incident = incident_start, incident
        first = np.r_[0, np.cumsum([b.n_particles for b in scene.bodies])]
        keys = [np.zeros(0, np.int64)]
        for body in sorted(bodies):
            own = np.flatnonzero(element_body == body)
            mine = elements[own] - first[body]
            keys += _neighbourhoods(scene.bodies[body], mine, margin, own, first[body], self.n_elements)
        #: (particle, element) pairs left out, as ``particle * m + element``, sorted.
        self.excluded = np.unique(np.concatenate(keys))

    def left_out(self, particles: IntArray, elements: IntArray) -> np.ndarray:
        """Whether each (particle, element) pair is in the particle's neighbourhood, bool (k,)."""
        keys = np.asarray(particles, np.int64) * self.n_elements + np.asarray(elements, np.int64)
        at = np.minimum(np.searchsorted(self.excluded, keys), max(len(self.excluded) - 1, 0))
        return self.excluded[at] == keys if len(self.excluded) else np.zeros(len(keys), bool)

    def near(self, vertices: IntArray, elements: IntArray) -> np.ndarray:
        """Whether any of each row of surface ``vertices`` (k, a) has the element (k,) in its
        neighbourhood, bool (k,): two crossing elements of a body so near each other are a
        fold of its surface (its lattice collapsed there, or a concave corner closed), farther ones two
        parts touching or a contact missed."""
        if not len(elements):
            return np.zeros(0, bool)
        vertices = np.asarray(vertices).reshape(len(elements), -1)
        return np.column_stack([self.left_out(v, elements) for v in vertices.T]).any(axis=1)

    def touchable(self, pairs: IntArray) -> np.ndarray:
        """Of candidate (particle, element) pairs (k, 2), those not in a neighbourhood, bool (k,)."""
        out = np.ones(len(pairs), bool)
        own = self.particle_body[pairs[:, 0]] == self.element_body[pairs[:, 1]]
        if own.any():
            out[own] = ~self.left_out(pairs[own, 0], pairs[own, 1])
        return out

    def read(self, contact) -> tuple[np.ndarray, FloatArray]:
        """The rows of a :class:`flexbody.surface_contact.SurfaceContact` (k) that give a gap,
        bool (k,), and their gaps, shape (k,): a particle's own features on the rim of its
        neighbourhood give none, and those it lies more than ``INSIDE`` margins behind are
        reflected (see the module docstring)."""
        keep, gap = np.ones(len(contact.particle), bool), contact.gap
        own = np.flatnonzero(self.particle_body[contact.particle] == self.element_body[contact.element])
        if not len(own):
            return keep, gap
        deep = own[gap[own] < -INSIDE * self.margin]
        if len(deep):
            gap = gap.copy()
            gap[deep] = -2.0 * INSIDE * self.margin - gap[deep]
        rim = own[contact.kind[own] != FACE]
        if len(rim):
            first = contact.feature[rim, 0]  # a vertex, or an edge's lower end
            start, stop = self._start[first], self._start[first + 1]
            owner = np.repeat(np.arange(len(rim)), stop - start)
            around = self._incident[slices(start, stop)]
            second = contact.feature[rim, 1][owner]  # an edge's other end (-1 after a vertex)
            # a vertex: every element at it; an edge: the two triangles that have both its ends
            sides = (second < 0) | (self._elements[around] == second[:, None]).any(axis=1)
            hit = sides & self.left_out(contact.particle[rim][owner], around)
            keep[rim[np.unique(owner[hit])]] = False
        return keep, gap

    def inside(self, contact) -> np.ndarray:
        """Which rows of a :class:`flexbody.surface_contact.SurfaceContact` (its gaps as
        measured, not read) put a particle more than ``INSIDE`` margins behind its own
        surface, bool (k,): at an instant, a contact that is not one (the module docstring)."""
        own = self.particle_body[contact.particle] == self.element_body[contact.element]
        return own & (contact.gap < -INSIDE * self.margin)


def _neighbourhoods(body, mine: IntArray, margin: float, own: IntArray, first: int, m: int) -> list[IntArray]:
    """Each surface particle's neighbourhood on its own surface ``mine`` (k, dim; indices
    within the body, global numbers ``own`` (k,)): the elements with a vertex within reach
    through the body's links (shortest paths along their rest lengths), as keys
    ``particle * m + element`` (global numbering; the body's particles start at ``first``)."""
    n = body.n_particles
    links = np.asarray(body.links, np.intp).reshape(-1, 2)
    # a link of rest length 0 is a path of length 0, not a missing edge (csgraph drops zeros)
    lengths = np.maximum(np.asarray(body.rest_lengths, float), np.finfo(float).tiny)
    graph = csr_matrix((lengths, (links[:, 0], links[:, 1])), shape=(n, n))
    x0 = body.initial_positions()
    size = float(np.median(np.linalg.norm(x0[mine[:, 1]] - x0[mine[:, 0]], axis=1)))
    reach = NEIGHBOURHOOD * max(margin, size) * (1.0 + 1e-9)  # a regular lattice's paths of exactly that count
    particles = np.unique(mine)
    out = []
    for chunk in np.array_split(particles, max(1, len(particles) // CHUNK)):
        near = dijkstra(graph, directed=False, indices=chunk, limit=reach) <= reach  # (k, n)
        row, element = np.nonzero(near[:, mine].any(axis=2))
        out.append((first + chunk[row]) * m + own[element])
    return out
