"""Scene files: presets, the bundled scene, and one clear error per kind of mistake."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import flexbody
from flexbody.scene import OverdampedLinkWarning, SceneError, bundled_scenes

from .conftest import body, make_scene, scene_table


def problems_of(table) -> list[str]:
    with pytest.raises(SceneError) as info:
        flexbody.load_scene(table)
    return info.value.problems


def test_thesis_ball_is_bundled_with_the_thesis_parameters():
    assert "thesis_ball" in bundled_scenes()
    s = flexbody.load_scene("thesis_ball")
    b = s.bodies[0]
    assert s.n_particles == 23 and len(b.links) == 44
    assert np.all(b.masses == 0.05) and np.all(b.stiffness == 2000.0) and np.all(b.damping == 0.5)
    assert b.damper == "relative" and b.position == (0.0, 0.5) and b.angle == 0.05
    assert s.simulation.t_end == 2.0
    x = s.initial_positions()
    # centre is index 0, the perimeter starts at the body's angle and runs counter-clockwise
    np.testing.assert_allclose(x[0], [0.0, 0.5])
    r = x[1:] - x[0]
    np.testing.assert_allclose(np.hypot(*r.T), 0.1)
    angles = np.unwrap(np.arctan2(r[:, 1], r[:, 0]))
    np.testing.assert_allclose(angles, 0.05 + 2 * np.pi * np.arange(22) / 22)
    np.testing.assert_allclose(b.rest_lengths[:22], 0.1)  # spokes first


def test_presets_shapes_and_links():
    ring = make_scene(body(particles=None, links=None, shape="ring", count=6, radius=0.2, center=False))
    assert ring.bodies[0].links == tuple((k, (k + 1) % 6) for k in range(6))
    ell = make_scene(body(particles=None, links=None, shape="ellipse", count=8, radii=[0.2, 0.1], center=True))
    pts = ell.bodies[0].points
    np.testing.assert_allclose(pts[1], [0.2, 0.0])
    np.testing.assert_allclose(pts[3], [0.0, 0.1], atol=1e-15)
    assert len(ell.bodies[0].links) == 16
    chain = make_scene(body(particles=None, links=None, shape="chain", count=4, spacing=0.1))
    np.testing.assert_allclose(chain.bodies[0].points[:, 0], [-0.15, -0.05, 0.05, 0.15])
    square = make_scene(
        body(particles=None, links=None, shape="polygon", vertices=[[0, 0], [1, 0], [1, 1], [0, 1]], position=[0, 1])
    )
    assert sorted(tuple(sorted(link)) for link in square.bodies[0].links) == [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)]


def test_rigid_initial_velocity_and_spin():
    s = make_scene(body(velocity=[1.0, 2.0], angular_velocity=3.0, particle_velocities=[[0, 0], [0, 0.5]]))
    v = s.initial_velocities()
    np.testing.assert_allclose(v, [[1.0, 2.0 - 0.3], [1.0, 2.0 + 0.3 + 0.5]])


def test_overdamped_link_warns():
    with pytest.warns(OverdampedLinkWarning, match="4 k mu - c\\^2 <= 0"):
        make_scene(body(stiffness=1.0, damping=10.0))


@pytest.mark.parametrize(
    "table, field, rule",
    [
        (scene_table(body(colour="red")), "bodies[0].colour", "unknown key"),
        (scene_table(body(), gravity=[0.0, -9.81, 0.0, 1.0]), "gravity", "list of 2 (planar) or 3 (spatial) finite numbers"),
        (scene_table(body(position=[0.0, float("nan")])), "bodies[0].position", "finite"),
        (scene_table(body(mass=0.0)), "bodies[0].mass", "> 0"),
        (scene_table(body(mass=None, masses=[0.1, -1.0])), "bodies[0].masses", "> 0"),
        (scene_table(body(links=[[0, 2]])), "bodies[0].links[0]", "missing particle"),
        (scene_table(body(links=[[0, 1], [1, 0]])), "bodies[0].links[1]", "duplicate link"),
        (scene_table(body(links=[[1, 1]])), "bodies[0].links[0]", "itself"),
        (scene_table(body(particles=[[0, 0], [0, 0]])), "bodies[0].links[0]", "zero-length"),
        (scene_table(body(position=[0.0, -0.5])), "bodies[0].position", "below grounds[0]"),
        (scene_table(body(stiffness=-1.0)), "bodies[0].stiffness", ">= 0"),
        (scene_table(body(damping=[0.1, 0.2])), "bodies[0].damping", "1 such numbers"),
        (scene_table(body(damper="viscous")), "bodies[0].damper", "one of ['relative', 'axial']"),
        (scene_table(body(), grounds=[{"point": [0, 0], "normal": [0, 0]}]), "grounds[0].normal", "non-zero"),
        (scene_table(body(), grounds=[]), "grounds", "at least one ground"),
        (scene_table(body(), simulation={"t_end": 1.0, "method": "Euler"}), "simulation.method", "one of"),
        (scene_table(body(), simulation={"t_end": 1.0, "impact": "thesis"}), "simulation.impact_dt", "required"),
        (scene_table(body(), simulation={}), "simulation.t_end", "required"),
        (scene_table(body(), simulation={"t_end": 1.0, "chatter_impacts": 0}), "simulation.chatter_impacts", ">= 1"),
        (scene_table(body(), simulation={"t_end": 1.0, "chatter_impacts": 2.5}), "simulation.chatter_impacts",
         "an integer"),
        (scene_table(body(), simulation={"t_end": 1.0, "chatter_impacts": True}), "simulation.chatter_impacts",
         "an integer"),
        ({"simulation": {"t_end": 1.0}}, "bodies", "required"),
    ],
)
def test_each_mistake_names_field_value_and_rule(table, field, rule):
    problems = problems_of(table)
    assert any(p.startswith(f"`{field}`") and rule in p for p in problems), problems


def test_all_problems_reported_at_once():
    problems = problems_of(scene_table(body(mass=-1.0, stiffness="stiff", colour=1), simulation={"t_end": -2}))
    fields = {p.split("`")[1] for p in problems}
    assert {"bodies[0].mass", "bodies[0].stiffness", "bodies[0].colour", "simulation.t_end"} <= fields


def test_unknown_scene_name_lists_bundled_scenes():
    with pytest.raises(SceneError, match="thesis_ball"):
        flexbody.load_scene("no_such_scene")


def test_scene_objects_are_immutable():
    s = make_scene(body())
    with pytest.raises(ValueError, match="read-only"):
        s.bodies[0].masses[0] = 1.0
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.name = "other"


def test_topology_ignores_parameter_values():
    a = make_scene(body(stiffness=10.0, mass=1.0)).topology()
    b = make_scene(body(stiffness=20.0, mass=2.0)).topology()
    c = make_scene(body(damper="axial")).topology()
    assert a.digest("particles") == b.digest("particles") != c.digest("particles")
    assert a.digest("particles") != a.digest("floating")


def test_chain_position_is_its_midpoint_and_a_quarter_turn_stands_it_on_particle_0():
    chain = make_scene(body(particles=None, links=None, shape="chain", count=3, spacing=0.1, position=[2.0, 1.0],
                            angle=np.pi / 2))
    x = chain.initial_positions()
    np.testing.assert_allclose(x, [[2.0, 0.9], [2.0, 1.0], [2.0, 1.1]], atol=1e-15)


def test_polygon_diagonals_are_the_second_neighbours_and_a_centre_replaces_them():
    hexagon = [[np.cos(a), np.sin(a)] for a in np.arange(6) * np.pi / 3]
    plain = make_scene(body(particles=None, links=None, shape="polygon", vertices=hexagon, position=[0, 2]))
    diagonals = {tuple(sorted(link)) for link in plain.bodies[0].links} - {(k, (k + 1) % 6) for k in range(6)} \
        - {(0, 5)}
    assert diagonals == {(0, 2), (1, 3), (2, 4), (3, 5), (0, 4), (1, 5)}  # two triangles, not all nine
    centred = make_scene(body(particles=None, links=None, shape="polygon", vertices=hexagon, center=True,
                              position=[0, 2]))
    assert len(centred.bodies[0].links) == 12  # 6 edges + 6 spokes
    np.testing.assert_allclose(centred.bodies[0].points[1:], hexagon)  # vertices stay where given in T
