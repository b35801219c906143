"""Rigid bodies touching other bodies (flexbody.body_contact over the derived floating model).

References: a ground (a flexible ring landing on a rigid block that rests on the ground moves
as it does landing on a ground at the block's top), statics (a rigid block at rest carries
what rests on it: force and moment balance on its two corners), Newton's cradle of equal
rigid balls (exchange at e = 1, a common velocity at e = 0: momentum and the closed-form
energy), and the particles formulation (two flexible bodies colliding give the same motion
whether their particles are the coordinates or ride on frames T).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import flexbody

RING = {"name": "ring", "shape": "ring", "count": 8, "radius": 0.1, "center": True,
        "angle": float(np.pi / 8), "mass": 0.05, "stiffness": 2000.0, "damping": 0.5, "position": [0.03, 0.3]}
BLOCK = {"name": "block", "shape": "polygon", "rigid": True, "mass": 0.5, "position": [0.0, 0.0],
         "vertices": [[-0.2, 0.0], [0.2, 0.0], [0.2, 0.1], [-0.2, 0.1]]}
FLAT = {"point": [0.0, 0.0], "normal": [0.0, 1.0]}
SIMULATION = {"t_end": 0.5, "output_dt": 0.002, "rtol": 1e-10, "atol": 1e-12}


@pytest.fixture(scope="module")
def ring_on_block():
    table = {"name": "ring_on_rigid_block", "grounds": [FLAT], "bodies": [RING, BLOCK],
             "contacts": [{"bodies": ["ring", "block"]}], "simulation": SIMULATION}
    return flexbody.simulate(flexbody.load_scene(table))


def test_a_ring_landing_on_a_resting_rigid_block_moves_as_on_a_ground(ring_on_block):
    """The block rests on the ground on two corners (held, coupled through the block): the
    ring's impacts and its weight go through it to the ground and it does not move, so the
    ring bounces on its top face as on a ground there."""
    on_ground = flexbody.simulate(flexbody.load_scene({
        "name": "ring_on_ground", "grounds": [{"point": [0.0, 0.1], "normal": [0.0, 1.0]}], "bodies": [RING],
        "simulation": SIMULATION}), formulation="floating", method="RK45")
    a, b = ring_on_block, on_ground
    assert a.status == b.status == "success", (a.message, b.message)
    assert a.stats["impacts"] == b.stats["impacts"] >= 2 and a.stats["liftoffs"] == b.stats["liftoffs"] >= 1
    ring = slice(0, 9)
    assert np.abs(a.positions[:, ring] - b.positions).max() < 1e-8  # measured 1.5e-9 m
    assert np.abs(a.positions[:, 9:] - a.positions[0, 9:]).max() < 1e-12  # the block stays put
    assert a.stats["max_penetration_m"] < 1e-9


def test_a_rigid_block_carrying_a_ring_balances_force_and_moment(ring_on_block):
    """At every sample the block is at rest, so its corners' forces carry its weight and the
    ring's contact forces on its top: their sum, and their moment about the block's centre."""
    r = ring_on_block
    block = slice(9, 13)
    g = 9.81
    carried = r.contact_force[:, :9]  # the block's top pushes the ring's particles up (N)
    assert carried.sum(axis=1).max() > 1.0  # the ring lands and presses on the block
    corners = r.contact_force[:, block]
    weight = r.masses[block].sum() * g
    np.testing.assert_allclose(corners.sum(axis=1), weight + carried.sum(axis=1), rtol=1e-9)
    centre = r.positions[:, block, 0].mean(axis=1)
    moment = (corners * (r.positions[:, block, 0] - centre[:, None])).sum(axis=1) \
        - (carried * (r.positions[:, :9, 0] - centre[:, None])).sum(axis=1)
    assert np.abs(moment).max() < 1e-9 * weight
    left, right = corners[:, 0], corners[:, 1]  # the ring sits right of centre: the right corner carries more
    pressed = carried.sum(axis=1) > 1.0
    assert np.all(right[pressed] > left[pressed])


@pytest.mark.parametrize("e", [1.0, 0.0])
def test_newtons_cradle_of_rigid_balls_takes_the_closed_form(e):
    """Four equal rigid balls 1e-6 m apart, the first at 1 m/s: central impacts one after the
    other.  e = 1: each passes its velocity on, so the last leaves at 1 m/s alone.  e = 0:
    each impact adds a ball to the moving group, which ends at 1/4 m/s with 3/4 of the
    kinetic energy lost.  Nothing turns."""
    scene = flexbody.load_scene("newtons_cradle_rigid")
    scene = dataclasses.replace(scene, contacts=type(scene.contacts)(
        dataclasses.replace(pair, restitution=e) for pair in scene.contacts))
    r = flexbody.simulate(scene)
    assert r.status == "success", r.message
    v = r.velocities[-1].reshape(4, 12, 2)
    expected = [0.0, 0.0, 0.0, 1.0] if e == 1.0 else [0.25] * 4
    np.testing.assert_allclose(v[:, :, 0], np.repeat(np.array(expected)[:, None], 12, axis=1), atol=1e-12)
    assert np.abs(v[:, :, 1]).max() < 1e-12
    p = (r.masses[:, None] * r.velocities[-1]).sum(axis=0)
    np.testing.assert_allclose(p, [12 * 0.05, 0.0], atol=1e-14)
    ke_first = 0.5 * 12 * 0.05
    assert r.kinetic[-1] == pytest.approx(ke_first if e == 1.0 else ke_first / 4, rel=1e-12)
    assert r.stats["impacts"] == 3


TWO_RINGS = {
    "name": "two_rings", "gravity": [0.0, 0.0],
    "bodies": [
        {"name": "a", "shape": "ring", "count": 5, "radius": 0.05, "center": True, "mass": 0.02,
         "stiffness": 500.0, "damping": 0.1, "position": [-0.08, 1.0], "velocity": [1.0, 0.2]},
        {"name": "b", "shape": "ring", "count": 5, "radius": 0.05, "center": True, "mass": 0.03,
         "stiffness": 500.0, "damping": 0.1, "position": [0.08, 1.01], "velocity": [-0.5, 0.0]},
    ],
    "contacts": [{"bodies": ["a", "b"], "restitution": 0.5}],
    "simulation": {"t_end": 0.15, "output_dt": 0.001, "rtol": 1e-10, "atol": 1e-12},
}


@pytest.mark.slow  # an oracle: the whole scene derived on frames T (10 s with a cold cache, and its compile)
def test_flexible_bodies_on_frames_collide_as_in_the_particles_formulation():
    """The same two flexible rings colliding off-centre, on the particles formulation (their
    particles are the coordinates) and on the floating one (frames T, elastic coordinates in
    T: every contact row mapped by the derived particle Jacobian and bias): one motion."""
    scene = flexbody.load_scene(TWO_RINGS)
    a = flexbody.simulate(scene)
    b = flexbody.simulate(scene, formulation="floating")
    assert a.status == b.status == "success", (a.message, b.message)
    assert a.stats["impacts"] == b.stats["impacts"] >= 1
    np.testing.assert_allclose(a.events_time, b.events_time, atol=1e-9)
    assert np.abs(a.positions - b.positions).max() < 1e-10  # measured 4.2e-13 m over 16 impacts
    assert np.abs(a.velocities - b.velocities).max() < 1e-8  # measured 1.3e-10 m/s


@pytest.mark.slow
@pytest.mark.parametrize("formulation, kind", [("floating", "derived"), ("particles", "mixed")])
def test_a_rigid_and_a_flexible_icosahedron_colliding_in_space_conserve_momentum(formulation, kind):
    """3D frames: a rigid icosahedron (six coordinates) and a flexible one, on the floating
    formulation (derived whole, ~20 s once) and on the particles one (the flexible body
    assembled beside the rigid frame), collide off-centre in free space: linear and angular
    momentum are kept through the impacts (measured 6e-13 at rtol 1e-10), nothing gets
    inside anything, the ledger closes."""
    from pathlib import Path

    from tests.test_body_contact import _momenta_3d

    mesh = str(Path(flexbody.__file__).parent / "scenes" / "icosahedron.obj")
    body = {"shape": "mesh", "file": mesh, "scale": 0.1, "center": True, "mass_total": 0.65, "collide": True}
    table = {"name": "icosahedra_rigid", "gravity": [0.0, 0.0, 0.0],
             "bodies": [{**body, "name": "a", "rigid": True, "position": [-0.15, 0.01, 1.0],
                         "rotation": [0.3, 0.2, 0.0], "velocity": [1.0, 0.0, 0.0]},
                        {**body, "name": "b", "stiffness": 2000.0, "damping": 0.2, "damper": "axial",
                         "position": [0.15, -0.01, 1.02], "rotation": [0.0, -0.4, 0.1],
                         "velocity": [-1.0, 0.0, 0.0], "angular_velocity": [0.0, 0.0, 3.0]}],
             "simulation": {"t_end": 0.15, "output_dt": 0.005, "rtol": 1e-10, "atol": 1e-12}}
    r = flexbody.simulate(flexbody.load_scene(table), formulation=formulation)
    assert r.status == "success", r.message
    assert r.stats["formulation"] == formulation and r.stats["model"] == kind and r.stats["impacts"] >= 1
    p, L = _momenta_3d(r)
    np.testing.assert_allclose(p - p[0], 0.0, atol=1e-10)
    np.testing.assert_allclose(L - L[0], 0.0, atol=1e-10)
    assert r.stats["max_penetration_m"] < 1e-9
    assert r.stats["energy_drift_relative"] < 1e-9


@pytest.mark.slow
def test_the_ring_stack_on_a_rigid_block_stays_at_rest_for_10_s():
    """The issue's stack: the bundled scene (friction 0.5 between the bodies) with its block
    rigid, its frame beside the assembled rings (the default; derived whole, the floating
    formulation took ~40 s once) and run for 10 s (~40 s): at rest from about 2.5 s, no
    drift, nothing inside anything, the ground carrying everything on the block's two bottom
    corners, the block the two rings, the lower ring the upper one."""
    from tests.test_body_scenes import STACK, bundled, centres, weights

    table = bundled("ring_stack")
    block = table["bodies"][0]
    for key in ("stiffness", "damping"):
        block.pop(key)
    block["rigid"] = True
    r = flexbody.simulate(flexbody.load_scene(table))
    assert r.status == "success", r.message
    assert r.stats["model"] == "mixed" and r.stats["max_penetration_m"] < 1e-9  # measured 3.0e-12 m
    assert r.stats["energy_drift_relative"] < 1e-8  # measured 1.3e-11
    late = r.t >= 3.0
    w, F = weights(r), r.contact_force[late]
    np.testing.assert_allclose(F[:, :2].sum(axis=1), sum(w.values()), rtol=1e-6)
    np.testing.assert_allclose(F[:, STACK["lower"]].sum(axis=1), w["lower"] + w["upper"], rtol=1e-6)
    np.testing.assert_allclose(F[:, STACK["upper"]].sum(axis=1), w["upper"], rtol=1e-6)
    for name, c in centres(r).items():
        assert np.abs(c[late] - c[late][-1]).max() < 1e-9, name  # measured 6.6e-12 m
        assert np.abs(c[:, 0]).max() < 1e-9, name  # measured 9.3e-12 m
    assert r.kinetic[late].max() < 1e-12


def test_held_contacts_that_drift_are_put_back_on_their_surfaces(monkeypatch):
    """The ring landing on the rigid block at the default tolerances, both on frames (the
    floating formulation): its held contacts' gaps are not linear in the frames'
    coordinates, and without a projection (nor steps taken again shorter) they sank
    1.2e-10 m by 0.6 s (and the run said so).  With it (after any step that leaves one more
    than 2 gap tolerances off) they stay within a few gap tolerances.  The projection itself
    puts a held contact exactly back (gap and normal velocity 0) by a change along
    M^-1 J^T: the smallest in the kinetic metric.  A put-back from farther off than
    ``PUT_BACK_WARNING`` gap tolerances moves the bodies by that much and is flagged."""
    from flexbody import driver
    from flexbody.coupled import _coupling, project_held
    from flexbody.state import initial_coordinates

    table = {"name": "ring_on_rigid_block", "grounds": [FLAT], "bodies": [RING, BLOCK],
             "contacts": [{"bodies": ["ring", "block"]}], "simulation": {"t_end": 0.6, "output_dt": 0.002}}
    scene = flexbody.load_scene(table)
    kept = flexbody.simulate(scene, formulation="floating")
    assert kept.status == "success" and kept.stats["projections"] > 0
    assert kept.stats["max_penetration_m"] < 1e-11 and not kept.stats["warnings"]
    assert 0.0 < kept.stats["max_put_back_m"] < 1e-11  # each put back from a few gap tolerances off
    monkeypatch.setattr(driver, "PUT_BACK_WARNING", 1.0)  # a put-back from farther than 1 gap tolerance is flagged
    flagged = flexbody.simulate(scene, formulation="floating")
    assert any(w.startswith("held contacts were put back onto their surfaces from up to") for w in flagged.stats["warnings"])
    monkeypatch.setattr(driver, "PROJECT_GAPS", np.inf)
    monkeypatch.setattr(driver, "SINK_GAPS", np.inf)  # nor a step taken again shorter
    monkeypatch.setattr(driver, "SINK_WARNING", 10.0)  # warned of from 1e-11 m (100 gap tolerances by default)
    drifting = flexbody.simulate(scene, formulation="floating")
    assert drifting.stats["projections"] == 0 and drifting.stats["max_penetration_m"] > 1e-11
    assert any(w.startswith("a held contact sank") for w in drifting.stats["warnings"])

    model = flexbody.load_model(scene, formulation="floating")
    p = model.parameters(scene)
    q, u = initial_coordinates(scene, model)
    corners = np.flatnonzero(model.gaps(q, p)[: model.n_ground_contacts] == 0.0)  # the block's bottom corners
    assert len(corners) == 2
    rng = np.random.default_rng(5)
    y = np.concatenate([q + 1e-6 * rng.standard_normal(q.size), u + 1e-3 * rng.standard_normal(u.size), [0, 0]])
    out = project_held(model, y, p, corners)
    nq, nu = model.nq, model.nu
    J, cols, _, _, _ = _coupling(model, out[:nq], out[nq : nq + nu], p, corners)
    np.testing.assert_allclose(model.held_gaps(out[:nq], p, corners), 0.0, atol=1e-15)
    np.testing.assert_allclose(J @ out[nq : nq + nu][cols], 0.0, atol=1e-15)
    J0, cols0, _, _, _ = _coupling(model, y[:nq], y[nq : nq + nu], p, corners)
    pushed = model.inner.mass_matrix(y[:nq], p) @ (out[:nq] - y[:nq])  # M dq: a combination of J's rows
    assert np.abs(np.delete(pushed, cols0)).max(initial=0.0) == 0.0
    multipliers = np.linalg.lstsq(J0.T, pushed[cols0], rcond=None)[0]
    np.testing.assert_allclose(J0.T @ multipliers, pushed[cols0], atol=1e-9 * np.abs(pushed).max())


#: A rigid octagon bouncing (e = 0.5) to rest on a rigid bar that slides and turns on a
#: frictional ground (a fuzz campaign's scene, with its random numbers rounded).
OCTAGON_ON_BAR = {
    "name": "octagon_on_bar", "grounds": [{"point": [0.0, 0.0], "normal": [0.0, 1.0], "friction": 0.3,
                                           "restitution": 0.5}],
    "bodies": [
        {"name": "octagon", "shape": "ring", "count": 8, "radius": 0.0937, "center": True, "rigid": True,
         "mass": 0.0336, "angle": -0.3978, "position": [0.00785, 0.09343], "velocity": [-0.118, -0.00339],
         "angular_velocity": -1.006},
        {"name": "bar", "shape": "polygon", "center": True, "rigid": True, "mass": 0.042, "angle": -0.12,
         "vertices": [[-0.17039, -0.015263], [0.17039, -0.015263], [0.17039, 0.015263], [-0.17039, 0.015263]],
         "position": [0.0208, 0.21595], "velocity": [0.155, -0.0327], "angular_velocity": 0.811}],
    "contacts": [{"bodies": ["octagon", "bar"], "restitution": 0.5}],
    "simulation": {"t_end": 0.28, "output_dt": 0.005},
}


@pytest.mark.slow  # its two rigid bodies are derived whole (~8 s with a cold cache)
def test_rigid_bodies_resting_on_each_other_do_not_sink_at_default_tolerances():
    """Held contacts between rigid bodies are kept on accelerations; their gaps are not linear
    in the frames' angles, so the integrator's error drifts them.  At the default tolerances
    (rtol 1e-6, atol 1e-9) RK45 took a 20 ms step in which the octagon, held on the bar after
    its bounces died out, sank 3.9e-9 m (on the dense output where a lift-off was located;
    1e-10 m at the step's end).  Such a step is now taken again, shorter: nothing sinks more
    than 1e-9 m, checked by the driver at every step and event and here against the bar's
    faces at every sample."""
    scene = flexbody.load_scene(OCTAGON_ON_BAR)
    r = flexbody.simulate(scene)
    assert r.status == "success", r.message
    assert r.stats["impacts"] >= 10 and r.stats["steps_shortened"] >= 1
    assert r.stats["max_penetration_m"] < 1e-9  # 3.9e-9 m before; measured 3.9e-11 m
    octagon, bar = slice(0, 8), slice(8, 12)  # the bodies' particles in order; the bar's counter-clockwise
    depth = 0.0
    for x in r.positions:
        corners = x[bar]
        edges = np.roll(corners, -1, axis=0) - corners
        inward = np.column_stack([-edges[:, 1], edges[:, 0]]) / np.linalg.norm(edges, axis=1)[:, None]
        # a vertex's depth inside the convex bar: its smallest distance inside the faces' lines
        inside = np.einsum("pkd,kd->pk", x[octagon][:, None, :] - corners[None], inward).min(axis=1)
        depth = max(depth, float(inside.max()))
    assert depth < 1e-9
    assert r.stats["energy_drift_relative"] < 1e-6
