"""Broad phase of body-body contact: candidate (particle, surface element) pairs per step.

A particle p of one body and a surface element e of another (a boundary segment in 2D, a
surface triangle in 3D; its vertices are particles of its body) are a candidate when p
lies in e's bounding box grown by ``margin`` on every side.  The narrow phase (the
kernels ``segment_2d`` / ``triangle_3d`` and :mod:`flexbody.surface_contact`) only looks
at candidates, so ``margin`` must cover how far a particle and an element can approach
each other before the next broad-phase call.  Excluded: a body's own elements (self
contact is off by default) and, always, a particle that is a vertex of the element.

First, with self contact off, each body's box (around its particles) and the box around
its elements' grown boxes drop every particle and element that no other body comes near:
in a pile most of them (an (n + m) x bodies box test, done up to ``MAX_BODIES_PRUNED``
bodies).  Then one of two spatial indexes pairs the rest; both give the same set, which
tests/test_broadphase.py checks against brute force:

``"kdtree"`` (the default)
    A ``scipy.spatial.cKDTree`` over the particles, queried from each element's box centre
    with that element's own radius (its grown box's half-diagonal); the hits are then
    tested against the box itself.
``"grid"``
    A uniform grid of cells as large as the largest grown box: particles sorted by cell,
    each element visits the at most 2^d cells its box overlaps, pairs expanded with NumPy.

Why the k-d tree: ``python -m flexbody.broadphase`` measures one call (building its index
from scratch) on a pile of 20 discs of 200 particles (60 of them on the boundary: 1200
segments), the same pile in a box of 4 long segments, one disc of 10 000 particles on a
320-segment body, and a pile of 20 balls of 200 particles (their hulls: 3920 triangles of
uneven size); margin 2 mm.  Median CPU time of 30 calls; "kept" is the mean per step of
a :class:`CandidateList` (skin 4 mm) over 200 steps of 0.1 mm (1 m/s at dt = 0.1 ms),
its builds included.  2 cores shared with other jobs (load average 8 to 10), 2026-11-23:

===============================================  =========  =========  =========  =====
case                                             kdtree     grid       kept       pairs
===============================================  =========  =========  =========  =====
2D, 20 bodies x 200 particles                    2.1 ms     2.6 ms     0.33 ms    583
2D, the same with self contact (no pruning)      5.0 ms     3.4 ms     0.61 ms    892
2D, the same pile in a 4-segment box             6.0 ms     699 ms     0.54 ms    622
2D, the pile in the box with self contact        4.8 ms     472 ms     0.61 ms    931
2D, 1 body of 10 000 particles + 320 segments    1.3 ms     1.7 ms     0.17 ms    16
2D, the same with self contact                   4.3 ms     2.6 ms     0.24 ms    16
3D, 20 bodies x 200 particles                    2.6 ms     2.4 ms     0.49 ms    279
3D, the same with self contact (no pruning)      13.5 ms    33.9 ms    1.5 ms     2494
===============================================  =========  =========  =========  =====

On elements of one size the two are alike (the grid a little faster where a sort beats
building a tree), but the grid's cells are as large as the largest element: a box's
four long sides put the whole pile in a few cells and it degrades towards the brute
force (100 times slower), and the uneven triangles cost it 2.5 times the tree.  The tree
gives every element its own radius, needs no cell size and is maintained C code.
Between builds, :class:`CandidateList` keeps the pairs (a Verlet list): a step then
costs a displacement check and a filter of the kept pairs, 5 to 10 times less than a
search.
"""

from __future__ import annotations

import argparse
import functools
import itertools
import json
import sys
import time
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

FloatArray = np.ndarray
IntArray = np.ndarray
METHODS = ("kdtree", "grid")
#: Up to this many bodies, particles and elements far from every other body are dropped first
#: (an (n + m) x bodies box test: beyond this it grows like the square of the scene's size).
MAX_BODIES_PRUNED = 256


def element_boxes(x: FloatArray, elements: IntArray, margin: float) -> tuple[FloatArray, FloatArray]:
    """Bounding boxes of the elements grown by ``margin``: lower and upper corners, each (m, d)."""
    corners = [x[vertex] for vertex in elements.T]  # per vertex: NumPy is slow at reducing short axes
    return functools.reduce(np.minimum, corners) - margin, functools.reduce(np.maximum, corners) + margin


def _keep(pairs: IntArray, x: FloatArray, elements: IntArray, lo: FloatArray, hi: FloatArray,
          particle_body: IntArray, element_body: IntArray, self_contact: bool) -> IntArray:
    """The pairs whose particle is in the element's grown box and may touch it, sorted."""
    if not self_contact:  # first: most raw pairs are a body's particles near its own elements
        pairs = pairs[particle_body[pairs[:, 0]] != element_body[pairs[:, 1]]]
    p, e = pairs[:, 0], pairs[:, 1]
    keep = np.ones(len(pairs), bool)
    for k in range(x.shape[1]):
        keep &= (x[p, k] >= lo[e, k]) & (x[p, k] <= hi[e, k])
    for vertex in elements.T:
        keep &= vertex[e] != p  # a vertex never touches its own element
    pairs = pairs[keep]
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


def _kdtree_pairs(x: FloatArray, lo: FloatArray, hi: FloatArray) -> IntArray:
    centre = (lo + hi) / 2
    radius = np.linalg.norm((hi - lo) / 2, axis=1)  # each element's own ball around its grown box
    hits = cKDTree(x).query_ball_point(centre, radius, return_sorted=False)
    count = np.fromiter(map(len, hits), np.int64, len(hits))
    particle = np.fromiter(itertools.chain.from_iterable(hits), np.int64, int(count.sum()))
    return np.column_stack([particle, np.repeat(np.arange(len(hits)), count)])


def _grid_pairs(x: FloatArray, lo: FloatArray, hi: FloatArray) -> IntArray:
    d = x.shape[1]
    size = float((hi - lo).max())  # a grown box spans at most 2 cells per axis
    size = size if size > 0 else 1.0
    origin = np.minimum(x.min(axis=0), lo.min(axis=0))
    shape = np.floor((np.maximum(x.max(axis=0), hi.max(axis=0)) - origin) / size).astype(np.int64) + 2
    strides = np.cumprod(np.r_[1, shape[:-1]])
    key = np.floor((x - origin) / size).astype(np.int64) @ strides
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    first = np.floor((lo - origin) / size).astype(np.int64)
    last = np.floor((hi - origin) / size).astype(np.int64)
    offsets = np.indices((2,) * d).reshape(d, -1).T  # (2^d, d)
    cells = first[:, None, :] + offsets[None]  # (m, 2^d, d)
    inside = np.all(cells <= last[:, None, :], axis=2)
    element, corner = np.nonzero(inside)
    cell_key = cells[element, corner] @ strides
    start = np.searchsorted(sorted_key, cell_key, side="left")
    count = np.searchsorted(sorted_key, cell_key, side="right") - start
    element = np.repeat(element, count)
    # Expand each (element, cell) into its particles: start + 0, 1, ..., count - 1.
    within = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    particle = order[np.repeat(start, count) + within]
    return np.column_stack([particle, element]).astype(np.int64)


def candidate_pairs(x: FloatArray, elements: IntArray, particle_body: IntArray, margin: float = 0.0,
                    element_body: IntArray | None = None, self_contact: bool = False,
                    method: str = "kdtree") -> IntArray:
    """Candidate (particle, element) pairs: the particle lies in the element's grown bounding box.

    Parameters
    ----------
    x : ndarray, shape (n, d)
        Positions of every particle of every body.
    elements : ndarray of int, shape (m, k)
        Each surface element's vertices as particle indices (k = 2: segments, 3: triangles).
    particle_body : ndarray of int, shape (n,)
        The body of each particle.
    margin : float
        Growth of each box on every side (m, >= 0).
    element_body : ndarray of int, shape (m,), optional
        The body of each element; default: its first vertex's body.
    self_contact : bool
        Also pair a body's particles with its own elements (never with an element they are a
        vertex of).
    method : {"kdtree", "grid"}
        The spatial index (see the module docstring); both give the same pairs.

    Returns
    -------
    ndarray of int, shape (pairs, 2)
        ``(particle, element)`` rows, sorted by particle then element.
    """
    x = np.asarray(x, float)
    elements = np.asarray(elements, dtype=np.int64)
    particle_body = np.asarray(particle_body)
    if method not in METHODS:
        raise ValueError(f"`method` must be one of {', '.join(METHODS)}; got {method!r}")
    if not (np.isfinite(margin) and margin >= 0):
        raise ValueError(f"`margin` must be a finite length >= 0 (m); got {margin!r}")
    if x.ndim != 2 or x.shape[1] not in (2, 3):
        raise ValueError(f"`x` must have shape (n, 2) or (n, 3); got {x.shape}")
    if elements.ndim != 2 or len(elements) and (elements.min() < 0 or elements.max() >= len(x)):
        raise ValueError(f"`elements` must be an (m, k) array of particle indices in [0, {len(x)}); "
                         f"got shape {elements.shape}")
    if particle_body.shape != (len(x),):
        raise ValueError(f"`particle_body` must have shape ({len(x)},); got {particle_body.shape}")
    element_body = particle_body[elements[:, 0]] if element_body is None else np.asarray(element_body)
    if element_body.shape != (len(elements),) or not np.isin(element_body, particle_body).all():
        raise ValueError(f"`element_body` must have shape ({len(elements)},) and name bodies of "
                         f"`particle_body`; got shape {element_body.shape}")
    if len(elements) == 0 or len(x) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    lo, hi = element_boxes(x, elements, margin)
    particles, kept = np.arange(len(x)), np.arange(len(elements))
    if not self_contact and len(np.unique(particle_body)) <= MAX_BODIES_PRUNED:
        particles, kept = _near_other_bodies(x, lo, hi, particle_body, element_body)
        if len(particles) == 0 or len(kept) == 0:
            return np.zeros((0, 2), dtype=np.int64)
    pairs = (_kdtree_pairs if method == "kdtree" else _grid_pairs)(x[particles], lo[kept], hi[kept])
    pairs = np.column_stack([particles[pairs[:, 0]], kept[pairs[:, 1]]])
    return _keep(pairs, x, elements, lo, hi, particle_body, element_body, self_contact)


def _group_boxes(lo: FloatArray, hi: FloatArray, group: IntArray, count: int) -> tuple[FloatArray, FloatArray]:
    """Per group, the box around the rows' boxes [lo, hi] (empty groups: an empty box)."""
    order = np.argsort(group, kind="stable")
    starts = np.searchsorted(group[order], np.arange(count))
    filled = starts < len(group)
    filled[filled] = group[order][starts[filled]] == np.arange(count)[filled]
    box_lo, box_hi = np.full((count, lo.shape[1]), np.inf), np.full((count, lo.shape[1]), -np.inf)
    box_lo[filled] = np.minimum.reduceat(lo[order], starts[filled])
    box_hi[filled] = np.maximum.reduceat(hi[order], starts[filled])
    return box_lo, box_hi


def _near_other_bodies(x: FloatArray, lo: FloatArray, hi: FloatArray, particle_body: IntArray,
                       element_body: IntArray) -> tuple[IntArray, IntArray]:
    """The particles in some other body's elements' box, and the elements whose box meets some
    other body's particles' box: the only ones that can pair (a body touches others only
    where their boxes overlap: most of a pile's particles and elements are dropped here)."""
    bodies, particle_of = np.unique(particle_body, return_inverse=True)
    element_of = np.searchsorted(bodies, element_body)
    p_lo, p_hi = _group_boxes(x, x, particle_of, len(bodies))
    e_lo, e_hi = _group_boxes(lo, hi, element_of, len(bodies))
    # (bodies, n) and (bodies, m), one axis at a time: NumPy's fast layout for these tests.
    in_box = np.ones((len(bodies), len(x)), bool)
    meets = np.ones((len(bodies), len(lo)), bool)
    for k in range(x.shape[1]):
        xk, lok, hik = (np.ascontiguousarray(a[:, k]) for a in (x, lo, hi))
        in_box &= (xk >= e_lo[:, k, None]) & (xk <= e_hi[:, k, None])
        meets &= (lok <= p_hi[:, k, None]) & (hik >= p_lo[:, k, None])
    in_box[particle_of, np.arange(len(x))] = False
    meets[element_of, np.arange(len(lo))] = False
    return np.flatnonzero(in_box.any(axis=0)), np.flatnonzero(meets.any(axis=0))


def brute_force_pairs(x: FloatArray, elements: IntArray, particle_body: IntArray, margin: float = 0.0,
                      element_body: IntArray | None = None, self_contact: bool = False) -> IntArray:
    """:func:`candidate_pairs` by testing every particle against every box: O(n m), the reference."""
    x, elements = np.asarray(x, float), np.asarray(elements, dtype=np.int64)
    particle_body = np.asarray(particle_body)
    element_body = particle_body[elements[:, 0]] if element_body is None else np.asarray(element_body)
    lo, hi = element_boxes(x, elements, margin)
    found = []
    for first in range(0, len(x), 512):  # 512 particles at a time against every box
        inside = np.ones((min(512, len(x) - first), len(elements)), bool)
        for k in range(x.shape[1]):
            inside &= (x[first : first + 512, k, None] >= lo[:, k]) & (x[first : first + 512, k, None] <= hi[:, k])
        p, e = np.nonzero(inside)
        found.append(np.column_stack([p + first, e]))
    every = np.vstack(found) if found else np.zeros((0, 2), dtype=np.int64)
    return _keep(every, x, elements, lo, hi, particle_body, element_body, self_contact)


def slices(start: IntArray, stop: IntArray) -> IntArray:
    """The indices of the slices ``start[i]:stop[i]`` (k,) each, end to end, shape (sum of
    their lengths,): one array's slices by their bounds (as in a CSR layout)."""
    counts = np.asarray(stop) - np.asarray(start)
    return np.repeat(start - np.cumsum(counts) + counts, counts) + np.arange(counts.sum())


class CandidateList:
    """Candidate pairs kept between steps (a Verlet list): rebuilt only when a particle has moved.

    The pairs are built with ``margin + skin``.  While no coordinate of any particle has
    moved more than ``skin / 2`` since, no particle can have entered an element's
    ``margin``-grown box without having been in its ``(margin + skin)``-grown box then
    (the box test is per axis: the particle moves at most skin / 2 along each, and so
    does every box side); so each call only filters the kept pairs with the current
    boxes, O(pairs), and the answer is exactly :func:`candidate_pairs`'s.

    Parameters
    ----------
    elements, particle_body, margin, element_body, self_contact, method
        As in :func:`candidate_pairs`.
    skin : float
        Extra growth of the boxes at a rebuild (m, > 0): larger means fewer rebuilds and
        more pairs to filter.

    Attributes
    ----------
    rebuilds : int
        Spatial-index builds so far.
    seconds : float
        Wall time (s) spent in the list's calls so far: its builds and filters (the bodies
        study reports it against the whole run's).
    """

    def __init__(self, elements: IntArray, particle_body: IntArray, margin: float, skin: float,
                 element_body: IntArray | None = None, self_contact: bool = False, method: str = "kdtree") -> None:
        if not (np.isfinite(skin) and skin > 0):
            raise ValueError(f"`skin` must be a finite length > 0 (m); got {skin!r}")
        self.elements = np.asarray(elements, dtype=np.int64)
        self.particle_body = np.asarray(particle_body)
        self.element_body = self.particle_body[self.elements[:, 0]] if element_body is None else element_body
        self.margin, self.skin, self.self_contact, self.method = margin, skin, self_contact, method
        self.rebuilds = 0
        self.seconds = 0.0
        self._built_at: FloatArray | None = None
        self._pairs = np.zeros((0, 2), dtype=np.int64)
        self._first = np.zeros(1, dtype=np.intp)  # particle i's pairs: _pairs[_first[i] : _first[i + 1]]

    def pairs(self, x: FloatArray, particles: IntArray | int | None = None) -> IntArray:
        """The candidate pairs at positions x (n, d): equal to ``candidate_pairs(x, ..., margin)``;
        with ``particles`` (an index or distinct indices), theirs only."""
        start = time.perf_counter()
        x = np.asarray(x, float)
        self._renew(x)
        if particles is None:
            kept = self._pairs
        elif np.ndim(particles) == 0:
            kept = self._pairs[self._first[particles] : self._first[particles + 1]]
        else:  # the particles' slices, end to end
            kept = self._pairs[slices(self._first[particles], self._first[np.asarray(particles) + 1])]
        inside = kept[self._inside(x, kept)]
        self.seconds += time.perf_counter() - start
        return inside

    def all_kept(self, x: FloatArray) -> IntArray:
        """Every kept pair at positions x (n, d), shape (k, 2), unfiltered: a superset of
        :meth:`pairs`, which are those whose particle lies in the element's box grown by
        ``margin`` (a filter the C narrow phase can apply itself); the same array until
        the next rebuild (:attr:`rebuilds`)."""
        start = time.perf_counter()
        self._renew(np.asarray(x, float))
        self.seconds += time.perf_counter() - start
        return self._pairs

    def kept(self, x: FloatArray, particle: int) -> IntArray:
        """Particle ``particle``'s kept pairs at positions x (n, d), shape (k, 2): a superset
        of its :meth:`pairs` (every element whose ``margin``-grown box holds it is among
        them), unfiltered; its closest element within ``margin`` is among them."""
        start = time.perf_counter()
        self._renew(np.asarray(x, float))
        self.seconds += time.perf_counter() - start
        return self._pairs[self._first[particle] : self._first[particle + 1]]

    def _renew(self, x: FloatArray) -> None:
        """Rebuild the kept pairs if a particle has moved more than ``skin / 2`` since they were built."""
        moved = np.inf if self._built_at is None else np.max(np.abs(x - self._built_at), initial=0.0)
        if moved > self.skin / 2:
            found = candidate_pairs(x, self.elements, self.particle_body, self.margin + self.skin,
                                    self.element_body, self.self_contact, self.method)
            # by particle, so that one particle's pairs are a slice (event location asks for one)
            self._pairs = found[np.argsort(found[:, 0], kind="stable")]
            self._first = np.searchsorted(self._pairs[:, 0], np.arange(len(x) + 1))
            self._built_at = x.copy()
            self.rebuilds += 1

    def _inside(self, x: FloatArray, pairs: IntArray) -> np.ndarray:
        """Which ``pairs`` have the particle inside the element's box grown by ``margin``."""
        p, e = pairs[:, 0], pairs[:, 1]
        vertices = self.elements[e].T  # only the boxes of kept pairs, one axis at a time (fast)
        inside = np.ones(len(p), bool)
        for k in range(x.shape[1]):
            coordinate = x[:, k]
            corner = coordinate[vertices]  # (vertices per element, pairs)
            here = coordinate[p]
            inside &= (here >= functools.reduce(np.minimum, corner) - self.margin)
            inside &= here <= functools.reduce(np.maximum, corner) + self.margin
        return inside


# --- the measurement behind the choice (python -m flexbody.broadphase) -------------------------


def _disc_body(n: int, radius: float, centre: FloatArray, rim: int, rng: np.random.Generator):
    """A 2D body of n particles: ``rim`` on its counter-clockwise boundary, the rest inside."""
    angle = 2 * np.pi * np.arange(rim) / rim
    boundary = np.column_stack([np.cos(angle), np.sin(angle)]) * radius
    r = radius * np.sqrt(rng.uniform(0, 0.95, n - rim))
    phi = rng.uniform(0, 2 * np.pi, n - rim)
    inner = np.column_stack([r * np.cos(phi), r * np.sin(phi)])
    segments = np.column_stack([np.arange(rim), (np.arange(rim) + 1) % rim])
    return np.vstack([boundary, inner]) + centre, segments


def _sphere_body(n: int, radius: float, centre: FloatArray, rng: np.random.Generator):
    """A 3D body of n particles: half on its outward-oriented convex hull, the rest inside."""
    from scipy.spatial import ConvexHull

    rim = n // 2
    surface = rng.normal(size=(rim, 3))
    surface *= radius / np.linalg.norm(surface, axis=1, keepdims=True)
    inner = rng.normal(size=(n - rim, 3))
    inner *= radius * 0.9 * rng.uniform(0, 1, (n - rim, 1)) / np.linalg.norm(inner, axis=1, keepdims=True)
    triangles = ConvexHull(surface).simplices
    a, b, c = (surface[triangles[:, k]] for k in range(3))
    inward = np.einsum("ij,ij->i", np.cross(b - a, c - a), a) < 0
    triangles[inward] = triangles[inward][:, ::-1]  # counter-clockwise seen from outside
    return np.vstack([surface, inner]) + centre, triangles


def benchmark_scenes(seed: int = 0) -> dict[str, tuple[FloatArray, IntArray, IntArray, float]]:
    """The measured cases: name -> (x, elements, particle_body, margin)."""
    rng = np.random.default_rng(seed)
    scenes = {}
    parts = [_disc_body(200, 0.05, np.array([0.1 * (b % 5), 0.099 * (b // 5)]), 60, rng) for b in range(20)]
    scenes["2D, 20 bodies x 200 particles"] = _stack(parts, 0.002)
    # The same pile in a box: 4 long segments beside 1200 short ones (the pile touches 3 sides).
    box = np.array([[-0.051, -0.051], [0.451, -0.051], [0.451, 0.6], [-0.051, 0.6]])
    container = (box, np.array([[0, 1], [1, 2], [2, 3], [3, 0]]))
    scenes["2D, the same pile in a 4-segment box"] = _stack(parts + [container], 0.002)
    ground = _disc_body(320, 2.0, np.array([0.0, -2.0]), 320, rng)
    disc = _disc_body(10_000, 0.5, np.array([0.0, 0.499]), 400, rng)
    x, elements, body, margin = _stack([disc, ground], 0.002)
    scenes["2D, 1 body of 10 000 particles + 320 segments"] = (x, elements[elements.min(axis=1) >= 10_000], body,
                                                               margin)
    parts3 = [_sphere_body(200, 0.05, np.array([0.1 * (b % 3), 0.1 * (b // 3 % 3), 0.099 * (b // 9)]), rng)
              for b in range(20)]
    scenes["3D, 20 bodies x 200 particles"] = _stack(parts3, 0.002)
    return scenes


def _stack(parts, margin):
    x = np.vstack([p for p, _ in parts])
    start = np.cumsum([0] + [len(p) for p, _ in parts])
    elements = np.vstack([e + start[k] for k, (_, e) in enumerate(parts)])
    body = np.repeat(np.arange(len(parts)), [len(p) for p, _ in parts])
    return x, elements, body, margin


def benchmark(repeats: int = 20) -> list[dict]:
    """Median CPU time (ms) of one :func:`candidate_pairs` call per case, method and self-contact
    setting (on: nothing is pruned by body, the index does all the work), and the pair counts."""
    rows = []
    for name, (x, elements, body, margin) in benchmark_scenes().items():
        for self_contact in (False, True):
            row = {"case": name, "self_contact": self_contact, "particles": len(x), "elements": len(elements)}
            for method in METHODS:
                candidate_pairs(x, elements, body, margin, self_contact=self_contact, method=method)  # warm up
                times = []
                for _ in range(repeats):  # CPU time: the machine's other jobs slow the wall clock, not this
                    start = time.process_time()
                    pairs = candidate_pairs(x, elements, body, margin, self_contact=self_contact, method=method)
                    times.append(time.process_time() - start)
                row[f"{method}_ms"] = 1e3 * float(np.median(times))
                row["pairs"] = len(pairs)
            row["kept_ms"], row["kept_rebuilds"] = _kept_list_cost(x, elements, body, margin, self_contact)
            rows.append(row)
    return rows


def _kept_list_cost(x, elements, body, margin, self_contact, calls: int = 200) -> tuple[float, int]:
    """Mean CPU time (ms) per call of a :class:`CandidateList` (skin 2 margins) over ``calls``
    steps of a motion at up to 1 m/s, 0.1 mm per step, and its rebuilds."""
    velocity = np.random.default_rng(1).uniform(-1, 1, x.shape) / np.sqrt(x.shape[1])
    kept = CandidateList(elements, body, margin, skin=2 * margin, self_contact=self_contact)
    start = time.process_time()
    for k in range(calls):
        kept.pairs(x + velocity * k * 1e-4)
    return 1e3 * (time.process_time() - start) / calls, kept.rebuilds


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m flexbody.broadphase",
                                     description="Time the broad phase's two indexes on the documented cases.")
    parser.add_argument("--out", type=Path, help="also save the rows as JSON here")
    parser.add_argument("--repeats", type=int, default=20, help="calls per case and method (default 20)")
    args = parser.parse_args(argv)
    if args.repeats < 1:
        print(f"error: --repeats must be >= 1; got {args.repeats}", file=sys.stderr)
        return 2
    rows = benchmark(args.repeats)
    for row in rows:
        case = row["case"] + (", self contact" if row["self_contact"] else "")
        print(f"{case:<62} {row['particles']:>6} particles {row['elements']:>5} elements "
              f"{row['pairs']:>6} pairs   kdtree {row['kdtree_ms']:7.2f} ms   grid {row['grid_ms']:7.2f} ms   "
              f"kept list {row['kept_ms']:6.2f} ms/step ({row['kept_rebuilds']} builds in 200 steps)")
    if args.out:
        args.out.write_text(json.dumps(rows, indent=1) + "\n")
        print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
