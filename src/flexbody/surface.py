"""Body surfaces: what another body's particles can hit, and the checks that make it usable.

A surface is an int array of elements, shape (m, d), with particle indices within one body:
in 2D segments ``[i, j]``, in 3D triangles ``[i, j, k]``.  Orientation is outward: a 2D
boundary runs counter-clockwise (the inside on the left of each segment), a 3D triangle is
counter-clockwise seen from outside (``(x_j - x_i) x (x_k - x_i)`` points out).

A surface is *closed* when it bounds an inside, which the sign of a body-body gap needs:

* 2D: every particle on it starts exactly one segment and ends exactly one (closed loops,
  consistently oriented);
* 3D: every edge is shared by exactly two triangles that run it in opposite directions.

A closed, outward surface encloses a positive signed area (shoelace) or volume (divergence
theorem): :func:`signed_measure`.
"""

from __future__ import annotations

import numpy as np

#: The outward faces of a positively oriented tetrahedron (a, b, c, d): det(b-a, c-a, d-a) > 0.
TETRA_FACES = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross(a, b)`` of 3-vectors along the last axis, bit for bit (the same products
    and differences), without its set-up: ~5 us a call on the few rows that event location
    asks about again and again, against ~13 us (9 times faster on 5 000 rows).

    Parameters
    ----------
    a, b : ndarray, shape (..., 3)
        Broadcast against each other.

    Returns
    -------
    ndarray, shape (..., 3)
    """
    a, b = np.asarray(a), np.asarray(b)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape), np.result_type(a, b))
    np.subtract(a[..., 1] * b[..., 2], a[..., 2] * b[..., 1], out=out[..., 0])
    np.subtract(a[..., 2] * b[..., 0], a[..., 0] * b[..., 2], out=out[..., 1])
    np.subtract(a[..., 0] * b[..., 1], a[..., 1] * b[..., 0], out=out[..., 2])
    return out


def empty(dim: int) -> np.ndarray:
    """No surface: an int array of shape (0, dim)."""
    return np.zeros((0, dim), dtype=np.intp)


def signed_measure(points: np.ndarray, surface: np.ndarray) -> float:
    """The area (2D) or volume (3D) a closed surface encloses; negative when it faces inward.

    Parameters
    ----------
    points : ndarray, shape (n, d)
    surface : ndarray of int, shape (m, d)

    Returns
    -------
    float
        2D: the shoelace sum ``1/2 sum (x_i y_j - x_j y_i)``; 3D: the divergence theorem
        ``1/6 sum x_i . (x_j x x_k)``.  Independent of the origin only for a closed surface.
    """
    x = np.asarray(points, dtype=float)[np.asarray(surface, dtype=np.intp)]
    if len(x) == 0:
        return 0.0
    if x.shape[1] == 2:
        return 0.5 * float(np.sum(x[:, 0, 0] * x[:, 1, 1] - x[:, 1, 0] * x[:, 0, 1]))
    return float(np.sum(np.einsum("ij,ij->i", x[:, 0], cross(x[:, 1], x[:, 2])))) / 6.0


def winding_numbers(points: np.ndarray, surface: np.ndarray, queries: np.ndarray) -> np.ndarray:
    """How many times a closed surface winds around each of the points ``queries``: 1
    inside, 0 outside (to rounding; a point on the surface reads between).

    Parameters
    ----------
    points : ndarray, shape (n, d)
    surface : ndarray of int, shape (m, d)
        Closed, oriented outward (counter-clockwise segments in 2D, triangles counter-clockwise
        from outside in 3D).
    queries : ndarray of int, shape (k,)
        Rows of ``points``.

    Returns
    -------
    ndarray, shape (k,)
        2D: the segments' signed angles at each point over 2 pi; 3D: the triangles' solid
        angles (Van Oosterom and Strackee, IEEE Trans. Biomed. Eng. 30(2), 1983) over 4 pi.
    """
    x = np.asarray(points, dtype=float)
    corners = x[np.asarray(surface, dtype=np.intp)][None] - x[np.asarray(queries, dtype=np.intp)][:, None, None]
    if x.shape[1] == 2:
        a, b = corners[..., 0, :], corners[..., 1, :]
        angle = np.arctan2(a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0], np.einsum("kmd,kmd->km", a, b))
        return angle.sum(axis=1) / (2.0 * np.pi)

    def dot(u, v):
        return np.einsum("kmd,kmd->km", u, v)

    a, b, c = (corners[..., j, :] for j in range(3))
    la, lb, lc = (np.linalg.norm(v, axis=2) for v in (a, b, c))
    solid = 2.0 * np.arctan2(dot(a, cross(b, c)), la * lb * lc + dot(a, b) * lc + dot(a, c) * lb + dot(b, c) * la)
    return solid.sum(axis=1) / (4.0 * np.pi)


def closure_problem(surface: np.ndarray) -> str:
    """Why a surface is not closed ("" when it is), naming the first offending particle or edge.

    Parameters
    ----------
    surface : ndarray of int, shape (m, d)
        Segments (d = 2) or triangles (d = 3), without repeated or degenerate elements.
    """
    surface = np.asarray(surface, dtype=np.intp)
    if len(surface) == 0:
        return "it is empty"
    if surface.shape[1] == 2:
        n = int(surface.max()) + 1
        starts = np.bincount(surface[:, 0], minlength=n)
        ends = np.bincount(surface[:, 1], minlength=n)
        bad = np.flatnonzero((starts + ends > 0) & ((starts != 1) | (ends != 1)))
        if bad.size:
            i = int(bad[0])
            more = f" (and {bad.size - 1} more particles like it)" if bad.size > 1 else ""
            return (f"particle {i} starts {starts[i]} segment(s) and ends {ends[i]}{more}; on a closed 2D surface "
                    "every particle starts exactly one segment and ends exactly one (closed loops, one direction)")
        return ""
    directed = surface[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    undirected, counts = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)
    bad = np.flatnonzero(counts != 2)
    if bad.size:
        more = f" (and {bad.size - 1} more edges like it)" if bad.size > 1 else ""
        return (f"edge {undirected[bad[0]].tolist()} belongs to {counts[bad[0]]} triangle(s){more}; on a closed 3D "
                "surface every edge belongs to exactly two")
    runs, run_counts = np.unique(directed, axis=0, return_counts=True)
    same_way = np.flatnonzero(run_counts > 1)
    if same_way.size:
        more = f" (and {same_way.size - 1} more edges like it)" if same_way.size > 1 else ""
        return (f"the two triangles on edge {runs[same_way[0]].tolist()} both run it from {runs[same_way[0], 0]} to "
                f"{runs[same_way[0], 1]}{more}; neighbouring triangles must run a shared edge in opposite directions "
                "(consistent orientation)")
    return ""


def degenerate(points: np.ndarray, surface: np.ndarray, relative: float = 1e-9) -> np.ndarray:
    """The elements without a normal, indices (k,): segments shorter than ``relative`` times
    the surface's size, triangles whose area is below ``relative`` times their longest edge
    squared (collinear or coincident corners).

    Parameters
    ----------
    points : ndarray, shape (n, d)
    surface : ndarray of int, shape (m, d)
    """
    corners = np.asarray(points, float)[np.asarray(surface, np.intp)]  # (m, d, d)
    if surface.shape[1] == 2:
        length = np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1)
        return np.flatnonzero(length <= relative * np.ptp(corners.reshape(-1, 2), axis=0).max())
    edges = corners[:, [1, 2, 0]] - corners
    area2 = np.linalg.norm(cross(edges[:, 0], edges[:, 1]), axis=1)
    return np.flatnonzero(area2 <= relative * np.sum(edges * edges, axis=2).max(axis=1))


def outward(points: np.ndarray, surface: np.ndarray) -> np.ndarray:
    """``surface`` with every element reversed if it encloses a negative measure, shape (m, d)."""
    surface = np.asarray(surface, dtype=np.intp)
    return surface[:, ::-1].copy() if signed_measure(points, surface) < 0.0 else surface


def perimeter(first: int, count: int) -> np.ndarray:
    """The loop ``first, first + 1, ..., first + count - 1, first``, shape (count, 2); empty for
    fewer than three particles (two particles enclose nothing)."""
    if count < 3:
        return empty(2)
    k = np.arange(count)
    return np.column_stack([first + k, first + (k + 1) % count])


def boundary(points: np.ndarray, cells: np.ndarray) -> np.ndarray:
    """The outward boundary of a mesh of triangles (2D) or tetrahedra (3D).

    Each cell is first turned to positive orientation; its faces are then outward, and the
    faces no other cell shares (each shared face is met once in each direction) make the
    boundary.

    Parameters
    ----------
    points : ndarray, shape (n, d)
    cells : ndarray of int, shape (c, d + 1)

    Returns
    -------
    ndarray of int, shape (m, d)
        Segments (2D) or triangles (3D), outward.
    """
    points = np.asarray(points, dtype=float)
    cells = np.asarray(cells, dtype=np.intp).copy()
    dim = points.shape[1]
    if len(cells) == 0:
        return empty(dim)
    edges = points[cells[:, 1:]] - points[cells[:, :1]]
    flip = np.linalg.det(edges) < 0.0
    cells[flip, :2] = cells[flip, 1::-1]  # swapping two corners reverses the orientation
    if dim == 2:
        faces = cells[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    else:
        faces = cells[:, TETRA_FACES].reshape(-1, 3)
    keys, counts = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=False, return_counts=True)
    once = keys[counts == 1]
    keep = _rows_in(np.sort(faces, axis=1), once)
    return faces[keep]


def hull(points: np.ndarray) -> np.ndarray:
    """The convex hull's triangles (scipy.spatial.ConvexHull, i.e. Qhull), outward, shape (m, 3).

    Only hull vertices appear: a particle inside the hull or on a flat face's interior does not.
    """
    from scipy.spatial import ConvexHull

    h = ConvexHull(points)
    tri = np.asarray(h.simplices, dtype=np.intp).copy()
    x = np.asarray(points, dtype=float)[tri]
    normal = cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    inward = np.einsum("ij,ij->i", normal, h.equations[:, :3]) < 0.0  # Qhull's normals point out
    tri[inward, 1:] = tri[inward, :0:-1]
    return tri


#: An end counts as on one side of a line (plane) only farther from it than this fraction
#: of its segment's (edge's) length: rounding puts the ends of a straight side's collinear
#: segments, or a flat face's coplanar edges, on either side at random (a fuzz found an
#: undeformed 3 x 3 x 2 box in free flight reported folded, its edge through a triangle of
#: the same face).
STRICT = 1e-9


def crossings(points: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """The pairs of 2D segments that share no particle and cross: each one's ends strictly on
    either side of the other's line (beyond :data:`STRICT` of its length: a surface that
    folds over itself; ends merely touching, or collinear, do not count).  Only pairs whose
    midpoints are within the longest segment's length can cross, and only those are tested
    (a k-d tree on the midpoints, ``scipy.spatial.cKDTree``), so the cost grows as m log m.

    Parameters
    ----------
    points : ndarray, shape (n, 2)
    segments : ndarray of int, shape (m, 2)

    Returns
    -------
    ndarray of int, shape (k, 2)
        Rows ``(a, b)``, ``a < b``, of ``segments``, ascending.
    """
    pairs, first, second = _near_segments(points, segments)

    def apart(line: np.ndarray, x: np.ndarray) -> np.ndarray:  # the ends x strictly on either side
        d = line[:, 1] - line[:, 0]
        u = _ends_across(line, x)
        return (u[:, 0] * u[:, 1] < 0.0) & (np.abs(u).min(axis=1) > STRICT * np.einsum("ij,ij->i", d, d))

    hit = apart(first, second) & apart(second, first)
    return pairs[hit]


def segments_across(points: np.ndarray, segments: np.ndarray, depth: float) -> tuple[np.ndarray, np.ndarray]:
    """The pairs of 2D segments that share no particle and cross by more than ``depth``: each
    one's ends on either side of the other's line, each end more than ``depth`` from it.  Two
    bodies' boundaries crossing like a plus sign (thin tips through each other) do this with
    no particle inside the other body; a particle inside by d makes its two segments cross
    the other's by at most about d.  The 2D twin of :func:`edges_through`; the candidates
    are :func:`crossings`'.

    Parameters
    ----------
    points : ndarray, shape (n, 2)
    segments : ndarray of int, shape (m, 2)
    depth : float
        How far past touching a crossing must be (m).

    Returns
    -------
    pairs : ndarray of int, shape (k, 2)
        Rows ``(a, b)``, ``a < b``, of ``segments``, ascending.
    depths : ndarray, shape (k,)
        How far an end must move to stop the crossing (m): the least of the four ends'
        distances to the other segment's line.
    """
    pairs, first, second = _near_segments(points, segments)

    def sides(line: np.ndarray, x: np.ndarray) -> np.ndarray:  # signed distances of the ends x, (k, 2)
        with np.errstate(divide="ignore", invalid="ignore"):  # a zero-length segment's NaNs cross nothing
            return _ends_across(line, x) / np.linalg.norm(line[:, 1] - line[:, 0], axis=1)[:, None]

    a, b = sides(first, second), sides(second, first)
    depths = np.minimum(np.abs(a).min(axis=1), np.abs(b).min(axis=1))
    hit = (a[:, 0] * a[:, 1] < 0.0) & (b[:, 0] * b[:, 1] < 0.0) & (depths > depth)
    return pairs[hit], depths[hit]


def _ends_across(line: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``d x (x_end - a)`` for each of the two ends of segments ``x`` against the lines
    ``line`` (a -> b, d = b - a), (k, 2, 2) each: |d| times each end's signed distance from
    the line (> 0 on its left), shape (k, 2)."""
    d = line[:, 1] - line[:, 0]
    r = x - line[:, :1]
    return d[:, None, 0] * r[:, :, 1] - d[:, None, 1] * r[:, :, 0]


def _near_segments(points: np.ndarray, segments: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pairs of 2D ``segments`` (m, 2) sharing no particle whose midpoints are within the
    longest one's length (only these can cross; a k-d tree, ``scipy.spatial.cKDTree``), rows
    ``(a, b)``, ``a < b``, ascending, shape (k, 2), and their ends, (k, 2, 2) each."""
    from scipy.spatial import cKDTree

    segments = np.asarray(segments, dtype=np.intp)
    if len(segments) < 2:
        return np.zeros((0, 2), np.intp), np.zeros((0, 2, 2)), np.zeros((0, 2, 2))
    ends = points[segments]  # (m, 2 ends, 2)
    reach = float(np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1).max())
    pairs = cKDTree(ends.mean(axis=1)).query_pairs(reach, output_type="ndarray").reshape(-1, 2)
    pairs = np.sort(pairs, axis=1)
    pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
    pairs = pairs[_share_none(segments[pairs[:, 0]], segments[pairs[:, 1]])]
    return pairs, ends[pairs[:, 0]], ends[pairs[:, 1]]


def _share_none(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Which rows of element arrays ``a`` (k, i) and ``b`` (k, j) share no particle, shape (k,)."""
    return (a[:, :, None] != b[:, None, :]).all(axis=(1, 2))


def piercings(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """The edges of a 3D surface that pass through one of its triangles they share no particle
    with (a surface that folds through itself; touching does not count): each edge's
    ends strictly on either side of the triangle's plane (beyond :data:`STRICT` of the
    edge's length: an edge in the plane does not count), and its line strictly inside the
    triangle's three edges.  Only an edge whose midpoint is within reach of a triangle's
    centre (its largest corner distance plus half the longest edge) can pass through it, and
    only those pairs are tested (a k-d tree on the edges' midpoints, ``scipy.spatial.cKDTree``),
    so the cost grows as m log m.

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    triangles : ndarray of int, shape (m, 3)

    Returns
    -------
    ndarray of int, shape (k, 2)
        Rows ``(triangle, edge)``: a triangle's index in ``triangles`` and an edge's particles'
        row in ``edges(triangles)``.
    """
    triangles = np.asarray(triangles, dtype=np.intp)
    edge = edges(triangles)
    if len(triangles) == 0:
        return np.zeros((0, 2), np.intp)
    corners, ends = points[triangles], points[edge]  # (m, 3, 3), (e, 2, 3)
    tri, ed = _within_reach(corners, ends)
    apart = _share_none(triangles[tri], edge[ed])
    tri, ed = tri[apart], ed[apart]
    hit = segments_through(ends[ed, 0], ends[ed, 1], corners[tri])
    return np.column_stack([tri[hit], ed[hit]])


def segments_through(p: np.ndarray, q: np.ndarray, corners: np.ndarray, into: bool = False) -> np.ndarray:
    """Whether each segment ``p -> q`` passes through its triangle, pair by pair: its ends
    strictly on either side of the triangle's plane (beyond :data:`STRICT` of its length: a
    segment in the plane does not count) and its line strictly inside the triangle's three
    edges (signed volumes, no division).

    Parameters
    ----------
    p, q : ndarray, shape (k, 3)
        The segments' ends.
    corners : ndarray, shape (k, 3, 3)
        Each one's triangle.
    into : bool
        Count also a segment from the triangle into its body: one end on it (within
        STRICT of its plane, the line inside its edges), the other strictly behind it
        (opposite its normal ``(b - a) x (c - a)``, outward): an edge whose vertex a
        contact holds on a face, going in.

    Returns
    -------
    ndarray of bool, shape (k,)
    """
    a, b, c = (corners[:, k] for k in range(3))

    def volume(u, v, w, x):  # six times the signed volume of the tetrahedron (u, v, w, x)
        return np.einsum("ij,ij->i", cross(v - u, w - u), x - u)

    at_p, at_q = volume(a, b, c, p), volume(a, b, c, q)  # the ends' distances times |(b - a) x (c - a)|
    size = np.linalg.norm(cross(b - a, c - a), axis=1) * np.linalg.norm(q - p, axis=1)
    nearer = np.minimum(np.abs(at_p), np.abs(at_q))  # the end nearer the plane
    through_plane = (at_p * at_q < 0.0) & (nearer > STRICT * size)
    if into:
        through_plane |= (nearer <= STRICT * size) & (np.minimum(at_p, at_q) < -STRICT * size)
    sides = np.stack([volume(p, q, a, b), volume(p, q, b, c), volume(p, q, c, a)])
    inside = ((sides > 0.0).all(axis=0)) | ((sides < 0.0).all(axis=0))
    return through_plane & inside


def edges_through(points: np.ndarray, segments: np.ndarray, triangles: np.ndarray,
                  depth: float) -> tuple[np.ndarray, np.ndarray]:
    """The edges of one 3D surface that pass through triangles of another by more than
    ``depth``: on either side of the triangle's plane, through its inside, and more than
    ``depth`` from not crossing (see ``depths`` below).  Two bodies
    whose edges cross (the contact between two edges) do this with no vertex inside the
    other; resting face to face (edges in the other's plane, to round-off) they do not.
    Only an edge whose midpoint is within reach of a triangle's centre is tested (a k-d
    tree, ``scipy.spatial.cKDTree``).

    Parameters
    ----------
    points : ndarray, shape (n, 3)
    segments : ndarray of int, shape (e, 2)
        The edges tested (a surface's: :func:`edges` of its triangles).
    triangles : ndarray of int, shape (m, 3)
        The triangles they may pass through (outward: counter-clockwise seen from outside).
    depth : float
        How far past touching a crossing must be (m).

    Returns
    -------
    rows : ndarray of int, shape (k, 2)
        ``(triangle, edge)``: a row of ``triangles`` and a row of ``segments``.
    depths : ndarray, shape (k,)
        How far each edge must move to stop crossing its triangle (m): the least of its
        ends' distances to the plane, its crossing point's to the triangle's edges, and the
        shift along the normal that slides the crossing point out of the triangle (where a
        flat face is split into triangles, a lower bound on how far the bodies overlap).
    """
    none = np.zeros((0, 2), np.intp), np.zeros(0)
    triangles, edge = np.asarray(triangles, dtype=np.intp), np.asarray(segments, dtype=np.intp)
    if len(triangles) == 0 or len(edge) == 0:
        return none
    corners, ends = points[triangles], points[edge]
    tri, ed = _within_reach(corners, ends)
    if len(tri) == 0:
        return none
    a, b, c = (corners[tri, k] for k in range(3))
    p, q = ends[ed, 0], ends[ed, 1]
    normal = cross(b - a, c - a)
    with np.errstate(divide="ignore", invalid="ignore"):  # a degenerate triangle's NaNs make no hit
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    dp, dq = np.einsum("ij,ij->i", normal, p - a), np.einsum("ij,ij->i", normal, q - a)
    through = (np.minimum(np.abs(dp), np.abs(dq)) > depth) & (dp * dq < 0.0)
    crossing = p + (dp / np.where(through, dp - dq, 1.0))[:, None] * (q - p)
    # How far the edge must move to stop crossing: its ends to the plane (along the normal),
    # the crossing point to the triangle's edges (in the plane), or, along the normal, until
    # the crossing point slides out of the triangle: an edge nearly in the plane (a face
    # pressed flat on another) moves its crossing point a long way for a tiny shift
    # (tan of its angle to the plane), so it crosses by round-off, not by a depth.
    with np.errstate(divide="ignore", invalid="ignore"):  # nor a zero-length edge's
        direction = (q - p) / np.linalg.norm(q - p, axis=1, keepdims=True)
    rise = np.abs(np.einsum("ij,ij->i", direction, normal))
    flat = direction - np.einsum("ij,ij->i", direction, normal)[:, None] * normal  # its run along the plane
    run = np.linalg.norm(flat, axis=1)
    inside, slide = np.full(len(tri), np.inf), np.full(len(tri), np.inf)
    for u, v in ((a, b), (b, c), (c, a)):
        along = v - u
        with np.errstate(divide="ignore", invalid="ignore"):
            inward = cross(normal, along) / np.linalg.norm(along, axis=1, keepdims=True)
        distance = np.einsum("ij,ij->i", inward, crossing - u)
        inside = np.minimum(inside, distance)
        towards = np.abs(np.einsum("ij,ij->i", inward, flat)) / np.maximum(run, 1e-300)
        with np.errstate(divide="ignore", invalid="ignore"):
            slide = np.minimum(slide, np.where(towards > 0.0, distance / towards, np.inf))
    with np.errstate(divide="ignore", invalid="ignore"):
        tilt = np.where(run > 0.0, rise / run, np.inf)
    depth_of = np.minimum(np.minimum(inside, np.minimum(np.abs(dp), np.abs(dq))), slide * tilt)
    hit = through & (inside > 0.0) & (depth_of > depth)
    return np.column_stack([tri[hit], ed[hit]]), depth_of[hit]


def _within_reach(corners: np.ndarray, ends: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The (triangle, edge) pairs that can cross, as index arrays (k,) each: an edge whose
    midpoint is within reach of a triangle's centre (its largest corner distance plus half
    the longest edge), found by a k-d tree on the midpoints (``scipy.spatial.cKDTree``).
    ``corners (m, 3, 3)``, ``ends (e, 2, 3)``."""
    from scipy.spatial import cKDTree

    centre, middle = corners.mean(axis=1), ends.mean(axis=1)
    reach = (np.linalg.norm(corners - centre[:, None], axis=2).max()
             + 0.5 * np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1).max())
    near = cKDTree(middle).query_ball_point(centre, reach)
    tri = np.repeat(np.arange(len(corners)), [len(k) for k in near])
    ed = np.concatenate([np.asarray(k, np.intp) for k in near] + [np.zeros(0, np.intp)])
    return tri, ed


def edges(cells: np.ndarray) -> np.ndarray:
    """The distinct edges of cells ``(m, k)`` (triangles, polygons' fans, tetrahedra): every
    two particles of a cell, each pair ascending, the pairs ascending, shape (e, 2)."""
    cells = np.asarray(cells, dtype=np.intp)
    if len(cells) == 0:
        return np.zeros((0, 2), np.intp)
    k = cells.shape[1]
    pairs = np.concatenate([cells[:, [a, b]] for a in range(k) for b in range(a + 1, k)])
    return np.unique(np.sort(pairs, axis=1), axis=0)


def _rows_in(rows: np.ndarray, table: np.ndarray) -> np.ndarray:
    """Which rows of ``rows`` (shape (a, k)) are rows of ``table`` (shape (b, k)), shape (a,)."""
    if len(table) == 0:
        return np.zeros(len(rows), dtype=bool)
    view = np.dtype((np.void, rows.dtype.itemsize * rows.shape[1]))
    a = np.ascontiguousarray(rows).view(view).ravel()
    b = np.ascontiguousarray(table.astype(rows.dtype)).view(view).ravel()
    return np.isin(a, b)
