"""A vertex of one body meeting a vertex of another is one contact (flexbody.body_contact).

A box's corner sliding along a floor reaches one of the floor's vertices: there the floor's
vertex also touches the box, at its corner.  That touch has no normal of its own (the
distance between two points is not differentiable where they meet), and taking the
direction of their relative motion for one stopped the slide.  The corner's contact with the
floor already keeps the two apart, so the floor vertex's touch is carried by it.

References: uniform motion (a frictionless slide on a flat floor keeps its velocity and
height exactly), the bodies' surfaces (nothing inside the other body), energy.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

import flexbody
from flexbody.body_contact import BodyContactModel

from .conftest import reference_table

G = 9.81


def _slide(t_end: float, speed: float) -> dict:
    """A rigid box (6 cm x 3 cm) 1 um above a rigid floor whose flat top has a vertex every
    0.1 m, sliding along it at ``speed``, frictionless; the floor rests on a rough ground."""
    top = [[x, 0.1] for x in np.linspace(0.5, -0.5, 11)]
    return {
        "name": "slide", "gravity": [0.0, -G],
        "grounds": [{"point": [0.0, 0.0], "normal": [0.0, 1.0], "friction": 1.0}],
        "bodies": [
            {"name": "floor", "shape": "polygon", "rigid": True, "vertices": [[-0.5, 0.0], [0.5, 0.0]] + top,
             "mass": 1.0, "position": [0.0, 0.0]},
            {"name": "box", "shape": "polygon", "rigid": True,
             "vertices": [[-0.43, 0.1], [-0.37, 0.1], [-0.37, 0.13], [-0.43, 0.13]],
             "mass": 0.05, "position": [0.0, 1e-6], "velocity": [speed, 0.0]},
        ],
        "contacts": [{"bodies": ["floor", "box"]}],
        "simulation": {"t_end": t_end, "output_dt": 0.005},
    }


def test_a_box_sliding_over_a_floors_vertices_keeps_its_velocity():
    """Over 0.4 s at 1 m/s the box's front corner passes the floor vertices at x = -0.3,
    -0.2, -0.1 and 0, and its rear corner the first three: each a vertex-to-vertex touch.
    Frictionless and flat, the box keeps 1 m/s (before: 0.095 m/s after the first vertex,
    the floor's vertex hit along the slide)."""
    result = flexbody.simulate(flexbody.load_scene(_slide(t_end=0.4, speed=1.0)))
    assert result.status == "success", result.message
    box = result.positions[:, -4:]  # the box's corners (the last body's particles)
    landed = result.t > 1e-3  # after its 1 um drop (0.45 ms)
    centre = box[landed].mean(axis=1)
    velocity = np.diff(centre[:, 0]) / np.diff(result.t[landed])
    np.testing.assert_allclose(velocity, 1.0, rtol=0, atol=1e-9)
    np.testing.assert_allclose(box[landed][:, :2, 1], 0.1, rtol=0, atol=1e-9)  # its bottom stays on the floor
    assert box[-1, 1, 0] > 0.0 + 1e-3  # the front corner is past the fourth vertex
    assert result.stats["max_penetration_m"] <= 1e-9
    # the landing is one instant (its three contacts); at a vertex nothing is lost: a floor
    # vertex the box comes to cover may be taken as a resting contact, touched at zero speed
    # (one at 0.27 s since steps are bounded by the bodies' relative speed), taking no energy
    landing = np.abs(result.events_time - np.sqrt(2e-6 / G)) < 1e-6
    assert landing.sum() == 3 and (result.events_kind[~landing] == "impact").all() and result.events_held.all()
    np.testing.assert_allclose(result.impact_loss[landed], result.impact_loss[landed][0], rtol=0, atol=1e-12)


def _corner_to_corner(restitution: float) -> dict:
    """Two rigid squares (10 cm) in free space, whose corners meet head-on at t = 0.01 s
    (the relative velocity along the line between them)."""
    def square(cx: float, cy: float, half: float = 0.05) -> list:
        return [[cx - half, cy - half], [cx + half, cy - half], [cx + half, cy + half], [cx - half, cy + half]]

    return {
        "name": "corners", "gravity": [0.0, 0.0],
        "bodies": [
            {"name": "a", "shape": "polygon", "rigid": True, "vertices": square(0.0, 1.0), "mass": 1.0,
             "position": [0.0, 0.0], "velocity": [0.5, 0.3]},
            {"name": "b", "shape": "polygon", "rigid": True, "vertices": square(0.11, 1.106), "mass": 2.0,
             "position": [0.0, 0.0], "velocity": [-0.5, -0.3]},
        ],
        "contacts": [{"bodies": ["a", "b"], "restitution": restitution}],
        "simulation": {"t_end": 0.03, "output_dt": 0.001},
    }


@pytest.mark.parametrize("restitution", [1.0, 0.5])
def test_two_corners_meeting_are_one_impact(restitution):
    """Each square's corner touches the other's surface at its corner: two slots, one
    contact.  One of them is hit (before: both, two rows with different normals between
    the same two points); momentum and angular momentum are conserved, and with e = 1 the
    kinetic energy too (one contact row: Newton's law keeps it)."""
    result = flexbody.simulate(flexbody.load_scene(_corner_to_corner(restitution)))
    assert result.status == "success", result.message
    assert list(result.events_kind) == ["impact"]
    assert result.events_time[0] == pytest.approx(0.01, abs=1e-12)
    m, x, v = result.masses, result.positions, result.velocities
    momentum = np.einsum("n,tnd->td", m, v)
    angular = np.einsum("n,tn->t", m, x[:, :, 0] * v[:, :, 1] - x[:, :, 1] * v[:, :, 0])
    np.testing.assert_allclose(momentum[-1], momentum[0], rtol=0, atol=1e-12)
    assert angular[-1] == pytest.approx(angular[0], rel=1e-12)
    kinetic = 0.5 * np.einsum("n,tnd->t", m, v * v)
    if restitution == 1.0:
        assert kinetic[-1] == pytest.approx(kinetic[0], rel=1e-12)
    else:
        assert kinetic[-1] < kinetic[0] - 0.1  # measured 2.04 J -> 1.80 J
    assert result.stats["max_penetration_m"] <= 1e-9


def _deepest(scene, result, pairs) -> float:
    """The least signed distance (m) of each (particle, body) of ``pairs`` to that body's
    surface over the output samples (negative: inside it)."""
    from flexbody.surface_contact import closest_features

    elements, owner = scene.surfaces()
    deepest = np.inf
    for x in result.positions:
        for particle, other in pairs:
            segments = np.flatnonzero(owner == other)
            pairs_k = np.column_stack([np.full(len(segments), particle), segments])
            deepest = min(deepest, float(closest_features(x, x, elements, pairs_k, owner).gap[0]))
    return deepest


def _corner_past_corner(restitution: float) -> dict:
    """Two rigid 10 cm squares side by side, 1 mm apart, no gravity: the left one moves at
    (1, -0.3) m/s and meets the right one at t = 1 ms with its bottom-right corner 1e-5 m
    above the other's bottom-left corner (and the other's top-left corner 1e-5 m below its
    top-right one)."""
    square = [[-0.05, -0.05], [0.05, -0.05], [0.05, 0.05], [-0.05, 0.05]]
    return {
        "name": "corner_past_corner", "gravity": [0.0, 0.0],
        "grounds": [{"point": [0.0, -10.0], "normal": [0.0, 1.0]}],
        "bodies": [
            {"name": "a", "shape": "polygon", "rigid": True, "vertices": square, "mass": 0.03,
             "position": [-0.001, 3.1e-4], "velocity": [1.0, -0.3]},
            {"name": "b", "shape": "polygon", "rigid": True, "vertices": square, "mass": 0.03,
             "position": [0.1, 0.0]},
        ],
        "contacts": [{"bodies": ["a", "b"], "restitution": restitution}],
        "simulation": {"t_end": 0.003, "output_dt": 1e-5},
    }


@pytest.mark.parametrize("restitution", [1.0, 0.5])
def test_a_corner_passing_through_another_corners_tip_within_a_step_is_an_impact(restitution):
    """The left square's corner reaches the right one's side 1e-5 m from its corner, moving
    down at 0.3 m/s: it would be through that corner's tip and out below it in 3.3e-5 s,
    within one step (free flight takes steps of ~0.05 s), positive at each of the step's
    checks.  Before, the impact was missed: the squares overlapped along their whole
    sides, and at the instant a corner came out of the tip and the other's corner went in
    through the bottom side, the two contacts, on the same line with opposite normals,
    took turns (e = 1: `chattering` at 1.03 ms, 7e-6 m inside at the samples; e = 0.5:
    `success`, 7e-6 m inside, unwarned).  The passage is now found from the two sides'
    lines: both corners hit the other square's side at 1 ms, momentum kept, and with
    e = 1 the kinetic energy."""
    scene = flexbody.load_scene(_corner_past_corner(restitution))
    result = flexbody.simulate(scene, max_wall_time=60.0)
    assert result.status == "success", result.message
    assert not result.stats["warnings"]
    assert list(result.events_kind) == ["impact", "impact"]
    np.testing.assert_allclose(result.events_time, 1e-3, rtol=0, atol=1e-12)
    assert sorted(result.events_particle) == [1, 7]  # a's bottom-right corner, b's top-left corner
    assert _deepest(scene, result, [(1, 1), (2, 1), (4, 0), (7, 0)]) >= -1e-9  # -7e-6 m before
    m, v = result.masses, result.velocities
    momentum = np.einsum("n,tnd->td", m, v)
    np.testing.assert_allclose(momentum[-1], momentum[0], rtol=0, atol=1e-12)
    kinetic = 0.5 * np.einsum("n,tnd->t", m, v * v)
    if restitution == 1.0:
        assert kinetic[-1] == pytest.approx(kinetic[0], rel=1e-9)


def _corner_past_edge(restitution: float, rigid: bool, vertex: bool = False) -> dict:
    """The 3D analog of :func:`_corner_past_corner`: two 10 cm cubes, the left one also
    2 cm along y, so that its bottom-right corner at y = -0.03 m meets the right one's left
    face 1e-5 m above its bottom edge, and the right one's top-left corner at y = 0.05 m
    the left one's right face 1e-5 m below its top edge.  With ``vertex`` the left one
    moves at (1, -0.3, -0.3) m/s and its corner meets the other's face 1e-5 m from its
    front and bottom edges, next to their vertex (and the other's corner the same).
    Flexible: 8 particles, 3000 N/m, undamped."""
    box = {"shape": "box", "count": [2, 2, 2], "size": [0.1] * 3, "mass": 0.03}
    box.update({"rigid": True} if rigid else {"stiffness": 3000.0, "damping": 0.0, "damper": "axial"})
    position, velocity = ([-0.001, 3.1e-4, 3.1e-4], [1.0, -0.3, -0.3]) if vertex else \
        ([-0.001, 0.02, 3.1e-4], [1.0, 0.0, -0.3])
    return {
        "name": "corner_past_edge", "gravity": [0.0, 0.0, 0.0],
        "grounds": [{"point": [0.0, 0.0, -10.0], "normal": [0.0, 0.0, 1.0]}],
        "bodies": [{**box, "name": "a", "position": position, "velocity": velocity},
                   {**box, "name": "b", "position": [0.1, 0.0, 0.0]}],
        "contacts": [{"bodies": ["a", "b"], "restitution": restitution}],
        "simulation": {"t_end": 0.003, "output_dt": 1e-5},
    }


def _check_corners_past_edges(scene, result) -> None:
    """Both corners hit the other cube's face at 1 ms, nothing is ever inside the other
    cube at the samples (every 1e-5 s: the passage took 3.3e-5 s), momentum is kept."""
    assert result.status == "success", result.message
    assert not [w for w in result.stats["warnings"] if "into another body" in w]
    first = np.abs(result.events_time - 1e-3) < 1e-12
    assert list(result.events_kind[first]) == ["impact", "impact"]
    assert sorted(result.events_particle[first]) == [1, 14]  # a's bottom-right corner in front, b's top-left behind
    corners = [(particle, 1) for particle in range(8)] + [(particle, 0) for particle in range(8, 16)]
    assert _deepest(scene, result, corners) >= -1e-9  # -7e-6 m before
    m, v = result.masses, result.velocities
    momentum = np.einsum("n,tnd->td", m, v)
    np.testing.assert_allclose(momentum[-1], momentum[0], rtol=0, atol=1e-12)


@pytest.mark.parametrize("vertex", [False, True])
@pytest.mark.parametrize("restitution", [1.0, 0.5])
def test_a_corner_passing_through_another_bodys_edge_within_a_step_is_an_impact(restitution, vertex):
    """3D: a corner reaching another cube's face 1e-5 m from its edge (or from two edges,
    by their vertex), moving down at 0.3 m/s, would be through that edge's wedge (the
    vertex's tip) and out in 3.3e-5 s, positive at each of the step's checks.  Before, the
    flexible cubes' corners went 7e-6 m inside unseen (the first impacts at 1.033 ms, of
    corners already past).  The passage is now found from the planes of two triangles at
    the vertex (the cubes' edges then still cross edge on edge: no edge contacts here,
    warned)."""
    scene = flexbody.load_scene(_corner_past_edge(restitution, rigid=False, vertex=vertex))
    result = flexbody.simulate(scene, max_wall_time=60.0)
    _check_corners_past_edges(scene, result)
    assert result.stats["energy_drift_relative"] < 1e-7  # measured 1.7e-8 (e = 1)


@pytest.mark.parametrize("vertex", [False, True])
def test_a_corner_passing_just_outside_another_bodys_edge_is_no_impact(vertex, monkeypatch):
    """A 5 cm cube whose top-right edge (corner) passes 1e-5 m outside the other cube's
    bottom-left edge (its vertex) at 1 ms, moving as above: within a step its corners
    cross the other's bottom plane outward, then its left plane inward (round the edge
    outside, not through it).  No impact, no event at all, nothing inside."""
    table = _corner_past_edge(1.0, rigid=False, vertex=vertex)
    small = 0.05
    y = -0.05 - 1e-5 + 3e-4 + small / 2 if vertex else 0.0  # its right top corner in front of the other's
    table["bodies"][0].update({"size": [small] * 3, "position": [0.049 - small / 2, y, -0.05 - 1e-5 + 3e-4 - small / 2]})
    scene = flexbody.load_scene(table)
    candidates = []  # the passages corner_cuts hands the event location: some, each rejected

    def recorded(self, *args):
        found = corner_cuts(self, *args)
        candidates.extend(found[0].tolist())
        return found

    corner_cuts = BodyContactModel.corner_cuts
    monkeypatch.setattr(BodyContactModel, "corner_cuts", recorded)
    result = flexbody.simulate(scene, max_wall_time=60.0)
    assert result.status == "success", result.message
    assert candidates  # measured: 13 (edge) and 23 (vertex) pairs of planes, in one step
    assert len(result.events_time) == 0 and not result.stats["warnings"]
    corners = [(particle, 1) for particle in range(8)] + [(particle, 0) for particle in range(8, 16)]
    assert _deepest(scene, result, corners) >= 0.0
    # free flight: nothing touched (the springs at rest to round-off)
    np.testing.assert_allclose(result.velocities[-1], result.velocities[0], rtol=0, atol=1e-12)


def test_the_pairs_of_planes_at_a_vertex_are_every_pair_of_its_triangles_once():
    """A cube's vertex has its triangles' every pair as a candidate corner; asked at both
    ends of one of its edges, the pairs the two vertices share (those at the edge) come
    once, with the lower vertex.  In 2D a vertex has its two segments, in order."""
    from flexbody.model import load_model

    model = load_model(flexbody.load_scene(_corner_past_edge(1.0, rigid=False)))
    u = int(model.elements[0, 0])
    around_u = model._elements_at(u)
    v = next(int(w) for w in model.elements[around_u].ravel() if w != u)  # an edge (u, v) of the surface
    around_v = model._elements_at(v)
    contacts, corners = model._corner_pairs(np.array([7, 7]), np.array([u, v]))
    pairs = [tuple(row) for row in corners[:, 1:].tolist()]
    expected = {(a, b) for around in (around_u, around_v) for a in around.tolist() for b in around.tolist() if a < b}
    assert len(pairs) == len(set(pairs)) and set(pairs) == expected and contacts.tolist() == [7] * len(pairs)
    shared = [w for w, pair in zip(corners[:, 0].tolist(), pairs) if set(pair) <= set(around_u) & set(around_v)]
    assert shared and all(w == min(u, v) for w in shared)
    flat = load_model(flexbody.load_scene(_corner_past_corner(1.0)))
    w = int(flat.elements[0, 1])
    contacts, corners = flat._corner_pairs(np.array([3]), np.array([w]))
    assert corners.tolist() == [[w, *flat._elements_at(w).tolist()]]


def test_random_passages_through_a_cubes_edge_or_vertex_are_each_an_impact():
    """Eight random passages of the left cube's corner through the right cube's bottom
    edge's wedge or its vertex's tip, 1e-6 to 3e-5 m deep, at 0.1 to 1 m/s across the
    bottom (and the front, for a vertex), e = 0, 0.5 or 1: each is an impact at 1 ms, and
    no particle is ever inside the other cube at the samples (every 2e-6 s from 0.99 ms:
    each passage would take 1e-6 to 3e-4 s).  Before the
    3D corner cuts every one was missed (30 of 30 in a longer run: first impacts 1e-5 to
    1e-4 s late, up to 1.4e-5 m inside)."""
    rng = np.random.default_rng(0)
    for case in range(8):
        vertex = case % 2 == 1
        d1, d2 = rng.uniform(1e-6, 3e-5, size=2)
        vz = -rng.uniform(0.1, 1.0)
        vy = -rng.uniform(0.1, 1.0) if vertex else rng.uniform(-0.2, 0.2)
        y_corner = -0.05 + d2 if vertex else rng.uniform(-0.04, 0.04)  # the corner at x = 0.05 at 1 ms
        table = _corner_past_edge(float(rng.choice([0.0, 0.5, 1.0])), rigid=False)
        table["bodies"][0].update({"position": [-1e-3, y_corner + 0.05 - vy * 1e-3, d1 - vz * 1e-3],
                                   "velocity": [1.0, vy, vz]})
        table["simulation"].update({"t_end": 1.2e-3, "output_dt": 2e-6})
        scene = flexbody.load_scene(table)
        result = flexbody.simulate(scene, max_wall_time=60.0)
        assert result.status == "success", result.message
        assert abs(result.events_time[0] - 1e-3) < 1e-9, (case, result.events_time[:2])
        corners = [(particle, 1) for particle in range(8)] + [(particle, 0) for particle in range(8, 16)]
        around = SimpleNamespace(positions=result.positions[result.t >= 0.99e-3])
        assert _deepest(scene, around, corners) >= -1e-9, case


@pytest.mark.slow  # the rigid cubes are derived whole (~20 s with a cold cache)
@pytest.mark.parametrize("vertex", [False, True])
@pytest.mark.parametrize("restitution", [1.0, 0.5])
def test_a_rigid_corner_passing_through_another_rigid_bodys_edge_is_an_impact(restitution, vertex):
    """The same with rigid cubes: the two impacts at 1 ms and no other event, no warning,
    and with e = 1 the kinetic energy kept.  Before: e = 1 `chattering` at 1.03 ms (26
    impacts, 1e-6 m inside), e = 0.5 7e-6 m inside and the edges crossed."""
    scene = flexbody.load_scene(_corner_past_edge(restitution, rigid=True, vertex=vertex))
    result = flexbody.simulate(scene, max_wall_time=120.0)
    _check_corners_past_edges(scene, result)
    assert list(result.events_kind) == ["impact", "impact"] and not result.stats["warnings"]
    kinetic = 0.5 * np.einsum("n,tnd->t", result.masses, result.velocities ** 2)
    if restitution == 1.0:
        assert kinetic[-1] == pytest.approx(kinetic[0], rel=1e-9)


def test_a_row_of_squares_with_coincident_corners_elastic_runs_on():
    """A fuzz's row (tests/reference/fuzz_row_coincident_corners_e1.json: four undamped
    flexible squares touching side to side, corners coincident, the first struck at 1 m/s,
    e = 1).  The first two squares' corners, met at t = 0, part and come back at 2.65 ms
    1e-5 m apart vertically: the first's corners went into the second's side and out
    through its bottom and top within one step (1.9e-4 s), unseen, 7.7e-6 m deep.  At the
    instant the second's corners went into the first through its bottom and top, the two
    pairs of contacts, opposite rows, took turns 26 times (`chattering` at 2.7 ms, warned
    of 1.3e-6 m).  Now the first's corners hit the second's side at 2.653 ms and the row
    runs on (measured: 20 events, 1e-12 m)."""
    scene = flexbody.load_scene(reference_table("fuzz_row_coincident_corners_e1"))
    result = flexbody.simulate(scene, max_wall_time=60.0)
    assert result.status == "success", result.message
    assert not result.stats["warnings"]
    assert result.stats["max_penetration_m"] <= 1e-9
    hit = (np.abs(result.events_time - 2.6531e-3) < 1e-7) & (result.events_kind == "impact")
    assert sorted(result.events_particle[hit]) == [1, 2]
    assert _deepest(scene, result, [(1, 1), (2, 1), (4, 0), (7, 0)]) >= -1e-9  # -7.7e-6 m before
