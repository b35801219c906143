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

The side (the sign of n) is a constant of a contact: n points out of the second edge's
body and into the first's, chosen by the edges' pseudo-normals (the sums of their two
triangles' unit normals): ``side`` makes ``n . (N_second - N_first) >= 0``.  Near the
crossing of two convex edges that is the side that puts the first edge outside the
second body for a positive gap (tested against inside tests of a convex body).

Outside [0, 1] the closest points of the edges are an end: that is a vertex's contact
with the other surface, not an edge's.  Parallel edges have no common normal (a face
lying on a face is held by its vertices) and are left out, as are the edges inside a flat
face (a triangulated box face's diagonal): an edge pressed onto such a face crosses its
rim's edges, which are the contacts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

FloatArray = np.ndarray
IntArray = np.ndarray

#: Edges whose directions' cross product is below this fraction of their lengths' product
#: are parallel: their common normal is undefined.
PARALLEL = 1e-9
#: An edge whose two triangles' unit normals sum to more than ``2 - FLAT`` lies in a flat
#: face (a box face's diagonal): no edge of the body's shape, and no edge contact.
FLAT = 1e-9


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
        The closest points' s on the first edge and t on the second, in [0, 1].
    normal : ndarray, shape (k, 3)
        n, out of the second edge's body.
    """

    pair: IntArray
    side: FloatArray
    gap: FloatArray
    parameters: FloatArray
    normal: FloatArray


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


def edge_contacts(x: FloatArray, first: IntArray, first_normals: FloatArray, second: IntArray,
                  second_normals: FloatArray, pairs: IntArray, reach: float) -> EdgeContact:
    """The candidate ``pairs`` whose edges touch or cross within ``reach``: not parallel,
    their lines' closest points on both edges (s, t in [0, 1]), ``|gap| <= reach``, and
    neither edge inside a flat face (see :data:`FLAT`).

    Parameters
    ----------
    x : ndarray, shape (n, 3)
        Positions.
    first, second : ndarray of int, shape (e1, 2) and (e2, 2)
        The two surfaces' edges (particle indices; either direction).
    first_normals, second_normals : ndarray, shape (e1, 3) and (e2, 3)
        Their pseudo-normals (the sum of each edge's two triangles' outward unit normals,
        :func:`flexbody.surface_contact.edge_pseudonormals`).
    pairs : ndarray of int, shape (k, 2)
        Candidate (first row, second row) pairs (:func:`edge_candidates`).
    reach : float
        m: farther pairs are left out.

    Returns
    -------
    EdgeContact
        The pairs kept, in the order given.
    """
    from .assembly import _kernels_module

    pairs = np.asarray(pairs, np.intp).reshape(-1, 2)
    first, second = np.asarray(first, np.intp), np.asarray(second, np.intp)
    a, b = x[first[pairs[:, 0], 0]], x[first[pairs[:, 0], 1]]
    c, d = x[second[pairs[:, 1], 0]], x[second[pairs[:, 1], 1]]
    common = np.cross(b - a, d - c)
    size = np.linalg.norm(b - a, axis=1) * np.linalg.norm(d - c, axis=1)
    crossing = np.linalg.norm(common, axis=1) > PARALLEL * size
    for normals, rows in ((first_normals, pairs[:, 0]), (second_normals, pairs[:, 1])):
        crossing &= np.linalg.norm(normals[rows], axis=1) <= 2.0 - FLAT
    facing = np.einsum("kd,kd->k", common, second_normals[pairs[:, 1]] - first_normals[pairs[:, 0]])
    side = np.where(facing >= 0.0, 1.0, -1.0)
    keep = np.flatnonzero(crossing)
    gap, parameters, normal, _ = _kernels_module().edge_3d(a[keep].T, b[keep].T, c[keep].T, d[keep].T,
                                                            side[keep][None, :])
    gap, parameters, normal = gap[0], parameters.T, normal.T
    on_both = (parameters >= 0.0).all(axis=1) & (parameters <= 1.0).all(axis=1) & (np.abs(gap) <= reach)
    keep = keep[on_both]
    return EdgeContact(pairs[keep], side[keep], gap[on_both], parameters[on_both], normal[on_both])
