"""The assembled particles formulation against the whole-scene derivation (the oracle).

The element kernels are derived once and assembled over a scene's index arrays at run
time; the whole-scene Kane derivation of the same topology must give the same
equations: accelerations, contact forces, normal velocities, impacts, energies, gaps
and Jacobians, at random states, to 1e-12 relative.  Also: a never-seen topology runs at
once (nothing derived or compiled), and a 400-particle ring lands cleanly.
"""

from __future__ import annotations

import numpy as np
import pytest

import flexbody
from flexbody.assembly import assembled_model
from flexbody.dynamics import state_jacobian
from flexbody.model import NumpyModel, load_derived_model
from flexbody.paths import cache_root
from flexbody.state import initial_coordinates

from .conftest import BACKENDS, HAS_CC, body, make_scene

RTOL = 1e-12


def random_scene(seed: int, dim: int = 2) -> flexbody.Scene:
    """A random topology: 1-2 bodies of 2-6 particles (2-5 in 3D), random links and damper
    laws, 1-2 grounds (the second tilted), gravity off the axes."""
    rng = np.random.default_rng(seed + 1000 * dim)
    bodies = []
    for b in range(rng.integers(1, 3)):
        n = int(rng.integers(2, 7 if dim == 2 else 6))
        points = rng.uniform(-0.2, 0.2, (n, dim))
        links = {(int(rng.integers(0, i)), i) for i in range(1, n)}  # a spanning tree: no lone particle
        links |= {tuple(sorted(map(int, rng.choice(n, 2, replace=False)))) for _ in range(rng.integers(0, n))}
        position = [float(b), 1.0] + [0.5] * (dim - 2)
        bodies.append(body(name=f"b{b}", particles=points.tolist(), links=sorted(map(list, links)),
                           masses=rng.uniform(0.02, 0.2, n).tolist(), mass=None,
                           stiffness=rng.uniform(100, 3000, len(links)).tolist(),
                           damping=rng.uniform(0.0, 0.3, len(links)).tolist(),
                           damper=str(rng.choice(["relative", "axial"])), position=position))
    up = [0.0] * dim
    up[1 if dim == 2 else 2] = 1.0
    grounds = [{"point": [0.0] * dim, "normal": up}]
    if rng.random() < 0.6:
        tilted = rng.normal(size=dim) * 0.4
        tilted[1 if dim == 2 else 2] = 1.0
        below = [0.0] * dim
        below[1 if dim == 2 else 2] = -2.0  # under every body, whatever the tilt
        grounds.append({"point": below, "normal": tilted.tolist()})
    gravity = [float(rng.normal()), -9.81] if dim == 2 else [float(rng.normal()), float(rng.normal()), -9.81]
    return make_scene(*bodies, grounds=grounds, gravity=gravity)
def derived_oracle(scene, tmp_path) -> NumpyModel:
    """The whole-scene particles model of ``scene``, derived and rendered here (SymPy)."""
    from derivation.codegen import render
    from derivation.mechanics import derive
    from derivation.writer import write_model

    folder = tmp_path / "oracle"
    write_model(render(derive(scene.topology(), "particles"), source="test", command="test"), folder)
    return NumpyModel(folder)


def random_state(model, rng, scene):
    x = scene.initial_positions() + rng.normal(0, 0.01, (scene.n_particles, scene.dim))
    v = rng.normal(0, 1.0, (scene.n_particles, scene.dim))
    return np.concatenate([x.ravel(), v.ravel(), [0.3, 0.1]])


def assert_close(a, b, what):
    a, b = np.asarray(a, float), np.asarray(b, float)
    scale = max(float(np.abs(b).max(initial=0.0)), 1e-300)
    np.testing.assert_allclose(a, b, rtol=0, atol=RTOL * scale, err_msg=what)


def assert_same_equations(assembled, oracle, scene, rng, states=5):
    p = assembled.parameters(scene)
    np.testing.assert_array_equal(p, oracle.parameters(scene))  # the same parameter order
    nc = assembled.n_contacts
    for _ in range(states):
        y = random_state(assembled, rng, scene)
        held = (rng.random(nc) < 0.4).astype(np.intc)
        if assembled.n_grounds > 1:  # at most one held ground per particle unless they are independent
            held.reshape(-1, assembled.n_grounds)[:, 1:] &= rng.random((scene.n_particles, 1)) < 0.5
        push = np.where(rng.random(nc) < 0.3, rng.uniform(0, 5, nc), 0.0) * (1 - held)
        for name, a, b in zip(("ydot", "lam"), assembled.rhs(y, p, held, push), oracle.rhs(y, p, held, push)):
            assert_close(a, b, name)
        for name, a, b in zip(("gaps", "vn", "lam"), assembled.contact_state(y, p, held, push),
                              oracle.contact_state(y, p, held, push)):
            assert_close(a, b, name)
        stop = (rng.random(nc) < 0.5).astype(np.intc)
        (ya, la), (yb, lb) = assembled.impact(y, p, stop), oracle.impact(y, p, stop)
        assert_close(ya, yb, "impact state")
        assert la == pytest.approx(lb, rel=1e-12, abs=1e-15)
        Xa, Va, Ea, lam_a = assembled.trajectory(y[None], p, held[None], push[None])
        Xb, Vb, Eb, lam_b = oracle.trajectory(y[None], p, held[None], push[None])
        for name, a, b in (("positions", Xa, Xb), ("velocities", Va, Vb), ("energies", Ea, Eb), ("lam", lam_a, lam_b)):
            assert_close(a, b, name)
        jac = assembled.jacobian_function(p, held)(0.0, y).toarray()
        assert_close(jac, state_jacobian(oracle, y, p, held), "state Jacobian")


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name", ["thesis_ball", "dumbbell"])
def test_assembled_equals_derived_for_bundled_scenes(name, backend, rng):
    scene = flexbody.load_scene(name)
    assert_same_equations(assembled_model(scene, backend), load_derived_model(scene, "numpy", "particles"), scene, rng)


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("seed", [0, 1] + [pytest.param(s, marks=pytest.mark.slow) for s in (2, 3, 4)])
def test_assembled_equals_derived_for_random_topologies(seed, dim, tmp_path, rng):
    scene = random_scene(seed, dim)
    assert scene.dim == dim
    oracle = derived_oracle(scene, tmp_path)
    for backend in BACKENDS:
        assert_same_equations(assembled_model(scene, backend), oracle, scene, rng, states=3)


@pytest.mark.skipif(not HAS_CC, reason="no C compiler")
def test_c_kernels_equal_numpy_kernels(rng):
    """The batched C kernels and their NumPy twins agree on random elements."""
    import ctypes

    from flexbody import runtime
    from flexbody.assembly import _kernels_module

    kernels, lib = _kernels_module(), runtime.library()
    for d in (2, 3):
        for law in ("relative", "axial"):
            m = 7
            xi, xj, vi, vj = (rng.normal(size=(m, d)) for _ in range(4))
            par = np.column_stack([rng.uniform(1, 10, m), rng.uniform(0, 1, m), rng.uniform(0.1, 1, m)])
            force, power = np.empty((m, d)), np.empty((m, 1))
            fn = getattr(lib, f"fb_kb_link_{law}_{d}d_force")
            fn.argtypes = [ctypes.c_long] + [ctypes.c_void_p] * 7
            fn(m, *(a.ctypes.data for a in (xi, xj, vi, vj, par, force, power)))
            f_np, p_np = getattr(kernels, f"link_{law}_{d}d_force")(xi.T, xj.T, vi.T, vj.T, par.T)
            np.testing.assert_allclose(force, f_np.T, rtol=1e-14)
            np.testing.assert_allclose(power[:, 0], p_np[0], rtol=1e-14)


def test_ground_tangents_are_an_orthonormal_basis(rng):
    """The ground kernel's normal and tangents form an orthonormal (right-handed in 3D) basis,
    also for normals along -z, where the branch-free formula switches sign."""
    from flexbody.assembly import _kernels_module

    kernels = _kernels_module()
    normals = np.vstack([rng.normal(size=(50, 3)), [[0, 0, -1.0], [0, 0, 1.0], [1.0, 0, 0], [0, 1e-30, -1]]])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    _, _, normal, tangents = kernels.ground_3d(np.zeros((3, len(normals))), np.zeros((3, len(normals))), normals.T)
    basis = np.stack([tangents[0], tangents[1], normal])  # (3, 3, m): rows t1, t2, n
    for k in range(len(normals)):
        B = basis[:, :, k]
        np.testing.assert_allclose(B @ B.T, np.eye(3), atol=1e-14)
        assert np.linalg.det(B) == pytest.approx(1.0, abs=1e-14)
    _, _, normal2, tangents2 = kernels.ground_2d(np.zeros((2, 1)), np.zeros((2, 1)), np.array([[0.6], [0.8]]))
    # exactly the normal turned by 90 degrees; summed in Python (NumPy's dot may fuse a
    # multiply-add, leaving 0.48's rounding error, 2.7e-17, on some machines)
    (tx, ty), (nx, ny) = tangents2[0, :, 0].tolist(), normal2[:, 0].tolist()
    assert (tx, ty) == (-ny, nx) and tx * nx + ty * ny == 0.0


def test_a_never_seen_topology_runs_without_deriving(tmp_path, monkeypatch):
    """A 37-particle ring nobody has derived: it runs at once, and no model is derived or cached."""
    monkeypatch.setenv("FLEXBODY_CACHE", str(tmp_path / "cache"))
    scene = make_scene(body(particles=None, links=None, shape="ring", count=36, radius=0.1, center=True,
                            mass=0.02, position=[0.0, 0.2]), simulation={"t_end": 0.05, "output_dt": 1e-3})
    result = flexbody.simulate(scene, backend=BACKENDS[-1])
    assert result.success, result.message
    assert not (cache_root() / "models").exists()
    assert result.stats["model"] == "assembled"


def test_a_400_particle_ring_lands_and_lifts_off_cleanly():
    """A ring of 399 perimeter particles and a centre lands flat-ish: no penetration, the
    energy ledger closed, and it runs until its first lift-off."""
    scene = make_scene(body(particles=None, links=None, shape="ring", count=399, radius=0.5, center=True,
                            mass=0.01, stiffness=2000.0, damping=0.05, position=[0.0, 0.52]),
                       simulation={"t_end": 0.2, "output_dt": 1e-3})
    result = flexbody.simulate(scene, backend=BACKENDS[-1])
    assert result.success, result.message
    kinds = list(result.events_kind)
    assert "impact" in kinds and "liftoff" in kinds, "the ring must touch down and lift off within 0.2 s"
    # "No penetration" is the event tolerance, 1e-12 of the scene's size (here 1.02 m), below
    # where a contact was released, which round-off may put a few ulps under the ground.
    size = max(1.0, float(np.abs(scene.initial_positions()).max()))
    tolerance = 1e-12 * size + 64 * np.finfo(float).eps * size
    assert result.stats["max_penetration_m"] <= tolerance
    assert result.positions[:, :, 1].min() >= -tolerance
    total = result.total_energy
    assert np.abs(total - total[0]).max() <= 1e-5 * abs(total[0])


@pytest.mark.skipif(not HAS_CC, reason="no C compiler")
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("seed", [0, 1])
def test_one_contact_alone_equals_the_whole_system_and_reads_only_its_stencil(seed, dim, rng):
    """Event location and event instants evaluate one contact from its particle's stencil:
    its gap, normal velocity and held force must equal contact_state's and rhs's bit for bit
    (else a root and the step's end disagree), and every entry outside the stencil may be
    garbage."""
    scene = random_scene(seed, dim)
    model = assembled_model(scene, "c")
    p, nc, G = model.parameters(scene), model.n_contacts, model.n_grounds
    links = np.asarray(model.links)
    for _ in range(3):
        y = random_state(model, rng, scene)
        held = (rng.random(nc) < 0.5).astype(np.intc)
        if G > 1:
            held.reshape(-1, G)[:, 1:] &= rng.random((scene.n_particles, 1)) < 0.5
        push = np.where(rng.random(nc) < 0.3, rng.uniform(0, 5, nc), 0.0) * (1 - held)
        gaps, vn, lam = model.contact_state(y, p, held, push)
        np.testing.assert_array_equal(lam, model.rhs(y, p, held, push)[1])
        for c in range(nc):
            i = c // G
            gap, vn_c, lam_c, entries = model.contact(y, p, held, push, c)
            assert (gap, vn_c, lam_c) == (gaps[c], vn[c], lam[c]), f"contact {c}"
            neighbours = {i} | {int(j) for a, b in links for j in (a, b) if i in (a, b)}
            expected = {k for j in neighbours for k in range(dim * j, dim * j + dim)}
            expected |= {dim * scene.n_particles + k for k in expected}  # their velocities
            assert set(entries.tolist()) == expected
            assert entries[:dim].tolist() == list(range(dim * i, dim * i + dim))  # its position first
            garbage = np.full_like(y, np.nan)
            garbage[entries] = y[entries]
            assert model.contact(garbage, p, held, push, c)[:3] == (gap, vn_c, lam_c)


@pytest.mark.skipif(not HAS_CC, reason="no C compiler")
@pytest.mark.parametrize("dim", [2, 3])
def test_threads_change_no_bit_of_a_large_bodys_equations(dim, rng):
    """A body of more than 2 x 4096 links splits the right-hand side's link loop over two
    threads (where the compiler has OpenMP): its accelerations, held forces and damping power
    must equal one thread's bit for bit, each held contact's force must equal the one
    evaluated alone (event location's), and the NumPy twin's to 1e-12."""
    from flexbody import cbuild
    from flexbody.bench_scale import cube_scene_table, disc_scene_table

    table = disc_scene_table(3000) if dim == 2 else cube_scene_table(1000)
    table["bodies"][0]["damper"] = "relative" if dim == 2 else "axial"
    scene = flexbody.load_scene(table)
    model, twin = assembled_model(scene, "c"), assembled_model(scene, "numpy")
    assert len(model.links) >= 2 * 4096
    p, nc = model.parameters(scene), model.n_contacts
    y = random_state(model, rng, scene)
    held = (rng.random(nc) < 0.05).astype(np.intc)
    push = np.where(rng.random(nc) < 0.05, rng.uniform(0, 5, nc), 0.0) * (1 - held)
    model.use_threads(1)
    one = model.rhs(y, p, held, push)
    assert model.threads == 1
    model.use_threads(2)
    two = model.rhs(y, p, held, push)
    if cbuild.OPENMP in cbuild.flags(cbuild.compiler()):
        assert model.threads == 2
    np.testing.assert_array_equal(two[0], one[0])
    np.testing.assert_array_equal(two[1], one[1])
    for c in np.flatnonzero(held)[:40]:
        assert model.contact(y, p, held, push, int(c))[2] == two[1][c], f"contact {c}"
    expected = twin.rhs(y, p, held, push)
    assert_close(two[0], expected[0], "right-hand side")
    assert_close(two[1], expected[1], "held forces")


@pytest.mark.skipif(not HAS_CC, reason="no C compiler")
def test_scipy_steppers_run_a_large_bodys_rhs_on_one_thread_and_restore_its_limit(monkeypatch):
    """With SciPy's steppers the right-hand side is called from Python between other work, so
    the run uses one thread (a sleeping second one costs more to wake than it saves); the
    compiled loop keeps two where the compiler has OpenMP.  The same stepper on two threads
    (the switch bypassed) gives the same samples bit for bit, and after each run the
    model's thread limit is the caller's again."""
    import contextlib

    from flexbody import cbuild, driver
    from flexbody.bench_scale import disc_scene_table

    table = disc_scene_table(3000)
    table["simulation"] = {"t_end": 2e-3, "output_dt": 1e-3}
    scene = flexbody.load_scene(table)
    model = assembled_model(scene, "c")
    assert len(model.links) >= 2 * 4096
    two = 2 if cbuild.OPENMP in cbuild.flags(cbuild.compiler()) else 1
    model.use_threads(2)
    scipy = flexbody.simulate(scene, model=model, method="RK45", rtol=1e-8)
    assert scipy.success and scipy.stats["threads"] == 1
    assert model.use_threads(2) == 2  # the limit it had before the run
    compiled = flexbody.simulate(scene, model=model, method="dopri5", rtol=1e-8)
    assert compiled.success and compiled.stats["threads"] == two
    monkeypatch.setattr(driver, "_one_rhs_thread", lambda model, scipy_stepper: contextlib.nullcontext())
    threaded = flexbody.simulate(scene, model=model, method="RK45", rtol=1e-8)
    assert threaded.stats["threads"] == two
    np.testing.assert_array_equal(threaded.positions, scipy.positions)
    np.testing.assert_array_equal(threaded.velocities, scipy.velocities)

@pytest.mark.skipif(not HAS_CC, reason="no C compiler")
def test_whole_scene_models_have_no_per_contact_evaluation():
    """Contacts of the floating formulation couple through M: no per-contact shortcut."""
    scene = flexbody.load_scene("dumbbell")
    model = flexbody.load_model(scene, formulation="floating")
    y = np.concatenate([*initial_coordinates(scene, model), [0.0, 0.0]])
    nc = model.n_contacts
    assert model.contact(y, model.parameters(scene), np.zeros(nc, np.intc), np.zeros(nc), 0) is None


@pytest.mark.parametrize("backend", BACKENDS)
def test_settle_sets_a_stopped_particle_found_below_the_ground_onto_it(backend):
    """Event location stops a particle up to the gap tolerance below the ground; settling
    puts it on the ground (else every stop-release-stop cycle of a chattering particle starts
    the next a tolerance lower), moving it along the normal only, and leaves particles not
    stopped, or above the ground, where they are."""
    scene = make_scene(body(particles=[[0.0, 0.0], [0.3, 0.0], [0.6, 0.0]], links=[[0, 1], [1, 2]], mass=0.1,
                            position=[0.0, 0.0]),
                       grounds=[{"point": [0.0, 0.0], "normal": [0.3, 1.0]}])
    model = assembled_model(scene, backend)
    p = model.parameters(scene)
    normal = np.array([0.3, 1.0]) / np.hypot(0.3, 1.0)
    x = np.array([[0.0, 0.0], [0.3, 0.0], [0.6, 0.0]])
    x -= (x @ normal)[:, None] * normal  # all on the ground ...
    x += np.array([-3e-12, -2e-12, 5e-13])[:, None] * normal  # ... then two below, one above
    y = np.concatenate([x.ravel(), [0.1, -1.0, 0.2, -0.5, 0.0, -0.3], [0.0, 0.0]])
    out = model.settle(y, p, np.array([1, 0, 1], np.intc))
    gaps, before = model.gaps(out[: model.nq], p), model.gaps(y[: model.nq], p)
    assert abs(gaps[0]) <= 1e-16  # stopped and below: set on the ground
    assert gaps[1] == before[1]  # below but not stopped: not this instant's business
    assert gaps[2] == before[2]  # stopped above the ground: not moved
    np.testing.assert_array_equal(out[6:], y[6:])  # velocities untouched
    moved = out[:2] - y[:2]
    assert abs(moved @ np.array([-normal[1], normal[0]])) <= 1e-20  # along the normal only
