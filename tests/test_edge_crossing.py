"""Edges crossing in 3D: held where edge contacts are modelled, else measured and said.

Two edges that meet (boxes crossed edge on edge, coarse polyhedra colliding) touch with
no particle on a surface.  For a pair with ``edges = true`` (3D) they are edge contacts
(:class:`flexbody.edge_contact.EdgeSlots`): an impact, a held row, a lift-off, and with
the pair's friction a slide and a stick.  Otherwise they pass through each other with no particle inside the other body:
every 3D run measures how deep surfaces cross that way (``stats["max_edge_crossing_m"]``)
and warns.

References: geometry by hand (an edge through a triangle by a known depth; a triangle
pressed flat on a plane, crossing by round-off only), the free fall of a box onto a box
crossed under it (they meet at sqrt(2 h / g)), statics (the upper box's weight on the edge),
Coulomb's law in closed form (a bar landing crosswise on a bar and sliding along itself).
"""

from __future__ import annotations

import re

import numpy as np
import pytest

import flexbody
from flexbody.surface import edges_through

from .conftest import reference_table

G = 9.81
SIDE = 0.1
DROP = 0.01


def test_an_edge_through_a_triangle_is_as_deep_as_the_least_move_that_frees_it():
    """A vertical edge through a horizontal triangle, 0.01 from its nearest side and ends
    0.3 and 0.2 from the plane: 0.01 deep.  Tilted 1e-6 rad and crossing by 1e-3 in the
    plane (a face pressed flat on another's edge, its vertices at round-off), it is 1e-9
    deep: shifting it by that along the normal slides the crossing point out."""
    triangle = np.array([[0, 1, 2]])
    points = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.2, 0.01, -0.2], [0.2, 0.01, 0.3]])
    rows, depths = edges_through(points, np.array([[3, 4]]), triangle, 0.0)
    assert rows.tolist() == [[0, 0]] and depths[0] == pytest.approx(0.01, rel=1e-12)
    flat = np.array([[0.5, -1.0, 0.0], [0.5, 1.0, 0.0]])  # along y at x = 0.5, through the side y = 0
    tilt = 1e-6
    flat[:, 2] = (flat[:, 1] - 1e-3) * tilt  # in the plane at y = 1e-3, inside by 1e-3
    points = np.vstack([points[:3], flat])
    rows, depths = edges_through(points, np.array([[3, 4]]), triangle, 0.0)
    assert rows.tolist() == [[0, 0]] and depths[0] == pytest.approx(1e-3 * tilt, rel=1e-6)
    assert len(edges_through(points, np.array([[3, 4]]), triangle, 1e-8)[0]) == 0


def _crossed_boxes(lift: float, friction: float = 0.0, edges: bool = False) -> dict:
    """Box ``a`` on the ground on one edge (along x), box ``b`` over it on an edge along y,
    ``lift`` above it: they meet edge on edge, crossed (``friction`` between them; edge
    contacts with ``edges``)."""
    a = {"name": "a", "shape": "box", "rigid": True, "count": [2, 2, 2], "size": [SIDE] * 3, "mass": 0.1,
         "position": [0.0, 0.0, SIDE * np.sqrt(2) / 2], "rotation": [np.pi / 4, 0.0, 0.0]}
    b = {"name": "b", "shape": "box", "rigid": True, "count": [2, 2, 2], "size": [SIDE] * 3, "mass": 0.1,
         "position": [0.0, 0.0, 1.5 * SIDE * np.sqrt(2) + lift], "rotation": [0.0, np.pi / 4, 0.0]}
    return {"name": "crossed_boxes", "gravity": [0.0, 0.0, -G], "bodies": [a, b],
            "grounds": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}],
            "contacts": [{"bodies": ["a", "b"], "friction": friction, "edges": edges}],
            "simulation": {"t_end": 0.1, "output_dt": 0.002}}


@pytest.mark.slow  # its two rigid boxes are derived whole (~20 s with a cold cache); the flexible pair below is quick
def test_boxes_meeting_edge_on_edge_hit_when_the_fall_says_and_rest_there():
    """The upper box falls DROP onto the lower one's edge, crossed, no vertex on a face: an
    edge contact, hit at sqrt(2 DROP / g) and then held (balanced on the crossing point);
    nothing crosses, and the lower box's ground contacts carry both weights, the edge
    contact the upper box's, half on each end of the lower box's top edge (it is crossed at
    its middle)."""
    r = flexbody.simulate(flexbody.load_scene(_crossed_boxes(DROP, edges=True)))
    assert r.success and r.stats["impacts"] == 1 and r.stats["liftoffs"] == 0
    assert abs(r.events_time[0] - np.sqrt(2 * DROP / G)) < 1e-9
    assert r.stats["max_edge_crossing_m"] == 0.0 and not any("edge on edge" in w for w in r.stats["warnings"])
    assert r.stats["max_penetration_m"] < 1e-9
    upper = r.positions[-1, 8:, 2]
    assert upper.min() == pytest.approx(SIDE * np.sqrt(2), abs=1e-9)  # resting on the lower box's top edge
    lower, upper = r.masses[:8].sum() * G, r.masses[8:].sum() * G
    # the ground carries both weights, the edge contact the upper box's
    assert r.contact_force[-1].sum() == pytest.approx(lower + 2 * upper, rel=1e-9)
    assert r.contact_force[-1, 8:].sum() == 0.0  # the edge contact's force is reported on the lower box's edge
    # split between its ends as (1 - s, s): the crossing is at the middle of the top edge, half each
    top = np.argsort(r.positions[-1, :8, 2])[-2:]
    np.testing.assert_allclose(r.contact_force[-1, top], [upper / 2, upper / 2], rtol=1e-9)


def test_flexible_boxes_crossed_edge_to_edge_stay_apart_with_edge_contacts_and_cross_without():
    """The same boxes flexible (8 particles, 3000 N/m, axial dampers), to 0.3 s: with edge
    contacts the upper one lands on the lower one's edge (the first impact a hair after the
    rigid boxes' sqrt(2 DROP / g): the lower box settles on the ground meanwhile), no edge
    crosses, nothing is inside anything and the ledger closes; without them the upper box
    falls 2 cm through the edge (measured 0.020 m) before its corners hit the faces."""
    runs = {}
    for edges in (True, False):
        runs[edges] = r = flexbody.simulate(flexbody.load_scene(_flexible(_crossed_boxes(DROP, edges=edges), 0.3)))
        assert r.success, r.message
        assert r.stats["max_penetration_m"] < 1e-9 and r.stats["energy_drift_relative"] < 1e-6
    held = runs[True]
    assert 0.0 <= held.events_time[0] - np.sqrt(2 * DROP / G) < 1e-3
    assert held.stats["max_edge_crossing_m"] == 0.0
    assert runs[False].stats["max_edge_crossing_m"] > 0.01
    assert runs[False].events_time[0] > 2 * held.events_time[0]


@pytest.mark.parametrize("friction", [0.0, 0.5])
def test_edges_of_a_pair_without_edge_contacts_pass_through_each_other_and_the_run_says_so(friction):
    """Without ``edges = true`` (the default) the edges cross; the run measures the crossing (from sqrt(2 DROP / g), as deep as
    the fall past it by the end) and warns, naming both bodies."""
    r = flexbody.simulate(flexbody.load_scene(_crossed_boxes(DROP, friction=friction)))
    assert r.success and r.stats["impacts"] == 0
    t_meet = np.sqrt(2 * DROP / G)
    fall = 0.5 * G * r.t[-1] ** 2 - DROP  # how far past the touch the upper edge is at the end: 0.039 m
    # the least move that frees an edge from one triangle: at most the fall (a face's
    # triangles split it, so less), and far more than round-off
    assert 1e-3 < r.stats["max_edge_crossing_m"] <= fall
    (warning,) = [w for w in r.stats["warnings"] if "edge on edge" in w]
    assert "'a'" in warning and "'b'" in warning
    start = float(warning.split("from t = ")[1].split(" s")[0])
    assert abs(start - t_meet) < 1e-8


@pytest.mark.parametrize("edges", [False, True])
def test_bodies_that_start_crossed_edge_on_edge_are_refused(edges):
    with pytest.raises(flexbody.InputError, match="start crossed edge on edge"):
        flexbody.simulate(flexbody.load_scene(_crossed_boxes(-0.01, edges=edges)))


@pytest.mark.parametrize("change, rule", [
    ({"edges": 1}, r"contacts\[0\]\.edges.*must be true or false"),
])
def test_edge_contacts_asked_for_where_they_cannot_be_are_refused_with_the_rule(change, rule):
    table = _crossed_boxes(DROP)
    ground_friction = change.pop("ground_friction", None)
    table["contacts"][0].update(change)
    if ground_friction is not None:
        table["grounds"][0]["friction"] = ground_friction
    with pytest.raises(flexbody.SceneError, match=rule):
        flexbody.load_scene(table)


def _flexible(table: dict, t_end: float) -> dict:
    """``table``'s boxes flexible (8 particles, 3000 N/m, axial dampers), run to ``t_end``."""
    for box in table["bodies"]:
        box.pop("rigid", None)
        box.update({"stiffness": 3000.0, "damping": 0.3, "damper": "axial"})
    table["simulation"]["t_end"] = t_end
    return table


def _third_box(table: dict) -> dict:
    """``table`` with a box ``c`` like ``a`` beside it on the ground, at y = 0.5."""
    table["bodies"].append({**table["bodies"][0], "name": "c", "position": [0.0, 0.5, SIDE * np.sqrt(2) / 2]})
    return table


def test_edge_contacts_hold_beside_friction_on_the_ground_and_on_other_pairs():
    """An edge row is frictionless (no tangent rows); the rough rows beside it keep theirs:
    the ground's (mu 0.3 under the lower box) and another pair's (a third box, mu 0.4, on
    the lower one's far end).  The upper box lands on the crossed edge a hair after the
    rigid boxes' sqrt(2 DROP / g), as on a frictionless ground (the lower box settles
    meanwhile: measured 0.18 ms later there, 0.53 ms on the rough one); no edge crosses,
    nothing is inside anything, and the ledger, friction's work included, closes."""
    runs = {}
    for mu in (0.0, 0.3):
        table = _flexible(_crossed_boxes(DROP, edges=True), 0.3)
        table["grounds"][0]["friction"] = mu
        if mu:
            _third_box(table)["contacts"].append({"bodies": ["a", "c"], "friction": 0.4})
        runs[mu] = r = flexbody.simulate(flexbody.load_scene(table))
        assert r.success, r.message
        assert r.stats["max_edge_crossing_m"] == 0.0 and r.stats["max_penetration_m"] < 1e-9
        assert r.stats["energy_drift_relative"] < 1e-6
    rough = runs[0.3]
    assert rough.stats["slips"] + rough.stats["sticks"] > 0 and rough.friction_work[-1] > 0.0
    for r in runs.values():  # the first touch between the boxes: an edge of 'a' on 'b'
        between = r.events_time[r.events_surface == 1]
        assert 0.0 <= between[0] - np.sqrt(2 * DROP / G) < 1e-3


def test_a_recorded_sample_restores_an_edge_rows_side_with_its_edge():
    """An edge row's held edge and side are one code (what the driver records per sample):
    held on a sample's code, the row's normal is that side's, whatever it holds now."""
    from flexbody.model import load_model

    scene = flexbody.load_scene(_crossed_boxes(DROP, edges=True))
    model = load_model(scene)
    x = scene.initial_positions()
    slots = model._edge_slots
    found = slots.closest(x, np.arange(slots.n_primary), np.full(len(slots), -1), 1.0)[1]
    first = int(np.flatnonzero(found >= 0)[0])  # the edge of a that b's edge crosses over
    row, edge = model.first_edge + first, found[first]
    up, down = model._edge_slots.encode([edge, edge], [1.0, -1.0])
    model.element_of[row] = up
    normal = model._edge_terms(np.array([row]), x, np.zeros_like(x)).normal[0]
    recorded = model.element_of.copy()
    recorded[row] = down
    with model.held_on(recorded):
        np.testing.assert_allclose(model._edge_terms(np.array([row]), x, np.zeros_like(x)).normal[0], -normal)
    assert model.element_of[row] == up


def test_edge_contacts_in_2d_are_refused():
    table = {"name": "rings", "bodies": [
        {"name": "a", "shape": "ring", "count": 8, "radius": 0.1, "mass": 0.05, "stiffness": 2000.0,
         "damping": 0.5, "position": [0.0, 0.5]},
        {"name": "b", "shape": "ring", "count": 8, "radius": 0.1, "mass": 0.05, "stiffness": 2000.0,
         "damping": 0.5, "position": [0.0, 0.2]}],
        "contacts": [{"bodies": ["a", "b"], "edges": True}]}
    with pytest.raises(flexbody.SceneError, match=r"contacts\[0\]\.edges.*3D bodies only"):
        flexbody.load_scene(table)


def test_a_box_resting_face_on_face_on_a_box_crosses_no_edge():
    """Faces pressed flat on each other (the upper box's bottom edges in the lower one's top
    plane, to round-off and the held contacts' drift) are no crossing."""
    lower = {"name": "lower", "shape": "box", "rigid": True, "count": [2, 2, 2], "size": [0.4, 0.4, 0.1], "mass": 0.2,
             "position": [0.0, 0.0, 0.05]}
    upper = {"name": "upper", "shape": "box", "rigid": True, "count": [2, 2, 2], "size": [0.2, 0.2, 0.1], "mass": 0.1,
             "position": [0.03, 0.02, 0.151], "rotation": [0.0, 0.0, 0.3]}
    r = flexbody.simulate(flexbody.load_scene({"name": "box_on_box", "gravity": [0.0, 0.0, -G], "bodies": [lower, upper],
                                               "contacts": [{"bodies": ["lower", "upper"]}],
                                               "simulation": {"t_end": 0.2, "output_dt": 0.002}}))
    assert r.success and r.stats["impacts"] >= 4
    assert r.stats["max_edge_crossing_m"] == 0.0 and not any("edge on edge" in w for w in r.stats["warnings"])
    assert r.stats["max_penetration_m"] < 1e-9


def _row_of_boxes(n: int, speed: float, restitution: float, rigid: bool = False) -> dict:
    """``n`` boxes of eight particles (flexible, or ``rigid``) side by side on a frictionless
    ground, faces and corners coincident (a box Newton's cradle), edge contacts on every
    pair, the first moving at ``speed`` (m/s) into the others."""
    material = {"rigid": True} if rigid else {"stiffness": 800.0, "damping": 0.5, "damper": "axial"}
    boxes = [{"name": f"b{k}", "shape": "box", "count": [2, 2, 2], "size": [SIDE] * 3, "mass_total": 0.2,
              **material, "position": [k * SIDE, 0.0, SIDE / 2],
              "velocity": [speed if k == 0 else 0.0, 0.0, 0.0]} for k in range(n)]
    pairs = [{"bodies": [f"b{i}", f"b{j}"], "restitution": restitution, "edges": True}
             for i in range(n) for j in range(i + 1, n)]
    return {"name": "row_of_boxes", "gravity": [0.0, 0.0, -G], "bodies": boxes, "contacts": pairs,
            "grounds": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}],
            "simulation": {"t_end": 0.05, "output_dt": 0.005}}


def test_boxes_side_by_side_with_coincident_corners_rest_and_collide_cleanly():
    """Where two boxes' corners coincide, a corner meets the other box at its vertex, where
    the direction between the two points is round-off, and each rim edge meets the other's
    edges at their ends.  A corner was held on whichever face the round-off chose (the
    other box's top face, the other corner on this one's: two rows opposite each other, a
    force problem with no answer), and an edge row that fired was given, by the fall-back
    search, an edge 0.1 m off (its lines "crossed" there) and put back onto it by that.
    Now a corner is held on a face its own box lies outside of, a face's rim point counts
    as its edge's or vertex's, and the fall-back takes an edge only within a slack of
    touching.  Three boxes at rest stay so; the first of two struck plastically carries
    the other along, the horizontal momentum kept (the ground is frictionless).  Before:
    'unsupported' at 0.3 ms, 0.11 m inside; 'chattering' at 0.5 ms; 'too_slow' at 0.35 ms."""
    r = flexbody.simulate(flexbody.load_scene(_row_of_boxes(3, 0.0, 0.0)))
    assert r.status == "success", r.message
    assert r.stats["max_penetration_m"] < 1e-9  # measured 6.6e-12 m
    assert r.stats["energy_drift_relative"] < 1e-6  # measured 1.7e-9
    momentum = np.einsum("i,tid->td", r.masses, r.velocities)
    assert np.abs(momentum[:, :2]).max() < 1e-12  # measured 4.3e-19 kg m/s
    # the middle box's sag spreads its base and pushes the outer two apart (4e-4 m), alike (to 1e-13 m)
    centre = [r.positions[:, 8 * k : 8 * (k + 1), 0].mean(axis=1) for k in range(3)]
    assert np.abs(centre[1] - SIDE).max() < 1e-6 and np.abs((centre[0] + centre[2]) / 2 - SIDE).max() < 1e-6
    r = flexbody.simulate(flexbody.load_scene(_row_of_boxes(2, 0.65, 0.0)))
    assert r.status == "success", r.message
    assert r.stats["max_penetration_m"] < 1e-9 and r.stats["max_edge_crossing_m"] == 0.0  # measured 2.0e-12 m
    assert r.stats["energy_drift_relative"] < 1e-6  # measured 1.5e-7
    momentum = np.einsum("i,tid->td", r.masses, r.velocities)[:, 0]
    np.testing.assert_allclose(momentum, 0.2 * 0.65, rtol=1e-9)


@pytest.mark.parametrize("n, speed, restitution", [(3, 0.65, 0.5), (4, 0.65, 0.5), (4, 0.8353701047548189, 1.0)])
def test_a_struck_row_of_flexible_boxes_keeps_every_point_outside_the_others(n, speed, restitution):
    """Three or four flexible boxes side by side, corners coincident, the first struck at
    0.65 m/s (e = 0.5).  Two failures before: (1) one box's top rim edge and the next
    one's, nearly parallel, read their lines 6.7e-6 m crossed along the face between them
    while their closest points lay on the other box's top face, and the penetration
    counted the lines' distance; it counts how far the points of a crossing are inside the
    other body now.  (2) A box's bottom corner lies on the next box's bottom plane (both on
    the ground), so its gap reads 0 there; its vertical edge and the next box's bottom
    edge were an edge contact at gap 0 with the closest point on the first edge's end
    (s = +1e-19), and as the corner moved into the next box s fell to -4e-10: off the
    edge, no contact, and the edges crossed by 7e-7 m unseen (four boxes stopped
    `chattering` at 17.8 ms, 2.1e-6 m of edges crossed; three warned of a put-back of
    4.6e-7 m and an edge 2.1e-9 m through a face).  A closest point within AT_END of an
    edge's end is on the edge now (and a held one is released only that far past it, else
    it was found and hit again at once, ten times in 1.5 us).  Measured: 2.0e-12 m (three,
    164 events), 3.0e-12 m (four, 316 events), no crossing, no warning; the momentum along
    the row kept (frictionless ground).  The third case is a fuzz's row (e = 1) that took
    those ten impacts and warned of a particle 1e-11 m inside (now 258 events, 3.0e-12 m)."""
    r = flexbody.simulate(flexbody.load_scene(_row_of_boxes(n, speed, restitution)))
    assert r.status == "success", r.message
    assert r.stats["max_penetration_m"] < 1e-9 and r.stats["max_edge_crossing_m"] == 0.0
    assert r.stats["warnings"] == []
    momentum = np.einsum("i,tid->td", r.masses, r.velocities)[:, 0]
    np.testing.assert_allclose(momentum, 0.2 * speed, rtol=1e-9)
    centres = r.positions[-1, :, 0].reshape(n, 8).mean(axis=1)
    assert (np.diff(centres) > SIDE - 1e-3).all()  # in order, apart by a side less their squeeze


def test_a_box_pushed_into_a_box_level_with_it_is_stopped_where_it_meets_it():
    """Two equal flexible cubes on the ground, 1e-6 m apart and 2 cm askew, the first pushed
    at 1 m/s (e = 0; a fuzz's scene): their tops and bottoms are coplanar, so the first
    cube's leading corners, once at the other's face, lie on its top and bottom planes and
    read a gap of exactly 0 from then on, a plateau.  The root was taken at the step's end
    (its value 0 too), 1e-4 m past the face they met, where the corners' closest face is
    the top one: held on it, sliding, the cube went all the way through the other
    (`success`, 0.02 m edges through, the second cube never moved).  The root is now the
    plateau's start: the corners hit the face they meet at 1 us, and the second cube is
    pushed along."""
    a = {"name": "a", "shape": "box", "count": [2, 2, 2], "size": [SIDE] * 3, "mass_total": 0.5,
         "stiffness": 3000.0, "damping": 0.3, "damper": "relative", "position": [0.0, 0.0, SIDE / 2],
         "velocity": [1.0, 0.0, 0.0]}
    b = {**a, "name": "b", "position": [SIDE + 1e-6, 0.02, SIDE / 2], "velocity": [0.0, 0.0, 0.0]}
    table = {"name": "pushed_level", "gravity": [0.0, 0.0, -G], "bodies": [a, b],
             "grounds": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0], "restitution": 0.3}],
             "contacts": [{"bodies": ["a", "b"], "restitution": 0.0, "edges": True}],
             "simulation": {"t_end": 0.1, "output_dt": 0.01}}
    r = flexbody.simulate(flexbody.load_scene(table))
    assert r.status == "success", r.message
    assert r.events_kind[0] == "impact" and r.events_time[0] == pytest.approx(1e-6, rel=1e-6)
    assert r.stats["max_penetration_m"] < 1e-9 and r.stats["max_edge_crossing_m"] == 0.0  # measured 2.6e-10 m
    centre = [r.positions[:, 8 * k : 8 * (k + 1), 0].mean(axis=1) for k in range(2)]
    assert (centre[1] - centre[0]).min() > SIDE - 1e-3  # apart by a side less its squeeze (0 m: through)
    momentum = np.einsum("i,tid->td", r.masses, r.velocities)[:, 0]
    np.testing.assert_allclose(momentum, 0.5, rtol=1e-6)  # frictionless ground


@pytest.mark.slow  # the whole-scene derivation of four rigid boxes (~40 s)
@pytest.mark.parametrize("restitution", [0.5, 1.0])
def test_a_row_of_four_rigid_boxes_struck_takes_the_simultaneous_impacts_closed_form(restitution):
    """Four rigid boxes side by side, corners coincident, the first struck at v = 0.65 m/s:
    every contact of the row touches at t = 0, so the impact is one LCP over all of them,
    Newton's law per contact.  Its answer in closed form: the struck box leaves the others
    at e v and the three move as one (the contacts between them, at rest, take impulse and
    stay closed), so v1 = (1 - 3 e) v / 4 and v2 = v3 = v4 = (1 + e) v / 4, kinetic energy
    kept with e = 1.  Before, a corner held at its rim was handed over onto the other box's
    top face ('unsupported' at t = 0), then the edge contacts at the coincident corners,
    their closest points at an edge's end, were released there at once and the row took a
    sequence of 238 impacts instead (measured on a fuzz's row, e = 0.41).  Nothing inside
    anything, the momentum kept (frictionless ground)."""
    v = 0.65
    r = flexbody.simulate(flexbody.load_scene(_row_of_boxes(4, v, restitution, rigid=True)))
    assert r.status == "success", r.message
    assert r.stats["max_penetration_m"] < 1e-9 and r.stats["max_edge_crossing_m"] == 0.0  # measured 1.7e-16 m
    speed = np.einsum("i,ki->k", r.masses[:8], r.velocities[-1, :, 0].reshape(4, 8)) / r.masses[:8].sum()
    e = restitution
    np.testing.assert_allclose(speed, [(1 - 3 * e) * v / 4] + [(1 + e) * v / 4] * 3, atol=1e-9)
    momentum = np.einsum("i,tid->td", r.masses, r.velocities)
    assert np.abs(momentum[:, 0] - 0.2 * v).max() < 1e-12 and np.abs(momentum[:, 1]).max() < 1e-12
    lost = 0.5 * 0.2 * (v**2 - ((1 - 3 * e) * v / 4) ** 2 - 3 * ((1 + e) * v / 4) ** 2)
    assert r.kinetic[0] - r.kinetic[-1] == pytest.approx(lost, abs=1e-12)  # 0 with e = 1


def test_a_body_starting_inside_another_is_told_so_before_any_edge_crossing():
    """Particles inside another body are the plainer reason: named first (with their depth)."""
    table = _crossed_boxes(0.0)
    for box in table["bodies"]:  # both flat, the upper one's bottom corners 0.02 m into the lower one
        box["rotation"] = [0.0, 0.0, 0.0]
    table["bodies"][0]["position"] = [0.0, 0.0, SIDE / 2]
    table["bodies"][1]["position"] = [0.01, 0.02, 1.5 * SIDE - 0.02]
    with pytest.raises(flexbody.InputError, match="starts inside"):
        flexbody.simulate(flexbody.load_scene(table))


@pytest.mark.slow  # three rigid boxes derived whole (cold cache); the run ~6 s
def test_a_fuzzed_stack_of_boxes_with_edge_contacts_keeps_its_edges_apart():
    """A fuzz's stack (tests/reference/fuzz_stacked_boxes_edges.json: three rigid boxes and a
    flexible one, `edges = true` on most pairs).  A rigid box's rim went 0.5 mm through the
    flexible box's bottom diagonal (flat at the start, so left out, then creased outward),
    then a rigid box's edge through the flexible box's top rim bent acute (the crossing's
    closest point lay outside the other body, so the crossing read no contact), and the run
    ended `too_slow` with particles 0.6 mm inside."""
    table = reference_table("fuzz_stacked_boxes_edges")
    r = flexbody.simulate(flexbody.load_scene(table), max_wall_time=300.0)
    assert r.status == "success", r.message
    assert r.stats["events"] > 200  # measured 339
    assert r.stats["max_edge_crossing_m"] == 0.0  # 4.9e-4 m before
    assert r.stats["max_penetration_m"] < 1e-9  # 6.1e-4 m before; measured 4.1e-12 m
    assert r.stats["energy_drift_relative"] < 1e-6  # measured 1.8e-8


@pytest.mark.slow  # flexible boxes: the tower ~10 s, the bridge ~30 s
@pytest.mark.parametrize("name", ["fuzz_rim_across_two_quads", "fuzz_bridge_middle_line"])
def test_an_edge_across_a_flexible_face_of_two_squares_has_a_row_for_each_line(name):
    """Two fuzzed scenes of flexible boxes (`edges = true`) whose edge lies across another
    box's face of two squares, which has five lines (two rims, the line between the squares,
    two diagonals), each a contact where it creases outward.  The edge had three rows, all
    held on three of them, and none watched the next.  A tower of three: the bottom box's
    top rim [6, 7] held on the middle box's [12, 15], [12, 16] and [13, 16] from t = 0.0676
    s; the other diagonal [13, 17] (s = 0.977, creased 7.4e-3 rad) reached gap 0 at 0.0788 s
    with no row to fire, 7.7e-6 m through unseen, then 8.8e-6 m of penetration and a
    put-back as a freed row found it.  A bridge of five bodies: the rim [34, 35] held on a
    rim and both diagonals of the top box's bottom; its middle line [37, 40] turned from a
    valley to a ridge as the edge reached it (gap and crease pass 0 together) and went
    3.9e-6 m through.  With five rows the fourth fires there."""
    r = flexbody.simulate(flexbody.load_scene(reference_table(name)), max_wall_time=300.0)
    assert r.status == "success", r.message
    assert r.stats["events"] > 500  # measured 819 and 1 442
    assert r.stats["max_edge_crossing_m"] == 0.0  # 7.7e-6 m and 4.4e-7 m before
    assert r.stats["max_penetration_m"] < 1e-9  # 8.8e-6 m and 3.9e-6 m before; measured 2.3e-12 and 1.2e-11 m
    assert r.stats["max_put_back_m"] < 1e-9  # as the penetration before
    assert r.stats["energy_drift_relative"] < 1e-6  # measured 3.8e-9 and 5.8e-9


@pytest.mark.slow  # two flexible boxes to 0.3 s, ~3 s each
@pytest.mark.parametrize("name", ["fuzz_leaning_box_corner_under_edge", "fuzz_leaning_box_back_diagonal"])
def test_a_leaning_boxs_bottom_edge_passing_over_a_corner_on_the_ground_crosses_no_edge(name):
    """A fuzz's scene (tests/reference/fuzz_leaning_box_corner_under_edge.json: a flexible
    box b1 tilted 0.053 rad leaning on another, b0, both on the ground, `edges = true`).
    b1's bottom edge [9, 11] slides onto b0's bottom corner 2 as b1 turns upright; the edge
    contact of b0's vertical corner edge [2, 6] with it has its closest point at the corner,
    and its gap passes 0 at t = 0.0282 s as that point passes the corner (s is the gap times
    the edge's lean): one step later s = -2.7e-8, past AT_END, and the pair was no contact.
    The corner passes beneath b1's bottom face (outside b1 by 1e-9 m) while [2, 6] goes
    through b1's side face: no vertex contact saw it, 7.2e-5 m crossed at 0.03 s, 7.4e-4 m
    (and 2.1e-4 m inside) at 0.3 s.  A crossed pair past one edge's end whose vertex there is
    less than half as deep in the other body as the lines cross, its edge through one of the
    other edge's triangles, the other's closest point inside it by the depth, is an edge
    contact (EdgeSlots._past_an_end): the row fires at the corner.  A variant (b1 2 mm
    farther, 2.8 cm along -y, faster: fuzz_leaning_box_back_diagonal.json) crossed 4.6e-4 m
    by 0.03 s, then with that rule alone took a pair 7.7e-5 m crossed near an end and
    stalled (`too_slow`); with a deep crossing near an end tested the same way it is clean
    (measured 4.0e-12 m, no crossing, 133 events to 0.3 s)."""
    r = flexbody.simulate(flexbody.load_scene(reference_table(name)), t_end=0.3, max_wall_time=120.0)
    assert r.status == "success", r.message
    assert r.stats["max_edge_crossing_m"] == 0.0  # 7.4e-4 m before
    assert r.stats["max_penetration_m"] < 1e-9  # 2.1e-4 m before; measured 4.0e-12 m (both)
    assert r.stats["max_put_back_m"] < 1e-9
    assert not r.stats["warnings"]
    assert r.stats["energy_drift_relative"] < 1e-6  # measured 4.5e-8 and 6.6e-8


@pytest.mark.slow  # two flexible boxes, ~2 s
def test_a_struck_boxs_corner_at_the_next_ones_rim_on_the_ground_crosses_no_edge():
    """A tenth fuzz's struck row (tests/reference/fuzz_row_corner_under_rim.json, cut to
    0.027 s: two flexible boxes side by side on the ground, `edges = true`): b0's bottom
    corner stands at b1's bottom rim [40, 44]; the edge row of b0's vertical corner edge
    [11, 23] held on that rim with its closest point at the corner was released at 0.02499
    s, and from then on the closest point lay just past the corner (beyond AT_END): the
    pair was no contact while the lines crossed, 5.2e-5 m by 0.02582 s, unwatched; held
    again at 0.02668 s and put back 2.05e-4 m (drift 5.4e-4).  Past the end, a crossed pair
    whose vertex is outside the other body is still the edges' contact (as the leaning
    box's above)."""
    r = flexbody.simulate(flexbody.load_scene(reference_table("fuzz_row_corner_under_rim")), max_wall_time=120.0)
    assert r.status == "success", r.message
    assert r.stats["max_edge_crossing_m"] == 0.0  # 7.9e-5 m before
    assert r.stats["max_put_back_m"] < 1e-9  # 2.05e-4 m before; measured 0
    assert r.stats["max_penetration_m"] < 1e-9  # measured 3.6e-12 m
    assert r.stats["energy_drift_relative"] < 1e-6  # 5.4e-4 before; measured 3.5e-9


@pytest.mark.slow  # three flexible boxes, ~10 s
def test_a_corner_edge_through_a_rim_within_one_step_near_its_end_is_the_edges_crossing():
    """A tenth fuzz's struck row (tests/reference/fuzz_row_rim_crossed_in_one_step.json, cut
    to 0.0446 s): b1's corner 24 on the ground at b0's bottom rim [5, 8].  One step (0.0441635
    to 0.0443280 s) took the rim's edge row against b1's vertical corner edge [24, 33] from
    +5.4e-6 to -3.73e-5 m, its closest point 1.3e-7 m up from the corner, 1.3e-7 m inside
    b0.  Deeper than DEEP_CROSSING slacks with the closest point nearer the end than that, a
    crossing was taken for the end vertex's, and refused: no sign change, 1.1e-4 m crossed
    by 0.0446 s (1.4e-3 m by 0.131 s).  The vertex is not that deep: the edges' crossing,
    as past the end (EdgeSlots._past_an_end); the row fires."""
    r = flexbody.simulate(flexbody.load_scene(reference_table("fuzz_row_rim_crossed_in_one_step")),
                          max_wall_time=120.0)
    assert r.status == "success", r.message
    assert r.stats["max_edge_crossing_m"] == 0.0  # 1.1e-4 m before
    assert r.stats["max_penetration_m"] < 1e-9 and r.stats["max_put_back_m"] < 1e-9  # measured 3.0e-12 m
    assert r.stats["energy_drift_relative"] < 1e-6  # measured 7.8e-8


@pytest.mark.slow  # three flexible boxes, ~20 s
def test_a_face_diagonal_under_an_acute_corner_edge_is_crossed_with_each_edge_in_the_other_body():
    """A tenth fuzz's struck row (tests/reference/fuzz_row_diagonal_under_acute_corner_edge.json,
    cut to 0.0078 s): b1's vertical corner edge [36, 40], its wedge squeezed to 87.8 deg,
    lies on b0's bulging face.  One step took the edge row of b0's face diagonal [14, 29]
    against it from +1.09e-6 to -1.6e-6 m (closest point s = 0.046): [36, 40]'s point
    inside b0 by the whole depth, the diagonal's 5.8e-8 m outside b1 (h cos 87.8 deg) while
    the diagonal goes through both of [36, 40]'s triangles; [36, 40] passes beneath both
    the diagonal's triangles, in and out of b0 through the next ones.  A crossing taken with
    both points inside or both edges through triangles was refused: no sign change, 1.6e-6
    m inside and put back.  Each edge in the other body by either test is the crossing
    (EdgeSlots._crossing_inside); the row fires."""
    r = flexbody.simulate(flexbody.load_scene(reference_table("fuzz_row_diagonal_under_acute_corner_edge")),
                          max_wall_time=120.0)
    assert r.status == "success", r.message
    assert r.stats["max_edge_crossing_m"] == 0.0
    assert r.stats["max_penetration_m"] < 1e-9  # 1.6e-6 m before; measured 6.3e-12 m
    assert r.stats["max_put_back_m"] < 1e-9  # as the penetration before
    assert not r.stats["warnings"]
    assert r.stats["energy_drift_relative"] < 1e-6  # 1.2e-5 before; measured 2.4e-8


@pytest.mark.slow  # three flexible boxes, ~18 s
def test_a_corner_edge_with_its_ends_on_both_faces_of_a_rim_crosses_it_as_an_edge():
    """A tenth fuzz's struck row (tests/reference/fuzz_row_corner_edge_on_both_rim_faces.json,
    cut to 0.103 s): b1's bottom corner 29 on the ground, on the plane of b2's bottom face,
    its vertical corner edge [29, 41] leaning toward b2 and b2's side face leaning away: the
    top corner 41 is held on that side face.  The corner slid under b2's bottom rim [45, 48]
    (the pair's closest point 5.5e-7 of the edge below the corner, past its end): the edge
    then cuts the rim's wedge from its bottom face to its side face, both ends on their
    planes, and passes strictly through neither triangle, and the pair was refused (1.6e-4
    m crossed, then 2.1e-4 m with the closest point back on the edge, still as the
    vertex's); a point went 4.3e-6 m inside b2.  From a triangle into the body counts as
    through it (EdgeSlots._past_an_end): the row fires as the corner passes the rim."""
    r = flexbody.simulate(flexbody.load_scene(reference_table("fuzz_row_corner_edge_on_both_rim_faces")),
                          max_wall_time=120.0)
    assert r.status == "success", r.message
    assert r.stats["max_edge_crossing_m"] == 0.0  # 1.8e-8 m before
    assert r.stats["max_penetration_m"] < 1e-9  # 4.3e-6 m before; measured 4.0e-12 m
    assert r.stats["max_put_back_m"] < 1e-9
    assert not r.stats["warnings"]
    assert r.stats["energy_drift_relative"] < 1e-6  # measured 1.7e-8


@pytest.mark.slow  # a rigid box derived whole (cold cache); the run ~4 s
def test_a_flexible_boxs_corner_handed_across_a_diagonal_still_slides_off_the_rim():
    """A fuzz's scene (tests/reference/fuzz_box_corner_over_rim.json: a flexible 3 x 2 x 2
    box, a sphere and a rigid box, `edges = true`).  A corner of the flexible box, held on a
    face of the rigid box, slid across the face's diagonal; the hand-over left a twin on
    the old triangle a hair past its boundary with a margin floor of 0, so its boundary
    event never fired: swapped back into the slot, the corner slid 0.08 m past the rim held
    on the old triangle's plane, its force down to -7 N with no lift-off.  And an edge of
    the flexible box went 1.9e-6 m through a triangle of the sphere (its face edges, flat
    at the start, were no edge contacts)."""
    table = reference_table("fuzz_box_corner_over_rim")
    r = flexbody.simulate(flexbody.load_scene(table), max_wall_time=300.0)
    assert r.status == "success", r.message
    assert r.stats["min_held_contact_force_N"] > -1e-6  # -6.9 N before
    assert r.stats["max_edge_crossing_m"] == 0.0  # 1.9e-6 m before
    assert r.stats["max_penetration_m"] < 1e-9
    assert r.stats["energy_drift_relative"] < 1e-6


@pytest.mark.slow  # three rigid boxes derived whole (cold cache); the run ~4 s
def test_a_vertex_held_beside_a_face_on_face_contact_is_no_deep_edge_crossing():
    """A fuzz's stack (tests/reference/fuzz_boxes_face_on_face_edges.json: three rigid boxes
    and a soft one, `edges = true` on every pair).  Two rigid boxes came to touch face on
    face, a vertex of one held on the other's face with its edge standing off that face
    and an edge of the other lying on it: the two edges' lines read crossed by 0.032 m
    along a normal in the contact plane, each closest point on the other body (the inside
    test's), and the free edge row fired an impact on it; the run reported 0.032 m
    inside.  A deep crossing at an edge's end is now not taken on that test (it is the
    end vertex's)."""
    table = reference_table("fuzz_boxes_face_on_face_edges")
    r = flexbody.simulate(flexbody.load_scene(table), max_wall_time=300.0)
    assert r.status == "success", r.message
    assert r.stats["max_penetration_m"] < 1e-9  # 0.032 m before; measured 1.5e-11 m
    assert r.stats["max_edge_crossing_m"] == 0.0
    assert r.stats["energy_drift_relative"] < 1e-6  # measured 6.7e-8


@pytest.mark.slow  # three rigid boxes derived whole (cold cache); the run ~11 s
def test_the_last_sample_is_read_with_the_contacts_held_then():
    """A fuzz's pile (tests/reference/fuzz_pile_stopped_chattering.json: three rigid boxes,
    a soft icosahedron and a flexible box, `edges = true` on every pair) stopped
    `chattering` at 0.2013 s, after its last output sample (0.2 s).  The stats read that
    sample's gaps with the contacts held and the edges they were held on at the stop: a
    free edge row read against an edge it held later showed its lines "crossed" by 3e-4 m
    (reported as penetration, with the warning that an impact was missed).  Read as the
    sample was, nothing is inside anything.  Since corners met at a vertex are held on a
    face their own body lies outside of, the pile runs to its end; with the guard's bound
    lowered to 10 impacts within 1 ms it stops at 0.172 s, after its 0.17 s sample, which
    read with the contacts held at the stop shows 3.2e-5 m."""
    table = reference_table("fuzz_pile_stopped_chattering")
    r = flexbody.simulate(flexbody.load_scene(table), max_wall_time=300.0)
    assert r.status == "success", r.message
    assert r.stats["max_penetration_m"] < 1e-9 and r.stats["max_edge_crossing_m"] == 0.0  # measured 5.7e-11 m
    table["simulation"]["chatter_impacts"] = 10
    r = flexbody.simulate(flexbody.load_scene(table), max_wall_time=300.0)
    assert r.status == "chattering", r.message  # the guard on a burst of impacts (README: "Piles of 3D bodies")
    stop = float(re.search(r"up to t = (\S+) s", r.message).group(1))
    assert r.t[-1] < stop  # its last sample is before the stop
    assert r.stats["max_penetration_m"] < 1e-9  # 3.2e-5 m read at the stop's contacts; measured 9.0e-12 m
    assert r.stats["max_edge_crossing_m"] == 0.0
    assert not any("between event checks" in w for w in r.stats["warnings"])


@pytest.mark.slow  # two rigid boxes derived whole (cold cache); the run ~7 s
def test_an_edge_row_that_fired_as_its_sibling_passed_an_end_is_not_held_apart():
    """A fuzz's stack (tests/reference/fuzz_edge_released_past_an_end.json: two rigid boxes
    and a flexible one, `edges = true`).  An edge of a rigid box, held on two edges of the
    flexible box's face, slid past a vertex onto the third edge there; its row held on the
    first was set free at that end as a third row of the same edge hit the third edge.
    Free, the released row watches the closest edge again (rows share their edge's
    contacts by rank), so the row that hit was held on the next closest, 2e-3 m apart,
    and putting it back moved the two bodies by that: the run stalled (`too_slow` at
    0.15 s, 0.77 mm inside).  A row that fired but watches an edge apart once its sibling
    is released is no longer touching."""
    table = reference_table("fuzz_edge_released_past_an_end")
    r = flexbody.simulate(flexbody.load_scene(table), max_wall_time=60.0)
    assert r.status == "success", r.message
    assert r.stats["max_penetration_m"] < 1e-9  # 7.7e-4 m before; measured 6.5e-11 m
    assert r.stats["max_edge_crossing_m"] == 0.0
    assert r.stats["energy_drift_relative"] < 1e-6  # measured 5.0e-8


@pytest.mark.slow  # four flexible bodies, ~7 s
def test_a_vertex_slot_beside_the_edge_row_at_its_corner_is_not_held_pulling():
    """An eleventh fuzz's row (tests/reference/fuzz_vertex_slot_and_edge_row_at_one_corner.json:
    a flexible box pushed into a 20-particle flexible sphere, then two flexible boxes, `edges
    = true`, frictionless).  b2's corner 61 is held on a face of b3 by its vertex slot (contact
    310); at 0.0028799 s the edge row of an edge at that corner (contact 1503) hits b3's edge
    there, its row 2e-6 from the slot's (W's condition 1e12).  The force LCP loads the edge
    row (0.044 N) and leaves the slot without force, accelerating away at 1.5e-9 m/s^2, below
    the release floor (3.1e-9): kept held, and the segment's solve held both at 0 by -2.35 N
    on the slot and +2.39 N on the edge row.  The slot's lift-off event, starting below 0,
    never fired: "a held contact's force turned negative (-0.94 N)" at the sample at 3.7 ms,
    held until 4.3 ms.  A row the LCP leaves unloaded that held would pull is set free as
    implied (coupled._held_pulling)."""
    r = flexbody.simulate(flexbody.load_scene(reference_table("fuzz_vertex_slot_and_edge_row_at_one_corner")),
                          max_wall_time=120.0)
    assert r.status == "success", r.message
    assert not r.stats["warnings"]  # -0.94 N before
    assert r.stats["min_held_contact_force_N"] >= 0.0  # measured 0
    assert r.stats["max_penetration_m"] < 1e-9  # measured 1.4e-12 m
    assert r.stats["max_edge_crossing_m"] == 0.0
    assert r.stats["energy_drift_relative"] < 1e-6  # measured 8.4e-10


@pytest.mark.slow  # three flexible boxes to 0.1226 s, ~40 s
def test_a_ridge_crossed_as_it_turns_to_a_valley_is_an_event_before_it_turns():
    """The seventh fuzz's stack of three flexible boxes (tests/reference/fuzz_stack_corner_over_diagonal.json,
    here to 0.1226 s).  b0's top diagonal [19, 23], a ridge flattening (1.35e-5 rad at
    0.12236 s, 2.3e-7 at 0.12243), lies across b1's bottom rim [29, 32], which comes down on
    b0's top face.  Its free edge row (contact 426) read the pair's gap +3.8e-9 m at
    0.1224234 s, crossed from 0.1224305 s, -1.24e-9 m when a corner of b1 landed at
    0.12243226 s; from 0.1224340 s the diagonal is a valley, which an edge row does not
    watch, and the row read the margin: the step's ends and the points checked in it saw no
    sign change, and the crossing was found only at that landing, 1.2e-9 m deep (a warning).
    Through a segment a pair of edges that may touch at its start is watched while crossed,
    convex or not (EdgeSlots.start_segment): the row fires at its root, before the turn."""
    table = reference_table("fuzz_stack_corner_over_diagonal")
    table["simulation"]["t_end"] = 0.1226
    r = flexbody.simulate(flexbody.load_scene(table), max_wall_time=300.0)
    assert r.status == "success", r.message
    assert r.stats["max_edge_crossing_m"] == 0.0  # 1.2e-9 m before
    assert r.stats["max_penetration_m"] < 1e-9  # 1.2e-9 m before
    assert not r.stats["warnings"]


def test_edge_rows_take_the_laws_of_their_own_pair_wherever_it_is_listed():
    """The edge rows of a pair listed after one without edges have their own pair's laws
    (here e = 0.5, friction 0), not those of the contact at their index among the pairs
    with edges (the first listed: mu 0.4, e 0.1).  Measured: a fuzzed stack's edge rows
    read another pair's friction 0.431; their stops then divided by their tangent rows'
    zero diagonal, and their restitution was that pair's too."""
    from flexbody.driver import _rebound_laws
    from flexbody.model import load_model

    table = _third_box(_flexible(_crossed_boxes(DROP, edges=True), 0.1))
    table["contacts"] = [{"bodies": ["a", "c"], "friction": 0.4, "restitution": 0.1},
                         {"bodies": ["a", "b"], "restitution": 0.5, "edges": True}]
    scene = flexbody.load_scene(table)
    model = load_model(scene)
    ng, edge = model.n_ground_contacts, np.arange(model.first_edge, model.n_slots)
    assert len(edge) and np.all(model.slot_pair[edge] == 1)
    assert np.all(model.mu[ng + edge] == 0.0)
    e = _rebound_laws(scene, model, SIDE)[0]
    assert np.all(e[ng + edge] == 0.5)
    assert np.all(e[ng : ng + model.first_edge][model.slot_pair[: model.first_edge] == 0] == 0.1)


def _crossed_bars(friction: float, ground_friction: float, speed: float) -> dict:
    """A rigid bar (0.4 x 0.12 x 0.05 m, along x) on the ground and another (0.05 x 0.4 x
    0.05 m, along y) dropped ``DROP`` onto it crosswise at ``speed`` along its own length:
    their faces cross, no vertex of either lies over the other's face, so they meet at four
    edge crossings only.  The lower bar is wide enough (0.12 m) not to tip under the
    friction at its top (a 0.05 m one is at the edge of it for mu = 0.5)."""
    lower = {"name": "lower", "shape": "box", "rigid": True, "count": [2, 2, 2], "size": [0.4, 0.12, 0.05],
             "mass_total": 0.5, "position": [0.0, 0.0, 0.025]}
    upper = {"name": "upper", "shape": "box", "rigid": True, "count": [2, 2, 2], "size": [0.05, 0.4, 0.05],
             "mass_total": 0.5, "position": [0.0, 0.0, 0.075 + DROP], "velocity": [0.0, speed, 0.0]}
    return {"name": "crossed_bars", "gravity": [0.0, 0.0, -G], "bodies": [lower, upper],
            "grounds": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0], "friction": ground_friction}],
            "contacts": [{"bodies": ["lower", "upper"], "friction": friction, "edges": True}],
            "simulation": {"t_end": 0.15, "output_dt": 0.005}}


def test_a_bar_sliding_crosswise_on_a_bar_meets_coulombs_law_at_its_edges():
    """On a frictionless ground: the upper bar lands at sqrt(2 h / g) on the four crossings
    (a plastic impact: its normal impulse m sqrt(2 g h) takes mu times that off its speed
    along y and gives it to the lower bar), then friction mu m g acts on both (mu = 0.5,
    equal masses) until they move together at v0 / 2, momentum along y kept throughout:
    the closed form to rounding (measured 2e-15 m/s).  Before this stop the pair's friction
    was refused with edge contacts, and without them the bar fell through the other's edges."""
    mu, v0, m = 0.5, 0.5, 0.5
    r = flexbody.simulate(flexbody.load_scene(_crossed_bars(mu, 0.0, v0)))
    assert r.status == "success", r.message
    assert r.stats["max_edge_crossing_m"] == 0.0 and r.stats["max_penetration_m"] < 1e-9
    assert r.stats["energy_drift_relative"] < 1e-6 and not r.stats["warnings"]
    t1 = np.sqrt(2 * DROP / G)
    assert abs(r.events_time[0] - t1) < 1e-9
    dv = mu * np.sqrt(2 * G * DROP)  # the landing's friction impulse over m
    (stick,) = set(r.events_time[r.events_kind == "stick"])
    assert stick == pytest.approx(t1 + (v0 - 2 * dv) / (2 * mu * G), abs=1e-9)
    upper, lower = r.velocities[:, 8:, 1].mean(axis=1), r.velocities[:, :8, 1].mean(axis=1)
    after = r.t - t1
    np.testing.assert_allclose(upper, np.where(r.t < t1, v0, np.maximum(v0 - dv - mu * G * after, v0 / 2)), atol=1e-12)
    np.testing.assert_allclose(lower, np.where(r.t < t1, 0.0, np.minimum(dv + mu * G * after, v0 / 2)), atol=1e-12)
    np.testing.assert_allclose(m * (upper + lower), m * v0, rtol=0, atol=1e-12)


def test_a_bar_sliding_crosswise_on_a_bar_on_a_rough_ground_stops_and_the_lower_stays_put():
    """The same on a rough ground (mu = 0.5): the lower bar does not move (its ground
    friction holds what the upper's pushes), and the upper stops sliding at
    t1 + (v0 - mu sqrt(2 g h)) / (mu g).  Not to rounding: the lower bar stands on four
    corners, redundant contacts whose forces are not unique; one is released at the landing
    (force 0) and the rocking that follows within 0.3 ms, at 1e-12 m, takes 1.1e-5 m/s
    more off the upper bar's speed (measured; the stop 2.3e-6 s early)."""
    mu, v0 = 0.5, 0.5
    r = flexbody.simulate(flexbody.load_scene(_crossed_bars(mu, 0.5, v0)))
    assert r.status == "success", r.message
    assert r.stats["max_edge_crossing_m"] == 0.0 and r.stats["max_penetration_m"] < 1e-9
    assert np.abs(r.velocities[:, :8]).max() < 1e-12
    t1 = np.sqrt(2 * DROP / G)
    (stick,) = set(r.events_time[r.events_kind == "stick"])
    assert stick == pytest.approx(t1 + (v0 - mu * np.sqrt(2 * G * DROP)) / (mu * G), abs=1e-5)
    assert np.abs(r.velocities[r.t > stick + 1e-3, 8:]).max() < 1e-12  # stuck


def test_a_fuzzed_rough_stack_sticks_and_slides_on_its_edge_rows(monkeypatch):
    """A fuzz's scene (tests/reference/fuzz_rough_edges_crossed_stack.json, stop 58: a
    flexible box dropped tilted onto a rigid one, friction 0.5 between them with edge
    contacts, a frictionless ground): its edge rows stick and slide, nothing crosses and
    nothing is inside anything by 1e-9 m (measured 1.3e-11 m), the ledger closes to 1e-6
    (8.0e-8), and the horizontal momentum, which only the bodies' own contacts act on,
    stays 0 (1.4e-11 kg m/s)."""
    from flexbody import driver
    from flexbody.contact import HELD, SLIDING

    phases = {HELD: set(), SLIDING: set()}  # edge rows with friction found sticking, sliding after an instant
    resolve_at = driver._Run.resolve_at

    def watched(run, t, touching, leaving):
        events = resolve_at(run, t, touching, leaving)
        model = run.model
        edge = np.arange(model.n_contacts) >= model.n_ground_contacts + model.first_edge
        for phase in phases:
            phases[phase] |= set(np.flatnonzero(edge & (run.phases.phase == phase) & (model.mu > 0.0)).tolist())
        return events

    monkeypatch.setattr(driver._Run, "resolve_at", watched)
    r = flexbody.simulate(flexbody.load_scene(reference_table("fuzz_rough_edges_crossed_stack")))
    assert r.status == "success", r.message
    assert phases[HELD] and phases[SLIDING]
    assert r.stats["max_edge_crossing_m"] == 0.0 and r.stats["max_penetration_m"] < 1e-9
    assert r.stats["energy_drift_relative"] < 1e-6
    momentum = np.einsum("tnd,n->td", r.velocities, r.masses)[:, :2]
    np.testing.assert_allclose(momentum, 0.0, atol=1e-9)
