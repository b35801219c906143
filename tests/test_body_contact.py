"""Contact between bodies in the runtime (flexbody.body_contact), against closed forms,
conservation laws, statics and the ground-only path.

References: the impulse of a particle hitting a segment in closed form (three point masses,
Newton's law along the segment's normal); linear and angular momentum of bodies touching
only each other; the mirror image of a symmetric collision; the weight a resting body puts
on what carries it; and the assembled model's own per-particle ground contacts.
"""

from __future__ import annotations

import re

import numpy as np
import pytest

import flexbody
from flexbody.body_contact import BodyContactModel
from flexbody.contact_problems import solve_forces
from flexbody.coupled import coupled_impact
from flexbody.dynamics import contact_solve
from flexbody.model import load_model

from .conftest import reference_table

# Two triangles 0.1 m long moving head-on along x in free space (no gravity): A's apex
# meets the middle of B's left face at s = 1/2.  Both are mirror-symmetric about y = 0.
TRIANGLES = {
    "name": "triangles",
    "gravity": [0.0, 0.0],
    "bodies": [
        {"name": "a", "shape": "polygon", "vertices": [[-0.05, -0.04], [0.05, 0.0], [-0.05, 0.04]],
         "mass": 0.05, "stiffness": 2000.0, "damping": 0.0, "position": [-0.1, 1.0], "velocity": [1.0, 0.0],
         "collide": True},
        {"name": "b", "shape": "polygon", "vertices": [[-0.05, 0.04], [-0.05, -0.04], [0.05, 0.0]],
         "mass": 0.05, "stiffness": 2000.0, "damping": 0.0, "position": [0.1, 1.0], "velocity": [-1.0, 0.0],
         "collide": True},
    ],
    "simulation": {"t_end": 0.15, "output_dt": 0.001},
}


def _scene(table, **contact):
    table = {**table, "bodies": [dict(b) for b in table["bodies"]]}
    if contact:
        for b in table["bodies"]:
            b.pop("collide", None)
        table["contacts"] = [{"bodies": [b["name"] for b in table["bodies"][:2]], **contact}]
    return flexbody.load_scene(table)


def _momenta(result):
    m = result.masses[None, :, None]
    p = (m * result.velocities).sum(axis=1)
    x, v = result.positions, result.velocities
    L = (result.masses[None, :] * (x[..., 0] * v[..., 1] - x[..., 1] * v[..., 0])).sum(axis=1)
    return p, L


@pytest.mark.parametrize("e", [0.0, 1.0])
def test_a_particle_hitting_a_segment_takes_the_closed_form_impulse(e):
    """At the instant A's apex touches B's face, the coupled impact gives the three particles
    the impulse of Newton's law with the effective mass 1 / (1/m + ((1-s)^2 + s^2)/m)."""
    scene = _scene(TRIANGLES, restitution=e)
    model = load_model(scene, backend="numpy")
    assert isinstance(model, BodyContactModel)
    p = model.parameters(scene)
    x = scene.initial_positions().copy()
    x[:3, 0] += 0.1  # A's apex (particle 1) onto B's left face, x = 0.05 (B's particles 3 and 4)
    apex, (a, b) = 1, (3, 4)
    assert x[apex, 0] == pytest.approx(x[a, 0]) and x[apex, 1] == pytest.approx(0.5 * (x[a, 1] + x[b, 1]))
    v = np.zeros_like(x)
    v[:3] = [0.7, 0.1]
    v[3:] = [-1.3, 0.2]
    v[a] += [0.4, 0.0]  # the face's ends move differently: the material point under the apex is their mean
    y = np.concatenate([x.ravel(), v.ravel(), [0.0, 0.0]])
    touching = np.zeros(model.n_contacts, bool)
    slot = np.flatnonzero((model.slot_particle == apex) & (model.slot_body == 1))
    touching[model.n_ground_contacts + slot] = True
    out = coupled_impact(model, y, p, touching, np.full(model.n_contacts, e), np.zeros(model.n_contacts))

    m, s, n = 0.05, 0.5, np.array([-1.0, 0.0])  # B's face's outward normal points to -x
    vn = n @ (v[apex] - (1 - s) * v[a] - s * v[b])
    P = -(1 + e) * vn / (1 / m + ((1 - s) ** 2 + s**2) / m)
    expected = v.copy()
    expected[apex] += P * n / m
    expected[a] -= (1 - s) * P * n / m
    expected[b] -= s * P * n / m
    got = out.y[model.nq : 2 * model.nq].reshape(-1, 2)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-13)
    assert out.loss == pytest.approx((1 - e**2) * 0.5 * vn**2 / (1 / m + ((1 - s) ** 2 + s**2) / m), abs=1e-14)


@pytest.mark.parametrize("e", [0.0, 1.0])
def test_head_on_bodies_conserve_momentum_and_mirror_symmetry(e):
    """Two bodies that touch only each other: linear and angular momentum constant through
    their impact (to the integration's accuracy), the motion its own mirror image about the
    line of approach, no particle inside the other body, the energy ledger closed."""
    result = flexbody.simulate(_scene(TRIANGLES, restitution=e), backend="numpy", rtol=1e-9, atol=1e-12)
    assert result.status == "success", result.message
    impacts = result.events_time[result.events_kind == "impact"]
    assert len(impacts) >= 1 and impacts[0] == pytest.approx(0.05, abs=1e-9)  # 0.1 m closed at 2 m/s
    p, L = _momenta(result)
    np.testing.assert_allclose(p, 0.0, atol=1e-10)
    np.testing.assert_allclose(L - L[0], 0.0, atol=1e-10)
    # Mirror image about y = 1: particle k of each triangle maps onto its mirror particle.
    mirror = np.array([2, 1, 0, 4, 3, 5])
    X = result.positions
    np.testing.assert_allclose(X[:, mirror, 0], X[:, :, 0], atol=1e-9)
    np.testing.assert_allclose(2.0 - X[:, mirror, 1], X[:, :, 1], atol=1e-9)
    assert result.stats["max_penetration_m"] <= 1e-9
    assert result.stats["energy_drift_relative"] < 1e-7
    # They separate: after the last event each body's own momentum is constant (nothing
    # touches it), and B moves away from A.
    after = result.t > result.events_time[-1] + 1e-3
    m = result.masses[:3, None]
    own_a = (m * result.velocities[after, :3]).sum(axis=1)
    np.testing.assert_allclose(own_a - own_a[0], 0.0, atol=1e-10)
    assert own_a[0, 0] < 0.0  # A (first moving at +1 m/s) bounced back
    if e == 1.0:  # no impulse took energy: the ledger's impact loss stays 0
        assert result.impact_loss[-1] == pytest.approx(0.0, abs=1e-12)
    else:
        assert result.impact_loss[-1] > 0.0


def test_two_segments_crossed_like_a_plus_are_as_deep_as_the_least_move_that_frees_them():
    """A segment along x from -1 to 1 and one along y at x = 0.3 from -0.2 to 0.5 cross; the
    nearest end to the other's line is 0.2 away: 0.2 deep.  An end on the other's line, a
    shared particle, or a depth asked above 0.2: none."""
    from flexbody.surface import segments_across

    points = np.array([[-1.0, 0.0], [1.0, 0.0], [0.3, -0.2], [0.3, 0.5], [0.3, 0.0]])
    rows, depths = segments_across(points, np.array([[0, 1], [2, 3]]), 0.0)
    assert rows.tolist() == [[0, 1]] and depths[0] == pytest.approx(0.2, rel=1e-12)
    assert len(segments_across(points, np.array([[0, 1], [2, 3]]), 0.25)[0]) == 0
    assert len(segments_across(points, np.array([[0, 1], [4, 3]]), 0.0)[0]) == 0  # touching at (0.3, 0)
    assert len(segments_across(points, np.array([[0, 1], [1, 3]]), 0.0)[0]) == 0  # sharing particle 1


def _plus(offset: float) -> dict:
    """Two thin 2D bars (0.2 x 0.01 m) crossed like a plus sign at the origin, the second
    ``offset`` along y: at 0 no particle of either is inside the other, yet they overlap."""
    bar = [[-0.1, -0.005], [0.1, -0.005], [0.1, 0.005], [-0.1, 0.005]]
    upright = [[-y, x] for x, y in bar]
    bodies = [{"name": name, "shape": "polygon", "vertices": vertices, "mass": 0.05, "stiffness": 2000.0,
               "damping": 0.0, "position": [0.0, 0.5 + shift], "collide": True}
              for name, vertices, shift in (("bar", bar, 0.0), ("upright", upright, offset))]
    return {"name": "plus", "gravity": [0.0, 0.0], "bodies": bodies, "simulation": {"t_end": 0.01, "output_dt": 0.001}}


def test_bodies_that_start_crossed_like_a_plus_are_refused():
    """Two bars crossed like a plus, no particle inside the other: refused as crossed,
    naming both bodies and the segments; moved apart along the upright (its end 1 mm above the
    bar), the same bars run."""
    with pytest.raises(flexbody.InputError, match=r"'bar' and 'upright' start crossed segment across segment "
                                                  r"\('bar': its segment \[\d+, \d+\] across the other's segment"):
        flexbody.simulate(flexbody.load_scene(_plus(0.0)))
    assert flexbody.simulate(flexbody.load_scene(_plus(0.106))).success


# A ring with spokes dropped onto a block that lies on the ground.
RING_ON_BLOCK = {
    "name": "ring_on_block",
    "bodies": [
        {"name": "ring", "shape": "ring", "count": 9, "radius": 0.1, "center": True, "mass": 0.05,
         "stiffness": 2000.0, "damping": 5.0, "position": [0.0, 0.25], "collide": True},
        {"name": "block", "shape": "polygon", "vertices": [[-0.2, 0.0], [0.2, 0.0], [0.2, 0.1], [-0.2, 0.1]],
         "mass": 0.1, "stiffness": 5000.0, "damping": 5.0, "position": [0.0, 0.0], "collide": True},
    ],
    "simulation": {"t_end": 1.5, "output_dt": 0.01},
}


def test_a_ring_comes_to_rest_on_a_block_carrying_its_weight():
    """Statics at rest: the block carries the ring's weight, the ground both bodies' weight;
    nothing inside anything, the ledger closed."""
    scene = _scene(RING_ON_BLOCK)
    result = flexbody.simulate(scene)
    assert result.status == "success", result.message
    assert result.stats["max_penetration_m"] <= 1e-9
    assert result.stats["energy_drift_relative"] < 1e-6
    g = 9.81
    ring, block = slice(0, 10), slice(10, 14)
    # Nothing pushes sideways (frictionless contacts): the rocking landing leaves the ring
    # sliding one way on the block and the block the other way on the ground, with no net
    # horizontal momentum; vertically everything is at rest.
    assert abs(float(result.masses @ result.velocities[-1, :, 0])) < 1e-9
    assert np.abs(result.velocities[-1, :, 1]).max() < 1e-3  # the last vibrations decay (measured 2.6e-4 m/s)
    ring_weight = result.masses[ring].sum() * g
    total_weight = result.masses.sum() * g
    model = load_model(scene)
    ng = model.n_ground_contacts
    # The block's top pushes the ring's particles; the ground pushes the block's.
    on_ring = result.contact_force[-1, ring].sum()
    on_ground = result.contact_force[-1, block].sum()
    assert on_ring == pytest.approx(ring_weight, rel=1e-4)  # measured 4.7e-6: what is left of the vibration
    assert on_ground == pytest.approx(total_weight, rel=1e-4)
    assert ng == scene.n_particles  # one ground


#: Two rings far apart that may touch (with ``_scene``): every contact is with the ground.
APART = {
    "name": "apart",
    "bodies": [
        {"name": "left", "shape": "ring", "count": 8, "radius": 0.1, "center": True, "mass": 0.05,
         "stiffness": 2000.0, "damping": 0.5, "position": [-0.5, 0.3], "angle": 0.05},
        {"name": "right", "shape": "ring", "count": 8, "radius": 0.1, "center": True, "mass": 0.05,
         "stiffness": 2000.0, "damping": 0.5, "position": [0.5, 0.4], "angle": -0.1},
    ],
    "simulation": {"t_end": 0.5, "output_dt": 0.01},
}


@pytest.mark.parametrize("instants, friction", [("per_particle", 0.0), ("per_particle", 0.4), ("lcp", 0.0)])
def test_contacts_that_never_touch_another_body_give_the_ground_only_answer(instants, friction, monkeypatch):
    """Two rings far apart that may touch: every contact is with the ground, decoupled, and
    the body-contact model gives the same events and motion as the assembled model's
    per-particle closed form: its instants through the LCPs (``lcp``), and solved per
    particle where they decouple (``per_particle``, the default: then every number is the
    ground-only run's, its right-hand side being the inner model's too), also where the
    rings' pair has friction (no slot takes part in a ground's instant: the friction
    between bodies decides nothing there)."""
    if instants == "lcp":
        monkeypatch.setattr(BodyContactModel, "per_particle", lambda *args: False)
    table = APART
    alone = flexbody.simulate(flexbody.load_scene(table), method="RK45")
    together = flexbody.simulate(_scene(table, restitution=0.0, friction=friction))
    assert alone.status == together.status == "success"
    assert len(alone.events_time) == len(together.events_time) > 5
    np.testing.assert_array_equal(alone.events_kind, together.events_kind)
    np.testing.assert_array_equal(alone.events_particle, together.events_particle)
    np.testing.assert_allclose(together.events_time, alone.events_time, atol=1e-9)
    np.testing.assert_allclose(together.positions, alone.positions, atol=1e-9)
    if instants == "per_particle":
        np.testing.assert_array_equal(together.events_time, alone.events_time)
        np.testing.assert_array_equal(together.positions, alone.positions)


def test_an_instant_is_solved_per_particle_only_where_nothing_couples_it():
    """``per_particle`` holds at a ground contact's instant with every slot free and out of
    reach; not with a slot held, a slot within the gap tolerance of its floor, or a slot
    among the instant's contacts."""
    from flexbody.constants import HELD
    from flexbody.contact import Phases
    from flexbody.state import initial_coordinates

    scene = _scene(APART, restitution=0.0)
    model = load_model(scene)
    p = model.parameters(scene)
    q, u = initial_coordinates(scene, model)
    y = np.concatenate([q, u, np.zeros(model.ny - model.nq - model.nu)])
    ng, nc = model.n_ground_contacts, model.n_contacts
    ground, slot = np.zeros(nc, bool), np.zeros(nc, bool)
    ground[0], slot[ng] = True, True
    free = Phases.all_free(nc)
    assert model.per_particle(y, p, free, ground, 1e-9)
    assert not model.per_particle(y, p, free, ground | slot, 1e-9)  # a slot among the instant's contacts
    held = free.copy()
    held.phase[ng + 3] = HELD
    assert not model.per_particle(y, p, held, ground, 1e-9)
    reach = free.copy()  # a free slot whose gap (margin: nothing near) is within the tolerance of its floor
    reach.floor[ng + 5] = model.gaps(y[: model.nq], p)[ng + 5] - 0.5e-9
    assert not model.per_particle(y, p, reach, ground, 1e-9)
    # friction between the rings takes no part in a ground's instant (a growing table without
    # their pair's slots solves it the same way); friction on the ground does
    for table, alone in ((APART, True), ({**APART, "grounds": [{"point": [0.0, 0.0], "normal": [0.0, 1.0],
                                                                 "friction": 0.4}]}, False)):
        rough = _scene(table, restitution=0.0, friction=0.4)
        rough_model = load_model(rough)
        assert rough_model.per_particle(y, rough_model.parameters(rough), free, ground, 1e-9) is alone


def test_a_bouncy_ground_keeps_the_coupled_instants(monkeypatch):
    """With e > 0 on the ground the instants stay the LCPs' (whose Zeno threshold counts the
    contact's own pull, not gravity's alone): the run is the same with the per-particle
    path forbidden, bit for bit."""
    table = {**APART, "grounds": [{"point": [0.0, 0.0], "normal": [0.0, 1.0], "restitution": 0.5}]}
    default = flexbody.simulate(_scene(table, restitution=0.0))
    monkeypatch.setattr(BodyContactModel, "per_particle", lambda *args: False)
    coupled = flexbody.simulate(_scene(table, restitution=0.0))
    assert default.status == coupled.status == "success" and len(default.events_time) > 10
    assert (default.events_kind == "impact").sum() > 8  # rebounds
    np.testing.assert_array_equal(default.events_time, coupled.events_time)
    np.testing.assert_array_equal(default.positions, coupled.positions)


def _momenta_3d(result):
    m = result.masses[None, :, None]
    p = (m * result.velocities).sum(axis=1)
    L = (m * np.cross(result.positions, result.velocities)).sum(axis=1)
    return p, L


@pytest.mark.parametrize("edges", [False, True])
def test_two_icosahedra_colliding_in_space_conserve_momentum_in_3d(edges):
    """3D: a particle against another body's triangles, and edges against edges
    (with ``edges = true``); two bodies in free space keep their total linear and angular
    momentum through the collision and no particle gets inside anything; with edge
    contacts no edge passes through another either (without, 12 mm)."""
    from pathlib import Path

    mesh = str(Path(flexbody.__file__).parent / "scenes" / "icosahedron.obj")
    body = {"shape": "mesh", "file": mesh, "scale": 0.1, "center": True, "mass_total": 0.65, "stiffness": 2000.0,
            "damping": 0.2, "damper": "axial", "collide": True}
    table = {"name": "icosahedra", "gravity": [0.0, 0.0, 0.0],
             "bodies": [{**body, "name": "a", "position": [-0.15, 0.01, 1.0], "rotation": [0.3, 0.2, 0.0],
                         "velocity": [1.0, 0.0, 0.0]},
                        {**body, "name": "b", "position": [0.15, -0.01, 1.02], "rotation": [0.0, -0.4, 0.1],
                         "velocity": [-1.0, 0.0, 0.0], "angular_velocity": [0.0, 0.0, 3.0]}],
             "contacts": [{"bodies": ["a", "b"], "edges": edges}],
             "simulation": {"t_end": 0.15, "output_dt": 0.005}}
    result = flexbody.simulate(flexbody.load_scene(table))
    assert result.status == "success", result.message
    assert (result.events_kind == "impact").any()
    p, L = _momenta_3d(result)
    np.testing.assert_allclose(p - p[0], 0.0, atol=1e-9)
    np.testing.assert_allclose(L - L[0], 0.0, atol=1e-9)
    assert result.stats["max_penetration_m"] <= 1e-9
    assert (result.stats["max_edge_crossing_m"] <= 1e-9) == edges
    assert result.stats["energy_drift_relative"] < 1e-6


def _crossing(t: np.ndarray, s: np.ndarray, reach: float = 0.0) -> float:
    """When ``s`` (samples, shape (nt,)) first reaches 0 from above, extrapolated from the two
    samples before (the motion is smooth until the event, not after it); with 1e-4 s samples
    and accelerations of ~1 m/s^2 its error is ~1e-8 s.  Where the motion stops at 0 (a
    particle held in a corner) the samples after it read 0 up to round-off: ``reach`` is how
    close counts as there."""
    k = np.flatnonzero((s[:-1] > reach) & (s[1:] <= reach))[0]
    return float(t[k] + s[k] / (s[k - 1] - s[k]) * (t[k] - t[k - 1]))


def test_a_body_sliding_off_a_blocks_edge_leaves_its_top_where_the_edge_is():
    """A frictionless triangle sliding flat along a block's top: its front particle is handed
    from the top segment to the side at the corner, which it leaves at once (a convex
    corner).  The lift-off is where its projection on the top reaches the corner: located
    independently on fine samples (their interpolation error is ~1e-8 s here)."""
    table = {
        "name": "slide_off",
        "bodies": [
            {"name": "slider", "shape": "polygon", "vertices": [[-0.05, 0.0], [0.05, 0.0], [0.0, 0.05]],
             "mass": 0.02, "stiffness": 2000.0, "damping": 0.5, "position": [0.0, 0.1], "velocity": [0.5, 0.0],
             "collide": True},
            {"name": "block", "shape": "polygon", "vertices": [[-0.2, 0.0], [0.2, 0.0], [0.2, 0.1], [-0.2, 0.1]],
             "mass": 0.1, "stiffness": 5000.0, "damping": 1.0, "position": [0.0, 0.0], "collide": True},
        ],
        "simulation": {"t_end": 0.35, "output_dt": 1e-4},
    }
    result = flexbody.simulate(flexbody.load_scene(table))
    assert result.status == "success", result.message
    assert result.stats["max_penetration_m"] <= 1e-9
    front, corner, other = 1, 5, 6  # the slider's front particle; the block's top runs 5 -> 6
    off = (result.events_particle == front) & (result.events_kind == "liftoff")
    assert off.sum() == 1
    X = result.positions
    top = X[:, other] - X[:, corner]
    s = np.einsum("td,td->t", X[:, front] - X[:, corner], top) / np.einsum("td,td->t", top, top)
    crossing = _crossing(result.t, s)
    assert result.events_time[off][0] == pytest.approx(crossing, abs=1e-7)
    assert crossing == pytest.approx(0.3, abs=1e-3)  # 0.15 m at 0.5 m/s, up to the bodies' vibration


def test_a_body_sliding_into_a_concave_corner_hits_the_wall_where_the_floor_ends():
    """The concave twin of the edge: sliding along an L-shaped block's floor into its inner
    corner, the front particle is handed from the floor to the wall, which it approaches: an
    impact there, at the instant its projection on the floor reaches the corner; the floor's
    contact goes on as the corner twin, and the impact (plastic) leaves the particle in the
    corner, held on both, not past it."""
    table = {
        "name": "slide_in",
        "bodies": [
            {"name": "slider", "shape": "polygon", "vertices": [[-0.05, 0.0], [0.05, 0.0], [0.0, 0.05]],
             "mass": 0.02, "stiffness": 2000.0, "damping": 0.5, "position": [-0.05, 0.1], "velocity": [0.5, 0.0],
             "collide": True},
            {"name": "block", "shape": "polygon",
             "vertices": [[-0.2, 0.0], [0.2, 0.0], [0.2, 0.2], [0.1, 0.2], [0.1, 0.1], [-0.2, 0.1]],
             "mass": 0.1, "stiffness": 5000.0, "damping": 1.0, "position": [0.0, 0.0], "collide": True},
        ],
        "simulation": {"t_end": 0.25, "output_dt": 1e-4},
    }
    result = flexbody.simulate(flexbody.load_scene(table))
    assert result.status == "success", result.message
    assert result.stats["max_penetration_m"] <= 1e-9
    front, corner, other = 1, 7, 8  # the floor runs from the inner corner (block vertex 4) to vertex 5
    hits = np.flatnonzero((result.events_particle == front) & (result.events_kind == "impact"))
    X = result.positions
    floor = X[:, other] - X[:, corner]
    s = np.einsum("td,td->t", X[:, front] - X[:, corner], floor) / np.einsum("td,td->t", floor, floor)
    crossing = _crossing(result.t, s, reach=1e-9 / 0.3)  # within 1e-9 m of the corner, on the 0.3 m floor
    assert crossing == pytest.approx(0.2, abs=1e-3)  # 0.1 m at 0.5 m/s, up to the bodies' vibration
    at_corner = hits[np.abs(result.events_time[hits] - crossing) < 1e-6]
    assert len(at_corner) == 1
    # The wall stopped it: the front particle never goes past the corner's x.
    assert (X[:, front, 0] - X[:, corner, 0]).max() <= 1e-9


L_BLOCK = {
    "name": "l_block", "gravity": [0.0, 0.0],
    "bodies": [
        {"name": "slider", "shape": "polygon", "vertices": [[-0.05, 0.0], [0.05, 0.0], [0.0, 0.05]],
         "mass": 0.02, "stiffness": 2000.0, "damping": 0.5, "position": [0.0, 0.5], "collide": True},
        # counter-clockwise: the floor runs from the inner (concave) corner, vertex 4, to vertex 5
        # (convex), the wall from vertex 3 down to the corner, the left side from 5 down to 0
        {"name": "block", "shape": "polygon",
         "vertices": [[-0.2, 0.0], [0.2, 0.0], [0.2, 0.2], [0.1, 0.2], [0.1, 0.1], [-0.2, 0.1]],
         "mass": 0.1, "stiffness": 5000.0, "damping": 1.0, "position": [0.0, 0.0], "collide": True},
    ],
    "simulation": {"t_end": 0.1, "output_dt": 0.01},
}


@pytest.mark.parametrize("corner, past, velocity, twin", [
    (7, [0.1 + 1e-9, 0.1], [0.0, 0.01], True),     # past the concave corner, moving up the wall
    (8, [-0.2 - 1e-9, 0.1], [0.0, -0.01], False),  # past the convex one, moving down the side
])
def test_a_slot_meeting_the_next_element_tangentially_keeps_the_old_one_only_at_a_concave_vertex(
        corner, past, velocity, twin):
    """A slot held on the L block's floor whose particle passes a vertex moving along the
    next element (normal speed 0 there: it stays held, no impact) is in a corner if the
    vertex is concave: its twin holds on to the floor, as where it hits the next element,
    so that it can rest there on both (a particle that slipped onto the flush one of two
    elements at a dent and off the other was hit again, unheld, each time: "chattering" in
    a pile).  Past a convex vertex nothing holds it to the floor's line."""
    scene = flexbody.load_scene(L_BLOCK)
    model = load_model(scene, backend="numpy")
    p = model.parameters(scene)
    ng, front = model.n_ground_contacts, 1  # the slider's front particle; the floor is [7, 8]
    q = scene.initial_positions().copy()
    q[front] = past
    u = np.zeros_like(q)
    u[front] = velocity
    y = np.concatenate([q.ravel(), u.ravel(), np.zeros(model.ny - 2 * q.size)])
    slot = int(model._slots_of(np.array([front]), np.array([1]))[0][0])
    model.element_of[slot] = next(e for e in range(len(model.elements)) if model.elements[e].tolist() == [7, 8])
    held = np.zeros(model.n_contacts, np.intc)
    held[ng + slot] = 1
    moved = model.switch_elements(y, p, held, gap_tolerance=1e-12, speed_tolerance=1e-7)
    assert moved.stay.tolist() == [ng + slot] and not len(moved.approach) and not len(moved.leave)
    assert model.elements[model.element_of[slot]].tolist() != [7, 8]  # handed on, to the wall or the side
    assert corner in model.elements[model.element_of[slot]]
    assert moved.corners.tolist() == ([ng + slot + model.n_primary] if twin else [])
    assert moved.sources.tolist() == ([ng + slot] if twin else [])
    if twin:
        assert model.elements[model.element_of[slot + model.n_primary]].tolist() == [7, 8]


def test_the_reported_contact_forces_obey_newtons_second_law_across_element_hand_overs():
    """A triangle sliding over a block whose top is two segments: its particles are handed
    from one to the other.  The reported contact forces on the triangle (each taken on the
    element its contact was on at that sample) equal its mass times its centre's
    acceleration plus its weight (central differences, away from the impulses)."""
    table = {
        "name": "slide_over",
        "bodies": [
            {"name": "slider", "shape": "polygon", "vertices": [[-0.05, 0.0], [0.05, 0.0], [0.0, 0.05]],
             "mass": 0.02, "stiffness": 2000.0, "damping": 0.5, "position": [-0.1, 0.1], "velocity": [0.5, 0.0],
             "collide": True},
            {"name": "block", "shape": "polygon",
             "vertices": [[-0.2, 0.0], [0.2, 0.0], [0.2, 0.1], [0.0, 0.1], [-0.2, 0.1]],
             "mass": 0.1, "stiffness": 5000.0, "damping": 1.0, "position": [0.0, 0.0], "collide": True},
        ],
        "simulation": {"t_end": 0.2, "output_dt": 1e-4},
    }
    result = flexbody.simulate(flexbody.load_scene(table))
    assert result.status == "success", result.message
    assert result.stats["max_penetration_m"] <= 1e-9
    slider = slice(0, 3)
    assert (result.positions[-1, slider, 0] > 0.0).sum() >= 1  # a particle crossed the middle vertex
    mass = result.masses[slider].sum()
    vy = (result.masses[None, slider] * result.velocities[:, slider, 1]).sum(axis=1) / mass
    dt = result.t[1] - result.t[0]
    accel = (vy[2:] - vy[:-2]) / (2 * dt)
    force = result.contact_force[1:-1, slider].sum(axis=1)
    t = result.t[1:-1]
    smooth = np.all(np.abs(t[:, None] - result.events_time[None, :]) > 2 * dt, axis=1)
    assert smooth.sum() > 0.9 * len(t)
    np.testing.assert_allclose(force[smooth], mass * (accel[smooth] + 9.81), rtol=0, atol=2e-3 * mass * 9.81)


@pytest.mark.parametrize("backend", ["numpy", "c"])
def test_one_contacts_gap_equals_its_entry_of_all_gaps(backend):
    """Locating an impact evaluates one contact's gap (``model.gap``), checking just released
    ones a few (``model.gaps_of``): each must be exactly the entry of the whole vector, for ground contacts and for slots near, on and far from the
    other body's surface, inside it too."""
    scene = _scene(TRIANGLES)
    model = load_model(scene, backend=backend)
    p = model.parameters(scene)
    rng = np.random.default_rng(7)
    for shift in (0.0, 0.04, 0.1, 0.105):  # apart, near, touching, inside
        x = scene.initial_positions().copy()
        x[:3, 0] += shift
        x += 1e-3 * rng.standard_normal(x.shape)
        q = x.ravel()
        gaps = model.gaps(q, p)
        assert [model.gap(q, p, c) for c in range(model.n_contacts)] == gaps.tolist()
        some = rng.permutation(model.n_contacts)[: model.n_contacts // 3]  # a pile's just released ones
        assert model.gaps_of(q, p, some).tolist() == gaps[some].tolist()
    assert (gaps[model.n_ground_contacts:] < 0).any()  # the last shift put a particle inside


def _squeezed_discs(squeeze: float, count: int = 23, seed: int = 0):
    """Four discs of the bodies study (two rows; ``count`` 23: 19 particles each) with their
    centres moved towards their mean by ``squeeze`` (1: as given; for 23, below ~0.85 some
    particles are within the contact margin of another disc, below ~0.68 inside it), every
    particle jittered by 1 mm: (model, q, p)."""
    from flexbody.bench_bodies import bodies_scene

    scene = bodies_scene(4, count, 0.1, True)
    model = load_model(scene)
    x = scene.initial_positions().reshape(4, -1, 2)
    centre = x.mean(axis=(0, 1))
    x = centre + squeeze * (x - centre) + (1.0 - squeeze) * (x - x.mean(axis=1, keepdims=True))
    x = x.reshape(-1, 2) + 1e-3 * np.random.default_rng(seed).standard_normal((len(scene.initial_positions()), 2))
    return model, x.ravel(), model.parameters(scene)


def test_a_slots_gap_from_the_kept_pairs_equals_its_entry_of_the_whole_sweep_among_several_bodies():
    """``model.gap`` (locating an impact) takes a slot's gap from the broad phase's kept pairs
    of its particle with the slot's body alone, where the whole sweep takes every slot's from
    the filtered candidates: among four discs, apart, near, touching and overlapping, and
    after the particles moved past the kept list's skin (a rebuild), they must agree exactly."""
    model, q0, p = _squeezed_discs(1.0)
    rebuilds = []
    for squeeze in (1.0, 0.85, 0.7, 0.64):
        q = _squeezed_discs(squeeze)[1]
        gaps = model.gaps(q, p)
        rebuilds.append(model._candidates.rebuilds)
        assert [model.gap(q, p, c) for c in range(model.n_contacts)] == gaps.tolist()
        slots = gaps[model.n_ground_contacts:]
    assert rebuilds[-1] > rebuilds[0]  # the kept pairs were rebuilt between the states
    assert (slots < 0).any() and ((slots > 0) & (slots < model.margin)).any()  # inside and near


def test_the_kept_whole_sweep_follows_the_positions_and_cannot_be_changed():
    """The whole sweep is kept by the positions it was made at: asked again at positions
    changed in place it must give a fresh model's answer, and what it hands out is read-only."""
    model, q, p = _squeezed_discs(0.7)
    fresh = _squeezed_discs(0.7)[0]
    x = q.reshape(-1, 2)
    gaps, near, _ = model._surface_contacts(x)
    with pytest.raises(ValueError):
        gaps[0] = 0.0
    assert not near.flags.writeable
    x[:5] -= 0.003  # in place: the same array, other positions
    x[40:45] += 0.004
    assert model.gaps(q, p).tolist() == fresh.gaps(q, p).tolist()


def test_a_kept_sweep_is_found_by_every_coordinate_not_only_those_its_lookup_reads_first():
    """The kept sweeps are looked up by a fingerprint of a few coordinates (the first,
    middle and last) before a whole comparison: positions changed everywhere else, in
    place, must still give a fresh model's answer, not the kept one."""
    from flexbody.body_contact import _fingerprint, _kept_at

    model, q, p = _squeezed_discs(0.7)
    fresh = _squeezed_discs(0.7)[0]
    before = model.gaps(q, p).copy()
    flat = q.reshape(-1)
    key = _fingerprint((flat,))
    middle = len(flat) // 2
    flat[1:middle] += 0.004
    flat[middle + 1 : -1] += 0.004
    assert _fingerprint((flat,)) == key  # the lookup's first reading cannot tell them apart
    after = model.gaps(q, p)
    assert after.tolist() != before.tolist() and after.tolist() == fresh.gaps(q, p).tolist()
    made = []  # arrays of no items: one answer, kept
    store: list = []
    for _ in range(2):
        assert _kept_at(store, (np.zeros((0, 3)), np.zeros(0, np.intp)), lambda: made.append(1) or "answer", 2) == "answer"
    assert made == [1]


def test_held_rows_kept_layout_gives_the_rows_of_a_fresh_model_and_W_is_J_M_inv_J_T():
    """The layout of held rows (where their terms go, the sparse ``J M^-1 J^T``'s pairs) is
    kept per set of rows and elements: at a second state it must give exactly the rows a
    fresh model builds there (ground rows and slots, with and without tangent rows), and W
    must be ``J M^-1 J^T``."""
    from flexbody.body_contact import DENSE_WIDTH

    model, q, p = _squeezed_discs(0.8, count=60)  # 37 slots within the margin, inside too
    fresh = _squeezed_discs(0.8, count=60)[0]
    x = q.reshape(-1, 2)
    _, near, _ = model._surface_contacts(x)
    slots = np.flatnonzero(near)
    model._constrain_elements(slots, x)
    fresh.element_of[:] = model.element_of
    u = np.random.default_rng(3).standard_normal(len(q))
    grounds = np.sort(np.argsort(x[:, 1])[:4])  # the lowest particles' ground contacts, with the slots
    for tangents in (False, True):
        model._rows(grounds, slots, q, u, p, tangents)  # the layout is kept here
        q2 = q + 1e-4 * np.random.default_rng(4).standard_normal(len(q))  # the same rows, moved
        kept, new = model._rows(grounds, slots, q2, u, p, tangents), fresh._rows(grounds, slots, q2, u, p, tangents)
        for a, b in zip(kept, new):
            assert np.array_equal(a, b)
        assert kept.J.shape[1] > DENSE_WIDTH  # the sparse product
        np.testing.assert_allclose(kept.W, kept.scaled @ kept.J.T, rtol=1e-13, atol=1e-13 * np.abs(kept.W).max())


@pytest.mark.parametrize("m, c", [(20, 90), (300, 60), (300, 1200)])
def test_products_of_contact_rows_are_A_B_T_densely_and_through_sparse_matrices(m, c):
    """``_gram`` multiplies contact rows densely unless there are many and they are wide
    (then through sparse matrices, the last case): either way ``A @ B.T`` to rounding, on
    rows of 12 nonzeros as a 3D slot's (its particle and three vertices)."""
    from flexbody.body_contact import SPARSE_ROWS, SPARSE_WIDTH, _gram

    rng = np.random.default_rng(m + c)
    A, B = np.zeros((m, c)), np.zeros((m, c))
    for row in range(m):
        for Z in (A, B):
            Z[row, rng.choice(c, 12, replace=False)] = rng.standard_normal(12)
    B[:, : c // 2] = A[:, : c // 2]  # rows that share coordinates, as C and G do
    assert (m >= SPARSE_ROWS and c > SPARSE_WIDTH) == (c == 1200)
    expected = A @ B.T
    np.testing.assert_allclose(_gram(A, B), expected, rtol=0, atol=1e-14 * np.abs(expected).max())


def test_redundant_rows_are_found_block_by_block_as_by_ranks_of_the_whole():
    """coupled._redundant finds the rows in the span of the others by blocks of rows that
    share columns: it must say for each row what two ranks of the whole matrix say (the row
    is redundant when removing it leaves the rank unchanged), for independent rows, for a
    row that is the sum of two others in its block (all three redundant, no other), and for
    two identical rows in different places."""
    from flexbody.coupled import _redundant

    rng = np.random.default_rng(3)
    found = 0
    for trial in range(40):
        k, c = 30, 60
        J = np.zeros((k, c))
        for r in range(k):  # each row touches a few columns, as a contact row touches its particles
            J[r, rng.choice(c, size=rng.integers(1, 5), replace=False)] = rng.standard_normal()
        if trial % 3 == 1:
            J[5] = J[2] + J[9]  # dependent, and it links their blocks
        elif trial % 3 == 2:
            J[17] = J[4]
        tol = 1e-9 * max(1.0, float(np.abs(J).max()))
        rank = np.linalg.matrix_rank(J, tol=tol)
        whole = np.array([np.linalg.matrix_rank(np.delete(J, r, axis=0), tol=tol) == rank for r in range(k)])
        asked = rng.random(k) < 0.7
        np.testing.assert_array_equal(_redundant(J, asked), whole & asked, err_msg=f"trial {trial}")
        assert whole[[2, 5, 9]].all() if trial % 3 == 1 else True
        assert whole[[4, 17]].all() if trial % 3 == 2 else True
        found += int(whole.sum())
    assert found >= 20  # the redundant rows were asked about, not only independent ones


def test_an_unloaded_row_within_rounding_of_another_is_not_held_pulling():
    """A vertex's slot and the edge row at that vertex (a fuzz's box pushed into another:
    tests/reference/fuzz_vertex_slot_and_edge_row_at_one_corner.json) constrain the same
    two points along normals 2e-6 rad apart (W's condition 1e12).  The force LCP puts the
    load on the edge row and leaves the slot without force, accelerating away at 1e-9
    m/s^2, below the release floor: not lifted, and not in the edge row's span.  Held, its
    acceleration is kept at 0 by the segment's solve, which takes that rate off through W's
    near-null direction: -0.91 N on the slot, +0.95 N on the edge row, and the slot's
    lift-off event starts below 0 and never fires (in the fuzz: -2.35 N, read -0.94 N at a
    sample).  coupled._held_pulling finds the slot; with the rows at right angles the same
    rate is held off by 3.6e-12 N, within the force tolerance, and it finds nothing."""
    from flexbody.coupled import _held_pulling

    m = 0.196 / 27  # a particle of the fuzz's box
    n, up = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])
    tolerance = np.full(2, 1e-10 * m * 9.81)  # the driver's
    for angle, pulls in ((2e-6, [True, False]), (np.pi / 2, [False, False])):
        bent = np.cos(angle) * n + np.sin(angle) * up
        J = np.array([np.concatenate([-n, n]), np.concatenate([-bent, bent])])  # two particles' rows
        W = J @ J.T / m
        a_free = np.array([1e-9, 0.0]) - W @ np.array([0.0, 0.0442])
        solution = solve_forces(W, a_free)
        assert solution.solved
        np.testing.assert_allclose(solution.normal, [0.0, 0.0442], rtol=1e-9)
        floor = 1e-10 * max(1.0, float(np.abs(a_free).max()))  # coupled_release's
        assert 0.0 < solution.normal_rate[0] <= floor  # kept held: not lifted
        held = contact_solve(W, -a_free)  # the segment's forces, both rows held
        assert (held[0] < -0.5) == pulls[0] and held[1] > 0.0
        assert _held_pulling(W, a_free, np.ones(2, bool), tolerance).tolist() == pulls
        assert not _held_pulling(W, a_free, np.array([False, True]), tolerance).any()  # alone: the LCP's


def _dart_in_notch(turn_deg: float) -> dict:
    """A block with a V notch (its flanks turned ``turn_deg`` at the bottom vertex, block
    particle 3) and a heavy-tipped dart (tip: particle 5) dropped 5 mm beside the bottom."""
    half = np.radians(turn_deg / 2)
    top = 0.05 + 0.2 * np.tan(half)
    return {
        "name": "notch",
        "bodies": [
            {"name": "block", "shape": "polygon",
             "vertices": [[-0.2, 0.0], [0.2, 0.0], [0.2, top], [0.0, 0.05], [-0.2, top]],
             "mass": 0.5, "stiffness": 5000.0, "damping": 20.0, "position": [0.0, 0.0], "collide": True},
            {"name": "dart", "shape": "polygon", "vertices": [[0.0, -0.03], [0.015, 0.0], [-0.015, 0.0]],
             "masses": [0.1, 0.005, 0.005], "stiffness": 2000.0, "damping": 4.0,
             "position": [0.003, 0.08 + 0.003 * np.tan(half) + 0.005], "collide": True},
        ],
        "simulation": {"t_end": 2.0, "output_dt": 1e-3},  # damped: all at rest by then (1e-7 m/s)
    }


@pytest.mark.parametrize("turn_deg", [20.0, 50.0])
def test_a_particle_sliding_into_a_v_notch_comes_to_rest_in_it_held_on_both_flanks(turn_deg):
    """The dart's tip slides down one flank and is handed to the other at the bottom, a
    plastic impact keeping cos(turn) of its speed each time (the exact hand-overs); once that
    speed is below the Zeno threshold the element it came from holds on too (the corner
    twin) and the tip rests in the notch.  Without the twin this ended in an accumulation
    of impacts ("chattering", 20 degrees) or the tip escaping past the bottom (2 cm inside
    the block, 50 degrees).  At rest the two flanks carry the dart's weight: with the
    deformed flanks' normals n_1, n_2, the forces solving ``l_1 n_1 + l_2 n_2 = m g`` are
    both positive and sum to the reported contact force on the tip."""
    scene = flexbody.load_scene(_dart_in_notch(turn_deg))
    result = flexbody.simulate(scene)
    assert result.status == "success", result.message
    assert result.stats["max_penetration_m"] <= 1e-9
    assert not result.stats["warnings"]
    tip, bottom, right, left = 5, 3, 2, 4  # the flanks run right -> bottom -> left (counter-clockwise)
    X, V = result.positions[-1], result.velocities[-1]
    assert np.linalg.norm(X[tip] - X[bottom]) <= 1e-9
    assert np.linalg.norm(V[tip] - V[bottom]) <= 1e-9
    assert np.abs(result.velocities[-1]).max() <= 1e-6  # everything at rest: statics holds
    hand_overs = np.sum((result.events_particle == tip) & (result.events_kind == "impact"))
    assert hand_overs >= 3  # it did slide from flank to flank before resting
    normals = []
    for a, b in ((right, bottom), (bottom, left)):
        edge = X[b] - X[a]
        normals.append(np.array([edge[1], -edge[0]]) / np.linalg.norm(edge))  # outward: into the notch
    weight = -result.masses[5:8].sum() * np.asarray(scene.gravity)
    forces = np.linalg.solve(np.column_stack(normals), weight)
    assert np.all(forces > 0.0)
    assert result.contact_force[-1, tip] == pytest.approx(forces.sum(), rel=1e-6)


def test_a_corner_row_left_alone_by_its_twin_gets_a_boundary_it_starts_above():
    """The dart's tip pinned at the notch's bottom vertex by both flanks (no boundary event:
    each row leaves by its force) is left held on the right flank alone when the left
    flank's row lifts off, a hair past the flank's end (its margin -1e-13 m, below its floor
    0).  Its margin floor is lowered below where it starts, so that going on past the vertex
    (into the block) is an event; a pile's disc particle resting in a dent went 2.3e-7 m
    through the dent's other flank unseen before (the floor was lowered only for rows newly
    held)."""
    scene = flexbody.load_scene(_dart_in_notch(20.0))
    model = load_model(scene, backend="numpy")
    p, ng, tol = model.parameters(scene), model.n_ground_contacts, 1e-12
    tip, bottom, right, left = 5, 3, 2, 4
    slot = int(model._slots_of(np.array([tip]), np.array([0]))[0][0])
    twin = slot + model.n_primary
    flank = {tuple(e): i for i, e in enumerate(model.elements.tolist())}
    model.element_of[[slot, twin]] = flank[(right, bottom)], flank[(bottom, left)]
    q = scene.initial_positions().copy()
    along = q[bottom] - q[right]
    q[tip] = q[bottom] + 1e-13 * along / np.linalg.norm(along)  # a hair past the right flank's end
    y = np.concatenate([q.ravel(), np.zeros(q.size), np.zeros(model.ny - 2 * q.size)])
    held = np.zeros(model.n_contacts, np.intc)
    held[ng + slot] = 1  # the twin has just lifted off
    changed = np.zeros(model.n_contacts, bool)
    changed[ng + twin] = True
    before = model.element_margins(y, p, held)[ng + slot]
    assert -2e-13 < before < 0.0  # its event function starts below 0: it would never cross it
    model.floor_margins(y, p, held, changed, gap_tolerance=tol)
    assert model.element_margins(y, p, held)[ng + slot] == pytest.approx(tol, rel=1e-6)


def test_a_tip_pressed_into_a_notch_far_harder_than_its_weight_rests_at_the_bottom(monkeypatch):
    """A light tip (0.2 g) under a heavy tail (0.2 kg) is pressed into a 34 degree notch by
    its links at ~500 times its weight.  Each hand-over keeps cos 34 deg = 0.83 of its speed,
    and the passes come faster as it slows: with the Zeno threshold of a rise against
    gravity alone it was handed over more than 25 times within 1 ms (``chattering`` at
    0.054 s).  Taking the contact's own pull back for the rise (``zeno_rise``) stops it in
    the corner after a few hand-overs, where it rests on both flanks."""
    from flexbody import driver

    table = _dart_in_notch(34.0)
    table["bodies"][1]["masses"] = [0.0002, 0.1, 0.1]
    table["simulation"]["t_end"] = 0.3
    with pytest.warns(flexbody.scene.OverdampedLinkWarning):  # the tip's links are overdamped: fine here
        scene = flexbody.load_scene(table)
    result = flexbody.simulate(scene)
    assert result.status == "success", result.message
    assert result.stats["max_penetration_m"] <= 1e-9 and result.stats["energy_drift_relative"] <= 1e-7
    tip, bottom = 5, 3
    resting = result.t >= 0.15
    assert np.linalg.norm(result.positions[resting, tip] - result.positions[resting, bottom], axis=1).max() <= 1e-9
    assert np.linalg.norm(result.velocities[resting, tip] - result.velocities[resting, bottom], axis=1).max() <= 1e-9
    assert (result.contact_force[resting, tip] > 0.0).all()
    # the same scene with gravity's rise alone: the accumulation the guard stops
    resolve = driver.resolve
    monkeypatch.setattr(driver, "resolve", lambda *args, **kwargs: resolve(*args, **{**kwargs, "zeno_rise": 0.0}))
    assert flexbody.simulate(scene).status == "chattering"


def _loop_and_dart(kick: float, braced: bool) -> dict:
    """A hexagonal loop, its opposite particles 0 and 3 thrown at each other at ``kick`` m/s
    (only its perimeter linked, softly, unless ``braced``), and a dart flying at it."""
    ring = [[k, (k + 1) % 6] for k in range(6)]
    angles = np.arange(6) * np.pi / 3
    kicks = np.zeros((6, 2))
    kicks[0, 0], kicks[3, 0] = -kick, kick
    braces = [[k, (k + j) % 6] for k in range(6) for j in (2, 3) if k < (k + j) % 6 or j == 2]
    return {
        "name": "loop_and_dart", "gravity": [0.0, 0.0],
        "bodies": [
            {"name": "loop", "particles": (0.05 * np.column_stack([np.cos(angles), np.sin(angles)])).tolist(),
             "links": ring + (braces if braced else []), "surface": ring, "mass": 0.05,
             "stiffness": 2000.0 if braced else 10.0, "damping": 0.0, "position": [0.0, 1.0],
             "particle_velocities": kicks.tolist(), "collide": True},
            {"name": "dart", "shape": "polygon", "vertices": [[-0.03, -0.02], [0.03, 0.0], [-0.03, 0.02]],
             "mass": 0.05, "stiffness": 2000.0, "damping": 0.0, "position": [-0.15, 1.0], "velocity": [1.0, 0.0],
             "collide": True},
        ],
        "simulation": {"t_end": 0.3, "output_dt": 0.001},
    }


def test_a_contact_against_a_surface_folded_over_itself_is_refused():
    """Particles 0 and 3 of a soft loop pass each other: its boundary crosses itself, and a
    gap's sign against it means nothing.  When the dart comes within reach of it (a
    particle within the model's margin of the other's surface, where its gap is read: on
    the folded loop, deep inside) the run stops as unsupported, naming the body and the
    crossing segments, after the samples show the fold and before the dart touches it (the
    last stop's code waited for a contact against it: 3 events, 0.146 s); a braced loop
    with the same kick does not fold and the dart's hit is simulated."""
    from flexbody.surface import crossings

    ring = np.array([[k, (k + 1) % 6] for k in range(6)])
    scene = flexbody.load_scene(_loop_and_dart(kick=1.0, braced=False))
    folded = flexbody.simulate(scene)
    assert folded.status == "unsupported"
    assert "'loop' has folded over (its segments" in folded.message
    crossed = [len(crossings(x[:6], ring)) > 0 for x in folded.positions]
    assert crossed[-1] and not crossed[0]
    assert folded.stats["events"] == 0
    # the bodies at the stop, a step after the last sample (no force but the loop's soft links)
    t_stop = float(re.search(r"at t = ([0-9.e-]+) s", folded.message).group(1))
    x = folded.positions[-1] + folded.velocities[-1] * (t_stop - folded.t[-1])
    elements, _ = scene.surfaces()
    loop, dart = elements[elements.max(axis=1) < 6], elements[elements.min(axis=1) >= 6]

    def nearest(points, segments):  # the least distance of the points to the segments
        a, b = x[segments[:, 0]], x[segments[:, 1]]
        s = np.clip(np.einsum("psd,sd->ps", points[:, None] - a, b - a) / np.einsum("sd,sd->s", b - a, b - a), 0, 1)
        return np.linalg.norm(points[:, None] - (a + s[..., None] * (b - a)), axis=2).min()

    assert min(nearest(x[6:], loop), nearest(x[:6], dart)) <= load_model(scene).margin
    braced = flexbody.simulate(flexbody.load_scene(_loop_and_dart(kick=1.0, braced=True)))
    assert braced.status == "success", braced.message
    assert braced.stats["impacts"] >= 1
    assert not any(len(crossings(x[:6], ring)) for x in braced.positions)


def test_a_fired_contact_reading_deep_below_its_floor_is_a_surface_turning_back_on_itself():
    """A particle's gap to a closed surface is continuous until the surface folds, so a free
    contact whose event fired reads its floor there: one reading deeper than the fold depth
    below its floor is that surface folding (its feature's pseudo-normal flipped), named by
    ``fold_onset``; a hair below, one armed as deep (released inside), or deeper than a
    looser depth allows, is not."""
    from flexbody.bench_bodies import bodies_scene
    from flexbody.state import initial_coordinates

    scene = bodies_scene(2, 23, 0.1, True, stiffness=6000.0, row=True)
    model = load_model(scene)
    p = model.parameters(scene)
    q, u = initial_coordinates(scene, model)
    n, d = model.n_particles, model.dim
    # the left disc's particle nearest the right disc, and its slot against that disc
    x = q.reshape(n, d)
    left, right = np.flatnonzero(model.particle_body == 0), np.flatnonzero(model.element_body == 1)
    contact = model._closest_features(x, np.array([[i, e] for i in left for e in right]))
    row = int(np.argmin(contact.gap))
    particle = int(contact.particle[row])
    c = model.n_ground_contacts + int(np.flatnonzero((model.slot_particle == particle) & (model.slot_body == 1))[0])
    depth = 1e3 * 1e-12
    for inside, folded in ((1e-2, True), (1e-11, False)):
        moved = x.copy()  # moved along its normal to that depth inside the right disc
        moved[particle] -= (float(contact.gap[row]) + inside) * contact.normal[row]
        y = np.concatenate([moved.ravel(), u, [0.0, 0.0]])
        gap = model.gap(y[: model.nq], p, c)  # (past a vertex the nearest feature inside is a side)
        assert -inside <= gap <= -inside / 2
        answer = model.fold_onset(y, p, [c], [0.0], depth)
        assert (answer is not None) == folded
        if folded:
            assert answer[0] == 1 and f"the gap of particle {particle} against it changed sign {-gap:.2g} m" in answer[1]
        assert model.fold_onset(y, p, [c], [gap - 1e-12], depth) is None  # armed there: it fired at its floor
        assert model.fold_onset(y, p, [c], [0.0], 2e-2) is None  # no deeper than a depth that allows it
        assert model.fold_onset(y, p, [0], [0.0], depth) is None  # a ground contact's is the inner model's


def test_a_soft_disc_folding_at_a_particle_of_another_body_stops_the_run_there():
    """A fuzzed 2D pile (polygon, ring, soft disc; friction and restitution): the disc's
    boundary folds over at a vertex 2.8 cm from a particle of the polygon.  That particle's
    gap changed sign there, its event fired and it read 2.8 cm inside; the run went on
    0.001 s to the sample where the segments crossed, warning of a missed impact 2.8 cm
    deep.  Now it stops at that instant (or at the crossing, where the trajectory's last
    bits differ): unsupported, the disc folded, no particle inside another body."""
    result = flexbody.simulate(flexbody.load_scene(reference_table("folding_disc_pile")))
    assert result.status == "unsupported"
    assert "body 'b2' has folded over" in result.message
    assert result.stats["max_penetration_m"] < 1e-9
    assert not result.stats["warnings"], result.stats["warnings"]


def _unbraced_ring_beside(other: dict, ring: dict, pair: dict, ground_e: float) -> dict:
    """An unbraced ring (perimeter links only: a mechanism) and another body that may touch it."""
    return {"name": "unbraced", "gravity": [0.0, -9.81],
            "grounds": [{"point": [0.0, 0.0], "normal": [0.0, 1.0], "restitution": ground_e}],
            "bodies": [other, {"name": "ring", "shape": "ring", "center": False, "damper": "axial", **ring}],
            "contacts": [{"bodies": [other["name"], "ring"], **pair}], "simulation": {"t_end": 0.3}}


#: Two scenes a fuzz of random piles found (seeds 64 and 18, shrunk): an unbraced ring
#: collapses beside a rigid box (it ended `success` reading a box corner 0.086 m inside it,
#: the corner's contact armed below that, none decided against the ring), and beside an
#: ellipse (it stalled at t = 0.1323 s, `too_slow`).
UNBRACED = {
    "box": _unbraced_ring_beside(
        {"name": "box", "shape": "polygon", "rigid": True, "mass_total": 0.1486, "position": [0.243873, 0.18587],
         "vertices": [[-0.052137, -0.033335], [0.052137, -0.033335], [0.052137, 0.033335], [-0.052137, 0.033335]],
         "angle": 0.3275, "velocity": [-0.9114, 0.1388], "angular_velocity": -0.1328},
        {"count": 8, "radius": 0.111721, "mass_total": 0.684, "stiffness": 12253.1, "damping": 0.768,
         "position": [-0.048178, 0.489351], "angle": 0.3426, "velocity": [0.2335, -0.4175], "angular_velocity": 2.3139},
        {"friction": 0.3, "restitution": 0.3}, 0.3),
    "ellipse": _unbraced_ring_beside(
        {"name": "ellipse", "shape": "ellipse", "count": 8, "radii": [0.092578, 0.066635], "center": True,
         "mass_total": 0.4489, "stiffness": 17845.7, "damping": 0.427, "damper": "axial",
         "position": [-0.119082, 0.407309], "angle": 0.2799, "velocity": [-0.7603, -0.6582], "angular_velocity": 1.3696},
        {"count": 12, "radius": 0.055791, "mass_total": 0.6075, "stiffness": 13597.8, "damping": 0.598,
         "position": [-0.264319, 0.216021], "angle": 0.189, "velocity": [0.8148, 0.7772], "angular_velocity": 2.6899},
        {"restitution": 0.8}, 0.8),
}


@pytest.mark.parametrize("beside", sorted(UNBRACED))
def test_a_surface_that_folds_with_no_contact_against_it_decided_stops_the_run(beside):
    """The unbraced ring's surface crosses itself while only its own particles touch
    anything: the run stops as unsupported, naming it, as soon as a free contact reads its
    gap against it (within reach; at an output sample or deep inside at a step's end), with
    nothing inside anything (the last stop's code: `success` 0.086 m inside, and `too_slow`)."""
    from flexbody.surface import crossings

    scene = flexbody.load_scene(UNBRACED[beside])
    result = flexbody.simulate(scene, max_wall_time=60.0)
    assert result.status == "unsupported", result.message
    assert "body 'ring' has folded over (its segments" in result.message
    assert result.stats["max_penetration_m"] <= 1e-9
    elements, body = scene.surfaces()
    crossed = [len(crossings(x, elements[body == 1])) > 0 for x in result.positions]
    assert not crossed[0]


@pytest.mark.slow  # a rigid base derived whole (~8 s with a cold cache); the run ~4 s
def test_the_penetration_leaves_out_the_gaps_read_on_a_folded_surface():
    """A fuzz's scene (tests/reference/fuzz_fold_penetration.json: a soft ellipse, a disc
    and a rigid base): the ellipse folds over at 0.0862 s and the run stops there.  A
    particle beside the folded surface reads 1.7e-3 m inside it at the step's end where the
    fold is found; a folded surface has no inside, so the stats leave that reading out (the
    last stop's code reported it, with the warning that an impact was missed) and report
    what the states before it read."""
    table = reference_table("fuzz_fold_penetration")
    result = flexbody.simulate(flexbody.load_scene(table), max_wall_time=120.0)
    assert result.status == "unsupported", result.message
    assert "body 'b1' has folded over (its segments" in result.message
    assert result.stats["max_penetration_m"] <= 1e-9
    assert not any("between event checks" in w for w in result.stats["warnings"])


def test_the_fold_check_names_the_folded_3d_body_and_how():
    """Two spheres that may touch: at their initial state neither has folded; with a vertex
    of the second thrown through its centre, a contact against it reports that body and an
    edge through a triangle; against the first, nothing."""
    ball = {"shape": "sphere", "count": 30, "radius": 0.1, "mass": 0.05, "stiffness": 2000.0, "damping": 0.1,
            "collide": True}
    scene = flexbody.load_scene({"name": "two_balls", "gravity": [0.0, 0.0, -9.81],
                                 "bodies": [{**ball, "name": "a", "position": [0.0, 0.0, 0.5]},
                                            {**ball, "name": "b", "position": [0.3, 0.0, 0.5]}],
                                 "simulation": {"t_end": 0.1}})
    model = load_model(scene, backend="numpy")
    assert isinstance(model, BodyContactModel)
    p = model.parameters(scene)
    y = np.concatenate([scene.initial_positions().ravel(), np.zeros(model.nu + 2)])
    on = {body: [model.n_ground_contacts + int(np.flatnonzero(model.slot_body == body)[0])] for body in (0, 1)}
    assert model.fold(y, p, on[0] + on[1]) is None
    x = scene.initial_positions()
    first_b = scene.bodies[0].n_particles
    centre = x[first_b:].mean(axis=0)
    x[first_b] = centre - 2.0 * (x[first_b] - centre)
    y[: model.nq] = x.ravel()
    assert model.fold(y, p, on[0]) is None
    body, how = model.fold(y, p, on[1])
    assert body == 1 and "passes through its triangle" in how



# --- an instant's problem over the contacts coupled to it (a pile) --------------------------


def _small_pile(monkeypatch=None, whole: bool = False, checks: list | None = None):
    """Three discs of 40 particles dropped onto each other and the ground (the bodies study's
    pile, small): 0.4 s, about 350 events.  ``whole``: every instant solved over every held
    contact (the model's coupling told to say "all"); ``checks`` receives, at each call of
    ``coupled_with``, the contacts it kept and those an independent reference requires."""
    from flexbody.bench_bodies import bodies_scene
    from flexbody.contact_problems import independent_blocks
    from flexbody.model import Model

    original = BodyContactModel.coupled_with

    def checked(model, q, p, seeds, among, jumped=None):
        kept = original(model, q, p, seeds, among, jumped)
        seeds = seeds.copy()
        if jumped is not None and jumped.any():  # contacts on a particle whose acceleration jumped
            seeds |= among & np.isin(model.contacts[:, 0], np.flatnonzero(jumped) // model.dim)
        rows = np.flatnonzero(seeds | among)
        if not len(rows):
            return kept
        W = model.contact_coupling(q, np.zeros(model.nu), p, rows)[2]
        required = np.zeros(model.n_contacts, bool)
        for block in independent_blocks(W):  # the reference: W's blocks that hold a seed
            if seeds[rows[block]].any():
                required[rows[block]] = True
        checks.append((kept.copy(), required, int((seeds | among).sum())))
        return kept

    if whole:
        monkeypatch.setattr(BodyContactModel, "coupled_with", Model.coupled_with)
    elif checks is not None:
        monkeypatch.setattr(BodyContactModel, "coupled_with", checked)
    return flexbody.simulate(bodies_scene(3, 40, 0.4, True))


def test_a_piles_instants_are_solved_over_their_own_contacts_with_the_whole_problems_answer(monkeypatch):
    """Each instant's impact and lift-off problems are solved over the contacts coupled to
    it (W's blocks that hold one of its contacts, or a particle whose free acceleration an
    impact changed), not every held one: at every instant of a pile the kept contacts hold
    every such block (against W itself, block by block), usually far fewer than all; and
    the run has the whole problem's events, instant by instant, and its final state."""
    checks = []
    island = _small_pile(monkeypatch, checks=checks)
    monkeypatch.undo()
    whole = _small_pile(monkeypatch, whole=True)
    assert island.status == whole.status == "success", (island.message, whole.message)
    assert len(checks) > 100
    assert not any((required & ~kept).any() for kept, required, _ in checks)
    kept_share = np.mean([kept.sum() / total for kept, _, total in checks])
    assert kept_share < 0.5  # measured 0.30 (472 calls, 346 events)
    np.testing.assert_array_equal(island.events_particle, whole.events_particle)
    np.testing.assert_array_equal(island.events_kind, whole.events_kind)
    # An event is located to the gap tolerance (1e-12 m here), so its time to that over its
    # speed: 3.5e-8 s for the slowest impact here (2.9e-5 m/s; the two answers' rounding
    # moved it 2.2e-9 s).  The states agree far closer.
    np.testing.assert_allclose(island.events_time, whole.events_time, rtol=0, atol=5e-8)
    np.testing.assert_allclose(island.positions[-1], whole.positions[-1], rtol=0, atol=1e-9)


def test_held_contacts_put_back_on_their_surfaces_leave_no_free_one_unarmed():
    """A pile's segments often end at an event after one step, so held contacts between
    bodies are put back on their surfaces at a segment's start too, not only after a step
    inside it (else their drift grew to 7e-9 m in the 20-disc pile).  That move shifts
    surfaces a hair: a free contact just released against one can end up below its floor,
    and then its event function starts negative and its next approach is never found (it
    sank 6e-6 m into another disc before free contacts were re-armed after the move)."""
    result = _small_pile()
    assert result.status == "success", result.message
    assert result.stats["projections"] > 50  # measured 211
    assert result.stats["max_penetration_m"] <= 1e-9  # measured 3.6e-10


def test_an_impact_answer_off_by_rounding_is_checked_with_its_restitution():
    """Lemke's final check can fail by rounding (a stack of 3D boxes, e = 0.5: a contact at
    rest left approaching at 9e-13 m/s); the answer is taken where Newton's law holds up to
    the Zeno speed.  The contact the impulse sends off at ``-e v-`` complies: its LCP rate is
    ``v+ + e v- = 0`` (the check read ``v+`` itself, 0.0117 m/s, and stopped the stack with
    ``unsupported``).  Left at rest instead, it breaks Newton's law."""
    from types import SimpleNamespace

    from flexbody.coupled import _within_rounding

    v_minus, e, slowest = np.array([-2.3439e-2, -9.1064e-13]), np.array([0.5, 0.5]), 8.7e-5
    answer = SimpleNamespace(status="inaccurate", normal=np.array([1.2145e-3, 0.0]),
                             normal_rate=np.array([0.5 * 2.3439e-2, -9.1064e-13]))
    assert _within_rounding(answer, v_minus, slowest, e)
    answer.normal_rate[0] = 0.0
    assert not _within_rounding(answer, v_minus, slowest, e)


@pytest.mark.slow  # its three rigid bodies are derived whole (~8 s with a cold cache); the run ~12 s
def test_a_slot_handed_back_its_corner_twins_element_keeps_its_boundary_event():
    """A fuzz's pile (tests/reference/fuzz_corner_pile.json: five 2D bodies, rigid and
    flexible, mixed friction and restitution): a rigid polygon's vertex rattles in a dent of
    a flexible disc.  Handed over at the dent's vertex, its slot hits the next flank and
    leaves it, and its corner twin hands the old flank back to it, held, at or a hair past
    that flank's end.  It kept the twin's margin floor (0), so its boundary event started
    below it and never fired: the vertex slid on along the flank's line, 1.5 mm into the
    disc, and the run ended too_slow.  The slot's floor is now lowered there as for any
    contact held at this instant."""
    table = reference_table("fuzz_corner_pile")
    r = flexbody.simulate(flexbody.load_scene(table), max_wall_time=120.0)  # 12 s; before, too_slow at any bound
    assert r.status == "success", r.message
    assert r.stats["events"] > 100
    assert r.stats["max_penetration_m"] < 1e-9  # 1.5e-3 m before; measured 3.0e-11 m
    assert r.stats["energy_drift_relative"] < 1e-6  # measured 1.1e-7


@pytest.mark.slow  # two rigid discs derived whole (~8 s with a cold cache); the run ~75 s
def test_a_pile_whose_redundant_contacts_lose_lemkes_pivots_runs_to_its_end():
    """A fuzz's pile (tests/reference/fuzz_redundant_friction_pile.json: two rigid and three
    flexible discs, friction): the force LCPs of its held contacts are singular to rounding
    (redundant contacts), and Lemke's pivots ended inaccurate at 0.164 s and on a ray at
    0.168 s, each stopping it `unsupported` as if Painlevé's; solved again on M + s I, it
    runs to its end (:mod:`flexbody.lcp`)."""
    table = reference_table("fuzz_redundant_friction_pile")
    r = flexbody.simulate(flexbody.load_scene(table), max_wall_time=400.0)
    assert r.status == "success", r.message
    assert r.stats["events"] > 1000  # measured 1 687
    assert r.stats["max_penetration_m"] < 1e-9  # measured 2.7e-11 m
    assert r.stats["energy_drift_relative"] < 1e-6  # measured 6.6e-8


def test_two_blocks_flying_at_each_other_meet_at_the_default_tolerances():
    """Two 3 x 2-cell blocks 0.4 m apart flying at each other at 1 m/s each in free space:
    free flight is exact for RK45, whose steps then grow without bound, and one step carried
    each block through the other (0 events, every gap read beyond reach at both ends; found
    by a fuzz).  A step now moves no particle relative to another by more than half a margin
    (``BodyContactModel.step_reach``): they meet, and no vertex gets inside."""
    cell = 0.01
    nodes = [(i, j) for i in range(4) for j in range(3)]
    index = {n: k for k, n in enumerate(nodes)}
    triangles = []
    for i in range(3):
        for j in range(2):
            a, b, c, d = index[(i, j)], index[(i + 1, j)], index[(i + 1, j + 1)], index[(i, j + 1)]
            triangles += [(a, b, c), (a, c, d)]
    corner, triangles = np.array(nodes, float) * cell, np.array(triangles)
    links = sorted({tuple(sorted((int(t[p]), int(t[q])))) for t in triangles for p in range(3) for q in range(p)})
    from flexbody.surface import boundary

    bodies = [{"name": name, "particles": (corner + [dx, 0.2 + dy]).tolist(), "links": [list(k) for k in links],
               "surface": boundary(corner, triangles).tolist(), "mass": 0.005, "stiffness": 5000.0, "damping": 0.0,
               "damper": "axial", "position": [0.0, 0.0], "velocity": [v, 0.0], "collide": True}
              for name, dx, dy, v in (("a", -0.23, 0.0, 1.0), ("b", 0.2, 0.004, -1.0))]
    table = {"name": "blocks", "gravity": [0.0, 0.0], "grounds": [{"point": [0.0, -10.0], "normal": [0.0, 1.0]}],
             "bodies": bodies, "contacts": [{"bodies": ["a", "b"], "restitution": 0.5}],
             "simulation": {"t_end": 0.3, "output_dt": 0.0005}}
    result = flexbody.simulate(flexbody.load_scene(table))
    assert result.status == "success", result.message
    assert result.stats["impacts"] > 10 and result.stats["max_penetration_m"] < 1e-9
    assert result.positions[-1, :12, 0].max() < result.positions[-1, 12:, 0].min()  # a still left of b


def test_a_soft_disc_turned_inside_out_against_a_block_stops_the_run():
    """A 7-particle disc (a hexagon round its centre particle, 500 N/m) hitting a rigid block
    at 3 m/s in space: its centre particle, which makes no contact (only surface particles
    do), passes out through its own hexagon and 2.4 cm into the block, and the disc turns
    inside out, while no surface crosses itself.  Found by a fuzz: the run said success.
    The whole fold check (at output samples) finds a particle off the disc's surface inside
    the block (the block's surface winds around it)."""
    scene = flexbody.load_scene({
        "name": "soft_disc_inverts", "gravity": [0.0, 0.0], "grounds": [{"point": [0, -10.0], "normal": [0, 1.0]}],
        "bodies": [{"name": "B", "shape": "polygon", "rigid": True, "mass": 0.2,
                    "vertices": [[-0.12, 0.0], [0.12, 0.0], [0.12, 0.07], [-0.12, 0.07]], "position": [0.0, 0.0]},
                   {"name": "A", "shape": "disc", "count": 7, "radius": 0.03, "mass": 0.05, "stiffness": 500.0,
                    "damping": 0.0, "position": [0.0, 0.101], "velocity": [0.0, -3.0]}],
        "contacts": [{"bodies": ["A", "B"]}], "simulation": {"t_end": 0.05, "output_dt": 1e-4}})
    result = flexbody.simulate(scene)
    assert result.status == "unsupported" and "body 'A' has folded over" in result.message
    assert "its particle 7, off its surface, is inside body 'B'" in result.message
    np.testing.assert_allclose(result.positions[0, 7], [0.0, 0.101])  # the disc's centre
    assert result.positions[:, 7, 1].min() > 0.07 - 0.005  # stopped before it was deep in the block (2.4 cm before)


def test_winding_numbers_tell_inside_from_outside():
    """A unit square and a unit cube (outward): a point inside reads 1, outside 0."""
    from flexbody.surface import winding_numbers

    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, 0.5], [1.5, 0.5]])
    np.testing.assert_allclose(winding_numbers(square, [[0, 1], [1, 2], [2, 3], [3, 0]], [4, 5]), [1.0, 0.0],
                               atol=1e-12)
    from flexbody.surface import hull

    corners = np.array([[i, j, k] for i in (0.0, 1.0) for j in (0.0, 1.0) for k in (0.0, 1.0)])
    x = np.vstack([corners, [[0.5, 0.5, 0.5], [1.5, 0.5, 0.5], [0.5, 0.5, -0.01]]])
    np.testing.assert_allclose(winding_numbers(x, hull(corners), [8, 9, 10]), [1.0, 0.0, 0.0], atol=1e-12)


def test_a_heavy_soft_disc_settling_over_a_small_ring_stops_when_its_inside_enters_the_ring():
    """A heavy soft disc (15 particles, 2.95 kg, 500 N/m) dropped on a small stiff ring (13
    particles with a centre) on the ground: its interior particle 5 comes through its own
    boundary into the ring from 0.1394 s (1.6 cm deep by 0.17 s, found by a fuzz, `success`
    before).  Only the ring's particles were near the disc's surface, so the check looked at
    the ring's inside against the disc only; it looks both ways now."""
    scene = flexbody.load_scene({
        "name": "disc_over_ring", "gravity": [0.0, -9.81],
        "grounds": [{"point": [0.0, 0.0], "normal": [0.0, 1.0], "friction": 0.7}],
        "bodies": [{"name": "A", "shape": "disc", "count": 15, "radius": 0.12881145650063947, "mass": 2.95,
                    "stiffness": 500.0, "damping": 0.493, "damper": "relative",
                    "position": [-0.0038950573165733443, 0.20920152439360415]},
                   {"name": "B", "shape": "ring", "count": 13, "radius": 0.04426799738835573, "center": True,
                    "mass": 0.0214, "angle": 5.9387, "stiffness": 20000.0, "damping": 0.0, "damper": "relative",
                    "position": [0.0, 0.0431654295672472]}],
        "contacts": [{"bodies": ["A", "B"], "friction": 0.0, "restitution": 0.588}],
        "simulation": {"t_end": 0.17, "output_dt": 8.5e-4}})
    result = flexbody.simulate(scene)
    assert result.status == "unsupported", result.message
    assert "its particle 5, off its surface, is inside body 'B'" in result.message
    assert 0.139 < result.t[-1] < 0.1405
