"""Body geometry presets: particle positions in frame T and the links between them.

Every preset returns ``(points, links)`` with ``points`` of shape (n, 2) in frame T and
``links`` a list of index pairs.  Index order is part of the contract (results are indexed
by it).  A body's ``position`` puts T's origin in N and ``angle`` turns T about it; where
T's origin lies in each preset is said below.

* ``ring`` / ``ellipse``: the centre particle (if any) is index 0, then the perimeter
  counter-clockwise starting on T's x-axis, which lies at the body's ``angle`` in N.
  Links: every perimeter neighbour pair, and a spoke from the centre to each perimeter
  particle.  T's origin is the centre: ``position`` is where the centre starts.
* ``polygon``: the given ``vertices`` in order (the centre first if ``center``), at the
  coordinates given: T's origin is the origin of the vertex coordinates (not their
  centroid), so ``position`` places that point.  Links: the edges, plus

  - with ``center = true``: a spoke from the centre particle (at the vertices' centroid)
    to every vertex, and no diagonals;
  - without a centre: the second-neighbour diagonals ``(k, k + 2)`` (for 4 or more
    vertices), which keep the shape from shearing flat.  For a quadrilateral these are
    both diagonals; for a pentagon the five of the star; for six or more vertices only
    these short diagonals (a hexagon gets two triangles, not all nine diagonals).  A
    triangle needs none.  For other bracing, give explicit ``particles`` and ``links``.
* ``chain``: ``count`` particles on T's x-axis, ``spacing`` apart, centred on T's origin
  (index 0 at the -x end), linked to their neighbours.  ``position`` is the chain's
  midpoint (the middle particle for an odd count), and ``angle`` tilts it: ``angle = 0``
  lies flat, ``pi/2`` stands it on end with particle 0 at the bottom.  A chain has no
  bending stiffness: it folds freely at every particle.

Surfaces (what other bodies' particles can hit; :mod:`flexbody.surface`), outward, by the
``*_surface`` functions and :func:`mesh`:

* ``ring`` / ``ellipse`` / ``polygon``: the perimeter segments ``[k, k + 1]`` in particle
  order, counter-clockwise (a clockwise polygon's are reversed); the centre particle is not
  on it.  Two particles enclose nothing: no surface.
* ``disc``: the boundary of the lattice's triangles (a rim particle held by one link only,
  in no triangle, is not on it).
* ``chain``: none (an open line has no inside).
* ``sphere``: the convex hull's triangles (Qhull), without the centre.
* ``box``: the six faces' lattice squares, two triangles each, so every particle on a face
  is on it; none for a box one particle thick along an axis.
* ``mesh``: a volume mesh's boundary faces (the tetrahedron faces used once), a surface
  mesh's own faces (quads split in two); either turned outward.
"""

from __future__ import annotations

import numpy as np

from .surface import boundary, edges, empty, hull, outward, perimeter

Links = list[tuple[int, int]]


def _perimeter_links(first: int, count: int) -> Links:
    if count < 2:
        return []
    if count == 2:
        return [(first, first + 1)]
    return [(first + k, first + (k + 1) % count) for k in range(count)]


def _with_centre(perimeter: np.ndarray, center: bool) -> tuple[np.ndarray, Links]:
    count = len(perimeter)
    if not center:
        return perimeter, _perimeter_links(0, count)
    points = np.vstack([np.zeros((1, 2)), perimeter])
    spokes = [(0, k) for k in range(1, count + 1)]
    return points, spokes + _perimeter_links(1, count)


def ellipse(count: int, radii: tuple[float, float], center: bool) -> tuple[np.ndarray, Links]:
    """``count`` particles on an ellipse with semi-axes ``radii`` (a circle when equal)."""
    phi = 2.0 * np.pi * np.arange(count) / count
    perimeter = np.column_stack([radii[0] * np.cos(phi), radii[1] * np.sin(phi)])
    return _with_centre(perimeter, center)


def polygon(vertices: list[tuple[float, float]], center: bool) -> tuple[np.ndarray, Links]:
    """Particles at ``vertices``; braced by spokes (with a centre) or second-neighbour diagonals.

    Parameters
    ----------
    vertices : list of (x, y)
        In frame T, in order around the polygon (3 or more).
    center : bool
        Add a particle at the vertices' centroid (index 0) with a spoke to each vertex.

    Returns
    -------
    points : ndarray, shape (n, 2)
    links : list of (int, int)
        The edges, then the spokes or the diagonals ``(k, k + 2)`` (see the module docstring).
    """
    perimeter = np.asarray(vertices, dtype=float)
    if center:
        centroid = perimeter.mean(axis=0)
        points, links = _with_centre(perimeter - centroid, True)
        return points + centroid, links
    count = len(perimeter)
    links = _perimeter_links(0, count)
    if count > 3:
        braces = {tuple(sorted((k, (k + 2) % count))) for k in range(count)}
        links += sorted(braces)
    return perimeter, links


def ellipse_surface(count: int, center: bool) -> np.ndarray:
    """:func:`ellipse`'s perimeter, counter-clockwise (the centre is not on it), shape (count, 2);
    empty for two particles, which enclose nothing."""
    return perimeter(1 if center else 0, count)


def polygon_surface(vertices: list[tuple[float, float]], center: bool) -> np.ndarray:
    """:func:`polygon`'s edges, turned counter-clockwise if the vertices run clockwise, shape (n, 2)."""
    loop = perimeter(0, len(vertices))
    return outward(np.asarray(vertices, dtype=float), loop) + (1 if center else 0)


def chain(count: int, spacing: float) -> tuple[np.ndarray, Links]:
    """``count`` particles in a straight line along T's x-axis, centred on the origin.

    Returns
    -------
    points : ndarray, shape (count, 2)
        ``x = spacing * (k - (count - 1) / 2)``, ``y = 0``: the body's ``position`` is the
        chain's midpoint.
    links : list of (int, int)
        ``(k, k + 1)``: neighbours only, so the chain bends freely.
    """
    x = spacing * (np.arange(count) - (count - 1) / 2.0)
    points = np.column_stack([x, np.zeros(count)])
    return points, [(k, k + 1) for k in range(count - 1)]


def disc(count: int, radius: float) -> tuple[np.ndarray, Links]:
    """About ``count`` particles on a triangular lattice filling a disc of ``radius``.

    Every particle is linked to its lattice neighbours (up to six), so the body is braced
    against shear and its fastest mode does not grow with ``count`` (a spoked ring's centre
    mode does).  The spacing is chosen so the disc holds about ``count`` particles; the
    exact number is ``len(points)``.  Particles are ordered by row, bottom to top, and
    left to right within a row.
    """
    points, links, _ = _disc_lattice(count, radius)
    return points, links


def disc_surface(count: int, radius: float) -> np.ndarray:
    """The outward boundary of :func:`disc`'s lattice triangles, shape (m, 2).

    A particle held by a single link (no triangle) at the rim is not on it."""
    return disc_with_surface(count, radius)[2]


def disc_with_surface(count: int, radius: float) -> tuple[np.ndarray, Links, np.ndarray]:
    """:func:`disc` and :func:`disc_surface` from one lattice (building it is the slow part)."""
    points, links, triangles = _disc_lattice(count, radius)
    return points, links, boundary(points, triangles)


def _disc_lattice(count: int, radius: float) -> tuple[np.ndarray, Links, np.ndarray]:
    """:func:`disc`'s points and links, and its lattice triangles (counter-clockwise), shape (t, 3)."""
    spacing = radius * np.sqrt(np.pi / (count * np.sqrt(3.0) / 2.0))
    height = spacing * np.sqrt(3.0) / 2.0
    rows = int(np.ceil(radius / height))
    columns = int(np.ceil(radius / spacing)) + 1
    index: dict[tuple[int, int], int] = {}
    points = []
    for r in range(-rows, rows + 1):
        for c in range(-columns, columns + 1):
            x, y = c * spacing + 0.5 * spacing * (r % 2), r * height
            if x * x + y * y <= radius * radius * (1 + 1e-9):
                index[r, c] = len(points)
                points.append((x, y))
    links = []
    triangles = []
    for (r, c), i in index.items():  # right, and the two neighbours in the row above
        up = (c, c + 1) if r % 2 else (c - 1, c)
        right, left_up, right_up = index.get((r, c + 1)), index.get((r + 1, up[0])), index.get((r + 1, up[1]))
        links += [(i, j) for j in (right, left_up, right_up) if j is not None]
        # the triangle pointing up (right, then the shared neighbour above) and the one pointing down
        if right is not None and right_up is not None:
            triangles.append((i, right, right_up))
        if right_up is not None and left_up is not None:
            triangles.append((i, right_up, left_up))
    return np.array(points), links, np.array(triangles, dtype=np.intp).reshape(-1, 3)


# ----------------------------------------------------------------------------- 3D presets
# Points are (n, 3) in frame T; a body's ``rotation`` (a rotation vector) turns T in N.


def _edges(cells: np.ndarray) -> Links:
    """The unique edges of polygon or tetrahedron cells ``(m, k)``, as sorted index pairs."""
    return [(int(i), int(j)) for i, j in edges(cells)]


def sphere(count: int, radius: float, center: bool) -> tuple[np.ndarray, Links]:
    """``count`` particles spread quasi-uniformly over a sphere (a Fibonacci lattice),
    linked along the edges of their convex hull's triangles (a closed triangulated shell,
    which is rigid); with ``center`` a centre particle (index 0) and a spoke to each.
    The surface particles go from the south pole (-z) to the north pole (+z)."""
    from scipy.spatial import ConvexHull

    k = np.arange(count) + 0.5
    z = -1.0 + 2.0 * k / count
    phi = np.pi * (1.0 + 5.0**0.5) * k
    rho = np.sqrt(1.0 - z * z)
    surface = radius * np.column_stack([rho * np.cos(phi), rho * np.sin(phi), z])
    links = _edges(ConvexHull(surface).simplices) if count >= 4 else _edges(np.arange(count)[None, :])
    if not center:
        return surface, links
    points = np.vstack([np.zeros((1, 3)), surface])
    return points, [(0, i) for i in range(1, count + 1)] + [(i + 1, j + 1) for i, j in links]


def sphere_surface(points: np.ndarray, center: bool) -> np.ndarray:
    """:func:`sphere`'s convex hull, outward (the centre is not on it), shape (m, 3)."""
    first = 1 if center else 0
    return hull(points[first:]) + first


def box(count: tuple[int, int, int], size: tuple[float, float, float]) -> tuple[np.ndarray, Links]:
    """A lattice of ``nx x ny x nz`` particles spanning ``size = [a, b, c]``, centred on T's
    origin, ordered x fastest, then y, then z.  Each lattice cell is braced by its 12
    edges, both diagonals of its 6 faces and its 4 body diagonals, so the box is not a
    mechanism; a count of 1 along an axis makes a plate or a line of cells."""
    counts = [int(c) for c in count]
    axes = [np.linspace(-s / 2, s / 2, c) if c > 1 else np.zeros(1) for c, s in zip(counts, size)]
    zz, yy, xx = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    points = np.column_stack([xx.ravel(), yy.ravel(), zz.ravel()])
    index = np.arange(len(points)).reshape(counts[2], counts[1], counts[0])
    cells = []
    steps = [(dx, dy, dz) for dz in (0, 1) for dy in (0, 1) for dx in (0, 1)]
    for z0 in range(max(counts[2] - 1, 1)):
        for y0 in range(max(counts[1] - 1, 1)):
            for x0 in range(max(counts[0] - 1, 1)):
                corners = {index[min(z0 + dz, counts[2] - 1), min(y0 + dy, counts[1] - 1), min(x0 + dx, counts[0] - 1)]
                           for dx, dy, dz in steps}
                cells.append(sorted(corners))
    links = set()
    for corners in cells:  # every pair of a cell's corners: edges, face and body diagonals
        for a in range(len(corners)):
            for b in range(a + 1, len(corners)):
                links.add((int(corners[a]), int(corners[b])))
    return points, sorted(links)


def box_surface(count: tuple[int, int, int]) -> np.ndarray:
    """:func:`box`'s six faces, each lattice square split into two triangles, outward, shape (m, 3).

    Every particle on a face is on the surface (a convex hull would leave out those inside a
    flat face).  A box one particle thick along an axis encloses nothing: empty.
    """
    nx, ny, nz = (int(c) for c in count)
    if min(nx, ny, nz) < 2:
        return empty(3)
    index = np.arange(nx * ny * nz).reshape(nz, ny, nx)
    triangles = []
    for grid in (index[0], index[-1], index[:, 0], index[:, -1], index[:, :, 0], index[:, :, -1]):
        a, b = grid[:-1, :-1].ravel(), grid[1:, :-1].ravel()
        c, d = grid[1:, 1:].ravel(), grid[:-1, 1:].ravel()
        triangles += [np.column_stack([a, b, c]), np.column_stack([a, c, d])]
    triangles = np.vstack(triangles)
    # Orient each triangle by its face's outward direction, on the lattice's integer coordinates
    # (scaling the axes by the positive edge lengths keeps every orientation).
    zz, yy, xx = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    grid_points = np.column_stack([xx.ravel(), yy.ravel(), zz.ravel()]) - (np.array([nx, ny, nz]) - 1) / 2.0
    x = grid_points[triangles]
    normal = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])
    inward = np.einsum("ij,ij->i", normal, x.mean(axis=1)) < 0.0  # the box is convex about its centre
    triangles[inward, 1:] = triangles[inward, :0:-1]
    return triangles


class MeshError(ValueError):
    """A mesh file that cannot be a body: unreadable, no edges, duplicate vertices."""


def mesh(path, center: bool) -> tuple[np.ndarray, Links, np.ndarray, np.ndarray]:
    """Particles at a mesh file's vertices, linked along its cells' edges.

    Surface meshes (OBJ, STL, PLY: triangles, quads) give vertex particles and edge links;
    volume meshes (Gmsh ``.msh``, VTK: tetrahedra) give vertices and tetrahedron edges.
    With ``center`` (surface meshes) a centre particle at the vertices' mean (index 0)
    gets a spoke to each vertex.  Vertices in no cell are dropped.  Read with meshio.

    Returns
    -------
    points : ndarray, shape (n, 3)
    links : list of (int, int)
    shares : ndarray, shape (n,)
        Each particle's share of the total mass: a third of the area of its triangles
        (a quarter of the volume of its tetrahedra for volume meshes), normalised; the
        centre particle, if any, an equal share with the vertices.
    surface : ndarray of int, shape (m, 3)
        Outward triangles: a volume mesh's boundary faces (those of one tetrahedron only); a
        surface mesh's own faces (a quad as two triangles), all reversed if they enclose a
        negative volume.  Whether they close is checked where it matters (a colliding body).
    """
    import contextlib
    import io
    import warnings

    import meshio

    try:
        with warnings.catch_warnings(), contextlib.redirect_stdout(io.StringIO()):
            warnings.simplefilter("ignore")
            data = meshio.read(str(path))
    except Exception as exc:  # noqa: BLE001 - meshio raises many types for a bad file
        raise MeshError(f"cannot be read as a mesh: {exc}") from None
    points = np.asarray(data.points, dtype=float)
    if points.size == 0:
        raise MeshError("has no vertices (is it a mesh file?)")
    if points.ndim != 2 or points.shape[1] not in (2, 3) or not np.all(np.isfinite(points)):
        raise MeshError("its vertices are not finite 3D points")
    points = np.column_stack([points, np.zeros(len(points))]) if points.shape[1] == 2 else points
    volume = [c.data for c in data.cells if c.type == "tetra"]
    surface = [c.data for c in data.cells if c.type in ("triangle", "quad")]
    cells = volume or surface
    if not cells:
        kinds = sorted({c.type for c in data.cells}) or ["none"]
        raise MeshError(f"has no triangles, quads or tetrahedra (cells: {', '.join(kinds)}), so no edges to link")
    used = np.unique(np.concatenate([c.ravel() for c in cells]))
    renumber = np.full(len(points), -1)
    renumber[used] = np.arange(len(used))
    points = points[used]
    cells = [renumber[c] for c in cells]
    _, first, counts = np.unique(points, axis=0, return_index=True, return_counts=True)
    if np.any(counts > 1):
        raise MeshError(f"has {int(np.sum(counts[counts > 1] - 1))} duplicate vertices (the same point twice); "
                        "merge them in the mesh")
    links = sorted(set().union(*(_edges(c) for c in cells)))
    shares = np.zeros(len(points))
    for c in cells:
        corners = points[c]
        if volume:
            measure = np.abs(np.einsum("ij,ij->i", np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]),
                                       corners[:, 3] - corners[:, 0])) / 6.0
        else:  # a quad as two triangles
            measure = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
            if c.shape[1] == 4:
                measure += 0.5 * np.linalg.norm(np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 0]),
                                                axis=1)
        np.add.at(shares, c, (measure / c.shape[1])[:, None] * np.ones(c.shape[1]))
    if not shares.sum() > 0:
        raise MeshError("its cells have no area or volume (all vertices on a line or a plane)")
    shares /= shares.sum()
    if volume:
        faces = boundary(points, np.concatenate(cells))
    else:
        faces = outward(points, np.concatenate([
            np.concatenate([c[:, [0, 1, 2]], c[:, [0, 2, 3]]]) if c.shape[1] == 4 else c for c in cells]))
    if center and not volume:
        n = len(points)
        points = np.vstack([points.mean(axis=0), points])
        links = [(0, i + 1) for i in range(n)] + [(i + 1, j + 1) for i, j in links]
        shares = np.concatenate([[1.0], shares * n]) / (n + 1)
        faces = faces + 1
    return points, links, shares, faces
