"""Which feature of another body's surface a particle touches, and its signed gap (NumPy).

The generated kernels ``segment_2d`` and ``triangle_3d`` (:mod:`derivation.elements`) give
the gap of a particle to an element's line or plane; that is its gap to the *surface*
only while the projection falls inside the element (``0 <= s <= 1``, barycentrics
``>= 0``).  Outside, the closest point of the surface is on an edge (3D) or a vertex, and
the contact belongs there: a particle sliding off a segment's end goes around the shared
vertex (gap ``|x - v|``) and onto the next segment, with a continuous gap, never lost
between two elements.

Surfaces are closed and oriented as in the kernels: a 2D boundary runs counter-clockwise
(segments ``(a, b)``), a 3D surface's triangles ``(a, b, c)`` run counter-clockwise seen
from outside.  The sign of an edge's or a vertex's gap comes from its angle-weighted
pseudo-normal (Baerentzen and Aanaes, "Signed distance computation using the angle
weighted pseudonormal", IEEE TVCG 11(3), 2005): ``(x - closest point) . pseudo-normal``
has the sign of the true inside/outside test for any closed, consistently oriented
surface.

That signed surface gap is the event function of contact onset: it is continuous where
the contact passes from one feature to the next, and it changes sign where the particle
reaches the surface, at a vertex or an edge too (an unsigned distance would only touch
zero there), while an element's own line or plane gap also changes sign beside the
element, where there is no contact.

Every feature's gap has the gradient ``normal`` with respect to x and ``-w_i normal``
with respect to its vertices (w: the closest point's weights on them), the element
kernels' form: with the weights in [0, 1] the contact forces balance.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .constants import EDGE, FACE, VERTEX  # the feature kinds, shared with the C twin
from .surface import cross

FloatArray = np.ndarray
IntArray = np.ndarray

KIND_NAMES = {FACE: "face", EDGE: "edge", VERTEX: "vertex"}


@dataclass(frozen=True)
class SurfaceContact:
    """One particle's closest feature of a surface, for each of k particles.

    Attributes
    ----------
    particle : ndarray of int, shape (k,)
        The particles, each once, ascending.
    kind : ndarray of int, shape (k,)
        ``FACE`` (a segment in 2D, a triangle in 3D), ``EDGE`` (3D only) or ``VERTEX``.
    element : ndarray of int, shape (k,)
        An element holding the closest point (the lowest-numbered of the closest ones).
    feature : ndarray of int, shape (k, d)
        The feature's vertices (a face: the element's d vertices; an edge: 2, a vertex: 1;
        canonical: edges sorted), padded with -1.  Equal rows are the same feature.
    weights : ndarray, shape (k, d)
        The closest point's weights on those vertices (sum 1; 0 on the padding).
    gap : ndarray, shape (k,)
        Signed distance to the surface (m, < 0 inside).
    normal : ndarray, shape (k, d)
        Unit gradient of the gap with respect to the particle's position.
    """

    particle: IntArray
    kind: IntArray
    element: IntArray
    feature: IntArray
    weights: FloatArray
    gap: FloatArray
    normal: FloatArray


def point_vertex(x: FloatArray, v: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Distance from points x to vertices v and its gradient with respect to x.

    Parameters
    ----------
    x, v : ndarray, shape (m, d)

    Returns
    -------
    distance : ndarray, shape (m,)
    direction : ndarray, shape (m, d)
        ``(x - v) / |x - v|`` (d distance / dx; d distance / dv is minus it); zero where
        x = v.
    """
    offset = np.asarray(x, float) - np.asarray(v, float)
    distance = np.linalg.norm(offset, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        direction = np.where(distance[:, None] > 0, offset / distance[:, None], 0.0)
    return distance, direction


def point_edge(x: FloatArray, a: FloatArray, b: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Distance from points x to segments a-b, the closest point's parameter and the gradient.

    Parameters
    ----------
    x, a, b : ndarray, shape (m, d)

    Returns
    -------
    distance : ndarray, shape (m,)
        Distance to the closest point ``a + t (b - a)`` of the segment.
    t : ndarray, shape (m,)
        Its parameter, clamped to [0, 1] (0 or 1: the closest point is a vertex).
    direction : ndarray, shape (m, d)
        ``(x - closest) / distance``: d distance / dx; with respect to a and b it is
        ``-(1 - t)`` and ``-t`` times this.  Zero where x is on the segment.
    """
    x, a, b = (np.asarray(z, float) for z in (x, a, b))
    edge = b - a
    t = np.clip(np.einsum("ij,ij->i", x - a, edge) / np.einsum("ij,ij->i", edge, edge), 0.0, 1.0)
    distance, direction = point_vertex(x, a + t[:, None] * edge)
    return distance, t, direction


def segment_normals(vertices: FloatArray, segments: IntArray) -> FloatArray:
    """Outward unit normals of a counter-clockwise 2D boundary's segments, shape (m, 2)."""
    edge = vertices[segments[:, 1]] - vertices[segments[:, 0]]
    normal = np.column_stack([edge[:, 1], -edge[:, 0]])  # right-hand perpendicular: outward
    return normal / np.linalg.norm(normal, axis=1, keepdims=True)


def triangle_normals(vertices: FloatArray, triangles: IntArray) -> FloatArray:
    """Outward unit normals of a closed surface's triangles (counter-clockwise from outside), (m, 3)."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    normal = cross(b - a, c - a)
    return normal / np.linalg.norm(normal, axis=1, keepdims=True)


def vertex_pseudonormals(vertices: FloatArray, elements: IntArray) -> FloatArray:
    """Angle-weighted pseudo-normals of the vertices (not normalised), shape (nv, d).

    In 2D every vertex joins two segments at angles that weigh the same, so its
    pseudo-normal is the sum of their normals; in 3D each incident triangle's normal is
    weighted by its angle at the vertex.
    """
    vertices = np.asarray(vertices, float)
    d = vertices.shape[1]
    pseudo = np.zeros_like(vertices)
    if d == 2:
        normal = segment_normals(vertices, elements)
        for k in range(2):
            np.add.at(pseudo, elements[:, k], normal)
        return pseudo
    normal = triangle_normals(vertices, elements)
    for k in range(3):
        here, after, before = (vertices[elements[:, (k + j) % 3]] for j in range(3))
        u, w = after - here, before - here
        cos = np.einsum("ij,ij->i", u, w) / (np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1))
        np.add.at(pseudo, elements[:, k], np.arccos(np.clip(cos, -1.0, 1.0))[:, None] * normal)
    return pseudo


def thinnest_width(x: FloatArray, elements: IntArray, particle_body: IntArray, element_body: IntArray,
                   reach: float) -> float:
    """How thin the thinnest body is across (m), looked for within ``reach`` only.

    The least distance from a surface vertex to an element of its own body's surface that
    is not one of its own and faces away from it (its outward normal against the vertex's
    pseudo-normal): a plate's thickness, a bar's width (and a U's gap between its arms,
    whose faces face each other).  ``reach`` where none is nearer: farther widths are not
    looked for (the broad phase's pairs within ``reach``, self-contact included).

    Parameters
    ----------
    x : ndarray, shape (n, d)
        Particle positions (every body's).
    elements : ndarray of int, shape (m, d)
        Every body's surface segments or triangles, oriented outward.
    particle_body, element_body : ndarray of int, shape (n,) and (m,)
    reach : float
        How far to look (m, > 0).
    """
    from .broadphase import candidate_pairs  # here: this module is the narrow phase's alone

    x, elements = np.asarray(x, float), np.asarray(elements, np.intp)
    pairs = candidate_pairs(x, elements, particle_body, reach, element_body, self_contact=True)
    pairs = pairs[particle_body[pairs[:, 0]] == element_body[pairs[:, 1]]]
    normals = (segment_normals if x.shape[1] == 2 else triangle_normals)(x, elements)
    across = np.einsum("kd,kd->k", vertex_pseudonormals(x, elements)[pairs[:, 0]], normals[pairs[:, 1]]) < 0.0
    if not across.any():  # an interior particle's pseudo-normal is 0: never across
        return float(reach)
    contact = closest_features(x, x, elements, pairs[across])
    return float(min(reach, np.abs(contact.gap).min()))


def edge_pseudonormals(vertices: FloatArray, triangles: IntArray) -> tuple[IntArray, FloatArray]:
    """Pseudo-normal of every edge of a closed 3D surface: the sum of its two triangles' normals.

    Returns
    -------
    edges : ndarray of int, shape (ne, 2)
        Each edge's vertices, sorted (i < j); the rows sorted too.
    pseudo : ndarray, shape (ne, 3)
    """
    triangles = np.asarray(triangles, dtype=np.int64)
    normal = triangle_normals(vertices, triangles)
    ends = np.concatenate([triangles[:, [k, (k + 1) % 3]] for k in range(3)])
    ends.sort(axis=1)
    edges, which = np.unique(ends, axis=0, return_inverse=True)
    pseudo = np.zeros((len(edges), 3))
    np.add.at(pseudo, which.ravel(), np.tile(normal, (3, 1)))
    return edges, pseudo


def _closest_on_elements(x: FloatArray, vertices: FloatArray, elements: IntArray):
    """Closest point of each element to its particle (row by row): kind, feature, weights, distance.

    x has shape (m, d) and elements (m, d): row r pairs particle x[r] with element r.
    """
    from .assembly import _kernels_module

    m, d = elements.shape
    kernels = _kernels_module()
    corners = [vertices[elements[:, k]] for k in range(d)]
    kind = np.full(m, FACE)
    feature = elements.copy()
    if d == 2:
        gap, s, _, _ = kernels.segment_2d(x.T, corners[0].T, corners[1].T)
        weights = np.column_stack([1 - s[0], s[0]])
    else:
        gap, bary, _, _ = kernels.triangle_3d(x.T, *(c.T for c in corners))
        weights = bary.T.copy()
    distance = np.abs(gap[0])
    outside = np.flatnonzero((weights < 0).any(axis=1) | (weights > 1).any(axis=1))
    if len(outside):
        # The projection leaves the element: its closest point is on its boundary, on the
        # nearest of its edges (a segment's only edge is itself), inside it or at a vertex.
        rows = outside
        best = np.full(len(rows), np.inf)
        best_t = np.zeros(len(rows))
        best_k = np.zeros(len(rows), int)
        for k in range(1 if d == 2 else 3):  # edge k runs from corner k to corner k + 1
            dist, t, _ = point_edge(x[rows], corners[k][rows], corners[(k + 1) % d][rows])
            closer = dist < best
            best, best_t = np.where(closer, dist, best), np.where(closer, t, best_t)
            best_k = np.where(closer, k, best_k)
        i = elements[rows, best_k]
        j = elements[rows, (best_k + 1) % d]
        distance[rows] = best
        at_end = np.where(best_t >= 1.0, j, i)
        is_vertex = (best_t <= 0.0) | (best_t >= 1.0)
        kind[rows] = np.where(is_vertex, VERTEX, EDGE)
        lo, hi = np.minimum(i, j), np.maximum(i, j)
        t_hi = np.where(i < j, best_t, 1 - best_t)  # the weight of hi
        feature[rows] = -1
        weights[rows] = 0.0
        feature[rows, 0] = np.where(is_vertex, at_end, lo)
        feature[rows, 1] = np.where(is_vertex, -1, hi)
        weights[rows, 0] = np.where(is_vertex, 1.0, 1 - t_hi)
        weights[rows, 1] = np.where(is_vertex, 0.0, t_hi)
    return kind, feature, weights, distance


def closest_features(x: FloatArray, vertices: FloatArray, elements: IntArray,
                     pairs: IntArray | None = None, element_body: IntArray | None = None) -> SurfaceContact:
    """Each particle's closest feature of a closed surface (or of each body's) and its signed gap.

    Parameters
    ----------
    x : ndarray, shape (n, d)
        Particle positions.
    vertices : ndarray, shape (nv, d)
        The surface's vertices.
    elements : ndarray of int, shape (m, d)
        Its segments (d = 2) or triangles (d = 3), oriented as in the module docstring.
    pairs : ndarray of int, shape (k, 2), optional
        Candidate ``(particle, element)`` pairs (from :mod:`flexbody.broadphase`); default:
        every particle against every element.  Each particle is answered once (once per
        body with ``element_body``), from its own candidates.  When the elements' vertices are particles (the broad phase's
        numbering), pass ``x`` itself as ``vertices`` and leave a particle out of its own
        elements' pairs.
    element_body : ndarray of int, shape (m,), optional
        The body of each element, when ``elements`` holds several bodies' surfaces: then a
        particle gets one answer per body it has candidates on (it can touch two at once).

    Returns
    -------
    SurfaceContact
        One row per particle that has a candidate (per particle and body with
        ``element_body``), ordered by particle (then body).
    """
    x, vertices = np.asarray(x, float), np.asarray(vertices, float)
    elements = np.asarray(elements, dtype=np.int64)
    d = x.shape[1]
    if vertices.shape[1] != d or elements.shape[1] != d:
        raise ValueError(f"`vertices` and `elements` must be of dimension {d} like `x`; got shapes "
                         f"{vertices.shape} and {elements.shape}")
    if pairs is None:
        pairs = np.indices((len(x), len(elements))).reshape(2, -1).T
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    if len(pairs) == 0:
        empty = np.zeros((0, d))
        return SurfaceContact(np.zeros(0, int), np.zeros(0, int), np.zeros(0, int), np.zeros((0, d), int), empty,
                              np.zeros(0), empty)
    kind, feature, weights, distance = _closest_on_elements(x[pairs[:, 0]], vertices, elements[pairs[:, 1]])
    # One answer per particle (and body): its nearest candidate, ties to the lowest-numbered element.
    surface = np.zeros(len(pairs), int) if element_body is None else np.asarray(element_body)[pairs[:, 1]]
    order = np.lexsort((pairs[:, 1], distance, surface, pairs[:, 0]))
    group = np.column_stack([pairs[order, 0], surface[order]])
    first = order[np.r_[True, np.any(group[1:] != group[:-1], axis=1)]]
    particle, element = pairs[first, 0], pairs[first, 1]
    kind, feature, weights, distance = kind[first], feature[first], weights[first], distance[first]
    xp = x[particle]
    closest = np.einsum("kj,kjd->kd", weights, vertices[np.maximum(feature, 0)])
    offset = xp - closest
    face_normal = (segment_normals if d == 2 else triangle_normals)(vertices, elements[element])
    pseudo = face_normal.copy()
    vertex_rows = kind == VERTEX
    if vertex_rows.any():  # from the elements at those vertices only: O(answers), not O(surface)
        at = feature[vertex_rows, 0]
        pseudo[vertex_rows] = vertex_pseudonormals(vertices, elements[np.isin(elements, at).any(axis=1)])[at]
    edge_rows = np.flatnonzero(kind == EDGE)
    if len(edge_rows):
        edges, edge_pseudo = edge_pseudonormals(vertices, elements)
        code = edges[:, 0] * len(vertices) + edges[:, 1]  # sorted, as the edges are
        pseudo[edge_rows] = edge_pseudo[np.searchsorted(code, feature[edge_rows, 0] * len(vertices)
                                                        + feature[edge_rows, 1])]
    sign = np.where(np.einsum("kd,kd->k", offset, pseudo) < 0, -1.0, 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        direction = np.where(distance[:, None] > 0, offset / distance[:, None],
                             pseudo / np.linalg.norm(pseudo, axis=1, keepdims=True))
    normal = np.where((kind == FACE)[:, None], face_normal, sign[:, None] * direction)
    return SurfaceContact(particle=particle, kind=kind, element=element, feature=feature, weights=weights,
                          gap=sign * distance, normal=normal)


def jacobian_entries(contact: SurfaceContact, dim: int) -> tuple[IntArray, IntArray, FloatArray]:
    """The gaps' Jacobian with respect to every coordinate, as sparse (row, column, value) entries.

    Row r is contact r's gap; its entries are ``normal`` on the particle's coordinates and
    ``-w_i normal`` on each feature vertex i's (column ``index * dim + axis``).  The
    feature's vertex indices must be particle indices: call :func:`closest_features` with
    the particles' positions as ``vertices``, as the broad phase numbers elements.

    Parameters
    ----------
    contact : SurfaceContact
        k contacts.
    dim : int
        2 or 3.

    Returns
    -------
    rows, columns : ndarray of int, shape (k * (1 + d) * dim,)
    values : ndarray, shape (k * (1 + d) * dim,)
        Duplicates (a particle twice in a row) do not occur; padding entries are dropped.
    """
    k, width = contact.feature.shape
    points = np.column_stack([contact.particle, contact.feature])  # (k, 1 + width)
    scale = np.column_stack([np.ones(k), -contact.weights])
    rows = np.repeat(np.arange(k), (1 + width) * dim)
    columns = (points[:, :, None] * dim + np.arange(dim)).reshape(-1)
    values = (scale[:, :, None] * contact.normal[:, None, :]).reshape(-1)
    used = np.repeat(points.reshape(-1) >= 0, dim)
    return rows[used], columns[used], values[used]


def vertex_elements(elements: IntArray, n_vertices: int) -> tuple[IntArray, IntArray]:
    """The elements each vertex is a corner of, ascending, as one array (CSR): vertex i's
    are ``flat[start[i] : start[i + 1]]``.

    Parameters
    ----------
    elements : ndarray of int, shape (m, d)
    n_vertices : int

    Returns
    -------
    start : ndarray of int, shape (n_vertices + 1,)
    flat : ndarray of int, shape (m d,)
    """
    corners = np.asarray(elements).ravel()
    start = np.zeros(n_vertices + 1, np.intp)
    np.cumsum(np.bincount(corners, minlength=n_vertices), out=start[1:])
    return start, np.argsort(corners, kind="stable") // np.shape(elements)[1]


class CompiledClosestFeatures:
    """:func:`closest_features` in C (``fb_closest_features`` of the runtime library) for
    one surface: its elements, their bodies and each vertex's elements are converted once.

    Parameters
    ----------
    elements : ndarray of int, shape (m, d)
        The surface's segments (d = 2) or triangles (d = 3), oriented as for
        :func:`closest_features`; vertex indices below ``n_vertices``.
    n_vertices : int
    element_body : ndarray of int, shape (m,), optional
        As for :func:`closest_features`.
    """

    def __init__(self, elements: IntArray, n_vertices: int, element_body: IntArray | None = None) -> None:
        from . import runtime

        self.lib = runtime.library()
        self.elements = np.ascontiguousarray(elements, dtype=np.intc)
        self.dim = self.elements.shape[1]
        self.element_body = None if element_body is None else np.ascontiguousarray(element_body, dtype=np.intc)
        # Each vertex's elements (CSR): the pseudo-normals of vertices and edges.
        self.incident_start, self.incident = (np.ascontiguousarray(a, dtype=np.intc)
                                              for a in vertex_elements(self.elements, n_vertices))
        # Addresses taken once (each costs microseconds, and event location calls this with
        # a pair or two thousands of times); the answers land in buffers kept between calls.
        self._surface = (self.elements.ctypes.data,
                         None if self.element_body is None else self.element_body.ctypes.data,
                         self.incident_start.ctypes.data, self.incident.ctypes.data)
        self._grow(64)

    def _grow(self, k: int) -> None:
        d = self.dim
        self._out = (np.empty(k, np.intc), np.empty(k, np.intc), np.empty(k, np.intc), np.empty((k, d), np.intc),
                     np.empty((k, d)), np.empty(k), np.empty((k, d)))
        self._out_addresses = tuple(a.ctypes.data for a in self._out)

    def __call__(self, x: FloatArray, vertices: FloatArray, pairs: IntArray, reach: float = np.inf) -> SurfaceContact:
        """Each particle's closest feature over its candidate ``pairs`` (k, 2): as
        :func:`closest_features` with this surface; with ``reach``, over the pairs whose
        particle lies in the element's bounding box grown by ``reach`` (m) only (the broad
        phase's filter, :meth:`flexbody.broadphase.CandidateList.pairs`)."""
        x = np.ascontiguousarray(x, dtype=float)
        vertices = x if vertices is x else np.ascontiguousarray(vertices, dtype=float)
        pairs = np.ascontiguousarray(pairs, dtype=np.intc).reshape(-1, 2)
        k = len(pairs)
        if k > len(self._out[0]):
            self._grow(2 * k)
        elements, body, start, incident = self._surface
        x_at = x.ctypes.data
        rows = self.lib.fb_closest_features(self.dim, k, x_at, x_at if vertices is x else vertices.ctypes.data,
                                            elements, body, pairs.ctypes.data, start, incident, float(reach),
                                            *self._out_addresses)
        if rows < 0:
            raise MemoryError(f"cannot allocate the narrow phase's {k} candidates")
        particle, kind, element, feature, weights, gap, normal = (a[:rows] for a in self._out)
        return SurfaceContact(particle=particle.astype(np.intp), kind=kind.astype(np.intp),
                              element=element.astype(np.intp), feature=feature.astype(np.intp),
                              weights=weights.copy(), gap=gap.copy(), normal=normal.copy())


class CompiledDenseGaps:
    """Free particles' gaps to other bodies' surfaces on a step's dense output, in C
    (``fb_gap_root`` and ``fb_dense_gaps`` of the runtime library): an impact's instant, the
    root search of :func:`flexbody.events._root` step for step, and a few contacts' event
    functions at one time (event location's samples of a step), each evaluated at the
    particle and its body's surface vertices only.

    Locating an impact between bodies evaluates one contact's gap about ten times a root;
    in Python each evaluation interpolates the whole state (every body's coordinates) and
    crosses into C for the narrow phase, ~0.1 ms in a pile of 4 000 particles, where this
    takes microseconds.  The gap is the nearest of the body's elements, as
    :meth:`CompiledClosestFeatures.__call__` reads it over the broad phase's pairs, which
    hold that element whenever it is within ``margin`` (farther reads ``margin`` either way).

    Parameters
    ----------
    narrow : CompiledClosestFeatures
        The surface's narrow phase (its elements, as C ints, and each vertex's elements).
    element_body : ndarray of int, shape (m,)
        The body of each element.
    n_particles : int
        The particles' count (the positions are the state's first ``n_particles * dim``).
    n_bodies : int
        The bodies' count (a body without surface elements has none to search).
    """

    #: SciPy's dense output whose formula the C evaluates: its explicit Runge-Kutta
    #: steppers' (RK23, RK45), ``y_old + h Q (s, s^2, ...)``, s = (t - t_old) / h.
    DENSE_OUTPUT = ("scipy.integrate._ivp.rk", "RkDenseOutput")
    #: A body of more surface elements is left to the broad phase's pairs (each evaluation
    #: here visits every element of the body).
    MAX_ELEMENTS = 512

    def __init__(self, narrow: CompiledClosestFeatures, element_body: IntArray, n_particles: int,
                 n_bodies: int) -> None:
        self.lib, self.dim = narrow.lib, narrow.dim
        element_body = np.asarray(element_body, np.intp)
        #: Whether each body's surface is searched here (at most MAX_ELEMENTS elements), bool (n_bodies,).
        self.searched = np.bincount(element_body, minlength=n_bodies) <= self.MAX_ELEMENTS
        # each body's elements and their vertices, as CSR (C's Surfaces)
        order = np.argsort(element_body, kind="stable")
        element_start = np.searchsorted(element_body[order], np.arange(n_bodies + 1))
        vertices = [np.unique(narrow.elements[order[a:b]]) for a, b in zip(element_start[:-1], element_start[1:])]
        vertex_start = np.concatenate([[0], np.cumsum([len(v) for v in vertices])])
        self._arrays = [np.ascontiguousarray(a, np.intc) for a in
                        (element_start, order, vertex_start, np.concatenate(vertices + [np.zeros(0, np.intp)]))]
        self._narrow = narrow  # its arrays, whose addresses are held below
        self._x = np.empty(n_particles * self.dim)  # scratch: the rows evaluated
        self._root = np.empty(1)
        # addresses taken once (each costs microseconds; a pile asks thousands of roots)
        self._surfaces = (narrow.elements.ctypes.data, narrow.incident_start.ctypes.data, narrow.incident.ctypes.data,
                          *(a.ctypes.data for a in self._arrays))
        self._scratch = (self._x.ctypes.data, self._root.ctypes.data)
        self._dense: tuple | None = None  # the last step's output, its arrays and their addresses

    def _step(self, output: object) -> tuple[int, int, int] | None:
        """The addresses of ``output``'s y_old and Q and Q's column count, or None if it is
        not :data:`DENSE_OUTPUT` (one step's output serves many calls: kept)."""
        if self._dense is None or self._dense[0] is not output:
            kind = type(output)
            if (kind.__module__, kind.__name__) != self.DENSE_OUTPUT:
                return None
            Q, y_old = (np.ascontiguousarray(a, dtype=float) for a in (output.Q, output.y_old))
            self._dense = (output, Q, y_old, (y_old.ctypes.data, Q.ctypes.data, Q.shape[1]))
        return self._dense[3]

    def root(self, output: object, particle: int, body: int, floor: float, margin: float, ta: float, tb: float,
             xtol: float) -> float | None:
        """The first time in [ta, tb] where ``particle``'s gap to ``body``'s surface (``margin``
        where farther) less ``floor`` is not above 0, on ``output``, a step's dense output;
        ``tb`` if it stays above 0 there.  None where this does not apply: another dense
        output, a surface of more than :data:`MAX_ELEMENTS` elements, or a gap at ``ta`` not
        above 0 (:func:`flexbody.events._root` decides that case itself)."""
        step = self._step(output)
        if step is None or not self.searched[body]:
            return None
        y_old, Q, powers = step
        status = self.lib.fb_gap_root(self.dim, *self._surfaces, int(particle), int(body), y_old, Q, powers,
                                      float(output.t_old), float(output.h), float(floor), float(margin), float(ta),
                                      float(tb), float(xtol), *self._scratch)
        return float(self._root[0]) if status == 0 else None

    def at(self, output: object, particles: IntArray, bodies: IntArray, floors: FloatArray, margin: float,
           t: float) -> FloatArray | None:
        """Each of k particles' gap to its body's surface (``margin`` where farther) less its
        floor at time ``t`` on ``output``, shape (k,); None where this does not apply (another
        dense output, or a surface of more than :data:`MAX_ELEMENTS` elements)."""
        step = self._step(output)
        bodies = np.ascontiguousarray(bodies, np.intc)
        if step is None or not self.searched[bodies].all():
            return None
        particles = np.ascontiguousarray(particles, np.intc)
        floors = np.ascontiguousarray(floors, dtype=float)
        out = np.empty(len(particles))
        y_old, Q, powers = step
        status = self.lib.fb_dense_gaps(self.dim, *self._surfaces, len(particles), particles.ctypes.data,
                                        bodies.ctypes.data, floors.ctypes.data, y_old, Q, powers,
                                        float(output.t_old), float(output.h), float(margin), float(t),
                                        self._scratch[0], out.ctypes.data)
        return out if status == 0 else None
