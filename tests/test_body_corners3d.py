"""Concave corners between 3D bodies (flexbody.body_contact): a particle held on the two
faces of a concave edge slides along the edge up to its end, and in an inner corner where
three faces meet it is held by three rows.

References: statics (at rest in a corner of three orthogonal walls, the normal forces add
up to the weight's components along the walls' normals), the bodies' surfaces (nothing
inside another body), and the barycentric weights of a point on a triangle's edge.
"""

from __future__ import annotations

import itertools
from typing import NamedTuple

import numpy as np
import pytest

import flexbody
from flexbody.contact import FREE, HELD, Event
from flexbody.driver import _Run, _settings
from flexbody.model import load_model

from .conftest import reference_table

G = 9.81
#: A light tetrahedron whose apex carries nearly all its mass: the particle that finds the corner.
TET_MASSES = [0.05, 0.001, 0.001, 0.001]
TET_SURFACE = [[0, 2, 1], [0, 3, 2], [0, 1, 3], [1, 2, 3]]
TET_LINKS = [[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]]


def _notched_block(size: float = 0.1):
    """A cube of side ``2 size`` without the cube ``[size, 2 size]^3``: seven voxels, their
    outer faces split into triangles (outward), every pair of a voxel's corners linked.  The
    notch's inner corner, ``(size, size, size)``, is a concave vertex of three faces."""
    voxels = [c for c in itertools.product((0, 1), repeat=3) if c != (1, 1, 1)]
    squares = []
    for voxel, axis, side in itertools.product(voxels, range(3), (0, 1)):
        beside = list(voxel)
        beside[axis] += 1 if side else -1
        if tuple(beside) in voxels:
            continue
        u, w = [a for a in range(3) if a != axis]
        corners = []
        for du, dw in ((0, 0), (1, 0), (1, 1), (0, 1)):
            p = list(voxel)
            p[axis] += side
            p[u] += du
            p[w] += dw
            corners.append(tuple(p))
        normal = np.zeros(3)
        normal[axis] = 1.0 if side else -1.0
        a, b, c = (np.array(p, float) for p in corners[:3])
        squares.append(corners if np.cross(b - a, c - a) @ normal > 0 else corners[::-1])
    points = sorted({p for square in squares for p in square})
    index = {p: i for i, p in enumerate(points)}
    triangles = []
    for square in squares:
        a, b, c, d = (index[p] for p in square)
        triangles += [[a, b, c], [a, c, d]]
    links = set()
    for voxel in voxels:
        inside = [i for i, p in enumerate(points) if all(voxel[k] <= p[k] <= voxel[k] + 1 for k in range(3))]
        links |= set(itertools.combinations(inside, 2))
    return (size * np.array(points, float)).tolist(), sorted(links), triangles, index[(1, 1, 1)]


def _tetrahedron(axis: np.ndarray, length: float = 0.03, half_angle_deg: float = 10.0) -> list:
    """Apex at the origin, its base ``length`` along ``axis``, a narrow cone around it."""
    axis = axis / np.linalg.norm(axis)
    e1 = np.cross(axis, [1.0, 0.0, 0.0] if abs(axis[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(axis, e1)
    half = np.radians(half_angle_deg)
    base = [length * (np.cos(half) * axis + np.sin(half) * (np.cos(a) * e1 + np.sin(a) * e2))
            for a in (0.0, 2.0 * np.pi / 3.0, 4.0 * np.pi / 3.0)]
    return [[0.0, 0.0, 0.0]] + [b.tolist() for b in base]


def _notch_scene(t_end: float) -> tuple[dict, int, np.ndarray]:
    """A notched block held by three grounds (x, y, z = 0), gravity towards its notch's inner
    corner, and a tetrahedron dropped apex first into the notch: the apex lands on the
    floor, slides into the edge with one wall, along it into the corner."""
    points, links, triangles, corner = _notched_block()
    direction = np.array([0.36, 0.48, 0.8])  # a unit vector
    table = {
        "name": "notch", "gravity": (-G * direction).tolist(),
        "grounds": [{"point": [0.0, 0.0, 0.0], "normal": n} for n in ([1, 0, 0], [0, 1, 0], [0, 0, 1])],
        "bodies": [
            {"name": "block", "particles": points, "links": [list(k) for k in links], "surface": triangles,
             "mass": 1.0, "stiffness": 2e4, "damping": 5.0, "position": [0.0, 0.0, 0.0]},
            {"name": "tet", "particles": _tetrahedron(direction), "links": TET_LINKS, "surface": TET_SURFACE,
             "masses": TET_MASSES, "stiffness": 500.0, "damping": 0.2, "position": [0.103, 0.102, 0.1005]},
        ],
        "contacts": [{"bodies": ["block", "tet"]}],
        "simulation": {"t_end": t_end, "output_dt": 1e-3},
    }
    return table, corner, direction


def test_a_particle_in_a_three_face_inner_corner_is_held_by_three_rows():
    """The apex reaches the notch's inner corner and rests there, against its three walls
    at once: no wall lets it through (with two rows it went 0.03 m into the third), it ends
    at the corner's vertex, and the walls' normal forces add up to the tetrahedron's weight
    along their normals (the walls stay orthogonal to 1e-3 rad; the rest of the
    tetrahedron touches nothing)."""
    table, corner, direction = _notch_scene(1.0)
    result = flexbody.simulate(flexbody.load_scene(table))
    assert result.status == "success", result.message
    assert result.stats["max_penetration_m"] <= 1e-9  # measured 1.4e-12
    apex = len(table["bodies"][0]["particles"])
    np.testing.assert_allclose(result.positions[-1, apex], result.positions[-1, corner], rtol=0, atol=1e-9)
    weight = sum(TET_MASSES) * G
    assert result.contact_force[-1, apex] == pytest.approx(weight * direction.sum(), rel=2e-3)  # measured 5e-4
    assert not (result.contact_force[-1, apex + 1 :] > 0).any()


def _trough(segments: int = 4, length: float = 0.2, half_width: float = 0.05, height: float = 0.04,
            depth: float = 0.02):
    """A prism along x whose top is a V groove (its crease at y = 0, z = height - depth),
    ``segments`` long; its flanks' triangles run the crease from vertex to vertex."""
    section = [(-half_width, 0.0), (half_width, 0.0), (half_width, height), (0.0, height - depth),
               (-half_width, height)]  # (y, z), counter-clockwise seen from +x
    k = len(section)
    points = [[x, y, z] for x in np.linspace(0.0, length, segments + 1) for y, z in section]
    triangles = []
    for i, j in itertools.product(range(segments), range(k)):
        a, b = i * k + j, i * k + (j + 1) % k
        triangles += [[a, b + k, a + k], [a, b, b + k]]
    caps = [[3, 4, 0], [3, 0, 1], [3, 1, 2]]  # fans from the groove's (reflex) vertex
    triangles += [[a, c, b] for a, b, c in caps] + [[segments * k + v for v in cap] for cap in caps]
    links = set()
    for i in range(segments):
        links |= set(itertools.combinations(range(i * k, (i + 2) * k), 2))
    return points, sorted(links), triangles, height - depth


def _trough_scene(height: float, velocity: float, t_end: float) -> tuple[dict, list, float]:
    """The trough on the ground and a tetrahedron, apex down, ``height`` above its crease at
    x = 0.02 m, moving along it at ``velocity``; also the trough's particles and the crease's z."""
    points, links, triangles, bottom = _trough()
    table = {
        "name": "trough", "gravity": [0.0, 0.0, -G],
        "bodies": [
            {"name": "block", "particles": points, "links": [list(k) for k in links], "surface": triangles,
             "mass": 1.0, "stiffness": 2e4, "damping": 5.0, "position": [0.0, 0.0, 0.0]},
            {"name": "tet", "particles": _tetrahedron(np.array([0.0, 0.0, 1.0]), length=0.02), "links": TET_LINKS,
             "surface": TET_SURFACE, "masses": TET_MASSES, "stiffness": 500.0, "damping": 0.2,
             "position": [0.02, 0.0, bottom + height], "velocity": [velocity, 0.0, 0.0]},
        ],
        "contacts": [{"bodies": ["block", "tet"]}],
        "simulation": {"t_end": t_end, "output_dt": 1e-3},
    }
    return table, points, bottom


def test_a_particle_sliding_along_a_concave_crease_stays_in_it_across_its_vertices():
    """A tetrahedron dropped apex first onto the crease of a V groove, sliding along it at
    0.4 m/s: the apex lands on the edge between the flanks (a hair past one face's boundary:
    that must still be an event, else it slid on along the face's plane, 0.02 m into the
    other flank), ends up held on both, and goes on along the crease past its vertices at
    its speed."""
    table, points, bottom = _trough_scene(height=0.0005, velocity=0.4, t_end=0.4)
    result = flexbody.simulate(flexbody.load_scene(table))
    assert result.status == "success", result.message
    assert result.stats["max_penetration_m"] <= 1e-9  # measured 2.1e-12
    apex = len(points)
    x = result.positions[:, apex]
    # past the crease's three inner vertices (0.05, 0.1, 0.15 m), its speed kept: there the
    # crease's vertex met the apex, vertex to vertex (an impact that took 70 % of its speed),
    # and at 0.1 m the apex passed onto a face bent 1e-4 rad up from the one it left (the
    # trough sags), both held (the corner) and stopped: half its speed
    assert x[-1, 0] > 0.15 + 0.02  # measured 0.1787
    speed = (x[-1, 0] - x[-101, 0]) / (result.t[-1] - result.t[-101])  # over the last 0.1 s
    assert speed == pytest.approx(0.4, abs=0.01)  # measured 0.397
    assert abs(x[-1, 1]) < 1e-6 and abs(x[-1, 2] - bottom) < 1e-3  # in the crease (the block sags 0.8 mm)


def test_a_particle_held_on_both_faces_of_a_concave_edge_has_the_edges_ends_for_boundary():
    """Held on the two crease faces of the first segment, a particle on the crease at x
    projects onto each face on its edge: the third vertex's weight is 0 all along it, so it
    bounds nothing (it would make every point of the crease a boundary).  The margin is the
    crease vertices' smaller weight times the face's size, reaching 0 at the edge's end;
    there the slot (alone: its twin follows at its own event) is handed on, held, to the
    next face along the crease."""
    table, points, bottom = _trough_scene(height=0.01, velocity=0.0, t_end=0.1)
    scene = flexbody.load_scene(table)
    model = load_model(scene, backend="numpy")
    p, ng, apex = model.parameters(scene), model.n_ground_contacts, len(points)
    crease = [3, 8]  # the crease's first edge: (0, 0, bottom) to (0.05, 0, bottom)
    faces = [e for e in range(len(model.elements)) if set(crease) <= set(model.elements[e].tolist())]
    assert len(faces) == 2
    slot = int(model._slots_of(np.array([apex]), np.array([0]))[0][0])
    rows = [slot, slot + model.n_primary]
    held = np.zeros(model.n_contacts, np.intc)
    held[ng + np.array(rows)] = 1

    def state(x_apex):
        q = scene.initial_positions().copy()
        q[apex] = [x_apex, 0.0, bottom]
        u = np.zeros_like(q)
        u[apex] = [0.4, 0.0, 0.0]
        return np.concatenate([q.ravel(), u.ravel(), np.zeros(model.ny - 2 * q.size)])

    for x_apex in (0.01, 0.03, 0.045):
        model.element_of[rows] = faces
        margins = model.element_margins(state(x_apex), p, held)[ng + np.array(rows)]
        for face, margin in zip(faces, margins):
            e = model.elements[face]
            size = np.linalg.norm(np.subtract(points[e[1]], points[e[0]]))
            assert margin == pytest.approx(min(x_apex, 0.05 - x_apex) / 0.05 * size, rel=1e-9)
    model.element_of[rows] = faces
    moved = model.switch_elements(state(0.05 + 1e-9), p, held, gap_tolerance=1e-12, speed_tolerance=1e-7)
    assert moved.stay.tolist() == [ng + slot] and not len(moved.approach) and not len(moved.leave)
    assert 8 in model.elements[model.element_of[slot]] and model.element_of[slot] not in faces
    assert model.element_of[rows[1]] in faces  # the twin waits for its own event


def _row_runs_clean(name: str, max_wall_time: float) -> None:
    """The frictionless row of boxes ``tests/reference/<name>.json`` runs to its end with
    no penetration, edge crossing or warning, its ledger closed and its momentum along x
    (the push) kept."""
    r = flexbody.simulate(flexbody.load_scene(reference_table(name)), max_wall_time=max_wall_time)
    assert r.status == "success", r.message
    assert r.stats["max_penetration_m"] < 1e-9
    assert r.stats["max_edge_crossing_m"] == 0.0
    assert not r.stats["warnings"]
    assert r.stats["energy_drift_relative"] < 1e-6
    momentum = np.einsum("i,tid->td", r.masses, r.velocities)[:, 0]  # frictionless ground: kept along x
    np.testing.assert_allclose(momentum, momentum[0], rtol=1e-9)


def test_a_particle_dithering_across_a_slightly_concave_crease_keeps_its_twin():
    """An eleventh fuzz's row (tests/reference/fuzz_row_dithering_on_a_crease.json: two
    flexible 4 x 3 x 2 boxes side by side on a frictionless ground, 1e-6 m apart, b1's
    lattice points on b0's, b0 pushed at 0.897 m/s, e = 0.183, `edges = true`).  b1's
    bottom rim midpoint slides up b0's face along the face's vertical middle line, a crease
    concave by more than rounding, crossing it back and forth by ~1e-11 m at ~2e-6 m/s (the
    undamped face vibrating) with a normal approach of 2e-9 m/s.  Met tangentially, each
    crossing keeps a corner twin on the old triangle; a rule that made every crossing faster
    than the speed tolerance an impact without a twin (tried for a stack's corner sliding
    across a face diagonal) made it an impact and a hold every 10-20 us, `chattering` at
    2.8 ms.  The crease here, 8e-4 rad, has a line the held pair slides along; only
    creases flatter than ``EDGE_LINE`` take the rule now (the next test)."""
    _row_runs_clean("fuzz_row_dithering_on_a_crease", 120.0)  # measured 2.0e-12 m, drift 3.5e-9


def test_the_same_row_with_no_gap_runs_to_its_end():
    """The row above with its 1e-6 m gap closed (tests/reference/fuzz_row_on_a_crease_gap_0.json,
    the boxes touching from the start) was `too_slow` at 6 ms (6 632 events in 120 s) and
    read a held force of -79 N between event checks.  Its force LCPs tied rows across
    large divisors (Lemke's ratio test now judges ties in the tableau's units): 162 events
    to its end, no warning."""
    _row_runs_clean("fuzz_row_on_a_crease_gap_0", 60.0)  # measured 2.5e-12 m, drift 3.6e-9


def test_a_corner_sliding_over_a_diagonal_creased_by_a_hair_hits_the_next_triangle():
    """A seventh fuzz's stack of three flexible boxes (tests/reference/fuzz_stack_corner_over_diagonal.json,
    cut to 9.5 ms; frictionless, e = 0, edges): b0's top corner 19, held on b1's bottom
    face, slides at 0.19 m/s across that face's diagonal, creased concave by 5e-7 rad, onto
    the next triangle at 1e-7 m/s (below the speed tolerance, 3.1e-7).  Met tangentially, it
    kept a corner twin on the old triangle, the force LCP put the load on the twin and
    released the slot still approaching, and the slot was handed the old triangle back
    1e-12 m short of passing its end again: a lift-off every 3.7e-12 s, `no_progress` at
    t = 0.00903134 s.  Now it hits the next triangle there (an impact, no twin) and slides on."""
    r = flexbody.simulate(flexbody.load_scene(reference_table("fuzz_stack_corner_over_diagonal")),
                          max_wall_time=120.0)  # ~2 s
    assert r.status == "success", r.message
    assert r.t[-1] == pytest.approx(0.0095)  # past the stall at 0.00903134 s
    assert r.stats["max_penetration_m"] < 1e-9  # measured 2.0e-12 m
    assert r.stats["max_edge_crossing_m"] == 0.0
    assert not r.stats["warnings"]
    assert r.stats["events"] < 100  # measured 56; 200 lift-offs of that corner alone in the stall


def test_a_rim_midpoint_crossing_a_crease_while_sliding_along_it_leaves_its_twin_behind():
    """An eleventh fuzz's row (tests/reference/fuzz_row_twin_left_behind_on_a_crease.json:
    three flexible 4 x 3 x 2 boxes on a rough ground, frictionless between them, no edge
    contacts, b0 pushed at 0.427 m/s; cut to 0.03 s).  b0's top rim midpoint 19, held on
    b1's top face, crosses a crease of 1.36e-5 rad at 3.3e-3 m/s while sliding along it at
    1.16e-2 m/s, approaching the next triangle at 4.5e-8 m/s (tangential: the slot is handed
    over and a corner twin kept on the old triangle).  The force LCP held the twin alone and
    released the slot; handed the old triangle back, the slot passed its end again
    2.56e-10 s later, 201 times in a row: `no_progress` at t = 0.0252199787 s.  Now the slot
    keeps the new triangle (held alone there it pushes, 8.0 N) and the twin lifts off.  Its
    warnings are the scene's own, from before the stall (edges crossing unseen without edge
    contacts, a friction direction not converged, a particle 8.9e-11 m inside)."""
    r = flexbody.simulate(flexbody.load_scene(reference_table("fuzz_row_twin_left_behind_on_a_crease")),
                          max_wall_time=120.0)  # ~15 s
    assert r.status == "success", r.message
    assert r.t[-1] == pytest.approx(0.03)  # past the stall at 0.0252199787 s
    assert r.stats["max_penetration_m"] < 1e-9  # measured 8.9e-11 m, before the stall
    assert r.stats["events"] < 1500  # measured 1 052; 1 197 up to the stall, 201 of them its last lift-offs
    assert r.stats["min_held_contact_force_N"] >= 0.0  # measured 4.0e-3 N
    assert not any("force turned negative" in w for w in r.stats["warnings"])


def _creased_block(rise: float, size: float = 0.1) -> tuple[list, list, list, list]:
    """A cube of side ``size`` whose top face is split along its diagonal from (0, 0) to
    (size, size), the top corner (size, 0) raised by ``rise``: the diagonal is a crease
    concave by ``rise`` / (``size`` / sqrt 2) rad.  Its particles, links (every pair),
    triangles (outward) and the two top triangles (the raised one first)."""
    points = [[x, y, z] for z in (0.0, size) for y in (0.0, size) for x in (0.0, size)]
    points[5][2] += rise  # (size, 0, size)
    top = [[4, 5, 7], [4, 7, 6]]
    triangles = [[0, 2, 3], [0, 3, 1], [0, 1, 5], [0, 5, 4], [1, 3, 7], [1, 7, 5],
                 [3, 2, 6], [3, 6, 7], [2, 0, 4], [2, 4, 6]] + top
    return points, [list(k) for k in itertools.combinations(range(8), 2)], triangles, top


class _ApexOnCrease(NamedTuple):
    """A tetrahedron's apex over a creased cube's top diagonal (:func:`_apex_on_crease`)."""

    scene: flexbody.Scene
    model: object
    apex: int  # the apex particle
    slot: int  # its slot against the block
    raised: int  # the raised top triangle (element index)
    other: int  # the flat one
    on: np.ndarray  # the diagonal's midpoint (3,)
    downhill: np.ndarray  # unit (3,): in the raised triangle's plane, square to the diagonal
    diagonal: np.ndarray  # unit (3,): along the diagonal


def _apex_on_crease(rise: float, size: float = 0.1) -> _ApexOnCrease:
    """A tetrahedron (falling from above) whose apex may touch a cube of side ``size`` whose
    top face is creased concave along its diagonal by ``rise`` (:func:`_creased_block`), as
    a NumPy model, with the geometry that places the apex across the crease."""
    points, links, triangles, top = _creased_block(rise, size)
    table = {
        "name": "crease", "gravity": [0.0, 0.0, -G],
        "bodies": [
            {"name": "block", "particles": points, "links": links, "surface": triangles,
             "mass": 1.0, "stiffness": 2e4, "damping": 5.0, "position": [0.0, 0.0, 0.0]},
            {"name": "tet", "particles": _tetrahedron(np.array([0.0, 0.0, 1.0]), length=0.02), "links": TET_LINKS,
             "surface": TET_SURFACE, "masses": TET_MASSES, "stiffness": 500.0, "damping": 0.2,
             "position": [0.05, 0.05, 0.2]},
        ],
        "contacts": [{"bodies": ["block", "tet"]}],
        "simulation": {"t_end": 0.1, "output_dt": 1e-3},
    }
    scene = flexbody.load_scene(table)
    model = load_model(scene, backend="numpy")
    apex = len(points)
    raised, other = ([e for e in range(len(model.elements)) if sorted(model.elements[e]) == sorted(t)][0] for t in top)
    slot = int(model._slots_of(np.array([apex]), np.array([0]))[0][0])
    diagonal = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    on = 0.5 * size * diagonal + [0.0, 0.0, size]
    downhill = on - np.array(points[5])  # from the raised corner
    downhill -= (downhill @ diagonal) * diagonal
    downhill /= np.linalg.norm(downhill)
    return _ApexOnCrease(scene, model, apex, slot, raised, other, on, downhill, diagonal)


@pytest.mark.parametrize("rise, across, along, twin", [
    (3.5e-8, 0.19, 0.01, False),  # 5e-7 rad: crossed at 0.19 m/s, 1e-7 m/s onto the next triangle: an impact
    (3.5e-8, 1e-7, 0.0, True),    # crossed slower than the speed tolerance: the corner keeps its twin
    (3.5e-8, 1e-3, 0.19, True),   # sliding along the crease, a hair across it
    (3.5e-10, 1e-5, 0.0, True),   # 5e-9 rad, 5e-14 m/s onto it: round-off of the velocities, no sign
    (7e-5, 1e-4, 0.0, True),      # 1e-3 rad, 1e-7 m/s onto it: the planes meet on a line (the held pair slides along it)
])
def test_a_particle_crossing_a_crease_concave_by_a_hair_hits_the_next_triangle(rise, across, along, twin):
    """A tetrahedron's apex held on the raised triangle of a cube's top face, a hair past its
    diagonal, moving across it onto the other triangle, down the raised one's slope (below
    the other's plane by the crease's angle times the crossing speed).  Where the crease is
    flatter than ``EDGE_LINE`` (its planes meet nowhere definite: a twin cannot hold the
    particle on a line) and the particle crosses it faster than the speed tolerance, more
    across it than along it, the hand-over is an impact without a corner twin (a fuzzed
    stack's corner crossing a diagonal creased by 5e-7 rad at 0.19 m/s stalled with one,
    tests/reference/fuzz_stack_corner_over_diagonal.json).  Slower, along the crease, or at
    a crease whose planes meet on a line, the particle keeps its twin and the force LCP
    decides (a particle sliding along such a crease, dithering across it:
    tests/reference/fuzz_row_dithering_on_a_crease.json)."""
    c = _apex_on_crease(rise)
    model, slot, raised, other, apex = c.model, c.slot, c.raised, c.other, c.apex
    p, ng = model.parameters(c.scene), model.n_ground_contacts
    held = np.zeros(model.n_contacts, np.intc)
    held[ng + slot] = 1
    model.element_of[slot] = raised
    q = c.scene.initial_positions().copy()
    q[apex] = c.on + 1e-9 * c.downhill  # a hair past the diagonal, on the raised plane
    u = np.zeros_like(q)
    u[apex] = across * c.downhill + along * c.diagonal
    y = np.concatenate([q.ravel(), u.ravel(), np.zeros(model.ny - 2 * q.size)])
    moved = model.switch_elements(y, p, held, gap_tolerance=1e-12, speed_tolerance=3e-7)
    assert model.element_of[slot] == other
    if twin:
        assert moved.stay.tolist() == [ng + slot] and not len(moved.approach)
        assert model.element_of[moved.corners - ng].tolist() == [raised]  # the twin, on the old triangle
    else:
        assert moved.approach.tolist() == [ng + slot] and not len(moved.stay) and not len(moved.corners)


@pytest.mark.parametrize("across, squeeze, kept", [
    (1e-3, 0.9, True),   # crossing onto the new triangle, pressed onto it: the slot keeps it, the twin lifts off
    (1e-7, 0.9, False),  # slower than the speed tolerance (3.1e-7 m/s): in the corner, handed back
    (1e-3, 1.1, False),  # held alone on the new triangle the slot would pull: handed back
])
def test_a_slot_crossing_a_crease_keeps_the_new_triangle_where_the_lcp_released_it(across, squeeze, kept):
    """A tetrahedron's apex a hair past the diagonal of a cube's top face creased concave by
    1e-5 rad (above ``EDGE_LINE``: a crease with a line, so a tangential crossing keeps a
    corner twin), its slot handed to the flat triangle and its twin held on the raised
    one; the force LCP released the slot (as in a fuzzed row whose rim midpoint crossed a
    crease at 3.3e-3 m/s sliding along it at 1.2e-2 m/s: the LCP's one solution held the
    twin alone, and the slot, handed the raised triangle back, passed its end again every
    2.56e-10 s, tests/reference/fuzz_row_twin_left_behind_on_a_crease.json).  Crossing onto
    the flat triangle faster than the speed tolerance, the slot keeps it, held, and the
    twin lifts off; slower (the particle may rest in the corner), or where the slot alone
    would pull there (its lift-off event would start below 0 and never fire), the slot is
    handed the twin's triangle back.  Either way the lift-off recorded is the twin's.  The
    tetrahedron, squeezed (``squeeze`` < 1) or stretched along its height, presses its apex
    onto the face or pulls it off (block and tetrahedron fall alike: gravity alone would
    leave the slot's force at 0)."""
    c = _apex_on_crease(7.07e-7)
    model, slot, raised, other, apex = c.model, c.slot, c.raised, c.other, c.apex
    run = _Run(c.scene, model, _settings(c.scene, {"backend": "numpy"}), None, 10**6)
    ng, twin = model.n_ground_contacts, slot + model.n_primary
    model.element_of[slot], model.element_of[twin] = other, raised
    run.phases.phase[ng + twin] = HELD  # the slot released (free), its twin held
    q = c.scene.initial_positions().copy()
    shape = (q[apex:] - q[apex]) * [1.0, 1.0, squeeze]
    q[apex:] = c.on + 1e-9 * c.downhill + shape  # the apex a hair past the diagonal, on the raised plane
    u = np.zeros_like(q)
    u[apex:] = across * c.downhill + 1e-2 * c.diagonal  # across the crease while sliding along it
    run.y = np.concatenate([q.ravel(), u.ravel(), np.zeros(model.ny - 2 * q.size)])
    new = [Event(0.0, ng + slot, "liftoff")]
    run.settle_corners(new)
    assert new[0].contact == ng + twin
    assert run.phases.phase[ng + slot] == HELD and run.phases.phase[ng + twin] == FREE
    if kept:
        assert model.element_of[slot] == other and model.element_of[twin] == -1
    else:
        assert model.element_of[slot] == raised
