"""Rigid bodies (DESIGN §6): a body's frame T without elastic coordinates, against closed forms.

A rigid body's particles are fixed in T, so its motion is T's: free flight is a parabola of
the centre of mass with a constant spin (2D) or a conserved angular momentum (3D); resting
on the ground its contact forces are those of statics; landing flat, its plastic impulses
stop it whole, in any order of its particles.
"""

from __future__ import annotations

import numpy as np
import pytest

import flexbody
from flexbody.driver import simulate
from flexbody.errors import InputError
from flexbody.model import load_model

from .conftest import needs_cc

G = 9.81
TIGHT = dict(rtol=1e-10, atol=1e-12)


def rigid_scene(particles, masses, *, position, angle=0.0, velocity=None, angular_velocity=None, t_end=1.0,
                output_dt=1e-3, gravity=(0.0, -G), reverse=False):
    """One rigid body (its links carry no load: a rigid body has no springs or dampers)."""
    particles, masses = list(particles), list(masses)
    if reverse:  # the same body, its particles listed the other way round
        particles, masses = particles[::-1], masses[::-1]
    n, dim = len(particles), len(gravity)
    body = {"name": "rigid", "rigid": True, "particles": particles, "masses": masses,
            "links": [[i, i + 1] for i in range(n - 1)], "position": list(position)}
    if dim == 2:
        body["angle"] = angle
    else:
        body["rotation"] = list(angle) if np.ndim(angle) else [0.0, 0.0, 0.0]
    if velocity is not None:
        body["velocity"] = list(velocity)
    if angular_velocity is not None:
        body["angular_velocity"] = angular_velocity
    return flexbody.load_scene({"name": "rigid_body", "gravity": list(gravity), "bodies": [body],
                                "simulation": {"t_end": t_end, "output_dt": output_dt}})


def centre(r, masses):
    return np.einsum("i,tid->td", np.asarray(masses) / np.sum(masses), r.positions)


# ----------------------------------------------------------------- free flight


@needs_cc
def test_a_spinning_rigid_triangle_flies_on_a_parabola_with_a_constant_spin():
    tri = [[-0.2, 0.0], [0.3, 0.0], [0.05, 0.25]]
    masses = [0.1, 0.2, 0.3]
    v0, w = np.array([0.7, 2.0]), 5.0
    scene = rigid_scene(tri, masses, position=[0.0, 5.0], velocity=v0, angular_velocity=w, t_end=0.5)
    r = simulate(scene, **TIGHT)
    assert r.success and len(r.events_kind) == 0, r.message
    c0 = centre(r, masses)[0]
    # the centre of mass moves with the body's velocity at its centre of mass
    x0 = r.positions[0]
    vc = np.einsum("i,id->d", np.asarray(masses) / np.sum(masses), r.velocities[0])
    expected_centre = c0 + np.outer(r.t, vc) + np.outer(r.t**2, [0.0, -G / 2])
    np.testing.assert_allclose(centre(r, masses), expected_centre, atol=1e-9)
    # and every particle turns about it at w: x_i(t) = c(t) + R(w t) (x_i(0) - c(0))
    rel0 = x0 - c0
    for k in (len(r.t) // 3, -1):
        a = w * r.t[k]
        R = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])
        np.testing.assert_allclose(r.positions[k] - centre(r, masses)[k], rel0 @ R.T, atol=1e-9)
    np.testing.assert_allclose(r.total_energy - r.total_energy[0], 0.0, atol=1e-10 * r.total_energy[0])  # rtol 1e-10


@needs_cc
def _locking_rotation(points) -> list[float]:
    """The rotation vector that turns the frame of ``points``' gauge particles (x towards the
    reference, x-y plane through the third) so that its z-axis lies along N's x-axis: the
    gimbal lock of its X-Y-Z angles."""
    from flexbody.state import gauge_frame
    from flexbody.topology import gauge_particles

    points = np.asarray(points, float)
    R0, _ = gauge_frame(points, np.zeros_like(points), gauge_particles(points))
    axis = np.cross(R0[:, 2], [1.0, 0.0, 0.0])
    turn = np.arcsin(np.linalg.norm(axis)) if R0[0, 2] >= 0 else np.pi - np.arcsin(np.linalg.norm(axis))
    return (axis / np.linalg.norm(axis) * turn).tolist()


TET = [[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.0, 0.2, 0.0], [0.05, 0.05, 0.25]]


@pytest.mark.parametrize("pose", ["turned", "gauge_lock"])
def test_a_3d_rigid_body_keeps_its_angular_momentum_and_energy_in_free_flight(pose):
    """Free flight from any pose: where its gauge particles' frame would start at the gimbal
    lock of its angles (a fuzz's rigid sphere was refused there), a rigid body's frame T
    starts along N's axes, its angles at 0."""
    from flexbody.state import initial_coordinates

    tet, masses = TET, [0.1, 0.2, 0.15, 0.25]
    rotation = [0.3, 0.2, 0.1] if pose == "turned" else _locking_rotation(TET)
    scene = rigid_scene(tet, masses, position=[0.0, 0.0, 5.0], angle=rotation, velocity=[0.5, -0.2, 1.0],
                        angular_velocity=[1.0, -2.0, 3.0], gravity=(0.0, 0.0, -G), t_end=0.4)
    q, _ = initial_coordinates(scene, load_model(scene))
    assert (q[3:6].tolist() == [0.0, 0.0, 0.0]) == (pose == "gauge_lock")
    r = simulate(scene, **TIGHT)
    assert r.success and len(r.events_kind) == 0, r.message
    np.testing.assert_allclose(r.positions[0], scene.initial_positions(), atol=1e-15)
    np.testing.assert_allclose(r.velocities[0], scene.initial_velocities(), atol=1e-14)
    m = np.asarray(masses)
    c = centre(r, masses)
    vc = np.einsum("i,tid->td", m / m.sum(), r.velocities)
    momentum = np.einsum("i,tid->td", m, np.cross(r.positions - c[:, None], r.velocities - vc[:, None]))
    np.testing.assert_allclose(momentum, np.broadcast_to(momentum[0], momentum.shape), atol=1e-9 * np.abs(momentum[0]).max())
    np.testing.assert_allclose(vc, vc[0] + np.outer(r.t, [0.0, 0.0, -G]), atol=1e-9)
    np.testing.assert_allclose(r.total_energy - r.total_energy[0], 0.0, atol=1e-10 * r.total_energy[0])  # rtol 1e-10
    # rigid: every distance between particles stays what it was
    d = np.linalg.norm(r.positions[:, :, None] - r.positions[:, None], axis=-1)
    np.testing.assert_allclose(d, np.broadcast_to(d[0], d.shape), atol=1e-12)


# ----------------------------------------------------------------- on the ground


TRIANGLE = [[-0.4, 0.0], [0.6, 0.0], [0.35, 0.3]]  # base on the ground, apex off centre
TRIANGLE_MASSES = [0.2, 0.1, 0.4]


def _statics(particles, masses):
    """Forces of the two base particles (x1 < x2) holding the body: sum = M g, no moment about its centre."""
    x = np.asarray(particles)[:, 0]
    m = np.asarray(masses)
    xc = float(m @ x / m.sum())
    x1, x2 = x[0], x[1]
    share = (x2 - xc) / (x2 - x1)
    return m.sum() * G * np.array([share, 1.0 - share])


@needs_cc
@pytest.mark.parametrize("reverse", [False, True], ids=["listed", "reversed"])
def test_a_rigid_body_landing_flat_stops_whole_and_rests_on_the_forces_of_statics(reverse):
    h = 0.5
    scene = rigid_scene(TRIANGLE, TRIANGLE_MASSES, position=[0.0, h], reverse=reverse)
    r = simulate(scene, **TIGHT)
    assert r.success, r.message
    base = [0, 1] if not reverse else [2, 1]
    t1 = np.sqrt(2 * h / G)
    assert list(r.events_kind) == ["impact", "impact"]
    assert sorted(r.events_particle) == sorted(base)
    np.testing.assert_allclose(r.events_time, t1, rtol=1e-10)
    # plastic: both base contacts stop, so the whole body stops (all its kinetic energy lost)
    m = np.sum(TRIANGLE_MASSES)
    assert r.impact_loss[-1] == pytest.approx(0.5 * m * (G * t1) ** 2, rel=1e-9)
    after = r.t > t1 + 1e-3
    np.testing.assert_allclose(r.velocities[after], 0.0, atol=1e-12)
    expected = _statics(TRIANGLE, TRIANGLE_MASSES)
    np.testing.assert_allclose(r.contact_force[-1, base], expected, rtol=1e-9)
    total = r.total_energy
    assert np.abs(total - total[0]).max() < 1e-9 * total[0]


@needs_cc
def test_the_flat_landing_impulses_solve_the_plastic_impact_of_the_two_contacts_by_hand():
    # Impulses P1 + P2 = M v (the body stops), P1 (xc - x1) = P2 (x2 - xc) (its spin stays 0):
    # P = M v (x2 - xc, xc - x1) / (x2 - x1), both >= 0 with the centre between the base
    # particles, so this is also the linear complementarity problem's unique solution.
    scene = rigid_scene(TRIANGLE, TRIANGLE_MASSES, position=[0.0, 0.5])
    model = load_model(scene)
    p = model.parameters(scene)
    from flexbody.state import initial_coordinates

    q, _ = initial_coordinates(scene, model)
    v = 2.0
    u = np.zeros(model.nu)
    u[1] = -v  # T's origin falls at v, no spin
    y = np.concatenate([q, u, [0.0, 0.0]])
    stop = np.zeros(model.n_contacts, np.intc)
    stop[[0, 1]] = 1
    out, loss = model.impact(y, p, stop)
    du = out[model.nq : model.nq + model.nu] - u
    M, J = model.mass_matrix(q, p), model.gap_jacobian(q, p)[[0, 1]]
    impulses = np.linalg.solve(J @ np.linalg.solve(M, J.T), J @ du)
    expected = _statics(TRIANGLE, TRIANGLE_MASSES) / G * v
    np.testing.assert_allclose(impulses, expected, rtol=1e-12)
    np.testing.assert_allclose(out[model.nq : model.nq + model.nu], 0.0, atol=1e-14)
    assert loss == pytest.approx(0.5 * np.sum(TRIANGLE_MASSES) * v**2, rel=1e-12)


@needs_cc
def test_a_3d_rigid_tetrahedron_landing_on_its_base_rests_on_the_barycentric_forces_of_statics():
    # The three base forces hold the weight with no moment: F_k = M g b_k, where b are the
    # barycentric coordinates of the centre of mass's projection in the base triangle.
    tet = [[0.0, 0.0, 0.0], [0.4, 0.0, 0.0], [0.1, 0.3, 0.0], [0.25, 0.1, 0.2]]
    masses = [0.1, 0.2, 0.15, 0.3]
    scene = rigid_scene(tet, masses, position=[0.0, 0.0, 0.3], gravity=(0.0, 0.0, -G))
    r = simulate(scene, **TIGHT)
    assert r.success, r.message
    assert sorted(r.events_particle) == [0, 1, 2] and set(r.events_kind) == {"impact"}
    np.testing.assert_allclose(r.events_time, np.sqrt(2 * 0.3 / G), rtol=1e-10)
    m = np.asarray(masses)
    c = (m @ np.asarray(tet))[:2] / m.sum()
    base = np.asarray(tet)[:3, :2]
    b = np.linalg.solve(np.vstack([base.T, np.ones(3)]), np.append(c, 1.0))
    np.testing.assert_allclose(r.contact_force[-1, :3], m.sum() * G * b, rtol=1e-9)
    assert r.contact_force[-1, 3] == 0.0


@needs_cc
def test_a_flexible_and_a_rigid_body_in_one_scene_move_as_each_does_alone():
    """Side by side (particles formulation: the rigid frame beside the assembled dumbbell) and
    derived whole (floating formulation)."""
    formulations, kinds = ("particles", "floating"), {"particles": "mixed", "floating": "derived"}
    flexible = {"name": "dumbbell", "particles": [[-0.1, 0.0], [0.1, 0.0]], "links": [[0, 1]], "mass": 0.05,
                "stiffness": 2000.0, "damping": 0.5, "position": [2.0, 0.3], "angle": 0.3}
    rigid = {"name": "bar", "rigid": True, "particles": TRIANGLE, "masses": TRIANGLE_MASSES,
             "links": [[0, 1], [1, 2]], "position": [0.0, 0.5], "angle": 0.1}

    def run(*bodies, **options):
        return simulate(flexbody.load_scene({"name": "mix", "bodies": list(bodies),
                                             "simulation": {"t_end": 0.8, "output_dt": 1e-3}}), **TIGHT, **options)

    alone_flexible, alone_rigid = run(flexible), run(rigid)
    assert alone_flexible.success and alone_rigid.success
    for formulation in formulations:
        both = run(flexible, rigid, formulation=formulation)
        assert both.success and both.stats["model"] == kinds[formulation]
        # the flexible body alone runs on the assembled particles formulation, in the mix on the one asked
        np.testing.assert_allclose(both.positions[:, :2], alone_flexible.positions, atol=1e-8)
        np.testing.assert_allclose(both.positions[:, 2:], alone_rigid.positions, atol=1e-8)
        assert both.stats["impacts"] == alone_flexible.stats["impacts"] + alone_rigid.stats["impacts"]


@needs_cc
def test_the_bundled_rigid_bar_lands_flat_on_both_ends_at_once_and_rests_on_statics():
    r = simulate("rigid_bar", **TIGHT)
    assert r.success, r.message
    t1 = np.sqrt(2 * 0.5 / G)
    assert list(r.events_kind) == ["impact", "impact"] and sorted(r.events_particle) == [0, 1]
    np.testing.assert_allclose(r.events_time, t1, rtol=1e-10)
    masses = np.array([0.3, 0.7])
    assert r.impact_loss[-1] == pytest.approx(0.5 * masses.sum() * (G * t1) ** 2, rel=1e-9)
    xc = masses @ np.array([-0.5, 0.5]) / masses.sum()  # forces M g (x2 - xc, xc - x1) / L
    np.testing.assert_allclose(r.contact_force[-1], masses.sum() * G * np.array([0.5 - xc, xc + 0.5]), rtol=1e-9)


@needs_cc
@pytest.mark.parametrize("reverse", [False, True], ids=["listed", "reversed"])
def test_a_rigid_triangle_landing_flat_bounces_by_newton_on_its_coupled_contacts(reverse):
    # Both base contacts approach at v with the same e: Newton's LCP gives P = (1 + e) times
    # the plastic impulses (W P = (1 + e) v on both rows), so the body leaves at e v without
    # spin and bounces like a point: t_{k+1} = t_k + 2 e^k t1, at rest by t1 (1 + e) / (1 - e).
    e, h = 0.5, 0.5
    particles, masses = (TRIANGLE[::-1], TRIANGLE_MASSES[::-1]) if reverse else (TRIANGLE, TRIANGLE_MASSES)
    scene = flexbody.load_scene({
        "name": "bouncing_triangle", "grounds": [{"point": [0.0, 0.0], "normal": [0.0, 1.0], "restitution": e}],
        "bodies": [{"name": "tri", "rigid": True, "particles": particles, "masses": masses, "links": [[0, 1], [1, 2]],
                    "position": [0.0, h]}],
        "simulation": {"t_end": 1.5, "output_dt": 1e-3}})
    r = simulate(scene, **TIGHT)
    assert r.success, r.message
    t1 = np.sqrt(2 * h / G)
    pairs = r.events_time.reshape(-1, 2)  # both base particles in every instant
    np.testing.assert_allclose(pairs[:, 0], pairs[:, 1], rtol=0, atol=0)
    k = np.arange(len(pairs))
    expected = t1 + np.concatenate([[0.0], np.cumsum(2 * e ** k[1:] * t1)])
    # where the landing speed e^k g t1 is above 1e-2 m/s: slower, the gap tolerance (1e-12 m)
    # shifts an impact by up to 1e-12 / v s (1.6e-8 s at the 15th, measured)
    fast = e**k * G * t1 > 1e-2
    assert fast.sum() >= 8
    np.testing.assert_allclose(pairs[fast, 0], expected[fast], rtol=1e-9)
    np.testing.assert_allclose(pairs[:, 0], expected, atol=1e-7)
    assert pairs[-1, 0] <= t1 * (1 + e) / (1 - e)
    base = [0, 1] if not reverse else [2, 1]
    np.testing.assert_allclose(r.contact_force[-1, base], _statics(TRIANGLE, TRIANGLE_MASSES), rtol=1e-9)
    total = r.total_energy
    assert np.abs(total - total[0]).max() < 1e-9 * total[0]


@needs_cc
def test_an_instant_of_coupled_contacts_satisfies_newtons_law_and_lifts_a_pushed_corner():
    # The triangle rests on corner A (held) and turns so that corner B lands: one instant, two
    # touching contacts.  Whatever the solver, the outcome must satisfy Newton's law per
    # contact, checked here from the velocity jump alone: impulses P = W^-1 J du >= 0,
    # v+ >= 0, P . v+ = 0 (plastic), and the contact that leaves is free.
    from flexbody.constants import FREE, HELD
    from flexbody.contact import Phases, resolve
    from flexbody.state import initial_coordinates

    scene = rigid_scene(TRIANGLE, TRIANGLE_MASSES, position=[0.0, 0.0])
    model = load_model(scene)
    p = model.parameters(scene)
    q, _ = initial_coordinates(scene, model)
    for spin in (-3.0, 3.0):  # lands on B turning about A, and the mirror case: A lands while B rests
        u = np.zeros(model.nu)
        u[2] = spin  # T turns about its origin (the anchor particle)
        y = np.concatenate([q, u, [0.0, 0.0]])
        J = model.gap_jacobian(q, p)
        vn = J @ u
        assert np.all(model.gaps(q, p)[[0, 1]] == pytest.approx(0.0, abs=1e-15))
        phases = Phases.all_free(model.n_contacts)
        phases.phase[np.argmax(vn[[0, 1]])] = HELD  # the base corner that does not approach rests
        hit = np.zeros(model.n_contacts, bool)
        hit[np.argmin(vn[[0, 1]])] = True
        res = resolve(model, 0.0, y, p, phases, hit, np.zeros(model.n_contacts, bool), gap_tolerance=1e-12,
                      force_tolerance=np.full(model.n_contacts, 1e-9), masses=np.array(TRIANGLE_MASSES),
                      speed_tolerance=1e-9)
        du = res.y[model.nq : model.nq + model.nu] - u
        rows = [0, 1]
        M = model.mass_matrix(q, p)
        W = J[rows] @ np.linalg.solve(M, J[rows].T)
        impulses = np.linalg.solve(W, J[rows] @ du)
        v_plus = J[rows] @ res.y[model.nq : model.nq + model.nu]
        assert np.all(impulses >= -1e-12) and np.all(v_plus >= -1e-12)
        np.testing.assert_allclose(impulses * v_plus, 0.0, atol=1e-12)
        for c in rows:  # held where it stays, free where it leaves
            assert res.phases.phase[c] == (FREE if v_plus[c] > 1e-9 else HELD)


@needs_cc
def test_a_body_resting_with_its_centre_beyond_a_corner_lifts_the_other_and_pivots_with_the_closed_form_force():
    # Resting on both base corners with its centre of mass beyond corner 1: Signorini's law
    # (one LCP over both held contacts) keeps corner 1 and lifts corner 0 at t = 0.  From
    # rest on a frictionless point, the centre falls straight and the body turns about it:
    # N = M g I_c / (I_c + M d^2), d the horizontal distance from the centre to the corner.
    particles = [[-0.4, 0.0], [0.6, 0.0], [1.5, 0.3]]
    masses = [0.1, 0.1, 0.5]
    scene = rigid_scene(particles, masses, position=[0.0, 0.0], t_end=0.05, output_dt=1e-3)
    r = simulate(scene, **TIGHT)
    assert r.success, r.message
    assert (r.events_kind[0], r.events_particle[0], r.events_time[0]) == ("liftoff", 0, 0.0)
    m, x = np.asarray(masses), np.asarray(particles)
    c = m @ x / m.sum()
    I_c = float(m @ np.sum((x - c) ** 2, axis=1))
    d = x[1, 0] - c[0]
    N = m.sum() * G * I_c / (I_c + m.sum() * d**2)
    assert r.contact_force[0, 0] == 0.0
    assert r.contact_force[0, 1] == pytest.approx(N, rel=1e-10)


BOX = [[x, y, z] for z in (0.0, 0.2) for y in (0.0, 0.3) for x in (0.0, 0.5)]
BOX_MASSES = [0.1, 0.2, 0.1, 0.3, 0.1, 0.1, 0.2, 0.1]


@needs_cc
@pytest.mark.parametrize("e", [0.0, 0.5])
def test_a_3d_rigid_box_landing_flat_on_four_corners_is_solved_though_its_forces_are_not_unique(e):
    # Four coplanar corners, three freedoms they constrain: W = J M^-1 J^T is singular, the
    # impact and the resting forces are not unique.  The LCP gives impulses that stop the
    # box whole (e = 0) or send it up at e v without spin, like a point (so the same impact
    # times), and resting forces >= 0 that hold its weight with no moment (statics).
    h = 0.5
    scene = flexbody.load_scene({
        "name": "flat_box", "gravity": [0.0, 0.0, -G],
        "grounds": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0], "restitution": e}],
        "bodies": [{"name": "box", "rigid": True, "particles": BOX, "masses": BOX_MASSES,
                    "links": [[i, i + 1] for i in range(7)], "position": [0.0, 0.0, h]}],
        "simulation": {"t_end": 1.5, "output_dt": 1e-3}})
    r = simulate(scene, **TIGHT)
    assert r.success, r.message
    t1 = np.sqrt(2 * h / G)
    instants = r.events_time.reshape(-1, 4)  # the four bottom corners in every instant
    assert set(r.events_particle) == {0, 1, 2, 3}
    np.testing.assert_allclose(instants, instants[:, :1] * np.ones(4), rtol=0, atol=0)
    if e == 0.0:
        assert len(instants) == 1
    else:
        k = np.arange(min(len(instants), 8))
        np.testing.assert_allclose(instants[k, 0], t1 + np.concatenate([[0.0], np.cumsum(2 * e ** k[1:] * t1)]),
                                   rtol=1e-9)
    np.testing.assert_allclose(instants[0, 0], t1, rtol=1e-10)
    m, x = np.asarray(BOX_MASSES), np.asarray(BOX)
    force = r.contact_force[-1]
    assert np.all(force >= 0.0) and np.all(force[4:] == 0.0)
    np.testing.assert_allclose(force.sum(), m.sum() * G, rtol=1e-10)
    np.testing.assert_allclose(force @ x[:, :2], m.sum() * G * (m @ x[:, :2]) / m.sum(), rtol=1e-10)
    total = r.total_energy
    assert np.abs(total - total[0]).max() < 1e-9 * total[0]


@needs_cc
@pytest.mark.parametrize("e", [0.0, 0.3])
def test_a_tumbling_3d_rigid_box_comes_to_rest_on_a_face(e):
    # Corners land one after another, rock on edges (a corner that the others' impulses
    # would lift slower than a 1e-9 m rise stays: no Zeno cascade) and the box ends on a
    # face, still sliding and turning on the frictionless ground: vertical velocity 0, the
    # face's four corners at gap 0 carrying the weight, the ledger closed.
    scene = flexbody.load_scene({
        "name": "tumbling_box", "gravity": [0.0, 0.0, -G],
        "grounds": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0], "restitution": e}],
        "bodies": [{"name": "box", "rigid": True, "particles": BOX, "masses": BOX_MASSES,
                    "links": [[i, i + 1] for i in range(7)], "position": [0.0, 0.0, 0.5],
                    "rotation": [0.2, 0.1, 0.0], "angular_velocity": [1.0, -0.5, 0.3]}],
        "simulation": {"t_end": 2.0, "output_dt": 1e-3}})
    r = simulate(scene, **TIGHT)
    assert r.success, r.message
    z = r.positions[-1, :, 2]
    face = np.abs(z) < 1e-9
    assert face.sum() == 4 and np.all(z[~face] > 0.1)
    assert r.positions[:, :, 2].min() > -1e-9
    np.testing.assert_allclose(r.velocities[-1, :, 2], 0.0, atol=1e-9)
    force = r.contact_force[-1]
    assert np.all(force >= 0.0) and np.all(force[~face] == 0.0)
    np.testing.assert_allclose(force.sum(), np.sum(BOX_MASSES) * G, rtol=1e-9)
    total = r.total_energy
    assert np.abs(total - total[0]).max() < 1e-8 * total[0]


# ----------------------------------------------------------------- input


@pytest.mark.parametrize("x", [-0.15, 0.15])
def test_a_block_resting_on_three_collinear_points_hit_off_centre_stays_at_rest(x):
    """A rigid block on three points in a line (one more than its motion needs: one is set
    free at rest as implied by the others) takes a small square's plastic landing near either
    end: the ground's impulses keep it still (all three may push, so the LCP finds them), and
    the square stops on it.  Before, the implied point was left out of the impact, the block
    tipped about the two held ones and rocked (7 impacts, 3 lift-offs, moving 3e-5 m)."""
    block = {"name": "block", "shape": "polygon", "rigid": True, "mass": 0.5, "position": [0.0, 0.0],
             "vertices": [[-0.2, 0.0], [0.0, 0.0], [0.2, 0.0], [0.2, 0.1], [-0.2, 0.1]]}
    square = {"name": "square", "shape": "polygon", "rigid": True, "mass": 0.05, "position": [x, 0.11],
              "vertices": [[-0.03, 0.0], [0.03, 0.0], [0.03, 0.06], [-0.03, 0.06]]}
    r = simulate(flexbody.load_scene({"name": "land_on_3", "bodies": [block, square],
                                      "contacts": [{"bodies": ["block", "square"]}],
                                      "simulation": {"t_end": 0.1, "output_dt": 0.001, **TIGHT}}))
    assert r.success, r.message
    t1 = np.sqrt(2 * 0.01 / G)
    assert list(r.events_kind) == ["impact", "impact"] and np.abs(r.events_time - t1).max() < 1e-9
    assert np.abs(r.velocities[:, :5]).max() < 1e-12  # the block never moves
    assert np.abs(r.velocities[r.t > t1 + 1e-6]).max() < 1e-12  # nor the square once landed
    assert r.impact_loss[-1] == pytest.approx(0.5 * r.masses[5:].sum() * (G * t1) ** 2, rel=1e-9)


def test_a_scene_of_rigid_bodies_alone_runs_on_its_frames_whichever_formulation_is_asked():
    """A rigid body is its frame T in both formulations; with no flexible body the particles
    formulation has nothing to assemble, so the run is the floating one, bit for bit."""
    scene = rigid_scene(TRIANGLE, TRIANGLE_MASSES, position=[0.0, 0.5])
    asked, default = simulate(scene, formulation="particles", t_end=0.4), simulate(scene, t_end=0.4)
    assert asked.success and asked.stats["formulation"] == "floating" and asked.stats["model"] == "derived"
    np.testing.assert_array_equal(asked.positions, default.positions)


def test_a_rigid_body_beside_a_flexible_body_too_large_for_the_floating_formulation():
    """The floating formulation derives the whole scene and is offered up to 40 flexible
    particles: asked for with 41 it is refused, naming the count and the way out; by default
    (the particles formulation) the rigid slab's frame runs beside the assembled ring."""
    table = {"name": "r", "bodies": [
        {"name": "slab", "rigid": True, "particles": [[-0.5, 0.0], [0.5, 0.0]], "masses": [0.5, 0.5],
         "links": [[0, 1]], "position": [0.0, 0.1]},
        {"name": "ring", "shape": "ring", "count": 41, "radius": 0.1, "mass": 0.01, "stiffness": 1000.0,
         "damping": 0.1, "position": [0.0, 0.5]}], "simulation": {"t_end": 0.1}}
    with pytest.raises(InputError) as error:
        simulate(flexbody.load_scene(table), formulation="floating")
    message = str(error.value)
    assert "41 particles" in message and "use the particles formulation" in message
    r = simulate(flexbody.load_scene(table))
    assert r.success and r.stats["model"] == "mixed" and r.stats["formulation"] == "particles"


def test_a_rigid_body_with_particle_velocities_that_are_not_a_rigid_motion_is_refused():
    table = {"name": "r", "bodies": [{"name": "bar", "rigid": True, "particles": [[-0.5, 0.0], [0.5, 0.0]],
                                      "masses": [0.5, 0.5], "links": [[0, 1]],
                                      "position": [0.0, 1.0], "particle_velocities": [[0.0, 0.0], [1.0, 0.0]]}],
             "simulation": {"t_end": 0.1}}
    with pytest.raises(InputError, match="not a rigid motion"):
        simulate(flexbody.load_scene(table))


def test_a_rigid_bar_sliding_flat_on_a_rough_ground_stops_at_the_closed_form_time():
    """Both ends sliding (coupled contacts with friction): the bar decelerates at mu g and
    stops at v0 / (mu g), having slid v0^2 / (2 mu g); friction takes its kinetic energy."""
    mu, v0 = 0.5, 1.0
    table = {"name": "r", "grounds": [{"point": [0.0, 0.0], "normal": [0.0, 1.0], "friction": mu}],
             "bodies": [{"name": "bar", "rigid": True, "particles": [[-0.5, 0.0], [0.5, 0.0]], "masses": [0.3, 0.7],
                         "links": [[0, 1]], "position": [0.0, 0.0], "velocity": [v0, 0.0]}],
             "simulation": {"t_end": 0.3, "output_dt": 0.001, "rtol": 1e-10, "atol": 1e-12}}
    r = simulate(flexbody.load_scene(table))
    assert r.status == "success", r.message
    g, stop = 9.81, v0 / (mu * 9.81)
    np.testing.assert_allclose(r.velocities[:, :, 0], np.maximum(v0 - mu * g * r.t, 0.0)[:, None] * [1, 1], atol=1e-9)
    sticks = r.events_time[r.events_kind == "stick"]
    assert len(sticks) == 2 and np.abs(sticks - stop).max() < 1e-9
    np.testing.assert_allclose(r.positions[-1, :, 0] - r.positions[0, :, 0], v0**2 / (2 * mu * g), rtol=1e-9)
    assert r.friction_work[-1] == pytest.approx(0.5 * 1.0 * v0**2, rel=1e-9)
    np.testing.assert_allclose(r.contact_force[-1], [0.3 * g, 0.7 * g], rtol=1e-9)  # at rest: statics


@needs_cc
def test_a_redundant_contact_set_free_as_implied_is_not_hit_again_at_later_instants():
    """A box resting on its four bottom corners: three freedoms, four contacts, so the
    release sets one free as implied (no force, held at gap 0 by the others).  It stays at
    its gap, approaching at the others' round-off speed (here 1e-13 m/s): a later instant
    must not count that as an impact (it did, at every instant: 26 in 1 ms ended a pile
    of discs with "chattering")."""
    from flexbody.constants import HELD
    from flexbody.contact import Phases, resolve
    from flexbody.state import initial_coordinates

    scene = flexbody.load_scene({
        "name": "resting_box", "gravity": [0.0, 0.0, -G],
        "bodies": [{"name": "box", "rigid": True, "particles": BOX, "masses": BOX_MASSES,
                    "links": [[i, i + 1] for i in range(7)], "position": [0.0, 0.0, 0.0],
                    "velocity": [0.0, 0.0, -1e-13]}],
        "simulation": {"t_end": 1.0, "output_dt": 1e-3}})
    model = load_model(scene)
    q, u = initial_coordinates(scene, model)
    y, p, nc = np.concatenate([q, u, [0.0, 0.0]]), model.parameters(scene), model.n_contacts
    phases = Phases.all_free(nc)
    phases.phase[:4] = HELD
    laws = dict(gap_tolerance=1e-12, force_tolerance=np.full(nc, 1e-10), masses=np.asarray(BOX_MASSES),
                restitution=np.zeros(nc), min_rebound=np.full(nc, 1e-4))
    none = np.zeros(nc, bool)
    first = resolve(model, 0.0, y, p, phases, none, none, **laws)
    implied = np.flatnonzero(~first.phases.on_ground[:4])
    assert len(implied) == 1 and not first.events  # set free without an event
    _, vn, lam = model.contact_state(first.y, p, first.phases.held, first.phases.push)
    assert vn[implied[0]] < 0.0  # approaching by round-off
    np.testing.assert_allclose(lam[:4].sum(), np.sum(BOX_MASSES) * G, rtol=1e-12)
    later = resolve(model, 1e-3, first.y, p, first.phases, none, none, **laws)
    assert not later.events
    np.testing.assert_array_equal(later.phases.phase, first.phases.phase)
