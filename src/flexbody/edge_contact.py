"""Where two 3D surfaces touch edge on edge, and the signed gap there (NumPy).

Two triangle meshes can meet with no vertex on a face: two boxes crossed edge to edge, a
coarse sphere's edge on a block's rim.  A contact between a particle and a surface
(:mod:`flexbody.surface_contact`) never sees that; the edges pass through each other
(``flexbody.surface.edges_through`` measures how far).  This module finds such contacts:
an edge ``a -> b`` of one surface and an edge ``c -> d`` of another touch where their
lines' closest points lie on both edges (parameters s and t in [0, 1]); their signed gap
is the lines' distance along the common normal ``n = ±(b - a) x (d - c) / |...|``, the
generated ``edge_3d`` kernel's (:mod:`derivation.elements`), which changes sign where one
edge passes through the other.

Two edges can only touch where n lies in the second edge's cone of outward normals (the
arc between its two triangles' unit normals) and -n in the first's: the closest points of
two convex bodies are then on these edges (the edge-edge faces of their Minkowski
difference, as in the separating-axis test of convex polyhedra; within :data:`CONE_SLACK`
of the arc, for edges lying nearly on a face).  That fixes the side
(the sign of n, a constant of a contact: out of the second body and into the first) and
leaves out pairs of edges whose lines pass close by without being the bodies' closest
features (tested against inside tests of a convex body).

Outside [0, 1] (beyond :data:`AT_END`) the closest points of the edges are an end: that
is a vertex's contact with the other surface, not an edge's; except for a crossed pair
whose vertex at that end is less than half as deep in the other body as the lines cross
while its edge passes through (or from on it into) one of the other edge's triangles, the
other's closest point inside it by the depth (:meth:`EdgeSlots._past_an_end`: no vertex
contact sees that crossing).  Parallel edges have no common normal (a face lying on a
face is held by its vertices) and are left out, as are the edges inside a flat face (a
triangulated box face's diagonal): an edge pressed onto such a face crosses its rim's
edges, which are the contacts.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .surface import cross, segments_through
from .surface_contact import CompiledClosestFeatures, closest_features

FloatArray = np.ndarray
IntArray = np.ndarray

#: Edges whose directions' cross product is below this fraction of their lengths' product
#: (an angle of 1e-6 rad) are parallel: their common normal is undefined.
PARALLEL = 1e-6
#: cos(5 deg): a common normal within 5 degrees of an edge's arc counts as in it.  An edge
#: lying nearly on a face beside the other edge crosses that edge with the normal a hair
#: outside the arc (a fine mesh's arcs are ~15 degrees wide), and a pair that became an edge
#: contact only once past it read crossed at once: in a pile of 60-particle spheres a free
#: edge row read 3e-6 m crossed and the ledger missed 1e-5 of the energy; with the slack
#: 3.5e-12 m and 8.5e-9 (1 and 5 degrees alike).
CONE_SLACK = float(np.cos(np.radians(5.0)))
#: A crossed pair read deeper than this many times its inside test's slack (1e-3 of the
#: search's reach) with a closest point nearer an end of its edge than that depth is not
#: taken on that test (:meth:`EdgeSlots._crossing_inside`); an instant's fall-back search
#: for an edge row that fired takes a pair within this many slacks of touching.
DEEP_CROSSING = 1e3
#: A closest point within this fraction of its edge's length beyond an end is on the edge:
#: a box's corner lying on the next box's bottom plane (both on the ground) reads a gap of
#: 0 there, and the edge contact of its vertical edge with that box's bottom edge, at the
#: corner, is what keeps it out of the box; its closest point's parameter is the end's to
#: rounding (+1e-19), and as the corner moved in it fell to -4e-10, off the edge, and the
#: edges crossed 7e-7 m unseen (a struck row of four flexible boxes).
AT_END = 1e-9
#: An edge whose two triangles' unit normals differ by less than this (about the angle of
#: its crease, rad) lies in a flat face (a box face's diagonal): no edge of the body's shape,
#: and no edge contact.  Linear in the angle, and small: an edge pressed across a face whose
#: diagonal creases as the body deforms meets the diagonal's ridge at a gap of about the
#: angle times the distance to the face's rim, so the pair must count from there on.  The
#: old test, 2 - |n1 + n2| <= 1e-9 (quadratic: an angle of 6.3e-5 rad), let such a pair in
#: a pile of 100-particle spheres appear already 2.7e-7 m crossed; an exactly flat face's
#: normals differ by rounding (~1e-16 times its size over its edges' length).
FLAT = 1e-10


@dataclass(frozen=True)
class EdgeContact:
    """Pairs of edges (one of each surface) whose lines' closest points lie on both edges.

    Attributes
    ----------
    pair : ndarray of int, shape (k, 2)
        Rows of the first and of the second edge array.
    side : ndarray, shape (k,)
        +1 or -1: the ``edge_3d`` kernel's input, n = side (b - a) x (d - c) / |...|.
    gap : ndarray, shape (k,)
        Signed distance of the lines (m, < 0: crossed), ``n . (a - c)``.
    parameters : ndarray, shape (k, 2)
        The closest points' s on the first edge and t on the second, in [0, 1] (to :data:`AT_END`).
    normal : ndarray, shape (k, 3)
        n, out of the second edge's body.
    index : ndarray of int, shape (k,)
        Each one's row in the candidate pairs given.
    """

    pair: IntArray
    side: FloatArray
    gap: FloatArray
    parameters: FloatArray
    normal: FloatArray
    index: IntArray


def edge_candidates(x: FloatArray, first: IntArray, second: IntArray, reach: float) -> IntArray:
    """Every pair of edges (one of ``first``, one of ``second``) that may come within
    ``reach`` of each other, a superset, shape (k, 2): a k-d tree on the second edges'
    midpoints (``scipy.spatial.cKDTree``) queried with each first edge's midpoint and the
    radius ``reach`` plus the two longest half-lengths (two points of two segments are at
    most that far from the segments' midpoints when they are within ``reach``).

    Parameters
    ----------
    x : ndarray, shape (n, 3)
    first, second : ndarray of int, shape (e1, 2) and (e2, 2)
        Edges (particle indices).
    reach : float
        m, >= 0.
    """
    from scipy.spatial import cKDTree

    first, second = np.asarray(first, np.intp).reshape(-1, 2), np.asarray(second, np.intp).reshape(-1, 2)
    if not len(first) or not len(second):
        return np.zeros((0, 2), np.intp)
    half = [0.5 * np.linalg.norm(x[e[:, 1]] - x[e[:, 0]], axis=1).max() for e in (first, second)]
    middle = [0.5 * (x[e[:, 0]] + x[e[:, 1]]) for e in (first, second)]
    near = cKDTree(middle[1]).query_ball_point(middle[0], reach + half[0] + half[1])
    rows = np.repeat(np.arange(len(first)), [len(k) for k in near])
    columns = np.concatenate([np.asarray(k, np.intp) for k in near] + [np.zeros(0, np.intp)])
    return np.column_stack([rows, columns])


class EdgeKernels:
    """The generated ``edge_3d`` and ``edge_3d_velocity`` kernels on k pairs at once, with the
    signatures of their NumPy twins (inputs (3, k) each and the sides (1, k); outputs
    (size, k)): the compiled ones (``fb_kb_*`` of the runtime library) with ``backend = "c"``
    (the velocity kernel is 1 492 operations: NumPy spent about half a millisecond a call
    on that many small arrays, 15 % of a pile of spheres with edge contacts), else NumPy's.
    The two agree to rounding (tested)."""

    #: Each output's size per pair, in the kernels' order.
    SIZES = {"edge_3d": (1, 2, 3, 12), "edge_3d_velocity": (1, 3, 1), "edge_3d_slip": (2, 2, 6)}

    def __init__(self, backend: str = "numpy") -> None:
        from .assembly import _kernels_module

        self.numpy = _kernels_module()
        self._c = None
        if backend == "c":
            import ctypes

            from .runtime import library

            lib = library()
            self._c = {name: getattr(lib, f"fb_kb_{name}") for name in self.SIZES}
            for name, function in self._c.items():
                inputs = 5 if name == "edge_3d" else 9
                function.argtypes = [ctypes.c_long] + [ctypes.c_void_p] * (inputs + len(self.SIZES[name]))
                function.restype = None

    def edge_3d(self, a, b, c, d, side) -> tuple[FloatArray, ...]:
        """Gap (1, k), parameters (2, k), normal (3, k) and gap Jacobian (1, 12, k)."""
        if self._c is None:
            return self.numpy.edge_3d(a, b, c, d, side)
        gap, parameters, normal, jacobian = self._run("edge_3d", (a, b, c, d, side))
        return gap, parameters, normal, jacobian.reshape(1, 12, -1)

    def edge_3d_velocity(self, a, b, c, d, side, va, vb, vc, vd) -> tuple[FloatArray, ...]:
        """Gap rate (1, k), tangential velocity (3, k) and gap bias (1, k)."""
        if self._c is None:
            return self.numpy.edge_3d_velocity(a, b, c, d, side, va, vb, vc, vd)
        return self._run("edge_3d_velocity", (a, b, c, d, side, va, vb, vc, vd))

    def edge_3d_slip(self, a, b, c, d, side, va, vb, vc, vd) -> tuple[FloatArray, ...]:
        """Slip rates (2, k) along t1 = (b - a) / |b - a| and t2 = n x t1, their accelerations'
        velocity terms (2, k) and t1, t2 (6, k): friction between the edges."""
        if self._c is None:
            return self.numpy.edge_3d_slip(a, b, c, d, side, va, vb, vc, vd)
        return self._run("edge_3d_slip", (a, b, c, d, side, va, vb, vc, vd))

    def _run(self, name: str, inputs) -> tuple[FloatArray, ...]:
        """The compiled kernel ``name`` on ``inputs`` (each (size, k)): its outputs (size, k)."""
        from .runtime import batched_call

        outputs = batched_call(self._c[name], [np.asarray(z, float).T for z in inputs],  # pair e reads row e
                               [(size,) for size in self.SIZES[name]])
        return tuple(z.T for z in outputs)


def edge_contacts(x: FloatArray, first: IntArray, first_faces: FloatArray, second: IntArray,
                  second_faces: FloatArray, pairs: IntArray, reach: float,
                  kernels: EdgeKernels | None = None, past_an_end: bool = False) -> EdgeContact:
    """The candidate ``pairs`` whose edges touch or cross within ``reach``: not parallel,
    neither inside a flat face (see :data:`FLAT`), the common normal in both edges' cones
    (see the module docstring), their lines' closest points on both edges (s, t in [0, 1],
    to :data:`AT_END`) and ``|gap| <= reach``.

    Parameters
    ----------
    x : ndarray, shape (n, 3)
        Positions.
    first, second : ndarray of int, shape (e1, 2) and (e2, 2)
        The two surfaces' edges (particle indices; either direction).
    first_faces, second_faces : ndarray, shape (e1, 2, 3) and (e2, 2, 3)
        The outward unit normals of each edge's two triangles.
    pairs : ndarray of int, shape (k, 2)
        Candidate (first row, second row) pairs (:func:`edge_candidates`).
    reach : float
        m: farther pairs are left out.
    kernels : EdgeKernels, optional
        The kernels to evaluate (default: NumPy's).
    past_an_end : bool
        Keep also the crossed pairs (gap < 0) whose closest point lies beyond an end of one
        edge (beyond :data:`AT_END`) and within both ends of the other: candidates for
        :meth:`EdgeSlots.closest`, which keeps those no vertex contact takes over
        (:meth:`EdgeSlots._past_an_end`).

    Returns
    -------
    EdgeContact
        The pairs kept, in the order given.
    """
    pairs = np.asarray(pairs, np.intp).reshape(-1, 2)
    first, second = np.asarray(first, np.intp), np.asarray(second, np.intp)
    a, b = x[first[pairs[:, 0], 0]], x[first[pairs[:, 0], 1]]
    c, d = x[second[pairs[:, 1], 0]], x[second[pairs[:, 1], 1]]
    common, crossing = _common_normals(a, b, c, d)
    length = np.linalg.norm(common, axis=1)
    faces_a, faces_b = first_faces[pairs[:, 0]], second_faces[pairs[:, 1]]
    for faces in (faces_a, faces_b):
        crossing &= np.linalg.norm(faces[:, 0] - faces[:, 1], axis=1) >= FLAT
    n = common / np.where(crossing, length, 1.0)[:, None]
    forward = _in_cone(n, faces_b) & _in_cone(-n, faces_a)  # n out of the second body, into the first
    backward = _in_cone(-n, faces_b) & _in_cone(n, faces_a)
    side = np.where(forward, 1.0, -1.0)
    keep = np.flatnonzero(crossing & (forward | backward))
    kernels = EdgeKernels() if kernels is None else kernels
    gap, parameters, normal, _ = kernels.edge_3d(a[keep].T, b[keep].T, c[keep].T, d[keep].T, side[keep][None, :])
    gap, parameters, normal = gap[0], parameters.T, normal.T
    within = _from_ends(parameters) >= 0.0
    on_both = within.all(axis=1)
    if past_an_end:  # crossed with the closest point past one end: the caller decides
        on_both |= within.any(axis=1) & (gap < 0.0)
    on_both &= np.abs(gap) <= reach
    keep = keep[on_both]
    return EdgeContact(pairs[keep], side[keep], gap[on_both], parameters[on_both], normal[on_both], keep)


class EdgeTerms(NamedTuple):
    """Edge contacts against the edges they are held on, k of them (the kernels' outputs).

    ``gap`` (k,) m; ``coefficients`` (k, 4): the row's weights on its points ``[a, b, c,
    d]``, ``[1 - s, s, -(1 - t), -t]`` (times ``normal`` (k, 3)); ``rate`` (k,) m/s;
    ``bias`` (k,) m/s^2, the gap acceleration's velocity term; ``margin`` (k,) m: how far
    the closest points are inside both edges (``min(s, 1 - s) |b - a|`` and ``min(t, 1 - t)
    |d - c|``, the lesser, each edge widened by :data:`AT_END` at both ends), 0 where one reaches
    AT_END beyond an end."""

    gap: FloatArray
    coefficients: FloatArray
    normal: FloatArray
    rate: FloatArray
    bias: FloatArray
    margin: FloatArray


class EdgeSlots:
    """The edge contacts of a 3D scene: ``PER_EDGE`` rows for each convex surface edge of
    the first body of a pair that may touch against the second body's convex edges (one
    way round: an edge pair is one contact).  Several, because one edge can lie across
    several edges of the other body at once: a bar's edge across a block's two rims, an
    edge across a strip of two triangles (their two outer edges and, a hair higher, the
    diagonal between them: in a pile of 100-particle spheres, with two rows, that diagonal
    went 2e-9 m through the edge held on the other two).  Five, because an edge lying across
    a flexible face meets every line of it that creases outward: a face of two squares
    (a box three particles long) has two rims, the line between the squares and two
    diagonals, each of which the edge crosses.  A row held on each of them leaves none free
    to watch the next: with three rows, in a fuzzed bridge of five boxes, an edge held on a
    rim and both diagonals of such a face went 3.9e-6 m through the middle line as it
    turned from a valley to a ridge (its gap and its crease pass 0 together), unwatched.

    Parameters
    ----------
    elements : ndarray of int, shape (m, 3)
        Every body's surface triangles (global particle indices, outward).
    element_body : ndarray of int, shape (m,)
    pairs : list of (int, int)
        The pairs of bodies whose edges touch (scene order); each gets its rows in order.
    x0 : ndarray, shape (n, 3)
        The initial positions: a rigid body's edges convex there are the ones that touch
        (:func:`convex_edges`; a flat face's diagonals and its concave edges never do).
    backend : {"numpy", "c"}
        Whose edge kernels evaluate the gaps and rows (:class:`EdgeKernels`).
    deforming : collection of int, optional
        The flexible bodies: every edge of theirs may touch, those not convex at ``x0``
        while they are convex (a box face's diagonal creasing outward as the body deforms
        is the lowest line of that face: in a fuzzed stack of boxes, a rigid box's rim went
        0.5 mm through a flexible box's bottom diagonal, which was left out as flat at the
        start).
    surface_search : CompiledClosestFeatures, optional
        The C narrow phase over ``elements`` (the body-contact model's), for the crossing
        tests' searches of a whole surface (a point against every triangle of a body, a few
        hundred, at many event evaluations); without it NumPy's
        :func:`~flexbody.surface_contact.closest_features`.

    Attributes
    ----------
    edges : ndarray of int, shape (E, 2)
        The edges of the bodies in ``pairs`` that may touch (sorted particle indices).
    edge_body : ndarray of int, shape (E,)
    creasing : ndarray of bool, shape (E,)
        The edges that touch only while convex (a flexible body's, not convex at ``x0``).
    convex_at_start : ndarray of bool, shape (E,)
        The edges that may touch at the present segment's start (:meth:`start_segment`;
        none before the first): through the segment a pair of two of them is crossed
        wherever its gap reads so, convex or not (see :meth:`closest`).
    own, body, pair : ndarray of int, shape (ns,)
        Each row's edge (a row of ``edges``), the body it may touch and its pair (index in
        ``pairs``); rows ``j``, ``j + n_primary``, ``j + 2 n_primary`` are one edge's, its
        *siblings*, ranked in that order.
    """

    PER_EDGE = 5

    def __init__(self, elements: IntArray, element_body: IntArray, pairs: list[tuple[int, int]],
                 x0: FloatArray, backend: str = "numpy", deforming: Collection[int] = (),
                 surface_search: CompiledClosestFeatures | None = None) -> None:
        self.kernels = EdgeKernels(backend)
        elements = np.asarray(elements, np.intp)
        bodies = sorted({b for pair in pairs for b in pair})
        edges, faces, owner, creasing = [], [], [], []
        for b in bodies:
            rows = np.flatnonzero(element_body == b)
            found, two = surface_edges(elements[rows])
            convex = convex_edges(x0, elements[rows], found, two)
            kept = np.ones(len(found), bool) if b in deforming else convex
            edges.append(found[kept])
            faces.append(rows[two[kept]])
            owner.append(np.full(int(kept.sum()), b))
            creasing.append(~convex[kept])
        self.edges = np.concatenate(edges + [np.zeros((0, 2), np.intp)]).astype(np.intp)
        self.edge_faces = np.concatenate(faces + [np.zeros((0, 2), np.intp)]).astype(np.intp)  # rows of elements
        self.edge_body = np.concatenate(owner + [np.zeros(0, np.intp)]).astype(np.intp)
        self.creasing = np.concatenate(creasing + [np.zeros(0, bool)])
        # each edge's second triangle's third vertex: below the first's plane where it is convex
        second = elements[self.edge_faces[:, 1]].reshape(-1, 3)
        self._third = second[np.arange(len(second)), np.argmax((second[:, :, None] != self.edges[:, None, :]).all(axis=2),
                                                               axis=1)]
        own, body, pair = [], [], []
        for k, (first, second) in enumerate(pairs):
            mine = np.flatnonzero(self.edge_body == first)
            own.append(mine)
            body.append(np.full(len(mine), second))
            pair.append(np.full(len(mine), k))
        self.n_primary = sum(len(a) for a in own)
        self.own = np.tile(np.concatenate(own + [np.zeros(0, np.intp)]), self.PER_EDGE).astype(np.intp)
        self.body = np.tile(np.concatenate(body + [np.zeros(0, np.intp)]), self.PER_EDGE).astype(np.intp)
        self.pair = np.tile(np.concatenate(pair + [np.zeros(0, np.intp)]), self.PER_EDGE).astype(np.intp)
        self._elements = elements
        self._surface_search = surface_search
        self._kept: tuple | None = None  # (reach, the edges' ends when made, start, other, row): see _candidates
        self.rebuilds = 0
        self._body_elements = {b: np.flatnonzero(element_body == b) for b in bodies}
        self.convex_at_start = np.zeros(len(self.edges), bool)

    def start_segment(self, x: FloatArray) -> None:
        """Take the edges that may touch at ``x``, a segment's start, as
        :attr:`convex_at_start` (:meth:`_convex_now`)."""
        self.convex_at_start = self._convex_now(x, self.face_normals(x), np.arange(len(self.edges)))

    def __len__(self) -> int:
        return len(self.own)

    def encode(self, edge: IntArray, side: FloatArray) -> IntArray:
        """One code per held row: the edge held against (a row of ``edges``) and the side in
        one integer, ``edge`` on side +1 and ``edge + E`` on side -1 (what the body-contact
        model keeps per slot, and records per sample, as a particle slot's element)."""
        return np.where(np.asarray(side) < 0.0, np.asarray(edge) + len(self.edges), np.asarray(edge)).astype(np.intp)

    def decode(self, code: IntArray) -> tuple[IntArray, FloatArray]:
        """The edges (-1 for a code of -1: none) and sides of codes from :meth:`encode`."""
        code = np.asarray(code, np.intp)
        return np.where(code < 0, -1, code % max(len(self.edges), 1)), np.where(code >= len(self.edges), -1.0, 1.0)

    def siblings(self, rows: IntArray) -> IntArray:
        """Each row's edge's rows (itself among them) in rank order, shape (k, PER_EDGE)."""
        return np.asarray(rows, np.intp)[:, None] % self.n_primary + self.n_primary * np.arange(self.PER_EDGE)

    def held_by_siblings(self, rows: IntArray, against: IntArray) -> IntArray:
        """The edges each row's siblings (not itself) hold (``against``: every row's code,
        :meth:`encode`), -1 where free, shape (k, PER_EDGE)."""
        return self._held_by_siblings(np.asarray(rows, np.intp), np.asarray(against))[0]

    def _held_by_siblings(self, rows: IntArray, against: IntArray) -> tuple[IntArray, IntArray]:
        """:meth:`held_by_siblings`, and the rows (indices into ``rows``) with a sibling held
        or held themselves: the others' answers are all -1, and only these are looked up (a
        search asks for every row at once, a few of which are held)."""
        out = np.full((len(rows), self.PER_EDGE), -1, np.intp)
        held = np.flatnonzero(against >= 0)
        if not len(held) or not len(rows):
            return out, np.zeros(0, np.intp)
        has = np.zeros(self.n_primary, bool)
        has[held % self.n_primary] = True
        some = np.flatnonzero(has[rows % self.n_primary])
        siblings = self.siblings(rows[some])
        out[some] = np.where(siblings == rows[some, None], -1, self.decode(against[siblings])[0])
        return out, some

    def face_normals(self, x: FloatArray, edges: IntArray | None = None) -> FloatArray:
        """The outward unit normals of each edge's two triangles at ``x``, (E, 2, 3); with
        ``edges`` (rows of ``edges``), theirs alone, the others' left 0 (a search for a few
        rows needs its candidates' only)."""
        faces = self.edge_faces if edges is None else self.edge_faces[edges]
        a, b, c = (x[self._elements[faces, k]] for k in range(3))
        normal = cross(b - a, c - a)
        normal /= np.linalg.norm(normal, axis=2, keepdims=True)
        if edges is None:
            return normal
        out = np.zeros((len(self.edges), 2, 3))
        out[edges] = normal
        return out

    def points(self, rows: IntArray, codes: IntArray) -> IntArray:
        """The particles each row moves, ``[a, b, c, d]``: its edge, then the edge it is held
        against (``codes`` (k,) from :meth:`encode`), shape (k, 4)."""
        return np.column_stack([self.edges[self.own[rows]], self.edges[self.decode(codes)[0]]])

    def closest(self, x: FloatArray, rows: IntArray, against: IntArray, reach: float, loose: bool = False
                ) -> tuple[FloatArray, IntArray, FloatArray]:
        """For each of ``rows`` (k,), the edge of its body its edge touches or crosses with
        the least gap (:func:`edge_contacts` within ``reach``), leaving out those its
        siblings hold (``against``: every row's code (:meth:`encode`), -1: none, shape
        (ns,)); of an edge's free rows, the first in rank takes the closest edge, the next
        the next closest, and so on.  ``loose``: every free row takes the edge no sibling
        holds whose gap is nearest 0, and a crossing needs no inside test, only a gap within
        ``DEEP_CROSSING`` slacks of 0 (an instant's fall-back for a row that fired but whose
        edge the strict search no longer finds).  A :attr:`creasing` edge counts while convex,
        and, with the edge it meets, while crossed where both may touch at the segment's
        start (:attr:`convex_at_start`).

        Returns
        -------
        gap : ndarray, shape (k,)
            ``reach`` where there is none.
        edge : ndarray of int, shape (k,)
            A row of ``edges``, -1 where there is none.
        side : ndarray, shape (k,)
        """
        rows = np.asarray(rows, np.intp)
        gap, edge, side = np.full(len(rows), float(reach)), np.full(len(rows), -1, np.intp), np.zeros(len(rows))
        if not len(rows) or not len(self.edges):
            return gap, edge, side
        left_out, some = self._held_by_siblings(rows, np.asarray(against))
        # each row's place among its edge's free rows (those before it take the closest edges):
        # its rank, less its held siblings ranked before it
        if loose:
            place = np.zeros(len(rows), np.intp)
        else:
            place = rows // self.n_primary
            place[some] = ((left_out[some] < 0) & (np.arange(self.PER_EDGE) < place[some, None])).sum(axis=1)
        # each edge's contacts found once for all its rows asked (siblings share them): the
        # primary rows asked, sorted, and each row's among them (np.unique's, without a sort)
        asked = rows % self.n_primary
        present = np.zeros(self.n_primary, bool)
        present[asked] = True
        primary, row_primary = np.flatnonzero(present), (np.cumsum(present) - 1)[asked]
        ends = x[self.edges]
        which, other = self._candidates(x, ends, primary, reach)
        mine = self.own[primary[which]]
        # the kept list's pairs whose edges' boxes, grown by reach, overlap now (most do not),
        # one coordinate at a time on contiguous arrays (a reduction over the 3 of each pair
        # cost a third of a pile's searches)
        low = (np.minimum(ends[:, 0], ends[:, 1]) - 0.5 * reach).T.copy()
        high = (np.maximum(ends[:, 0], ends[:, 1]) + 0.5 * reach).T.copy()
        keep = np.ones(len(mine), bool)
        for k in range(3):
            keep &= low[k][mine] <= high[k][other]
            keep &= low[k][other] <= high[k][mine]
        which, mine, other = which[keep], mine[keep], other[keep]
        # fewer pairs than edges (a root's search for one row): the normals of their edges alone
        few = len(mine) < len(self.edges)
        normals = self.face_normals(x, np.unique(np.concatenate([mine, other])) if few else None)
        creased = self._convex_now(x, normals, mine) & self._convex_now(x, normals, other)
        # a pair of edges that could touch at the segment's start also while crossed: a creasing
        # edge turning concave does not end a crossing begun while it was convex, and a pair
        # left out there at a negative gap leaves the free row's event function positive at the
        # step's end (measured: a flexible box's top diagonal flattening under the next box's
        # bottom rim, crossed by it 3.5 us before it turned from a ridge to a valley; the row
        # then read the margin, no point checked saw the crossing: 1.2e-9 m through, unseen)
        keep = creased | (self.convex_at_start[mine] & self.convex_at_start[other])
        which, mine, other, creased = which[keep], mine[keep], other[keep], creased[keep]
        found = edge_contacts(x, self.edges, normals, self.edges, normals, np.column_stack([mine, other]), reach,
                              self.kernels, past_an_end=not loose)
        found = _subset(found, creased[found.index] | (found.gap < 0.0))
        which = which[found.index]
        # loosely, a pair within DEEP_CROSSING slacks of touching: the row fired at gap 0, and a
        # deeper one is no contact, however its lines cross (measured: two boxes side by side,
        # corners coincident: a row given an edge 0.1 m off and put back onto it by that)
        if loose:
            real = np.abs(found.gap) <= DEEP_CROSSING * 1e-6 * reach
        else:
            past = ~(_from_ends(found.parameters) >= 0.0).all(axis=1)
            real = np.empty(len(past), bool)
            real[~past] = self._crossing_inside(x, _subset(found, ~past), 1e-6 * reach)
            real[past] = self._past_an_end(x, _subset(found, past), 1e-6 * reach)
        found = _subset(found, real)
        which = which[real]
        # each row's entries: its edge's contacts, in the order found, less those its siblings hold
        grouped = np.argsort(which, kind="stable")
        per_primary = np.bincount(which, minlength=len(primary))
        first, count = np.cumsum(per_primary) - per_primary, per_primary[row_primary]
        row = np.repeat(np.arange(len(rows)), count)
        entry = grouped[np.repeat(first[row_primary], count) + np.arange(len(row)) - np.repeat(np.cumsum(count) - count, count)]
        kept = ~(found.pair[entry, 1][:, None] == left_out[row]).any(axis=1)
        row, entry = row[kept], entry[kept]
        # by row, least gap first (a crossing is the contact); loosely, the gap nearest 0
        order = np.lexsort((np.abs(found.gap[entry]) if loose else found.gap[entry], row))
        start = np.searchsorted(row[order], np.arange(len(rows)))
        has = np.flatnonzero(np.bincount(row, minlength=len(rows)) > place)
        taken = entry[order[start[has] + place[has]]]
        gap[has], edge[has], side[has] = found.gap[taken], found.pair[taken, 1], found.side[taken]
        return gap, edge, side

    def _convex_now(self, x: FloatArray, normals: FloatArray, edges: IntArray) -> np.ndarray:
        """Whether each of ``edges`` (rows of ``edges``, (k,)) may touch at ``x``: one convex
        at the start always (its cone test is the one it needs), a :attr:`creasing` one
        while its second triangle's third vertex is below the first's plane (``normals``:
        :meth:`face_normals`), bool (k,)."""
        creasing = np.flatnonzero(self.creasing[edges])
        out = np.ones(len(edges), bool)
        e = edges[creasing]
        out[creasing] = np.einsum("kd,kd->k", normals[e, 0], x[self._third[e]] - x[self.edges[e, 0]]) < 0.0
        return out

    def nearest(self, x: FloatArray, rows: IntArray, against: IntArray) -> tuple[IntArray, FloatArray]:
        """For each of ``rows`` (k,), the edge of its body (not one its siblings hold) whose
        line is nearest its edge's line with the closest points on both edges (or the
        nearest line at all), on the side that makes the gap >= 0: a row the rules of
        :meth:`closest` leave without an edge, held harmlessly apart.  Returns the edges
        (rows of ``edges``) and sides, shape (k,) each."""
        kernels = self.kernels
        edge, side = np.empty(len(rows), np.intp), np.empty(len(rows))
        held = self.held_by_siblings(rows, against)
        for k, row in enumerate(np.asarray(rows, np.intp).tolist()):
            others = np.flatnonzero((self.edge_body == self.body[row]) & ~np.isin(np.arange(len(self.edges)), held[k]))
            a, b = (np.repeat(x[self.edges[self.own[row], j]][None], len(others), axis=0) for j in (0, 1))
            c, d = x[self.edges[others, 0]], x[self.edges[others, 1]]
            usable = _common_normals(a, b, c, d)[1]
            gap, parameters = np.full(len(others), np.inf), np.zeros((2, len(others)))
            if usable.any():
                g, st, _, _ = kernels.edge_3d(a[usable].T, b[usable].T, c[usable].T, d[usable].T,
                                              np.ones((1, int(usable.sum()))))
                gap[usable], parameters[:, usable] = g[0], st
            inside = (_from_ends(parameters) >= 0.0).all(axis=0)
            score = np.abs(gap) + np.where(inside, 0.0, np.inf)
            best = int(np.argmin(score)) if np.isfinite(score).any() else int(np.argmin(np.abs(gap)))
            edge[k], side[k] = others[best], 1.0 if gap[best] >= 0.0 else -1.0
        return edge, side

    def _candidates(self, x: FloatArray, ends: FloatArray, primary: IntArray, reach: float
                    ) -> tuple[IntArray, IntArray]:
        """The candidate (i, edge) pairs of rows ``primary`` (k,; rows below ``n_primary``),
        at positions ``x`` whose edges' ends are ``ends`` (E, 2, 3):
        ``i`` indexes ``primary``, ``edge`` is an edge of its body whose midpoint is within
        ``reach`` plus both edges' half-lengths (a superset).  From a kept list (a Verlet
        list, as :class:`flexbody.broadphase.CandidateList`'s): :func:`edge_candidates` for
        the largest reach asked so far plus a skin of twice that reach (ends that move half
        the reach move midpoints and half-lengths by at most that), made again once an
        edge's end has moved half the reach."""
        kept = self._kept
        ends = ends.reshape(-1, 3)
        if kept is None or reach > kept[0] or np.max(np.linalg.norm(ends - kept[1], axis=1), initial=0.0) > 0.5 * kept[0]:
            reach = max(reach, kept[0]) if kept is not None else reach
            row, other = edge_candidates(x, self.edges[self.own[: self.n_primary]], self.edges, 3.0 * reach).T
            keep = self.edge_body[other] == self.body[row]
            row, other = row[keep], other[keep]
            start = np.searchsorted(row, np.arange(self.n_primary + 1))
            self._kept = kept = (reach, ends.copy(), start, other, row)
            self.rebuilds += 1
        start, other = kept[2], kept[3]
        if len(primary) == self.n_primary:  # every row asked: the whole list, in its order
            return kept[4], other
        counts = start[primary + 1] - start[primary]
        which = np.repeat(np.arange(len(primary)), counts)
        offset = np.arange(len(which)) - np.repeat(np.cumsum(counts) - counts, counts)
        return which, other[np.repeat(start[primary], counts) + offset]

    def _crossing_inside(self, x: FloatArray, found: EdgeContact, slack: float) -> np.ndarray:
        """Which of the ``found`` pairs are apart (gap >= 0) or crossed: where each edge is in
        the other edge's body there, its closest point not outside that body by more than
        ``slack`` (m; round-off of a crossing just begun) or the edge through one of the
        other's two triangles, bool (k,).  A negative distance of two lines is a crossing
        only there: with their common normal in both edges' cones, two edges of bodies far
        apart along it (a block's rim under a small tetrahedron's far side) also read one,
        as deep as the bodies are across.  The triangles are for an acute other edge:
        crossed by h, the closest point can lie outside its body by up to h times the cosine
        of its dihedral angle (measured: a flexible box's rim bent to 89.5 deg, crossed
        2.6e-4 m at a step's end, had it 1.8e-6 m outside, and the crossing went unseen).
        Each edge by either test: the edge under an acute one can pass beneath both its own
        triangles, in and out of its body through the next ones, its closest point inside
        by the whole depth (measured: a flexible box's face diagonal under the next box's
        corner edge of 87.8 deg, crossed 1.6e-6 m in one step, the diagonal's point 5.8e-8 m
        outside: refused, no root, and put back from 1.6e-6 m inside).
        A crossing shallower than half the slack needs no test: each closest point is
        within |gap| of the other, which is on its body's surface (a held contact's
        rounding, most of a pile's)."""
        out = found.gap >= -0.5 * slack
        crossed = np.flatnonzero(~out)
        if not len(crossed):
            return out
        s, t = found.parameters[crossed].T
        first, second = self.edges[found.pair[crossed, 0]], self.edges[found.pair[crossed, 1]]
        inside = self._point_gaps(x, found.pair[crossed], s, t) <= slack  # each edge's, (k, 2)
        # ... a deep one (beyond DEEP_CROSSING slacks) only with both closest points that far
        # inside their edges: nearer an edge's end the crossing is the end vertex's (a box's
        # vertex held on a face, its edge standing off it: with the other body's edge lying
        # on that face the lines read "crossed" along a normal in the contact plane, each
        # point on the other body; measured: two rigid boxes face on face, -0.032 m, and an
        # impact on it).  A crossing just begun is shallow wherever it is.
        depth = -found.gap[crossed]
        inside &= ((depth <= DEEP_CROSSING * slack) | (_inside_edges(x, first, second, s, t) >= depth))[:, None]
        # the triangles' test for each edge whose point the inside test did not take
        for j, (edges, others) in enumerate(((first, found.pair[crossed, 1]), (second, found.pair[crossed, 0]))):
            rest = np.flatnonzero(~inside[:, j])
            inside[rest, j] = self._through_triangles(x, edges[rest], others[rest])
        inside = inside.all(axis=1)
        # a deep one near an end refused as the end vertex's crossing, where that vertex is not
        # so deep: the edges' crossing, as past the end (measured: a struck box's corner on the
        # ground at the next one's bottom rim, its vertical edge 3.7e-5 m through the rim's
        # line within one step, its closest point 1.3e-7 m up from the corner, 1.3e-7 m inside
        # the other box: refused, the crossing grew unwatched to 1.4e-3 m)
        near_end = np.flatnonzero(~inside & (depth > DEEP_CROSSING * slack))
        if len(near_end):
            inside[near_end] = self._past_an_end(x, _subset(found, crossed[near_end]), slack)
        out[crossed] = inside
        return out

    def _past_an_end(self, x: FloatArray, found: EdgeContact, slack: float) -> np.ndarray:
        """Which of the crossed ``found`` pairs whose closest point lies past an end of one
        edge (beyond :data:`AT_END`), or nearer an end than a deep crossing's depth
        (:meth:`_crossing_inside`), are still an edge contact, bool (k,): crossed deeper
        than half the inside test's ``slack`` (m; round-off), the vertex at that end less
        than half as deep inside the other edge's body as the lines cross (deeper, the
        crossing is the vertex's), the other edge's closest point inside that edge by the
        crossing's depth, and the edge through one of the other edge's two triangles, or
        from one of them into the other body.

        Past an end the crossing is normally the vertex's, a particle's contact with the
        other surface.  Not where the vertex is outside the other body while its edge is
        through the other edge's faces: two boxes on one ground, one's bottom edge pressing
        sideways onto the other's corner, the second box's wedge tilted up by 4e-4 rad.  The
        corner's vertical edge and that bottom edge meet at the corner, both on the ground;
        once crossed, their lines' closest point is below the corner by the gap times the
        vertical edge's tilt (-2.7e-8 of the edge for 6e-7 m), the corner passes beneath the
        wedge (outside it by 1e-9 m) and its edge goes through the wedge's side face: no
        vertex's contact sees it (measured: 7.2e-5 m crossed, unseen; a pair taken only
        within AT_END is lost one step after its gap passes 0, with no sign change to find).
        The lines' gap is the vertex's distance to the other edge's line along the common
        normal: the pair's contact is continuous through the end.

        From a triangle into the body counts as through it: where vertex contacts hold the
        edge's ends, each on one of the two triangles' planes, the edge cuts the wedge
        between them and passes strictly through neither (measured: a struck box's corner
        on the ground, on the plane of the next box's bottom face, its vertical edge's top
        corner held on that box's side face; the corner slid under the bottom rim, the pair
        was refused once crossed, 1.6e-4 m by the time its closest point was back on the
        edge, and a point went 4.3e-6 m inside)."""
        out = np.zeros(len(found.gap), bool)
        deep = np.flatnonzero(found.gap < -0.5 * slack)  # shallower: round-off (corners coincident)
        if not len(deep):
            return out
        gap, pair = found.gap[deep], found.pair[deep]
        s, t = found.parameters[deep].T
        first, second = self.edges[pair[:, 0]], self.edges[pair[:, 1]]
        inside = _inside_each_edge(x, first, second, s, t)
        # the edge whose closest point is past an end, or nearer one (m; :meth:`_crossing_inside`)
        first_past = inside[:, 0] <= inside[:, 1]
        # the other edge's closest point inside it by the crossing's depth (nearer its end the
        # crossing is a corner's on a corner: two boxes' coincident corners read their lines
        # 9e-6 m crossed, their edges 1e-13 m), as a deep crossing's (_crossing_inside)
        kept = inside.max(axis=1) >= -gap
        # the edge through one of the other edge's two triangles, or from one into the body
        rest = np.flatnonzero(kept)
        kept[rest] = self._through_triangles(x, np.where(first_past[rest, None], first[rest], second[rest]),
                                             np.where(first_past[rest], pair[rest, 1], pair[rest, 0]), into=True)
        # the vertex at that end against the other body's surface (clamped parameters): less
        # than half as deep as the lines cross, or the crossing is the vertex's; tested last,
        # on the few left (a search of the other body's whole surface)
        rest = np.flatnonzero(kept)
        if len(rest):
            ends = self._point_gaps(x, pair[rest], np.clip(s[rest], 0.0, 1.0), np.clip(t[rest], 0.0, 1.0))
            kept[rest] = np.where(first_past[rest], ends[:, 0], ends[:, 1]) > 0.5 * gap[rest]
        out[deep] = kept
        return out

    def _through_triangles(self, x: FloatArray, edges: IntArray, others: IntArray, into: bool = False) -> np.ndarray:
        """Whether each of ``edges`` ((k, 2) particle indices) passes through one of the two
        triangles of the surface edge ``others`` (k,), bool (k,); ``into``: or from one of
        them into the other body (``flexbody.surface.segments_through``)."""
        triangles = x[self._elements[self.edge_faces[others]]]  # (k, 2, 3, 3)
        p, q = x[edges[:, 0]], x[edges[:, 1]]
        return segments_through(p, q, triangles[:, 0], into) | segments_through(p, q, triangles[:, 1], into)

    def _point_gaps(self, x: FloatArray, pair: IntArray, s: FloatArray, t: FloatArray) -> FloatArray:
        """The signed distances of the closest points (parameters ``s`` on the first edge and
        ``t`` on the second, (k,) each) of edge ``pair`` (k, 2) to the other edge's body's
        surface (< 0: inside it), shape (k, 2): the first edge's point's, then the second's."""
        first, second = self.edges[pair[:, 0]], self.edges[pair[:, 1]]
        points = [x[first[:, 0]] + s[:, None] * (x[first[:, 1]] - x[first[:, 0]]),
                  x[second[:, 0]] + t[:, None] * (x[second[:, 1]] - x[second[:, 0]])]
        out = np.empty((len(pair), 2))
        for j, (point, other_edge) in enumerate(zip(points, (pair[:, 1], pair[:, 0]))):
            # each point against the whole surface of the other edge's body, in one search
            surfaces = [self._body_elements[int(b)] for b in self.edge_body[other_edge]]
            pairs = np.column_stack([np.repeat(np.arange(len(pair)), [len(e) for e in surfaces]),
                                     np.concatenate(surfaces)])
            out[:, j] = (closest_features(point, x, self._elements, pairs) if self._surface_search is None
                         else self._surface_search(point, x, pairs)).gap
        return out

    def crossing_depths(self, x: FloatArray, rows: IntArray, codes: IntArray) -> FloatArray:
        """How far the edges of ``rows`` (k,) cross those of their ``codes`` (k,) as points of
        one body inside the other, m, shape (k,): the lesser signed distance of their lines'
        closest points to the other body's surface (< 0: inside it).  Never below the lines'
        distance along their common normal (each point is within it of the other, which is
        on its body's surface), and above it where the edges are nearly parallel: two boxes'
        coincident rim edges, one's corner 1e-9 m below the other's top face, read their
        lines 2.6e-7 m crossed along the face between them."""
        points = self.points(rows, codes)
        parameters = self.kernels.edge_3d(*self._ends(x, points, codes))[1]
        edge, _ = self.decode(codes)
        pair = np.column_stack([self.own[np.asarray(rows, np.intp)], edge])
        return self._point_gaps(x, pair, *parameters).min(axis=1)

    def gaps(self, x: FloatArray, rows: IntArray, codes: IntArray) -> FloatArray:
        """The gaps of ``rows`` (k,) against the edges and sides of their ``codes`` (k,), m:
        :meth:`terms`' ``gap`` without the velocity kernel."""
        return self.kernels.edge_3d(*self._ends(x, self.points(rows, codes), codes))[0][0]

    def parameters(self, positions: FloatArray, samples: IntArray, rows: IntArray, codes: IntArray) -> FloatArray:
        """The closest point's parameter s on each row's own edge, ``rows`` (k,) against the
        edges and sides of their ``codes`` (k,) at ``samples`` (k,) of ``positions`` (nt, n,
        3), shape (k,)."""
        return self.kernels.edge_3d(*self._ends(positions, self.points(rows, codes), codes, samples))[1][0]

    def _ends(self, x: FloatArray, points: IntArray, codes: IntArray, samples: IntArray | None = None
              ) -> list[FloatArray]:
        """The ``edge_3d`` kernel's inputs for rows moving ``points`` (k, 4, :meth:`points`)
        against ``codes`` (k,): the four ends (3, k) each, from ``x`` (n, 3) or from
        ``samples`` (k,) of ``x`` (nt, n, 3), and the sides (1, k)."""
        at = [points[:, j] if samples is None else (samples, points[:, j]) for j in range(4)]
        return [x[j].T for j in at] + [np.asarray(self.decode(codes)[1], float)[None, :]]

    def _moving_ends(self, x: FloatArray, v: FloatArray, rows: IntArray, codes: IntArray
                     ) -> tuple[IntArray, list[FloatArray], FloatArray, list[FloatArray]]:
        """The velocity kernels' inputs for ``rows`` against ``codes``: the points (k, 4), the
        four ends (3, k) each, the sides (1, k) and the ends' velocities (3, k) each."""
        points = self.points(rows, codes)
        *ends, sides = self._ends(x, points, codes)
        return points, ends, sides, [v[points[:, j]].T for j in range(4)]

    def terms(self, x: FloatArray, v: FloatArray, rows: IntArray, codes: IntArray) -> EdgeTerms:
        """``rows`` (k,) against the edges and sides of their ``codes`` (k,, :meth:`encode`)."""
        kernels = self.kernels
        points, ends, sides, rates = self._moving_ends(x, v, rows, codes)
        gap, parameters, normal, _ = kernels.edge_3d(*ends, sides)
        rate, _, bias = kernels.edge_3d_velocity(*ends, sides, *rates)
        s, t = parameters
        coefficients = np.column_stack([1.0 - s, s, -(1.0 - t), -t])
        margin = _inside_edges(x, points[:, :2], points[:, 2:], s, t)
        return EdgeTerms(gap[0], coefficients, normal.T, rate[0], bias[0], margin)

    def slip_terms(self, x: FloatArray, v: FloatArray, rows: IntArray, codes: IntArray) -> tuple[FloatArray, FloatArray]:
        """``rows`` (k,) against the edges and sides of their ``codes`` (k,): the velocity terms
        (k, 2) of the slip rates' accelerations along t1 = (b - a) / |b - a| and t2 = n x t1
        of the row's own edge a -> b, and those tangents (k, 2, 3) (the ``edge_3d_slip``
        kernel; only friction asks for them)."""
        _, ends, sides, rates = self._moving_ends(x, v, rows, codes)
        _, bias, tangents = self.kernels.edge_3d_slip(*ends, sides, *rates)
        return bias.T, tangents.T.reshape(-1, 2, 3)


def _subset(found: EdgeContact, keep: np.ndarray) -> EdgeContact:
    """The pairs of ``found`` that ``keep`` (bool or rows) selects."""
    return EdgeContact(*(getattr(found, f)[keep] for f in ("pair", "side", "gap", "parameters", "normal", "index")))


def _inside_edges(x: FloatArray, first: IntArray, second: IntArray, s: FloatArray, t: FloatArray) -> FloatArray:
    """How far the closest points at ``s`` on edges ``first`` and ``t`` on ``second`` ((k, 2)
    particle indices each) are inside both edges (m, the lesser), shape (k,): 0 at
    :data:`AT_END` beyond an end, where the contact search stops taking the pair (a held
    row released at the end itself, its point then within AT_END, was found and hit again
    at once, armed a tolerance lower each time: ten impacts in 1.5 us in a struck row)."""
    return _inside_each_edge(x, first, second, s, t).min(axis=1)


def _inside_each_edge(x: FloatArray, first: IntArray, second: IntArray, s: FloatArray, t: FloatArray) -> FloatArray:
    """How far the closest point at ``s`` is inside edge ``first``, and the one at ``t``
    inside ``second`` ((k, 2) particle indices each; m, :func:`_from_ends` times each
    edge's length), shape (k, 2)."""
    lengths = [np.linalg.norm(x[e[:, 1]] - x[e[:, 0]], axis=1) for e in (first, second)]
    return np.column_stack([_from_ends(s) * lengths[0], _from_ends(t) * lengths[1]])


def _from_ends(parameters: FloatArray) -> FloatArray:
    """How far closest points' parameters (s or t, any shape) lie inside their edges, each
    widened by :data:`AT_END` at both ends, as fractions of the edges (< 0: beyond), the same
    shape: the one rule of where a pair is an edge contact (:func:`edge_contacts`,
    :meth:`EdgeSlots.nearest`) and of a held one's margin (:func:`_inside_edges`); a crossed
    pair past an end is one only where no vertex contact takes it
    (:meth:`EdgeSlots._past_an_end`: held, its gap is 0, and its closest point is back at
    the end)."""
    parameters = np.asarray(parameters)
    return np.minimum(parameters + AT_END, 1.0 + AT_END - parameters)


def _common_normals(a: FloatArray, b: FloatArray, c: FloatArray, d: FloatArray) -> tuple[FloatArray, np.ndarray]:
    """``(b - a) x (d - c)`` of edges a -> b and c -> d (k, 3) each, and whether they are
    not parallel (:data:`PARALLEL`), shape (k, 3) and (k,)."""
    common = cross(b - a, d - c)
    size = np.linalg.norm(b - a, axis=1) * np.linalg.norm(d - c, axis=1)
    return common, np.linalg.norm(common, axis=1) > PARALLEL * size


def _in_cone(n: FloatArray, faces: FloatArray) -> np.ndarray:
    """Whether each unit vector ``n`` (k, 3), normal to an edge, lies in the arc between its
    two triangles' unit normals ``faces`` (k, 2, 3) (``n = alpha n1 + beta n2`` with alpha
    and beta >= 0, solved by dot products up to the positive 1 / (1 - (n1 . n2)^2)) or
    within :data:`CONE_SLACK` of either end, bool (k,)."""
    n1, n2 = faces[:, 0], faces[:, 1]
    c = np.einsum("kd,kd->k", n1, n2)
    a1, a2 = np.einsum("kd,kd->k", n, n1), np.einsum("kd,kd->k", n, n2)
    return ((a1 - c * a2 >= 0.0) & (a2 - c * a1 >= 0.0) & (a1 + a2 > 0.0)) | (np.maximum(a1, a2) >= CONE_SLACK)


def surface_edges(triangles: IntArray) -> tuple[IntArray, IntArray]:
    """The edges of a closed triangle surface and the two triangles of each.

    Returns
    -------
    edges : ndarray of int, shape (e, 2)
        Sorted particle pairs, the rows sorted.
    faces : ndarray of int, shape (e, 2)
        Each edge's two rows of ``triangles``.
    """
    triangles = np.asarray(triangles, np.intp)
    ends = np.sort(np.concatenate([triangles[:, [k, (k + 1) % 3]] for k in range(3)]), axis=1)
    face = np.tile(np.arange(len(triangles)), 3)
    order = np.lexsort((ends[:, 1], ends[:, 0]))
    ends, face = ends[order], face[order]  # each edge twice on a closed surface, side by side
    return ends[::2].copy(), face.reshape(-1, 2)


def convex_edges(x: FloatArray, triangles: IntArray, edges: IntArray, faces: IntArray) -> np.ndarray:
    """Which ``edges`` (e, 2) of a closed outward surface, with their two triangles ``faces``
    (e, 2), are convex at ``x``: creased (not in a flat face, :data:`FLAT`) and the second
    triangle's third vertex below the first's plane, bool (e,)."""
    triangles = np.asarray(triangles, np.intp)
    first, second = triangles[faces[:, 0]], triangles[faces[:, 1]]
    normals = cross(x[first[:, 1]] - x[first[:, 0]], x[first[:, 2]] - x[first[:, 0]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    other = cross(x[second[:, 1]] - x[second[:, 0]], x[second[:, 2]] - x[second[:, 0]])
    other /= np.linalg.norm(other, axis=1, keepdims=True)
    third = np.array([row[~np.isin(row, edge)][0] for row, edge in zip(second, edges)], np.intp)
    below = np.einsum("kd,kd->k", normals, x[third] - x[first[:, 0]]) < 0.0
    return below & (np.linalg.norm(normals - other, axis=1) >= FLAT)

