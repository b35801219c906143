"""3D bodies: simultaneous landings, frame invariance, the planar case embedded in space,
modal frequencies, angular momentum, the mesh reader and bad input."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import flexbody
from flexbody.scene import SceneError, rotation_matrix

from .conftest import body, make_scene

G = 9.81
TIGHT = dict(rtol=1e-10, atol=1e-12)


def space_scene(*bodies, **top):
    top.setdefault("gravity", [0.0, 0.0, -G])
    return make_scene(*bodies, **top)


def landing(points, links, height, **options):
    """A body of unit-mass particles, its lowest face ``height`` above z = 0, dropped from rest."""
    points = np.asarray(points, float)
    table = body(particles=points.tolist(), links=links, mass=1.0, stiffness=5000.0, damping=0.5,
                 position=[0.0, 0.0, height - points[:, 2].min()])
    return flexbody.simulate(space_scene(table, simulation={"t_end": 0.5, "output_dt": 1e-3}), **options)


@pytest.mark.parametrize("shape", ["tetrahedron", "cube"])
def test_a_face_lands_flat_all_at_once(shape):
    """A regular tetrahedron (3 corners) and a cube (4 corners) on a face hit together at
    sqrt(2 h / g), symmetrically, without penetration."""
    if shape == "tetrahedron":
        bottom = [[np.cos(a), np.sin(a), 0.0] for a in 2 * np.pi * np.arange(3) / 3]
        points = np.array(bottom + [[0.0, 0.0, np.sqrt(2.0)]]) * 0.1
        links = [[i, j] for i in range(4) for j in range(i + 1, 4)]
        n_bottom = 3
    else:
        from flexbody.presets import box

        points, links = box((2, 2, 2), (0.1, 0.1, 0.1))
        links = [list(x) for x in links]
        n_bottom = 4
    height = 0.2
    r = landing(points, links, height, **TIGHT)
    assert r.success, r.message
    first = r.events_kind == "impact"
    t_hit = np.sqrt(2 * height / G)
    together = np.abs(r.events_time - t_hit) < 1e-9
    assert (first & together).sum() == n_bottom
    assert set(r.events_particle[first & together]) == set(np.flatnonzero(points[:, 2] == points[:, 2].min()))
    assert r.stats["max_penetration_m"] <= 1e-12
    # Symmetry: the landed corners stay at equal distances from their centroid.
    low = np.flatnonzero(points[:, 2] == points[:, 2].min())
    spread = np.linalg.norm(r.positions[:, low] - r.positions[:, low].mean(axis=1, keepdims=True), axis=2)
    assert np.abs(spread - spread[:, :1]).max() <= 1e-9


def test_a_rotated_scene_gives_the_rotated_trajectory():
    """Frame invariance: turn gravity, ground, particles and velocities by a random R, and the
    trajectory is R times the original one (to the integration tolerance)."""
    rng = np.random.default_rng(7)
    from flexbody.presets import box

    points, links = box((2, 2, 3), (0.1, 0.12, 0.2))
    velocities = rng.normal(0, 0.3, points.shape)
    R = rotation_matrix(rng.normal(size=3))

    def scene(Rm):
        table = body(particles=(points @ Rm.T).tolist(), links=[list(x) for x in links], mass=0.1,
                     stiffness=3000.0, damping=0.2, damper="axial", position=(Rm @ [0.0, 0.0, 0.3]).tolist(),
                     particle_velocities=(velocities @ Rm.T).tolist())
        return space_scene(table, gravity=(Rm @ [0.0, 0.0, -G]).tolist(),
                           grounds=[{"point": [0.0, 0.0, 0.0], "normal": (Rm @ [0.0, 0.0, 1.0]).tolist()}],
                           simulation={"t_end": 0.4, "output_dt": 1e-3})

    a = flexbody.simulate(scene(np.eye(3)), **TIGHT)
    b = flexbody.simulate(scene(R), **TIGHT)
    assert a.success and b.success
    assert list(a.events_kind) == list(b.events_kind) and list(a.events_particle) == list(b.events_particle)
    assert np.abs(a.events_time - b.events_time).max() <= 1e-8
    assert np.abs(a.positions @ R.T - b.positions).max() <= 1e-8


def test_a_planar_scene_in_the_z0_plane_of_space_gives_the_planar_run():
    """The thesis ball written in 3D (gravity along -y, ground y = 0, the ring in T's x-y
    plane, turned about z) has the 2D run's events and trajectory."""
    flat = flexbody.simulate("thesis_ball", t_end=1.0, **TIGHT)
    table = body(particles=None, links=None, shape="ring", count=22, radius=0.1, center=True, mass=0.05,
                 stiffness=2000.0, damping=0.5, position=[0.0, 0.5, 0.0], rotation=[0.0, 0.0, 0.05])
    space = make_scene(table, gravity=[0.0, -G, 0.0], grounds=[{"point": [0.0, 0.0, 0.0], "normal": [0.0, 1.0, 0.0]}],
                       simulation={"t_end": 1.0, "output_dt": 1e-3})
    r = flexbody.simulate(space, **TIGHT)
    assert r.success
    assert list(zip(r.events_particle, r.events_kind)) == list(zip(flat.events_particle, flat.events_kind))
    assert np.abs(r.events_time - flat.events_time).max() <= 1e-8
    assert np.abs(r.positions[:, :, :2] - flat.positions).max() <= 1e-8
    assert np.abs(r.positions[:, :, 2]).max() == 0.0


def stiffness_matrix(x, links, k):
    """The linear stiffness of a spring network at rest, K = sum_l k_l (e e^T) blocks, (3n, 3n)."""
    n = len(x)
    K = np.zeros((3 * n, 3 * n))
    for (i, j), kl in zip(links, k):
        e = (x[i] - x[j]) / np.linalg.norm(x[i] - x[j])
        block = kl * np.outer(e, e)
        for a, b, sign in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
            K[3 * a : 3 * a + 3, 3 * b : 3 * b + 3] += sign * block
    return K


def test_a_free_sphere_vibrates_at_its_network_frequencies():
    """A sphere of 30 particles with a centre, no gravity, no damping, started on its lowest
    elastic mode with a tiny amplitude: it vibrates at sqrt(lambda / m) of the network's
    linear analysis (an independent NumPy eigenproblem)."""
    from flexbody.presets import sphere

    m, k = 0.02, 2000.0
    points, links = sphere(30, 0.1, True)
    K = stiffness_matrix(points, links, [k] * len(links))
    values, vectors = np.linalg.eigh(K / m)
    elastic = np.flatnonzero(values > 1e-6 * values.max())
    assert len(values) - len(elastic) == 6  # three translations and three rotations
    mode = elastic[0]
    omega = np.sqrt(values[mode])
    shape = vectors[:, mode].reshape(-1, 3)
    amplitude = 1e-6
    table = body(particles=(points + amplitude * shape / np.abs(shape).max()).tolist(),
                 links=[list(x) for x in links], rest_lengths=[float(np.linalg.norm(points[i] - points[j]))
                                                              for i, j in links],
                 mass=m, stiffness=k, damping=0.0, position=[0.0, 0.0, 1.0])
    period = 2 * np.pi / omega
    scene = space_scene(table, gravity=[0.0, 0.0, 0.0], grounds=[{"point": [0, 0, -10.0], "normal": [0, 0, 1.0]}],
                        simulation={"t_end": 3 * period, "output_dt": period / 200})
    r = flexbody.simulate(scene, **TIGHT)
    assert r.success
    modal = np.einsum("tnd,nd->t", r.positions - r.positions[:, :, :].mean(axis=1, keepdims=True)
                      - (points - points.mean(axis=0)), shape) / np.sum(shape * shape)
    expected = modal[0] * np.cos(omega * r.t)
    assert np.abs(modal - expected).max() <= 2e-3 * np.abs(modal[0])


@pytest.mark.parametrize("damper, conserved", [("axial", True), ("relative", False)])
def test_axial_dampers_conserve_angular_momentum_and_relative_ones_drain_it(damper, conserved):
    """A free, spinning, vibrating box (no gravity): L = sum m x x v about the centre of mass
    is constant with axial dampers (central forces) and decays with relative ones."""
    from flexbody.presets import box

    points, links = box((2, 2, 2), (0.1, 0.15, 0.2))
    rng = np.random.default_rng(3)
    table = body(particles=(points + rng.normal(0, 0.005, points.shape)).tolist(), links=[list(x) for x in links],
                 rest_lengths=[float(np.linalg.norm(points[i] - points[j])) for i, j in links], mass=0.1,
                 stiffness=2000.0, damping=2.0, damper=damper, position=[0.0, 0.0, 1.0],
                 angular_velocity=[1.0, 2.0, 3.0])
    scene = space_scene(table, gravity=[0.0, 0.0, 0.0], grounds=[{"point": [0, 0, -10.0], "normal": [0, 0, 1.0]}],
                        simulation={"t_end": 0.5, "output_dt": 1e-3})
    r = flexbody.simulate(scene, **TIGHT)
    assert r.success
    x = r.positions - np.average(r.positions, axis=1, weights=r.masses)[:, None]
    L = np.einsum("n,tnd->td", r.masses, np.cross(x, r.velocities))
    change = np.linalg.norm(L - L[0], axis=1).max() / np.linalg.norm(L[0])
    if conserved:
        assert change <= 1e-8
    else:
        assert np.linalg.norm(L[-1]) < 0.9 * np.linalg.norm(L[0])


def test_the_mesh_reader_on_the_committed_icosahedron():
    """icosahedron.obj: 12 vertices and 30 edges, plus the centre and 12 spokes; a regular
    icosahedron's vertices share the surface equally, so mass_total spreads equally."""
    scene = flexbody.load_scene("icosahedron_drop")
    (ball,) = scene.bodies
    assert ball.n_particles == 13 and len(ball.links) == 42
    assert scene.masses.sum() == pytest.approx(0.65, rel=1e-14)
    np.testing.assert_allclose(scene.masses, 0.65 / 13, rtol=1e-12)
    radii = np.linalg.norm(ball.points[1:] - ball.points[0], axis=1)
    np.testing.assert_allclose(radii, 0.1, rtol=1e-12)


@pytest.mark.parametrize("name, text, message", [
    ("bad.obj", "this is not a mesh\n", "has no vertices"),
    ("bad.xyz", "1 2 3\n", "cannot be read as a mesh"),
    ("bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no triangles, quads or tetrahedra"),
    ("bad.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 0\nf 1 2 3\nf 4 2 3\n", "duplicate vertices"),
])
def test_a_bad_mesh_file_is_a_clear_error(tmp_path, name, text, message):
    (tmp_path / name).write_text(text)
    scene = tmp_path / "s.toml"
    scene.write_text(f'gravity = [0.0, 0.0, -9.81]\n[[bodies]]\nshape = "mesh"\nfile = "{name}"\nmass = 0.1\n'
                     'stiffness = 100.0\ndamping = 0.1\nposition = [0.0, 0.0, 1.0]\n[simulation]\nt_end = 0.1\n')
    with pytest.raises(SceneError, match=message):
        flexbody.load_scene(scene)
    out = tmp_path / "out"
    run = subprocess.run([sys.executable, "-m", "flexbody.cli", "run", str(scene), "--out", str(out)],
                         capture_output=True, text=True)
    assert run.returncode == 2 and message in run.stderr and "Traceback" not in run.stderr
    assert not out.exists()


@pytest.mark.parametrize("change, field, rule", [
    ({"gravity": [0.0, 0.0, -9.81, 0.0]}, "gravity", "2 (planar) or 3 (spatial)"),
    ({"bodies": [body(particles=[[0, 0], [0.1, 0]], position=[0, 0, 1.0])]}, "particles", "[x, y, z]"),
    ({"bodies": [body(particles=[[0, 0, 0], [0.1, 0, 0]], position=[0, 0, 1.0], angle=0.3)]}, "angle",
     "rotation = [rx, ry, rz]"),
    ({"gravity": [0.0, -9.81], "bodies": [body(rotation=[0, 0, 1.0])]}, "rotation", "in 2D give `angle`"),
    ({"gravity": [0.0, -9.81], "bodies": [body(particles=None, links=None, shape="sphere", count=10, radius=0.1)]},
     "shape", "needs a 3D scene"),
    ({"bodies": [body(particles=None, links=None, shape="mesh", file="missing.obj", position=[0, 0, 1.0])]},
     "file", "no such file"),
    ({"bodies": [body(particles=[[0, 0, 0], [0.1, 0, 0]], position=[0, 0, 1.0], angular_velocity=2.0)]},
     "angular_velocity", "3 finite numbers"),
])
def test_3d_input_mistakes_are_named(change, field, rule):
    table = {"gravity": [0.0, 0.0, -9.81], "bodies": [body(particles=[[0, 0, 0], [0.1, 0, 0]], position=[0, 0, 1.0])],
             "simulation": {"t_end": 0.1}}
    table.update(change)
    with pytest.raises(SceneError) as info:
        flexbody.load_scene(table)
    assert f"`{field}" in str(info.value) or f".{field}`" in str(info.value)
    assert rule in str(info.value)


def test_the_default_ground_faces_against_gravity():
    scene = space_scene(body(particles=[[0, 0, 0], [0.1, 0, 0]], position=[0, 0, 1.0]), gravity=[0.0, -3.0, -4.0])
    assert scene.grounds[0].normal == pytest.approx((0.0, 0.6, 0.8))


def test_the_bundled_sphere_drop_lands_without_penetration():
    r = flexbody.simulate("sphere_drop", t_end=0.5)
    assert r.success, r.message
    assert r.positions.shape[2] == 3 and r.stats["impacts"] > 0
    n = np.array([0.25881904510252074, 0.0, 0.9659258262890683])
    assert (r.positions @ n).min() >= -(1e-12 + 64 * np.finfo(float).eps)  # the event tolerance
    total = r.total_energy
    assert np.abs(total - total[0]).max() <= 1e-5 * abs(total[0])
