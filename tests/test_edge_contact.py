"""Edges of two 3D surfaces touching edge on edge (flexbody.edge_contact).

References: closed forms (two cubes crossed edge to edge a height apart, one falling
through the other at a known speed), an inside test of a convex body (the gap's sign
against where the closest point is), and a brute-force search over every pair of edges
(the k-d tree's candidates).
"""

from __future__ import annotations

import numpy as np
import pytest

from flexbody.edge_contact import convex_edges, edge_candidates, edge_contacts, surface_edges
from flexbody.scene import rotation_matrix
from flexbody.surface import hull
from flexbody.surface_contact import triangle_normals

CUBE = np.array([[i, j, k] for i in (0.0, 1.0) for j in (0.0, 1.0) for k in (0.0, 1.0)])


def convex_hull_edges(points: np.ndarray, offset: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """The convex edges of the hull of ``points`` (global indices from ``offset``) and their
    two triangles' unit normals, (e, 2) and (e, 2, 3)."""
    triangles = hull(points)
    edges, faces = surface_edges(triangles)
    convex = convex_edges(points, triangles, edges, faces)
    return edges[convex] + offset, triangle_normals(points, triangles)[faces[convex]]


def two_bodies(second_points: np.ndarray, first_points: np.ndarray = CUBE):
    """Positions of two convex bodies (the first's points, then the second's) and each
    one's convex edges (global indices) with their triangles' normals."""
    x = np.vstack([first_points, second_points])
    return x, *convex_hull_edges(first_points), *convex_hull_edges(second_points, len(first_points))


def crossed_cubes(height: float):
    """A cube turned 45 deg about y, its lowest edge along y at x = 0.5, ``height`` above
    the top front edge (along x at y = 0, z = 1) of the unit cube: they cross at the
    middle of both edges."""
    turned = CUBE @ rotation_matrix([0.0, np.pi / 4, 0.0]).T
    lowest = turned[:, 2].min()
    bottom = turned[np.isclose(turned[:, 2], lowest)]
    shift = np.array([0.5 - bottom[:, 0].mean(), -bottom[:, 1].mean(), 1.0 + height - lowest])
    return two_bodies(turned + shift)


def test_two_cubes_crossed_edge_to_edge_touch_once_at_the_middle_of_both_edges():
    """Their lowest and top front edges are the only pair: gap = the height (+ above, -
    once moved through), n = +z out of the lower cube, s = t = 1/2."""
    for height in (0.01, -0.01):
        x, edges_a, normals_a, edges_b, normals_b = crossed_cubes(height)
        # the upper cube's edges against the lower's: the upper one is "first"
        pairs = edge_candidates(x, edges_b, edges_a, reach=0.05)
        found = edge_contacts(x, edges_b, normals_b, edges_a, normals_a, pairs, reach=0.05)
        assert len(found.gap) == 1
        assert found.gap[0] == pytest.approx(height, rel=1e-12)
        np.testing.assert_allclose(found.normal[0], [0.0, 0.0, 1.0], atol=1e-12)
        np.testing.assert_allclose(found.parameters[0], [0.5, 0.5], atol=1e-12)
        lower_edge = edges_a[found.pair[0, 1]]
        np.testing.assert_allclose(np.sort(x[lower_edge][:, 0]), [0.0, 1.0])  # along x, at y = 0, z = 1
        np.testing.assert_allclose(x[lower_edge][:, 1:], [[0.0, 1.0], [0.0, 1.0]])
        # seen the other way round: the same contact, n out of the upper cube (-z), the same gap
        other = edge_contacts(x, edges_a, normals_a, edges_b, normals_b, pairs[:, ::-1], reach=0.05)
        assert len(other.gap) == 1 and other.gap[0] == pytest.approx(height, rel=1e-12)
        np.testing.assert_allclose(other.normal[0], [0.0, 0.0, -1.0], atol=1e-12)


def test_a_cube_falling_onto_a_crossed_edge_reaches_it_when_the_closed_form_says():
    """Falling at 2 m/s from 0.03 m above, the gap is 0.03 - 2 t: zero at t = 0.015 s, and
    linear in t on both sides (the event function an impact would be located on)."""
    x0, edges_a, normals_a, edges_b, normals_b = crossed_cubes(0.03)
    fall = np.zeros_like(x0)
    fall[8:, 2] = -2.0
    for t in np.linspace(0.0, 0.03, 7):
        x = x0 + fall * t
        found = edge_contacts(x, edges_b, normals_b, edges_a, normals_a, edge_candidates(x, edges_b, edges_a, 0.05),
                              reach=0.05)
        assert found.gap[0] == pytest.approx(0.03 - 2.0 * t, abs=1e-13)


def test_the_gaps_sign_says_whether_the_first_edge_is_inside_the_second_body(rng):
    """An edge laid across a cube's edge at a random point, along a random direction across
    it, offset by g along a random normal inside the cube's normal cone there: the gap is
    g, and its closest point is inside the cube (every face plane's distance < 0) exactly
    where g < 0."""
    triangles = hull(CUBE)
    edges, normals = convex_hull_edges(CUBE)
    assert len(edges) == 12  # the face diagonals are no edges of the cube
    face_normals, face_points = triangle_normals(CUBE, triangles), CUBE[triangles[:, 0]]
    checked = 0
    for _ in range(200):
        k = rng.integers(len(edges))
        c, d = CUBE[edges[k]]
        n1, n2 = normals[k]
        weights = rng.uniform(0.2, 1.0, size=2)
        n = weights[0] * n1 + weights[1] * n2
        n /= np.linalg.norm(n)
        along = np.cross(n, d - c)
        turn = rng.uniform(-0.6, 0.6)  # up to ~35 deg off square across the edge
        direction = np.cos(turn) * along / np.linalg.norm(along) + np.sin(turn) * (d - c) / np.linalg.norm(d - c)
        g = rng.uniform(-0.01, 0.01)
        t, s, length = rng.uniform(0.1, 0.9), rng.uniform(0.1, 0.9), rng.uniform(0.3, 1.0)
        p = c + t * (d - c) + g * n
        a, b = p - s * length * direction, p + (1 - s) * length * direction
        x = np.vstack([CUBE, a, b])
        # the first edge's own faces: their normals 40 deg either side of -n, about the edge
        axis = direction / np.linalg.norm(direction)
        own = np.array([[rotation_matrix(axis * angle) @ -n for angle in (-0.7, 0.7)]])
        found = edge_contacts(x, np.array([[8, 9]]), own, edges, normals,
                              np.column_stack([np.zeros(len(edges), np.intp), np.arange(len(edges))]), reach=0.05)
        mine = found.pair[:, 1] == k
        assert mine.sum() == 1
        assert found.gap[mine][0] == pytest.approx(g, abs=1e-12)
        np.testing.assert_allclose(found.parameters[mine][0], [s, t], atol=1e-9)
        # the point the function says is closest, inside the cube exactly where its gap is negative
        closest = a + found.parameters[mine][0, 0] * (b - a)
        inside = (np.einsum("fd,fd->f", face_normals, closest - face_points) < 0.0).all()
        assert inside == (found.gap[mine][0] < 0.0)
        checked += 1
    assert checked > 100


def test_ends_parallel_edges_and_far_pairs_are_not_edge_contacts():
    """Closest points past an edge's end (a vertex's contact), parallel edges (no common
    normal) and pairs farther than the reach are left out."""
    x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0],  # first edge along x
                  [1.5, -0.5, 0.01], [1.5, 0.5, 0.01],  # beyond its end: s = 1.5
                  [0.5, 0.0, 0.01], [0.7, 0.0, 0.01],  # parallel, just above it
                  [0.5, -0.5, 0.2], [0.5, 0.5, 0.2],  # crossing, 0.2 away
                  [0.5, -0.5, 0.01], [0.5, 0.5, 0.01]])  # crossing, 0.01 away: the one kept
    first, second = np.array([[0, 1]]), np.array([[2, 3], [4, 5], [6, 7], [8, 9]])
    # the first edge is a body's bottom edge (its faces face down), the others a body's top edges
    down = np.array([[[0.0, -0.6, -0.8], [0.0, 0.6, -0.8]]])
    up = np.array([[[-0.6, 0.0, 0.8], [0.6, 0.0, 0.8]]] * 4)  # edges along y
    up[1] = [[0.0, -0.6, 0.8], [0.0, 0.6, 0.8]]  # the parallel one, along x
    found = edge_contacts(x, first, down, second, up,
                          np.array([[0, 0], [0, 1], [0, 2], [0, 3]]), reach=0.05)
    assert found.pair.tolist() == [[0, 3]]
    assert found.gap[0] == pytest.approx(-0.01)  # the first edge is below the second: inside its body


def sphere_points(count: int, radius: float, centre) -> np.ndarray:
    """``count`` points spread over a sphere (a Fibonacci lattice), shape (count, 3)."""
    k = np.arange(count) + 0.5
    polar, azimuth = np.arccos(1 - 2 * k / count), np.pi * (1 + 5**0.5) * k
    return radius * np.column_stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth),
                                     np.cos(polar)]) + centre


def test_candidates_hold_every_pair_within_reach(rng):
    """The k-d tree's candidates hold every pair of edges of two 60-point spheres, close and
    turned at random, whose segments come within the reach (brute force: 21 x 21 points
    along every pair of segments), and leave most pairs out."""
    along = np.linspace(0.0, 1.0, 21)
    for _ in range(3):
        turn = rotation_matrix(rng.normal(size=3))
        points_b = sphere_points(60, 0.3, [0.0, 0.0, 0.0]) @ turn.T + [rng.uniform(0.56, 0.62), 0.0, 0.0]
        x, edges_a, _, edges_b, _ = two_bodies(points_b, sphere_points(60, 0.3, [0.0, 0.0, 0.0]))
        reach = 0.05
        on_a = x[edges_a[:, 0], None] + along[None, :, None] * (x[edges_a[:, 1]] - x[edges_a[:, 0]])[:, None]
        on_b = x[edges_b[:, 0], None] + along[None, :, None] * (x[edges_b[:, 1]] - x[edges_b[:, 0]])[:, None]
        closest = np.full((len(edges_a), len(edges_b)), np.inf)
        for i in range(len(edges_a)):
            gaps = np.linalg.norm(on_a[i][None, :, None] - on_b[:, None, :, :], axis=3)  # (eb, 21, 21)
            closest[i] = gaps.min(axis=(1, 2))
        within = {tuple(p) for p in np.argwhere(closest <= reach).tolist()}
        candidates = {tuple(p) for p in edge_candidates(x, edges_a, edges_b, reach).tolist()}
        assert len(within) > 0
        assert within <= candidates
        assert len(candidates) < 0.1 * closest.size


def test_every_row_asked_at_once_finds_what_each_finds_alone(rng):
    """A cube turned 45 deg about z over another, its bottom edges 1 mm above (or 0.1 mm
    through) the lower top's rims, each across two of them, some rows held: asking for every
    row at once (a search's whole sweep, with its shortcuts: the kept list in its order,
    only the rows with a held sibling looked up) gives each row the edge, side and gap it
    gets asked alone, and each row's left-out edges are its siblings' codes decoded."""
    from flexbody.edge_contact import EdgeSlots

    for h in (1e-3, -1e-4):
        top = (CUBE - 0.5) @ rotation_matrix([0.0, 0.0, np.pi / 4]).T + [0.5, 0.5, 1.5 + h]
        x = np.vstack([top, CUBE])
        elements = np.vstack([hull(top), hull(CUBE) + 8])
        slots = EdgeSlots(elements, np.repeat([0, 1], [len(hull(top)), len(hull(CUBE))]), [(0, 1)], x,
                          deforming=(0, 1))
        every, free = np.arange(len(slots)), np.full(len(slots), -1)
        gap, edge, side = slots.closest(x, every, free, reach=0.05)
        found = np.flatnonzero(edge >= 0)
        assert len(found) == 8 and np.allclose(gap[found], h, rtol=1e-9)  # 4 edges across 2 rims each
        for trial in range(4):
            held = free.copy()
            chosen = rng.choice(found, size=1 + trial, replace=False)
            held[chosen] = slots.encode(edge[chosen], side[chosen])
            answers = slots.closest(x, every, held, reach=0.05)
            for row in every.tolist():
                alone = slots.closest(x, np.array([row]), held, reach=0.05)
                assert [a[row] for a in answers] == [a[0] for a in alone], row
            left_out = slots.held_by_siblings(every, held)
            for row in every.tolist():
                want = [-1 if s == row or held[s] < 0 else held[s] % len(slots.edges)
                        for s in slots.siblings(np.array([row]))[0].tolist()]
                assert left_out[row].tolist() == want
            # with one of an edge's two rims held, its free rows take the other rim, once
            for row in chosen.tolist():
                pair = [r for r in slots.siblings(np.array([row]))[0].tolist() if r in found]
                if all(held[r] >= 0 for r in pair):
                    continue
                taken = sorted(int(answers[1][r]) for r in slots.siblings(np.array([row]))[0].tolist()
                               if held[r] < 0 and answers[1][r] >= 0)
                assert taken == sorted(int(edge[r]) for r in pair if r != row)


def test_an_edge_across_two_rims_is_held_by_two_of_its_rows():
    """A bar's bottom edges (along x) lie across a cube's two top rims (along y, at x = 0
    and 1), 1 cm above: each bottom edge has ``PER_EDGE`` rows, the first takes one rim,
    the second the other, both 1 cm apart, the others none; a row whose rules find no edge (its
    siblings holding the only ones in reach) is held against the nearest line, on the side
    that keeps it apart."""
    from flexbody.edge_contact import EdgeSlots

    h = 0.01
    bar = np.array([[x, y, z] for x in (-1.0, 2.0) for y in (0.4, 0.6) for z in (1.0 + h, 1.2)])
    x = np.vstack([bar, CUBE])
    elements = np.vstack([hull(bar), hull(CUBE) + 8])
    element_body = np.repeat([0, 1], [len(hull(bar)), len(hull(CUBE))])
    slots = EdgeSlots(elements, element_body, [(0, 1)], x)
    assert slots.n_primary == 12 and len(slots) == 12 * EdgeSlots.PER_EDGE  # the bar's 12 edges, PER_EDGE times
    bottom = [r for r in range(12) if np.allclose(x[slots.edges[slots.own[r]], 2], 1.0 + h)
              and np.ptp(x[slots.edges[slots.own[r]], 0]) == 3.0]
    assert len(bottom) == 2
    free = np.full(len(slots), -1)
    for row in bottom:
        rows = slots.siblings(np.array([row]))[0]
        gap, edge, side = slots.closest(x, rows, free, reach=0.05)
        np.testing.assert_allclose(gap, [h, h] + [0.05] * (EdgeSlots.PER_EDGE - 2), rtol=1e-12)  # the others: none
        assert (edge[2:] == -1).all()
        rims = x[slots.edges[edge[:2]]]
        assert sorted(rims[:, 0, 0].tolist()) == [0.0, 1.0] and np.allclose(rims[:, :, 2], 1.0)
        held = free.copy()
        held[row] = edge[0]  # the row holds the first rim: the second finds the other, the others none
        np.testing.assert_array_equal(slots.closest(x, rows[1:], held, reach=0.05)[1],
                                      [edge[1]] + [-1] * (EdgeSlots.PER_EDGE - 2))
        held[rows[1]] = edge[1]
        assert slots.closest(x, rows[2:], held, reach=0.05)[1][0] == -1
        # the second's rim taken: the row with no strict answer is held on the nearest line, apart
        lone, lone_side = slots.nearest(x, np.array([row]), held)
        assert lone[0] == edge[0] and lone_side[0] == side[0]  # the row's own rim, nearest, apart by h


def test_an_edge_across_a_strip_of_two_triangles_is_held_by_its_three_rows():
    """A bar's bottom edge lies across a square roof creased along its diagonal (two of its
    corners ``drop`` lower), h above the ridge: it crosses the ridge and two rims, which its
    three rows take, the ridge first (gap h exactly, the normal +z) and the two rims (gap
    about h + 0.8 drop, equal by symmetry); held on the ridge, the two others take the rims."""
    from flexbody.edge_contact import EdgeSlots

    h, drop = 1e-3, 0.01
    roof = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 0.0, -drop], [0.0, 1.0, -drop], [0.5, 0.5, -1.0]])
    along, across, up = np.array([1.0, -1.0, 0.0]) / np.sqrt(2.0), np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0), np.eye(3)[2]
    middle = np.array([0.6, 0.6, h])  # its bottom edge on x + y = 1.2: the rims at x = 1 and y = 1 at 0.2
    bar = np.array([middle + a * 1.5 * along + b * 0.1 * across + z * 0.2 * up
                    for a in (-1.0, 1.0) for b in (0.0, 1.0) for z in (0.0, 1.0)])
    x = np.vstack([bar, roof])
    elements = np.vstack([hull(bar), hull(roof) + 8])
    slots = EdgeSlots(elements, np.repeat([0, 1], [len(hull(bar)), len(hull(roof))]), [(0, 1)], x)
    row = next(r for r in range(slots.n_primary) if np.allclose(np.sum(x[slots.edges[slots.own[r]], :2], axis=1), 1.2)
               and np.allclose(x[slots.edges[slots.own[r]], 2], h))
    rows = slots.siblings(np.array([row]))[0]
    free = np.full(len(slots), -1)
    gap, edge, side = slots.closest(x, rows, free, reach=0.05)
    ridge = slots.edges[edge[0]]
    assert sorted(ridge.tolist()) == [8, 9]  # (0, 0, 0) to (1, 1, 0)
    assert gap[0] == pytest.approx(h, rel=1e-12)
    assert gap[1] == pytest.approx(gap[2], rel=1e-12) and gap[1] == pytest.approx(h + 0.8 * drop, rel=1e-3)
    assert len(set(edge[:3].tolist())) == 3 and (edge[3:] == -1).all()  # the ridge and two rims, no more
    held = free.copy()
    held[row] = slots.encode(edge[:1], side[:1])[0]
    assert sorted(slots.closest(x, rows[1:], held, reach=0.05)[1].tolist()) == sorted(edge[1:].tolist())


def test_an_edge_across_a_face_of_two_squares_has_a_row_for_each_of_its_five_lines():
    """A bar's bottom edge lies across a flexible box's face of two squares (a box three
    particles long), bent a hair outward along all its lines (a ridge along the middle
    line, each square a hair twisted): the edge crosses five lines, the two rims, the
    middle line and the two diagonals, each an edge contact.  Its rows take all five, the
    nearest first; held on three, two rows are still free, each watching one of the other
    two (with three rows none watched the fourth: in a fuzzed bridge of boxes the middle
    line went 3.9e-6 m through an edge held on a rim and both diagonals)."""
    from flexbody.edge_contact import EdgeSlots

    drop, twist, h = 0.01, 0.002, 1e-3
    face = np.array([[x, y, -drop * (x - 1.0) ** 2 + twist * x * y] for x in (0.0, 1.0, 2.0) for y in (0.0, 1.0)])
    block = np.vstack([face, [[1.0, 0.5, -1.0]]])  # closed by an apex below
    top = float(face[:, 2].max())
    bar = np.array([[x, y, top + h + z] for x in (-1.0, 3.0) for y in (0.4, 0.6) for z in (0.0, 0.2)])
    x = np.vstack([bar, block])
    elements = np.vstack([hull(bar), hull(block) + 8])
    slots = EdgeSlots(elements, np.repeat([0, 1], [len(hull(bar)), len(hull(block))]), [(0, 1)], x, deforming={1})
    row = next(r for r in range(slots.n_primary) if np.allclose(x[slots.edges[slots.own[r]], 1], 0.4)
               and np.allclose(x[slots.edges[slots.own[r]], 2], top + h))
    rows = slots.siblings(np.array([row]))[0]
    # the face's lines the edge crosses seen from above: every edge of the face (not the apex's)
    lines = {tuple(e) for e in slots.edges[slots.edge_body == 1].tolist() if max(e) < 8 + 6}
    crossed = {e for e in lines if (x[e[0], 1] - 0.4) * (x[e[1], 1] - 0.4) < 0.0}
    assert len(crossed) == 5
    free = np.full(len(slots), -1)
    gap, edge, side = slots.closest(x, rows, free, reach=0.05)
    found = [tuple(e) for e in slots.edges[edge[:5]].tolist()]
    assert set(found) == crossed and (gap[:5] > 0.0).all() and (np.diff(gap[:5]) >= 0.0).all()
    held = free.copy()
    held[rows[:3]] = slots.encode(edge[:3], side[:3])
    rest = slots.closest(x, rows[3:5], held, reach=0.05)[1]
    assert sorted(rest.tolist()) == sorted(edge[3:5].tolist())

def test_an_edge_lying_nearly_on_a_face_crosses_the_rim_as_an_edge_contact():
    """An edge laid over a cube's top front rim 2 degrees off lying flat on the top face:
    the common normal is 2 degrees outside the rim's arc (+z to -y), yet the pair is an edge
    contact (within CONE_SLACK): gap 1 mm, n the common normal.  Past 5 degrees it is not
    (the top face's vertices hold such an edge)."""
    c, d = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 1.0])  # the rim along x, faces +z (top) and -y (front)
    faces = np.array([[[0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]])
    for degrees, found in ((2.0, True), (8.0, False)):
        tilt = np.radians(degrees)
        n = np.array([0.0, np.sin(tilt), np.cos(tilt)])  # beyond +z, away from -y
        along = np.array([0.0, np.cos(tilt), -np.sin(tilt)])
        p = 0.5 * (c + d) + 1e-3 * n
        x = np.vstack([c, d, p - 0.02 * along, p + 0.02 * along])
        own = np.array([[rotation_matrix(along * angle) @ -n for angle in (-0.3, 0.3)]])
        got = edge_contacts(x, np.array([[2, 3]]), own, np.array([[0, 1]]), faces, np.array([[0, 0]]), reach=0.01)
        assert (len(got.gap) == 1) == found
        if found:
            assert got.gap[0] == pytest.approx(1e-3, rel=1e-9)
            np.testing.assert_allclose(got.normal[0], n, atol=1e-12)


def test_the_kept_candidate_list_holds_every_pair_within_reach_as_the_bodies_move(rng):
    """EdgeSlots' Verlet list (what the runtime searches): for two 60-point spheres moving
    towards each other, turning and stretching, at every position it holds each row's
    pairs with the other body's edges whose segments come within the reach (brute force,
    21 x 21 points along each pair), though it was made once and renewed only when needed."""
    from flexbody.edge_contact import EdgeSlots

    first = sphere_points(60, 0.3, [0.0, 0.0, 0.0])
    second = sphere_points(60, 0.3, [0.0, 0.0, 0.0]) @ rotation_matrix([0.3, -0.2, 0.5]).T
    x0 = np.vstack([first, second + [0.62, 0.0, 0.0]])
    elements = np.vstack([hull(first), hull(second) + 60])
    slots = EdgeSlots(elements, np.repeat([0, 1], len(hull(first))), [(0, 1)], x0)
    along = np.linspace(0.0, 1.0, 21)
    reach = 0.02
    checked = 0
    for step in range(12):
        x = x0.copy()
        x[60:] += [-0.004 * step, 0.001 * step, 0.0]  # closing in
        x[60:] = (x[60:] - x[60:].mean(axis=0)) * (1.0 + 0.002 * step) + x[60:].mean(axis=0)  # stretching
        which, other = slots._candidates(x, x[slots.edges], np.arange(slots.n_primary), reach)
        kept = set(zip(which.tolist(), other.tolist()))
        ends = x[slots.edges]
        for row in range(slots.n_primary):
            a, b = ends[slots.own[row]]
            on_row = a + along[:, None] * (b - a)
            theirs = np.flatnonzero(slots.edge_body == 1)
            on_theirs = ends[theirs, :1] + along[None, :, None] * (ends[theirs, 1:] - ends[theirs, :1])
            distance = np.linalg.norm(on_row[None, :, None] - on_theirs[:, None], axis=3).min(axis=(1, 2))
            for edge in theirs[distance <= reach]:
                assert (row, int(edge)) in kept
                checked += 1
    assert checked > 20  # the spheres came within reach
    assert 1 <= slots.rebuilds < 12  # kept between steps, renewed as the bodies moved


def test_a_face_creased_by_a_hair_along_its_diagonal_is_an_edge_from_its_first_crease(rng):
    """A square face creased along its diagonal (its two off-diagonal corners lowered by
    ``drop``, a ridge of angle ~2.8 drop) under an edge crossing the diagonal at its middle,
    ``height`` above it: once creased by 1e-6 rad the pair is an edge contact with gap =
    height (crossed by 1e-7 m: a pile's sphere creases so as it deforms, and the old flat
    test, 2 - |n1 + n2| <= 1e-9, counted the pair only from 6.3e-5 rad, already crossed);
    an exactly flat face is no edge contact, in any orientation (its normals differ by
    rounding)."""
    turn = rotation_matrix(rng.normal(size=3))
    for drop, height, found in ((1e-6 / (2.0 * np.sqrt(2.0)), -1e-7, True), (1e-6 / (2.0 * np.sqrt(2.0)), 1e-7, True),
                                (0.0, -1e-7, False), (0.0, 1e-7, False)):
        face = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 0.0, -drop], [0.0, 1.0, -drop], [0.5, 0.5, -1.0]])
        edge = np.array([[0.2, 0.8, height], [0.8, 0.2, height], [0.35, 0.35, height + 1.0], [0.65, 0.65, height + 1.0]])
        x, edges_a, normals_a, edges_b, normals_b = two_bodies(edge @ turn.T, face @ turn.T)
        got = edge_contacts(x, edges_b, normals_b, edges_a, normals_a, edge_candidates(x, edges_b, edges_a, 0.01),
                            reach=0.01)
        assert (len(got.gap) == 1) == found, (drop, height, got)
        if found:
            assert got.gap[0] == pytest.approx(height, abs=1e-12)
            np.testing.assert_allclose(got.parameters[0], [0.5, 0.5], atol=1e-6)
            np.testing.assert_allclose(got.normal[0], turn @ [0.0, 0.0, 1.0], atol=1e-6)


def _roof(drop: float) -> np.ndarray:
    """A unit square roof over an apex 1 below its middle, creased along its diagonal from
    (0, 0) to (1, 1) by lowering its two other corners by ``drop`` (negative: raising them,
    a valley)."""
    return np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 0.0, -drop], [0.0, 1.0, -drop], [0.5, 0.5, -1.0]])


def _bar_across_a_roof() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A bar (particles 0-7) whose bottom edge, at height 0, crosses the diagonal of
    :func:`_roof` (particles 8-12; the diagonal is 8-9) at its point (0.6, 0.6): the bar's
    points, the two bodies' triangles (the roof's split along its diagonal), each
    triangle's body, and the unit vector up."""
    along, across, up = np.array([1.0, -1.0, 0.0]) / np.sqrt(2.0), np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0), np.eye(3)[2]
    bar = np.array([np.array([0.6, 0.6, 0.0]) + a * 1.5 * along + b * 0.1 * across + z * 0.2 * up
                    for a in (-1.0, 1.0) for b in (0.0, 1.0) for z in (0.0, 1.0)])
    triangles = hull(_roof(0.01))  # the roof's surface: split along the ridge (8, 9)
    elements = np.vstack([hull(bar), triangles + 8])
    return bar, elements, np.repeat([0, 1], [len(hull(bar)), len(triangles)]), up


def _bottom_edge_rows(slots, x: np.ndarray) -> np.ndarray:
    """The rows of the bar's bottom edge (:func:`_bar_across_a_roof`) at ``x``, in rank order."""
    row = next(r for r in range(slots.n_primary) if np.allclose(np.sum(x[slots.edges[slots.own[r]], :2], axis=1), 1.2)
               and np.allclose(x[slots.edges[slots.own[r]], 2], x[:8, 2].min()))
    return slots.siblings(np.array([row]))[0]


def test_a_flexible_bodys_flat_diagonal_is_an_edge_while_it_creases_outward():
    """A bar's bottom edge 1 mm above the ridge of a square roof creased along its diagonal
    (two corners 1 cm lower), the roof flat at the start: for a flexible roof the ridge is
    an edge contact (gap h exactly), as it would be had it started creased; a rigid roof's
    diagonal, flat at the start, stays flat and is none.  Creased inward (the two corners 1
    cm higher, a valley) the diagonal is none either: the bar meets the rims first.  Before,
    every body's flat diagonals were left out (a fuzzed stack of boxes: a rigid box's rim
    went 0.5 mm through a flexible box's bottom diagonal)."""
    from flexbody.edge_contact import EdgeSlots

    h = 1e-3
    bar, elements, element_body, up = _bar_across_a_roof()
    x0 = np.vstack([bar + h * up, _roof(0.0)])
    for drop, deforming, ridge in ((0.01, {1}, True), (0.01, set(), False), (-0.01, {1}, False)):
        x = np.vstack([bar + (h + max(0.0, -drop)) * up, _roof(drop)])
        slots = EdgeSlots(elements, element_body, [(0, 1)], x0, deforming=deforming)
        gap, edge, _ = slots.closest(x, _bottom_edge_rows(slots, x), np.full(len(slots), -1), reach=0.05)
        found = [sorted(slots.edges[e].tolist()) for e in edge[edge >= 0]]
        assert ([8, 9] in found) == ridge, (drop, deforming, found)
        if ridge:
            assert gap[0] == pytest.approx(h, rel=1e-9) and found[0] == [8, 9]
        else:  # the rims alone, apart
            assert len(found) == 2 and (gap[edge >= 0] > h).all()


def test_a_diagonal_turning_concave_while_crossed_stays_an_edge_through_the_segment():
    """The flexible roof's diagonal a ridge at a segment's start (two corners 1 cm lower),
    then a valley (the two corners 1e-6 higher) with the bar's bottom edge 1e-7 below it:
    the pair stays an edge contact, gap -1e-7, through the segment.  A crossing begun while
    the diagonal was a ridge does not end where it turns concave, and before, the free
    row's gap jumped from the crossing to the margin there, a sign change no point of the
    step saw (a fuzzed stack: a box's top diagonal flattening under the next box's bottom
    rim, crossed by it 3.5 us before it turned, went 1.2e-9 m through unseen).  Apart (the
    edge 1e-7 above the valley), or a valley already at the segment's start, it is none."""
    from flexbody.edge_contact import EdgeSlots

    h, drop = 1e-7, 1e-6
    bar, elements, element_body, up = _bar_across_a_roof()
    x0 = np.vstack([bar, _roof(0.0)])
    for start, height, kept in ((0.01, -h, True), (0.01, h, False), (-drop, -h, False)):
        x = np.vstack([bar + height * up, _roof(-drop)])
        slots = EdgeSlots(elements, element_body, [(0, 1)], x0, deforming={1})
        slots.start_segment(np.vstack([bar, _roof(start)]))
        gap, edge, _ = slots.closest(x, _bottom_edge_rows(slots, x), np.full(len(slots), -1), reach=0.05)
        found = [sorted(slots.edges[e].tolist()) for e in edge[edge >= 0]]
        assert ([8, 9] in found) == kept, (start, height, found)
        if kept:
            assert gap[found.index([8, 9])] == pytest.approx(-h, rel=1e-6)


def test_an_edge_crossed_past_an_acute_rim_is_seen_crossed():
    """A wedge's bottom edge (along y) 1 mm below the rim (along x) of a prism whose rim is
    acute (73 deg: its side face leans in under the top face): the lines' closest point on
    the wedge's edge lies outside the prism, beyond its side face, by 0.29 of the depth, yet
    the edges have crossed (each passes through one of the other's triangles): the pair
    reads gap -1 mm, as a step's end that went past the touch must see it.  Before, its
    closest point had to be inside the prism, and the crossing read no contact (in a fuzzed
    stack of boxes a flexible box's rim, bent acute, let a rigid box's edge through)."""
    from flexbody.edge_contact import EdgeSlots

    h = 1e-3
    prism = np.array([[x, y, z] for x in (-1.0, 1.0) for (y, z) in ((0.0, 0.0), (1.0, 0.0), (0.3, -1.0))])
    wedge = np.array([[0.0, y, -h] for y in (-0.5, 0.5)] + [[x, y, 0.3] for x in (-0.2, 0.2) for y in (-0.5, 0.5)])
    x = np.vstack([prism, wedge])
    elements = np.vstack([hull(prism), hull(wedge) + 6])
    slots = EdgeSlots(elements, np.repeat([0, 1], [len(hull(prism)), len(hull(wedge))]), [(0, 1)], x)
    rim = next(r for r in range(slots.n_primary) if sorted(slots.edges[slots.own[r]].tolist()) == [0, 3])
    gap, edge, side = slots.closest(x, np.array([rim]), np.full(len(slots), -1), reach=0.05)
    assert sorted(slots.edges[edge[0]].tolist()) == [6, 7]
    assert gap[0] == pytest.approx(-h, rel=1e-9)
    # the closest point (0, 0, -h) is outside the prism: its side face passes y = 0.3 h there
    side_normal = np.array([0.0, -1.0, -0.3]) / np.linalg.norm([1.0, 0.3])
    assert side_normal @ (np.array([0.0, 0.0, -h]) - prism[0]) == pytest.approx(0.3 * h / np.linalg.norm([1.0, 0.3]))
    # the same edge 1 mm above the rim: apart by h
    wedge_above = wedge + np.array([0.0, 0.0, 2.0 * h])
    gap_above = slots.closest(np.vstack([prism, wedge_above]), np.array([rim]), np.full(len(slots), -1), reach=0.05)[0]
    assert gap_above[0] == pytest.approx(h, rel=1e-9)


def test_a_crossing_counts_how_deep_the_edges_points_are_inside_the_other_body():
    """What the penetration counts of an edge row read crossed (EdgeSlots.crossing_depths):
    the lesser distance of its lines' closest points to the other body's surface.  Two
    cubes crossed edge through edge by h (their edges at right angles, the common normal
    along the upper cube's 45 deg bisector): the lower edge's middle is h / sqrt 2 inside
    the turned cube, the upper edge's middle on the lower cube's front face; apart by h,
    both points are h outside.  Two cubes side by side, the second turned 1e-3 rad about x
    and pushed d = 1e-6 m into the first (coincident rim edges nearly parallel, as in a
    struck row of boxes): their top rims' lines read d crossed along x, yet their closest
    points lie on the other cube's top face (a vertex's depth, 0, not d's).  The C kernels
    and surface search read the same as NumPy's, to rounding."""
    from flexbody.edge_contact import EdgeSlots
    from flexbody.surface_contact import CompiledClosestFeatures

    def crossing(x, n_first, own_edge):
        elements = np.vstack([hull(x[:n_first]), hull(x[n_first:]) + n_first])
        element_body = np.repeat([0, 1], [len(hull(x[:n_first])), len(hull(x[n_first:]))])
        read = []
        for backend in ("numpy", "c"):
            search = CompiledClosestFeatures(elements, len(x), element_body) if backend == "c" else None
            slots = EdgeSlots(elements, element_body, [(0, 1)], x, backend, surface_search=search)
            row = next(r for r in range(slots.n_primary) if own_edge(x[slots.edges[slots.own[r]]]))
            gap, edge, side = slots.closest(x, np.array([row]), np.full(len(slots), -1), reach=0.05)
            assert edge[0] >= 0
            read.append((gap[0], slots.crossing_depths(x, np.array([row]), slots.encode(edge, side))[0]))
        np.testing.assert_allclose(read[1], read[0], rtol=1e-13, atol=1e-16)
        return read[0]

    for h in (0.01, -0.01):
        x, *_ = crossed_cubes(h)
        turned = x[8:]
        x = np.vstack([turned, CUBE])  # the turned cube first: its edge is the row's
        line_gap, depth = crossing(x, 8, lambda e: np.allclose(e[:, 0], 0.5) and np.allclose(e[:, 2], 1.0 + h))
        assert line_gap == pytest.approx(h, rel=1e-12)
        assert depth == pytest.approx(h if h > 0 else h / np.sqrt(2.0), rel=1e-9)
    d, angle = 1e-6, 1e-3
    second = (CUBE - [0.0, 0.5, 1.0]) @ rotation_matrix([angle, 0.0, 0.0]).T + [1.0 - d, 0.5, 1.0]
    x = np.vstack([CUBE, second])
    line_gap, depth = crossing(x, 8, lambda e: np.allclose(e[:, 0], 1.0) and np.allclose(e[:, 2], 1.0))
    assert line_gap == pytest.approx(-d, rel=1e-6)
    assert abs(depth) < 1e-15 and depth > line_gap


def _corner_under_a_wedge(d: float, bottom_slope: float = 1e-3, back: float = 3e-3, height: float = 0.5):
    """Two boxes on one ground (z = 0), as a fuzzed leaning box met another: a box A (x in
    [0, 1], y in [-1, 0]) whose vertical edge at its corner (0, 0, 0) leans 3e-4 rad toward
    -x, and a box B (``height`` tall) whose bottom edge (along y, from y = -2 to 1, at z =
    0) lies at x = d (> 0: d past A's side face x = 0), its bottom face rising toward -x by
    ``bottom_slope``, its side face at that edge leaning ``back`` (rad) past the vertical.
    Returns the positions, the edge slots (A's edges against B's), A's vertical corner
    edge's row and B's bottom edge."""
    from flexbody.edge_contact import EdgeSlots

    lean, width = -3e-4, 0.5
    a = np.array([[x + lean * z, y, z] for x in (0.0, 1.0) for y in (-1.0, 0.0) for z in (0.0, 1.0)])
    b = np.array([[d - w - back * z, y, bottom_slope * w + z] for w in (0.0, width) for y in (-2.0, 1.0)
                  for z in (0.0, height)])
    x = np.vstack([a, b])
    elements = np.vstack([hull(a), hull(b) + 8])
    slots = EdgeSlots(elements, np.repeat([0, 1], [len(hull(a)), len(hull(b))]), [(0, 1)], x)
    corner = int(np.flatnonzero(np.all(x[:8] == [0.0, 0.0, 0.0], axis=1))[0])
    row = next(r for r in range(slots.n_primary) if corner in slots.edges[slots.own[r]]
               and np.ptp(x[slots.edges[slots.own[r]], 2]) == 1.0)
    bottom = next(e for e in range(len(slots.edges)) if slots.edge_body[e] == 1
                  and np.allclose(x[slots.edges[e]], [[d, -2.0, 0.0], [d, 1.0, 0.0]]))
    return x, slots, row, bottom


def test_a_corner_passing_under_a_wedge_keeps_the_edge_contact_past_its_end():
    """A box's bottom edge pressed sideways onto another box's corner, both on one ground
    (tests/reference/fuzz_leaning_box_corner_under_edge.json): the corner's vertical edge and
    that bottom edge meet at the corner, and once crossed (by d) their lines' closest point
    is below the corner by d times the vertical edge's lean, past its end (3e-9 of it for
    d = 1e-5 m, beyond AT_END).  The corner passes beneath the wedge (its bottom face rises
    away), outside it, while the vertical edge goes through the wedge: no vertex's contact
    sees the crossing, and the pair reads it, gap -d.  Before, the pair was dropped past
    the end and the edges crossed unseen (7.2e-5 m).  Apart by d, the pair reads +d (its
    closest point on the edge); with the corner inside the wedge deeper than half the
    crossing (its bottom face dipping 45 deg below the ground: 0.71 d), past the end the
    crossing is the corner's, no edge contact."""
    from flexbody.edge_contact import AT_END

    for d in (1e-5, 1e-4):
        x, slots, row, bottom = _corner_under_a_wedge(d)
        free = np.full(len(slots), -1)
        gap, edge, side = slots.closest(x, slots.siblings(np.array([row]))[0], free, reach=0.05)
        assert edge[0] == bottom
        assert gap[0] == pytest.approx(-d, rel=1e-3)
        parameters = slots.kernels.edge_3d(*slots._ends(x, slots.points(np.array([row]), slots.encode(edge[:1], side[:1])),
                                                        slots.encode(edge[:1], side[:1])))[1]
        corner = int(np.flatnonzero(np.all(x[:8] == 0.0, axis=1))[0])
        s = parameters[0, 0] if slots.edges[slots.own[row], 0] == corner else 1.0 - parameters[0, 0]
        assert -s > AT_END  # past the corner's end of the edge
    x, slots, row, bottom = _corner_under_a_wedge(-1e-5)
    gap, edge, _ = slots.closest(x, np.array([row]), np.full(len(slots), -1), reach=0.05)
    assert edge[0] == bottom and gap[0] == pytest.approx(1e-5, rel=1e-3)
    x, slots, row, bottom = _corner_under_a_wedge(1e-5, bottom_slope=-1.0)  # the corner 0.71 d inside B
    gap, edge, _ = slots.closest(x, slots.siblings(np.array([row]))[0], np.full(len(slots), -1), reach=0.05)
    assert bottom not in edge.tolist()


def test_a_corner_edge_from_a_wedges_bottom_face_to_its_side_face_keeps_the_edge_contact():
    """The corner under a wedge as above, but on the plane of its bottom face (flat, on the
    ground) and with A's top corner on its side face, as vertex contacts hold them (B taller
    than A, its side face leaning back d + 3e-4 rad: tests/reference/
    fuzz_row_corner_edge_on_both_rim_faces.json).  Crossed by d, the vertical edge cuts the
    wedge from one face to the other with both ends on their planes: strictly through
    neither triangle, and the pair was refused past the end.  From a triangle into the body
    counts as through it: the pair reads the crossing, gap -d."""
    for d in (1e-5, 1e-4):
        x, slots, row, bottom = _corner_under_a_wedge(d, bottom_slope=0.0, back=d + 3e-4, height=1.5)
        gap, edge, _ = slots.closest(x, slots.siblings(np.array([row]))[0], np.full(len(slots), -1), reach=0.05)
        assert edge[0] == bottom
        assert gap[0] == pytest.approx(-d, rel=1e-3)
