"""The floating frame T in 3D (origin X, Y, Z and body-fixed X-Y-Z angles) against the
particles formulation: gauge, initial coordinates, accelerations, contact forces, a drop,
and the gimbal lock of the angles."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

import flexbody
from flexbody.driver import GIMBAL_LOCK_DEG
from flexbody.errors import InputError
from flexbody.model import load_derived_model, load_model
from flexbody.presets import box, sphere
from flexbody.scene import rotation_matrix
from flexbody.state import gauge_frame, initial_coordinates
from flexbody.topology import gauge_particles

from .conftest import body, make_scene, needs_cc

G = 9.81
ROOT = Path(__file__).resolve().parents[1]


def tetrahedron() -> tuple[np.ndarray, list[list[int]]]:
    """A regular tetrahedron (edge 0.1 sqrt(3) m) with a centre particle (index 0), all linked."""
    bottom = [[np.cos(a), np.sin(a), 0.0] for a in 2 * np.pi * np.arange(3) / 3]
    corners = np.array(bottom + [[0.0, 0.0, np.sqrt(2.0)]])
    points = np.vstack([corners.mean(axis=0), corners]) * 0.1
    links = [[0, i] for i in range(1, 5)] + [[i, j] for i in range(1, 5) for j in range(i + 1, 5)]
    return points, links


def cube() -> tuple[np.ndarray, list[list[int]]]:
    points, links = box((2, 2, 2), (0.1, 0.1, 0.1))
    return points, [list(link) for link in links]


SHAPES = {"tetrahedron": tetrahedron, "box": cube}


def space_scene(shape: str, **overrides) -> flexbody.Scene:
    """One body of ``shape`` 0.3 m up, turned and spinning, over the ground z = 0."""
    points, links = SHAPES[shape]()
    table = body(particles=points.tolist(), links=links, mass=0.1, stiffness=3000.0, damping=0.3,
                 damper="axial" if shape == "box" else "relative", position=[0.0, 0.0, 0.3],
                 rotation=[0.3, -0.2, 0.4], velocity=[0.2, -0.1, -0.5], angular_velocity=[1.0, -2.0, 0.5])
    table.update(overrides)
    return make_scene(table, gravity=[0.0, 0.0, -G], simulation={"t_end": 0.5, "output_dt": 1e-3})


@pytest.fixture(scope="module")
def models():
    """{(shape, formulation): whole-scene derived NumPy model}, derived once per test run (cached);
    its tests are ``slow``: with a cold cache (CI's) the four derivations take 45 s."""
    return {(shape, f): load_derived_model(space_scene(shape), "numpy", f)
            for shape in SHAPES for f in ("particles", "floating")}


# ------------------------------------------------------------------------------ gauge
def test_the_3d_gauge_picks_anchor_reference_and_the_farthest_third_particle():
    points, _ = tetrahedron()
    assert gauge_particles(points) == (0, 1, 2)  # centre; first corner; all corners are equally far off the line
    # The 2x2x2 box: every corner is as near the centre, so the anchor is corner 0 (-,-,-), the
    # reference corner 1 (+,-,-) on the same x-edge; corners 6 (-,+,+) and 7 (+,+,+) are farthest
    # from that edge (a face diagonal away), and 6 is the lower index.
    assert gauge_particles(cube()[0]) == (0, 1, 6)
    points, _ = sphere(12, 1.0, center=True)
    anchor, reference, third = gauge_particles(points)
    assert (anchor, reference) == (0, 1)
    off_line = np.linalg.norm(np.cross(points - points[0], points[1] - points[0]), axis=1)
    assert off_line[third] == off_line.max()
    assert gauge_particles(np.array([[0.0, 0, 0], [1, 1, 1], [2, 2, 2]])) == (1, 0, -1)  # collinear
    assert gauge_particles(np.array([[0.0, 0, 0]])) == (0, -1, -1)


def test_the_planar_gauge_is_unchanged():
    """The 2D gauge is still (anchor, reference), as in the committed thesis ball model."""
    manifest = json.loads((ROOT / "generated" / "thesis_ball_floating" / "manifest.json").read_text())
    ball = flexbody.load_scene("thesis_ball")
    assert [list(b.gauge) for b in ball.topology().bodies] == [b["gauge"] for b in manifest["topology"]["bodies"]]
    assert all(len(b.gauge) == 2 for b in ball.topology().bodies)


def test_collinear_bodies_are_refused_in_3d_floating():
    scene = make_scene(body(particles=[[0.0, 0, 0], [0.1, 0, 0], [0.2, 0, 0]], links=[[0, 1], [1, 2]],
                            position=[0.0, 0.0, 0.3]), gravity=[0.0, 0.0, -G])
    with pytest.raises(InputError, match=r"body 'b' has all its 3 particles on one line.*particles formulation"):
        load_model(scene, backend="numpy", formulation="floating")


# -------------------------------------------------------------------- initial state
@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.slow  # four whole-scene derivations (45 s with a cold cache)
def test_initial_coordinates_place_and_move_every_particle_as_the_scene_says(models, shape):
    scene, model = space_scene(shape), models[shape, "floating"]
    q, u = initial_coordinates(scene, model)
    p = model.parameters(scene)
    x, v = scene.initial_positions(), scene.initial_velocities()
    np.testing.assert_allclose(model.positions(q, p), x, rtol=0, atol=1e-14)
    np.testing.assert_allclose(model.velocities(q, u, p), v, rtol=0, atol=1e-13)
    # A rigid start (scene velocity and spin only): every particle is at rest in T.
    assert np.abs(u[6:]).max() <= 1e-13


# ------------------------------------------------------------ equations of motion
def particle_accelerations(model, q, u, p, held):
    """Particle accelerations in N (n, 3) and contact forces (nc,) of a model at a state.

    The gap of a ground with normal e_k is a particle's k-th coordinate; its second time
    derivative, ``gap_jacobian @ u' + gap_bias``, is that particle's acceleration along e_k.
    """
    ydot, lam = model.rhs(np.concatenate([q, u, [0, 0]]), p, held, np.zeros(model.n_contacts))
    udot = ydot[model.nq : model.nq + model.nu]
    names = list(model.p_names)
    out = []
    for axis in range(3):
        pa = p.copy()
        for k, a in enumerate("xyz"):
            pa[names.index(f"n0_{a}")] = float(k == axis)
            pa[names.index(f"P0_{a}")] = 0.0
        out.append(model.gap_jacobian(q, pa) @ udot + model.gap_bias(q, u, pa))
    return np.column_stack(out), lam


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.slow  # four whole-scene derivations (45 s with a cold cache)
def test_floating_and_particles_give_the_same_accelerations_and_contact_forces(models, shape, rng):
    scene = space_scene(shape)
    particles, floating = models[shape, "particles"], models[shape, "floating"]
    p = floating.parameters(scene)
    q0, u0 = initial_coordinates(scene, floating)
    for trial in range(4):
        q = q0 + 0.01 * rng.standard_normal(floating.nq)
        u = u0 + rng.standard_normal(floating.nu)
        M = floating.mass_matrix(q, p)
        np.testing.assert_allclose(M, M.T, rtol=0, atol=1e-15 * np.abs(M).max())
        assert np.linalg.eigvalsh(M).min() > 0  # the gauge removes all six rigid motions
        x, v = floating.positions(q, p).ravel(), floating.velocities(q, u, p).ravel()
        held = (np.arange(floating.n_contacts) % 3 == trial % 3).astype(int)
        for contacts in (np.zeros_like(held), held):
            got, lam_f = particle_accelerations(floating, q, u, p, contacts)
            expected, lam_p = particle_accelerations(particles, x, v, p, contacts)
            assert np.abs(got - expected).max() <= 1e-10 * np.abs(expected).max()
            assert np.abs(lam_f - lam_p).max() <= 1e-10 * max(np.abs(lam_p).max(), 1e-300)
        assert np.abs(lam_p).max() > 0  # the held contacts did push


@pytest.mark.slow  # a whole-scene derivation and its compile (12 s with a cold cache; the fixture's model)
@needs_cc
def test_a_3d_drop_gives_the_same_events_and_motion_in_both_formulations():
    scene = space_scene("tetrahedron")
    runs = {f: flexbody.simulate(scene, formulation=f, backend="c", method="dopri5", rtol=1e-10, atol=1e-12)
            for f in ("particles", "floating")}
    a, b = runs["particles"], runs["floating"]
    assert a.success and b.success, (a.message, b.message)
    assert len(a.events_kind) >= 2  # it lands
    assert list(a.events_kind) == list(b.events_kind) and list(a.events_particle) == list(b.events_particle)
    assert np.abs(a.events_time - b.events_time).max() <= 1e-7
    assert np.abs(a.positions - b.positions).max() <= 1e-7


# --------------------------------------------------------------------- gimbal lock
@pytest.mark.slow  # four whole-scene derivations (45 s with a cold cache)
def test_the_mass_matrix_is_singular_only_at_the_gimbal_lock(models):
    """beta = +-90 deg: the angles' rates no longer span every spin, so M loses rank."""
    scene, model = space_scene("tetrahedron"), models["tetrahedron", "floating"]
    p = model.parameters(scene)
    q, _ = initial_coordinates(scene, model)
    beta = model.q_names.index("beta0")
    for angle, singular in ((0.0, False), (np.radians(80.0), False), (np.pi / 2, True), (-np.pi / 2, True)):
        q[beta] = angle
        eig = np.linalg.eigvalsh(model.mass_matrix(q, p))
        assert (eig.min() <= 1e-12 * eig.max()) == singular, (angle, eig.min() / eig.max())


@pytest.mark.slow  # four whole-scene derivations (45 s with a cold cache)
def test_a_body_starting_at_the_gimbal_lock_is_refused(models):
    """Turn the tetrahedron so that T's z-axis is N's x-axis: a clear error, not a bad run."""
    points, _ = tetrahedron()
    R0, _ = gauge_frame(points, np.zeros_like(points), gauge_particles(points))
    axis = np.cross(R0[:, 2], [1.0, 0.0, 0.0])
    turn = np.arcsin(np.linalg.norm(axis)) if R0[0, 2] >= 0 else np.pi - np.arcsin(np.linalg.norm(axis))
    rotation = axis / np.linalg.norm(axis) * turn
    scene = space_scene("tetrahedron", rotation=rotation.tolist())
    R = rotation_matrix(rotation)
    np.testing.assert_allclose(R @ R0[:, 2], [1.0, 0.0, 0.0], atol=1e-12)
    with pytest.raises(InputError, match=r"body 'b'.*starts with its z-axis [-0-9.e]+ deg from N's x-axis.*particles"):
        initial_coordinates(scene, models["tetrahedron", "floating"])


@pytest.mark.slow  # the box's whole-scene derivation and compile (38 s with a cold cache; the fixture's model)
@needs_cc
def test_a_body_tumbling_through_the_gimbal_lock_stops_with_blow_up():
    """The 2x2x2 box starts with T's angles (45, 0, 0) deg (T's y-axis is the face diagonal
    (0, 1, 1)/sqrt(2), see the gauge test); spun about that axis, T's z-axis reaches N's x-axis
    after a quarter turn: M is singular there, and the run stops with blow_up naming the lock, having
    matched the particles formulation until then."""
    spin = 2.0
    axis = np.array([0.0, 1.0, 1.0]) / np.sqrt(2.0)
    points, links = cube()
    scene = make_scene(body(particles=points.tolist(), links=links, mass=0.1, stiffness=3000.0, damping=0.3,
                            damper="axial", position=[0.0, 0.0, 0.3], angular_velocity=(spin * axis).tolist()),
                       gravity=[0.0, 0.0, 0.0], grounds=[{"point": [0.0, 0.0, -10.0], "normal": [0.0, 0.0, 1.0]}],
                       simulation={"t_end": 1.5, "output_dt": 1e-3})
    q, _ = initial_coordinates(scene, load_derived_model(scene, "numpy", "floating"))
    np.testing.assert_allclose(q[3:6], [np.pi / 4, 0.0, 0.0], atol=1e-14)
    runs = {f: flexbody.simulate(scene, formulation=f, backend="c", method="dopri5", rtol=1e-8, atol=1e-10)
            for f in ("particles", "floating")}
    a, b = runs["particles"], runs["floating"]
    assert a.success
    # M's factorisation fails or the steps collapse first, by rounding (machine): the same lock
    assert b.status == "blow_up" and "body 'b' reached its frame T's gimbal lock" in b.message
    beta = float(re.search(r"beta = (-?[0-9.]+) deg", b.message).group(1))
    assert abs(abs(beta) - 90.0) < GIMBAL_LOCK_DEG
    assert abs(b.t[-1] - np.pi / 2 / spin) <= 1e-3
    assert np.abs(a.positions[: len(b.t)] - b.positions).max() <= 1e-8


@pytest.mark.parametrize("beta_deg, locked", [(89.5, True), (-90.4, True), (269.5, True), (88.0, False),
                                              (95.0, False), (30.0, False)])
def test_only_a_beta_within_a_degree_of_the_lock_is_reported_as_the_lock(beta_deg, locked):
    """_gimbal_lock names the body whose beta is within GIMBAL_LOCK_DEG of +-90 deg (mod 180),
    and leaves any other failure as it was (a body past the lock at 95 deg is not at it)."""
    from types import SimpleNamespace

    from flexbody.driver import _gimbal_lock

    model = SimpleNamespace(q_names=("X0", "Y0", "Z0", "alpha0", "beta0", "gamma0", "alpha1", "beta1", "gamma1"))
    scene = SimpleNamespace(bodies=[SimpleNamespace(name="first"), SimpleNamespace(name="second")])
    y = np.zeros(len(model.q_names))
    y[7] = np.radians(beta_deg)
    wrapped = SimpleNamespace(inner=model)  # as the body-contact model wraps a derived one
    for m in (model, wrapped):
        found = _gimbal_lock(scene, m, y, 1.25)
        assert (found is not None) == locked
        if locked:
            assert found[0] == "blow_up" and "body 'second' reached its frame T's gimbal lock" in found[1]
            assert "t = 1.25 s" in found[1]


def test_a_frame_starting_at_its_gimbal_lock_is_refused_with_advice():
    """T's x-axis along N's z and its x-y plane through N's y put T's z-axis on N's x-axis:
    the lock.  A flexible body may turn or take the particles formulation (a rigid body's T
    starts along N's axes instead, whatever its pose: tests/test_rigid.py)."""
    from flexbody.state import _floating_3d

    x = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
    with pytest.raises(InputError, match="gimbal lock") as error:
        _floating_3d(x, np.zeros_like(x), (0, 1, 2), "b")
    assert "particles formulation" in str(error.value) and "rotate the body" in str(error.value)
