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
"""

from __future__ import annotations

import numpy as np

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
    for (r, c), i in index.items():  # right, and the two neighbours in the row above
        up = (c, c + 1) if r % 2 else (c - 1, c)
        for key in ((r, c + 1), (r + 1, up[0]), (r + 1, up[1])):
            if key in index:
                links.append((i, index[key]))
    return np.array(points), links
