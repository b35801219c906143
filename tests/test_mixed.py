"""Rigid bodies beside flexible bodies of any size (flexbody.mixed.MixedModel).

References: a ground (a 199-particle disc landing on a rigid block that rests on the ground
moves as on a ground at the block's top), statics (the block's corners carry its weight and
what the disc presses on it), conservation laws (a rigid bar hitting a flexible disc in free
space keeps momentum and angular momentum), the floating formulation derived whole (the same
motion on a small scene), and the parts' own models (each part's right-hand side).
"""

from __future__ import annotations

import numpy as np
import pytest

import flexbody
from flexbody.bench_bodies import disc_radius
from flexbody.mixed import MixedModel, split_scene
from flexbody.state import initial_coordinates

G = 9.81
RADIUS = disc_radius(200)
DISC = {"name": "disc", "shape": "disc", "count": 200, "radius": RADIUS, "mass": 0.05, "stiffness": 6000.0,
        "damping": 0.5, "damper": "relative", "position": [0.02, 0.1 + RADIUS + 0.02], "angle": 0.1}
BLOCK = {"name": "block", "shape": "polygon", "rigid": True, "mass": 2.0, "position": [0.0, 0.0],
         "vertices": [[-0.4, 0.0], [0.4, 0.0], [0.4, 0.1], [-0.4, 0.1]]}
TIGHT = {"t_end": 0.3, "output_dt": 0.005, "rtol": 1e-9, "atol": 1e-12}


def disc_on_block():
    return flexbody.load_scene({"name": "disc_on_block", "bodies": [DISC, BLOCK],
                                "contacts": [{"bodies": ["disc", "block"]}], "simulation": TIGHT})


@pytest.fixture(scope="module")
def landed():
    return flexbody.simulate(disc_on_block())


def test_a_large_disc_landing_on_a_resting_rigid_block_moves_as_on_a_ground(landed):
    """199 particles (far past the floating formulation's 40): the block rests on two held
    corners, coupled through its frame, and does not move, so the disc lands, bounces and
    rests on its top as on a ground there (measured 2e-13 m apart, the same 10 impacts)."""
    on_ground = flexbody.simulate(flexbody.load_scene({
        "name": "disc_on_ground", "grounds": [{"point": [0.0, 0.1], "normal": [0.0, 1.0]}], "bodies": [DISC],
        "simulation": TIGHT}), method="RK45")
    a, b = landed, on_ground
    assert a.status == b.status == "success", (a.message, b.message)
    assert a.stats["model"] == "mixed" and b.stats["model"] == "assembled"
    assert a.stats["impacts"] == b.stats["impacts"] >= 5 and a.stats["liftoffs"] == b.stats["liftoffs"] >= 1
    n = b.positions.shape[1]
    assert np.abs(a.positions[:, :n] - b.positions).max() < 1e-9
    assert np.abs(a.positions[:, n:] - a.positions[0, n:]).max() < 1e-12  # the block stays put
    assert a.stats["max_penetration_m"] < 1e-9 and a.stats["energy_drift_relative"] < 1e-9


def test_the_rigid_block_carries_its_weight_and_the_disc_on_its_corners(landed):
    """At every sample the block is at rest: its corners' forces add up to its weight plus
    the disc's contact forces on its top, and their moments about its centre balance."""
    r = landed
    n = len(r.masses) - 4
    carried = r.contact_force[:, :n]
    assert carried.sum(axis=1).max() > r.masses[:n].sum() * G  # the disc lands and presses on the block
    corners = r.contact_force[:, n:]
    weight = r.masses[n:].sum() * G
    np.testing.assert_allclose(corners.sum(axis=1), weight + carried.sum(axis=1), rtol=1e-9)
    centre = r.positions[:, n:, 0].mean(axis=1)
    moment = (corners * (r.positions[:, n:, 0] - centre[:, None])).sum(axis=1) \
        - (carried * (r.positions[:, :n, 0] - centre[:, None])).sum(axis=1)
    assert np.abs(moment).max() < 1e-9 * weight


def test_a_rigid_bar_hitting_a_flexible_disc_in_space_keeps_momentum_and_angular_momentum():
    """No gravity, no ground: a rigid bar turning as it flies into a 199-particle disc, both
    plastic and with e = 0.5: what passes between them through the coupled impacts and the
    held contacts is internal, so linear and angular momentum stay what they were, and
    nothing gets inside anything."""
    for e in (0.0, 0.5):
        bar = {"name": "bar", "shape": "polygon", "rigid": True, "vertices": [[-0.15, 0.0], [0.15, 0.0], [0.0, 0.04]],
               "mass": 0.3, "position": [-RADIUS - 0.05, 1.03],
               "angle": 1.4, "velocity": [2.0, 0.1], "angular_velocity": 1.0}
        # far above the ground, which nothing pulls them to; axial dampers (relative ones, along
        # v_i - v_j, exert a moment: 0.01 of L here on either formulation)
        disc = dict(DISC, position=[0.0, 1.0], damper="axial")
        scene = flexbody.load_scene({"name": "bar_and_disc", "gravity": [0.0, 0.0], "bodies": [disc, bar],
                                     "contacts": [{"bodies": ["disc", "bar"], "restitution": e}],
                                     "simulation": dict(TIGHT, t_end=0.12, output_dt=0.002)})
        r = flexbody.simulate(scene)
        assert r.success and r.stats["model"] == "mixed" and r.stats["impacts"] >= 1, r.message
        m = r.masses[None, :, None]
        momentum = (m * r.velocities).sum(axis=1)
        angular = (r.masses[None] * (r.positions[..., 0] * r.velocities[..., 1]
                                     - r.positions[..., 1] * r.velocities[..., 0])).sum(axis=1)
        np.testing.assert_allclose(momentum - momentum[0], 0.0, atol=1e-10)
        np.testing.assert_allclose(angular - angular[0], 0.0, atol=1e-10)
        n = len(r.masses) - 3
        assert np.abs(r.velocities[-1, n:] - r.velocities[0, n:]).max() > 0.1  # the bar was hit
        assert r.stats["max_penetration_m"] < 1e-9 and r.stats["energy_drift_relative"] < 1e-8


@pytest.mark.slow  # an oracle: the whole scene derived (6.6 s with a cold cache, and its compile)
def test_a_small_mixed_scene_moves_as_derived_whole():
    """The oracle: a flexible ring landing on a rigid block that falls onto the ground, on the
    floating formulation (every body derived whole, Kane) and on the particles one (the ring
    assembled beside the block's frame): the same events and the same motion, to the
    integrators' error (rtol 1e-10; the two integrate different coordinates)."""
    ring = {"name": "ring", "shape": "ring", "count": 6, "radius": 0.08, "center": True, "mass": 0.05,
            "stiffness": 2000.0, "damping": 0.5, "position": [0.05, 0.3], "angle": 0.2}
    block = dict(BLOCK, vertices=[[-0.2, 0.0], [0.2, 0.0], [0.2, 0.1], [-0.2, 0.1]], mass=0.5,
                 position=[0.0, 0.02], angle=0.05)
    scene = flexbody.load_scene({"name": "ring_block_fall", "bodies": [ring, block],
                                 "contacts": [{"bodies": ["ring", "block"]}],
                                 "simulation": {"t_end": 0.35, "output_dt": 0.005, "rtol": 1e-10, "atol": 1e-12}})
    mixed, whole = flexbody.simulate(scene), flexbody.simulate(scene, formulation="floating")
    assert mixed.success and whole.success, (mixed.message, whole.message)
    assert (mixed.stats["model"], whole.stats["model"]) == ("mixed", "derived")
    assert mixed.stats["impacts"] >= 3 and list(mixed.events_kind) == list(whole.events_kind)
    np.testing.assert_allclose(mixed.events_time, whole.events_time, atol=1e-9)
    assert np.abs(mixed.positions - whole.positions).max() < 1e-7
    assert mixed.stats["max_penetration_m"] < 1e-9


def test_the_mixed_model_is_its_parts_side_by_side():
    """Initial coordinates put every particle where the scene says; the right-hand side of
    the whole is each part's on its own entries (works added); contacts and coordinate names
    keep the scene's numbering."""
    scene = disc_on_block()
    model = flexbody.load_model(scene)
    inner = model.inner
    assert isinstance(inner, MixedModel)
    p = model.parameters(scene)
    q, u = initial_coordinates(scene, model)
    x, v = inner.particle_state(q, u, p)
    np.testing.assert_allclose(x, scene.initial_positions(), atol=1e-15)
    np.testing.assert_allclose(v, scene.initial_velocities(), atol=1e-15)
    rng = np.random.default_rng(3)
    moving = np.arange(u.size) < inner.flexible.nu  # the disc moves, the block rests
    y = np.concatenate([q, u + 0.1 * rng.standard_normal(u.size) * moving, [0.0, 0.0]])
    held = np.zeros(inner.n_contacts, np.intc)
    held[inner.rigid_particle[inner.contacts[:, 0]] & (inner.gaps(q, p) == 0.0)] = 1  # the block's bottom corners
    assert held.sum() == 2
    ydot, lam = inner.rhs(y, p, held, np.zeros(inner.n_contacts))
    flexible, rigid = split_scene(scene)
    f_dot, _ = inner.flexible.rhs(y[inner._y_f], inner.flexible.parameters(flexible.scene),
                                  np.zeros(inner.flexible.n_contacts, np.intc), np.zeros(inner.flexible.n_contacts))
    np.testing.assert_array_equal(ydot[inner._y_f[:-2]], f_dot[:-2])
    weight = scene.masses[inner.rigid_particle].sum() * G
    assert lam[held == 1].sum() == pytest.approx(weight, rel=1e-12)  # the corners carry the block at rest
    assert inner.q_names[-1] == "theta1" and inner.q_names[0] == "x0"  # the block is body 1 of the scene
    np.testing.assert_array_equal(inner.contacts[:, 0], np.arange(scene.n_particles))


@pytest.mark.slow
def test_an_implicit_method_runs_the_mixed_model_with_its_jacobian():
    """Radau on a disc of 50 particles landing on the block: the Jacobian is each part's,
    placed on its state entries; the same landing as RK45's."""
    disc = dict(DISC, count=50, radius=disc_radius(50), position=[0.02, 0.1 + disc_radius(50) + 0.02])
    scene = flexbody.load_scene({"name": "disc_on_block", "bodies": [disc, BLOCK],
                                 "contacts": [{"bodies": ["disc", "block"]}],
                                 "simulation": dict(TIGHT, t_end=0.1, rtol=1e-8)})
    radau, rk45 = flexbody.simulate(scene, method="Radau"), flexbody.simulate(scene)
    assert radau.success and rk45.success, (radau.message, rk45.message)
    assert radau.stats["impacts"] == rk45.stats["impacts"] >= 1
    np.testing.assert_allclose(radau.events_time[0], rk45.events_time[0], atol=1e-8)
    assert np.abs(radau.positions - rk45.positions).max() < 1e-5


@pytest.mark.slow
def test_the_bundled_seesaw_tips_under_the_disc_and_its_wedge_stays():
    """``seesaw``: a 199-particle disc lands on the left end of a rigid plank balanced on a
    rigid wedge (rough contacts): the plank tips left about the apex, held on it, the wedge
    stands on the rough ground without moving, nothing gets inside anything, the ledger
    closes."""
    scene = flexbody.load_scene("seesaw")
    r = flexbody.simulate(scene, t_end=0.5)
    assert r.success and r.stats["model"] == "mixed", r.message
    wedge, plank = slice(0, 3), slice(3, 7)
    assert np.abs(r.positions[:, wedge] - r.positions[0, wedge]).max() < 1e-9
    left, right = r.positions[-1, 3, 1], r.positions[-1, 4, 1]  # the plank's bottom corners
    assert right - left > 0.1  # tipped by more than 5 degrees (measured 0.158 m over 1.2 m at 0.5 s)
    assert r.contact_force[-1, 2] > 0.0  # the apex still carries the plank
    apex = r.positions[:, 2]
    bottom = r.positions[:, 3:5]  # the plank's bottom face: never below the apex, on it at the end
    along = bottom[:, 1] - bottom[:, 0]
    gap = ((apex - bottom[:, 0])[:, 0] * along[:, 1] - (apex - bottom[:, 0])[:, 1] * along[:, 0])
    gap /= np.linalg.norm(along, axis=1)
    assert gap.min() > -1e-9 and abs(gap[-1]) < 1e-9
    assert gap.max() > 1e-3  # the impact throws the plank off the apex for a while (1.7 cm)
    assert r.stats["max_penetration_m"] < 1e-9 and r.stats["energy_drift_relative"] < 1e-6
    assert r.positions.shape[1] == scene.n_particles > 40 + 7


def test_a_compiled_method_is_refused_for_rigid_beside_flexible_bodies_with_the_reason():
    """The compiled loop knows one model, not the two side by side: `dopri5` is refused with
    the reason and the SciPy methods to use, before anything runs."""
    scene = flexbody.load_scene({"name": "apart", "bodies": [dict(DISC, count=23, radius=0.1, position=[1.0, 0.5]),
                                                             BLOCK], "simulation": {"t_end": 0.1}})
    with pytest.raises(flexbody.InputError, match="rigid bodies beside flexible ones .* use RK45"):
        flexbody.simulate(scene, method="dopri5")
    r = flexbody.simulate(scene)  # the default for it: RK45
    assert r.success and r.stats["method"] == "RK45" and r.stats["model"] == "mixed"


@pytest.mark.slow
def test_a_3d_sphere_of_200_particles_landing_on_a_rigid_box_moves_as_on_a_ground():
    """3D: the box's six frame coordinates beside a 200-particle sphere (the sphere alone is
    five times the floating formulation's limit): the box rests on its four bottom corners
    (one more than its motion needs) and does not move, so the sphere lands on its top as on
    a ground there (measured 8e-14 m apart, the same 76 impacts)."""
    sphere = {"name": "sphere", "shape": "sphere", "count": 200, "radius": 0.1, "mass": 0.01, "stiffness": 2000.0,
              "damping": 0.2, "damper": "axial", "position": [0.02, 0.01, 0.25]}
    box = {"name": "box", "shape": "box", "rigid": True, "count": [2, 2, 2], "size": [0.4, 0.4, 0.1], "mass": 0.2,
           "position": [0.0, 0.0, 0.05]}
    sim = {"t_end": 0.15, "output_dt": 0.005, "rtol": 1e-9, "atol": 1e-12}
    a = flexbody.simulate(flexbody.load_scene({"name": "sphere_on_box", "gravity": [0.0, 0.0, -G],
                                               "bodies": [sphere, box], "contacts": [{"bodies": ["sphere", "box"]}],
                                               "simulation": sim}))
    b = flexbody.simulate(flexbody.load_scene({"name": "sphere_on_ground", "gravity": [0.0, 0.0, -G],
                                               "grounds": [{"point": [0.0, 0.0, 0.1], "normal": [0.0, 0.0, 1.0]}],
                                               "bodies": [sphere], "simulation": sim}), method="RK45")
    assert a.status == b.status == "success", (a.message, b.message)
    assert a.stats["model"] == "mixed" and a.stats["impacts"] == b.stats["impacts"] >= 10
    n = b.positions.shape[1]
    assert np.abs(a.positions[:, :n] - b.positions).max() < 1e-9
    assert np.abs(a.positions[:, n:] - a.positions[0, n:]).max() < 1e-12
    assert a.stats["max_penetration_m"] < 1e-9


@pytest.mark.slow  # the whole scene derived (3.2 s with a cold cache, and its compile)
def test_the_whole_scene_derived_model_of_a_mixed_scene_is_the_floating_one():
    """``load_derived_model`` (the oracle, ``flexbody show``) derives rigid frames whole on the
    floating formulation: the default for a mixed scene, and 'particles' asked for is refused
    with the reason, before any derivation."""
    from flexbody.model import GeneratedModel, load_derived_model

    ring = {"name": "ring", "shape": "ring", "count": 4, "radius": 0.05, "mass": 0.05, "stiffness": 2000.0,
            "damping": 0.5, "position": [0.0, 0.3]}
    scene = flexbody.load_scene({"name": "ring_and_block", "bodies": [ring, BLOCK], "simulation": {"t_end": 0.1}})
    model = load_derived_model(scene, backend="numpy")
    assert isinstance(model, GeneratedModel) and model.formulation == "floating"
    with pytest.raises(flexbody.InputError, match="floating formulation only"):
        load_derived_model(scene, formulation="particles")


def test_phases_made_without_the_implied_field_take_an_instants_answer():
    """``Phases`` built by hand with the five fields of before (no ``implied``) get it, none
    implied: an instant resolved on them is assigned back whole."""
    from flexbody.contact import Phases

    mine = Phases(np.zeros(3, np.intc), np.zeros(3), np.zeros(3), np.full(3, np.inf), np.zeros(3, bool))
    answer = Phases.all_free(3)
    answer.phase[1], answer.implied[2] = 1, True
    mine.assign(answer)
    assert mine.phase.tolist() == [0, 1, 0] and mine.implied.tolist() == [False, False, True]
