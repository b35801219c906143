"""The 3D benchmark pieces: the scale study's cubes, and the MuJoCo model of a 3D scene
(the MuJoCo tests are skipped unless ``flexbody[mujoco]`` is installed)."""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest

import flexbody
from flexbody.bench_scale import SPACING, cube_scene_table

from .conftest import needs_cc


def _fastest_mode(scene: flexbody.Scene) -> float:
    """Highest angular frequency (rad/s) of the scene's spring network linearised at rest,
    assembled here independently of the runtime: K = sum k e e^T per link, M = diag(m)."""
    x = scene.initial_positions()
    n, d = x.shape
    K = np.zeros((n * d, n * d))
    stiffness = np.concatenate([b.stiffness for b in scene.bodies])
    for (i, j), k in zip(scene.links(), stiffness):
        e = (x[j] - x[i]) / np.linalg.norm(x[j] - x[i])
        block = k * np.outer(e, e)
        for a, b, sign in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
            K[a * d:(a + 1) * d, b * d:(b + 1) * d] += sign * block
    m = np.repeat(scene.masses, d)
    return float(np.sqrt(np.linalg.eigvalsh(K / np.sqrt(np.outer(m, m))).max()))


def test_scale_cubes_start_on_a_corner_0_3_m_up_on_the_disc_lattice():
    for count, side in ((23, 3), (100, 5), (1000, 10)):
        scene = flexbody.load_scene(cube_scene_table(count))
        x = scene.initial_positions()
        assert scene.dim == 3 and scene.n_particles == side**3
        assert x[:, 2].min() == pytest.approx(0.3, abs=1e-12)
        assert np.sum(np.isclose(x[:, 2], x[:, 2].min(), atol=1e-9)) == 1  # one corner lands first
        nearest = np.sort(np.linalg.norm(x[1:] - x[0], axis=1))[0]
        assert nearest == pytest.approx(SPACING, rel=1e-12)


def test_scale_cubes_keep_their_fastest_mode_below_the_infinite_lattice_bound():
    """The study's premise: the explicit step, held by the fastest mode, does not shrink with
    size (a spoked sphere's centre mode would grow as the square root of the spokes).

    A finite cube's spring energy is the infinite braced lattice's, less the cut links, so
    its fastest mode is below the lattice's, whose Bloch wave along a lattice axis with
    wavenumber pi/spacing has omega^2 = (4 + 8 + 16/3) k/m: the 2 axis neighbours along it,
    the 8 face diagonals and 8 body diagonals that cross a plane of it, each contributing
    2 k/m times the squared cosine of its angle with that axis."""
    bound = np.sqrt(52.0 / 3.0 * 2000.0 / 0.05)
    modes = [_fastest_mode(flexbody.load_scene(cube_scene_table(m**3))) for m in (3, 4, 6)]
    assert modes == sorted(modes)  # it grows with size, ...
    assert modes[-1] < bound  # ... but never past the infinite lattice's


#: The MuJoCo tests need the optional extra; the tests above do not.
needs_mujoco = pytest.mark.skipif(importlib.util.find_spec("mujoco") is None,
                                  reason="MuJoCo is not installed (pip install 'flexbody[mujoco]')")


def _model(scene: flexbody.Scene, timestep: float = 1e-4):
    import mujoco

    from flexbody.mujoco_compare import mjcf

    model = mujoco.MjModel.from_xml_string(mjcf(scene, timestep))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    return model, data


@needs_mujoco
def test_mujoco_model_of_a_3d_scene_has_its_particles_links_and_ground():
    import mujoco

    scene = flexbody.load_scene("sphere_drop")  # tilted ground: the plane must follow it
    model, data = _model(scene)
    (body,) = scene.bodies
    links = scene.links()
    x = scene.initial_positions()
    assert model.nbody - 1 == scene.n_particles and model.nv == 3 * scene.n_particles
    assert model.body_mass[1:].sum() == pytest.approx(scene.masses.sum(), rel=1e-12)
    np.testing.assert_allclose(model.body_mass[1:], scene.masses, rtol=1e-12)
    assert model.ntendon == len(links)
    np.testing.assert_allclose(model.tendon_lengthspring[:, 0], body.rest_lengths, rtol=1e-12)
    np.testing.assert_allclose(model.tendon_stiffness, body.stiffness, rtol=1e-12)
    np.testing.assert_allclose(model.tendon_damping, body.damping, rtol=1e-12)
    # where MuJoCo puts the particles: their sites, and so the tendons' lengths
    np.testing.assert_allclose(data.site_xpos, x, atol=1e-12)
    np.testing.assert_allclose(data.ten_length, np.linalg.norm(x[links[:, 1]] - x[links[:, 0]], axis=1), rtol=1e-12)
    (ground,) = scene.grounds
    plane = int(np.flatnonzero(model.geom_type == mujoco.mjtGeom.mjGEOM_PLANE)[0])
    normal = data.geom_xmat[plane].reshape(3, 3)[:, 2]
    np.testing.assert_allclose(normal, ground.normal, atol=1e-12)
    # a particle sphere touches the plane exactly when the particle reaches the ground
    from flexbody.mujoco_compare import SPHERE_RADIUS

    assert (np.asarray(ground.point) - data.geom_xpos[plane]) @ normal == pytest.approx(SPHERE_RADIUS, abs=1e-15)


@needs_mujoco
@needs_cc
def test_mujoco_spinning_sphere_in_free_flight_converges_to_flexbody_at_first_order():
    """A spinning sphere stretches its springs (about 1.3 mm, more than MuJoCo's error): with
    the right masses, stiffness, rest lengths and initial velocities MuJoCo's error halves
    with its step; 10 % off in the stiffness stops it halving (ratio about 1.4)."""
    from flexbody.mujoco_compare import run

    scene = flexbody.load_scene({
        "name": "spinning_sphere", "gravity": [0.0, 0.0, -9.81],
        "bodies": [{"name": "ball", "shape": "sphere", "count": 30, "radius": 0.1, "center": True, "mass": 0.05,
                    "stiffness": 2000.0, "damping": 0.5, "damper": "axial", "position": [0.0, 0.0, 1.0],
                    "velocity": [0.3, 0.0, 0.5], "angular_velocity": [5.0, 0.0, 20.0]}],
        "simulation": {"t_end": 0.2, "output_dt": 1e-4}})  # no impact before 0.2 s
    ours = flexbody.simulate(scene, method="dop853", rtol=1e-10, atol=1e-13)
    assert ours.stats["events"] == 0
    errors = []
    for dt in (2e-4, 1e-4):
        m = run(scene, dt, repeats=1)
        assert m["diverged_at_s"] is None
        reference = np.stack([[np.interp(m["t"], ours.t, ours.positions[:, i, d]) for d in range(3)]
                              for i in range(scene.n_particles)]).transpose(2, 0, 1)
        errors.append(np.abs(m["positions"] - reference).max())
    assert errors[1] < 1e-3
    assert 1.8 < errors[0] / errors[1] < 2.2
