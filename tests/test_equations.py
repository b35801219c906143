"""Derived and generated equations against hand derivations, invariants and each other."""

from __future__ import annotations

import re

import numpy as np
import pytest

from flexbody.model import load_derived_model as load_model  # the whole-scene derivation
from flexbody.scene import load_scene
from flexbody.state import initial_coordinates

from .conftest import BACKENDS, body, make_scene


def random_state(model, scene, rng, scale=0.01):
    """A random state near the scene's initial one, shape (nq,), (nu,)."""
    q, u = initial_coordinates(scene, model)
    return q + scale * rng.standard_normal(model.nq), u + rng.standard_normal(model.nu)


def particle_accelerations(model, q, u, p, held=None):
    """Particle accelerations in N, shape (n, 2), from the model's contact kinematics.

    The gap of a ground with normal e_x (e_y) is a particle's x (y); its second time
    derivative, ``gap_jacobian @ u' + gap_bias``, is that particle's acceleration.
    """
    held = np.zeros(model.n_contacts, int) if held is None else held
    ydot, _ = model.rhs(np.concatenate([q, u, [0, 0]]), p, held, np.zeros(model.n_contacts))
    udot = ydot[model.nq : model.nq + model.nu]
    out = []
    for axis in (0, 1):
        pa = p.copy()
        pa[list(model.p_names).index("n0_x")] = 1.0 - axis
        pa[list(model.p_names).index("n0_y")] = float(axis)
        out.append(model.gap_jacobian(q, pa) @ udot + model.gap_bias(q, u, pa))
    return np.column_stack(out)


@pytest.mark.parametrize("backend", BACKENDS)
def test_one_particle_falls_with_gravity(backend):
    scene = make_scene(body(particles=[[0.0, 0.0]], links=[], stiffness=[], damping=[], mass=0.3),
                       gravity=[0.5, -9.81])
    model = load_model(scene, backend=backend, formulation="particles")
    p = model.parameters(scene)
    q, u = np.array([0.2, 1.0]), np.array([0.1, -2.0])
    np.testing.assert_allclose(model.mass_matrix(q, p), np.diag([0.3, 0.3]))
    np.testing.assert_allclose(model.forcing(q, u, p), [0.15, -0.3 * 9.81])
    T, V, G, P = model.energies(q, u, p)
    assert T == pytest.approx(0.5 * 0.3 * (0.01 + 4.0)) and V == 0 and P == 0
    assert G == pytest.approx(-0.3 * (0.5 * 0.2 - 9.81 * 1.0))


@pytest.mark.parametrize("damper", ["relative", "axial"])
@pytest.mark.parametrize("backend", BACKENDS)
def test_one_link_matches_hand_derivation(backend, damper, rng):
    m, k, c, L = np.array([0.05, 0.08]), 2000.0, 0.5, 0.25
    scene = make_scene(body(masses=m.tolist(), mass=None, stiffness=k, damping=c, damper=damper, rest_lengths=L))
    model = load_model(scene, backend=backend, formulation="particles")
    p = model.parameters(scene)
    for _ in range(5):
        x = rng.uniform(-1, 1, (2, 2))
        v = rng.uniform(-1, 1, (2, 2))
        d = x[0] - x[1]
        r = np.linalg.norm(d)
        e = d / r
        dv = v[1] - v[0]
        f_damp = c * dv if damper == "relative" else c * (dv @ e) * e
        f0 = k * (L - r) * e + f_damp  # thesis eq. 3.7 and 3.8, on particle 0
        g = np.array([0.0, -9.81])
        expected = np.concatenate([f0 + m[0] * g, -f0 + m[1] * g])
        np.testing.assert_allclose(model.forcing(x.ravel(), v.ravel(), p), expected, rtol=1e-13, atol=1e-12)
        np.testing.assert_allclose(model.mass_matrix(x.ravel(), p), np.diag(np.repeat(m, 2)), rtol=1e-15)
        T, V, G, P = model.energies(x.ravel(), v.ravel(), p)
        assert V == pytest.approx(0.5 * k * (r - L) ** 2, rel=1e-13)
        assert P == pytest.approx(c * (dv @ dv if damper == "relative" else (dv @ e) ** 2), rel=1e-13)
        assert G == pytest.approx(-(m @ (x @ g)), rel=1e-13)
        assert T == pytest.approx(0.5 * m @ (v**2).sum(axis=1), rel=1e-13)


@pytest.mark.parametrize("backend", BACKENDS)
def test_formulations_give_the_same_particle_accelerations(ball, ball_models, rng, backend):
    particles, floating = ball_models["particles", backend], ball_models["floating", backend]
    p = floating.parameters(ball)
    for trial in range(4):
        q, u = random_state(floating, ball, rng)
        x, v = floating.positions(q, p), floating.velocities(q, u, p)
        expected = particle_accelerations(particles, x.ravel(), v.ravel(), p)
        got = particle_accelerations(floating, q, u, p)
        assert np.abs(got - expected).max() <= 1e-10 * np.abs(expected).max()
        # and with contacts held, the same accelerations and contact forces
        held = (np.arange(floating.n_contacts) % 3 == trial % 3).astype(int)
        yq = np.concatenate([q, u, [0, 0]])
        yp = np.concatenate([x.ravel(), v.ravel(), [0, 0]])
        _, lam_f = floating.rhs(yq, p, held, np.zeros(floating.n_contacts))
        _, lam_p = particles.rhs(yp, p, held, np.zeros(particles.n_contacts))
        np.testing.assert_allclose(lam_f, lam_p, rtol=1e-9, atol=1e-10 * np.abs(lam_p).max())
        np.testing.assert_allclose(
            particle_accelerations(floating, q, u, p, held), particle_accelerations(particles, x.ravel(), v.ravel(), p, held),
            atol=1e-10 * np.abs(expected).max(),
        )


@pytest.mark.skipif("c" not in BACKENDS, reason="no C compiler")
@pytest.mark.parametrize("formulation", ["particles", "floating"])
def test_numpy_and_c_backends_agree(ball, ball_models, rng, formulation):
    c, py = ball_models[formulation, "c"], ball_models[formulation, "numpy"]
    p = c.parameters(ball)
    for _ in range(3):
        q, u = random_state(c, ball, rng)
        a = rng.standard_normal(c.nu)
        for name in ("mass_matrix", "forcing", "energies", "positions", "velocities", "gaps",
                     "gap_jacobian", "gap_bias", "particle_jacobian", "particle_bias", "jacobian_q", "jacobian_u"):
            x, y = c._call(name, q, u, p, a), py._call(name, q, u, p, a)
            assert np.abs(x - y).max() <= 1e-12 * max(1.0, np.abs(y).max()), name
        held = (rng.random(c.n_contacts) < 0.3).astype(int)
        push = np.where(rng.random(c.n_contacts) < 0.2, 1.5, 0.0)
        y = np.concatenate([q, u, [0, 0]])
        (dc, lc), (dn, ln) = c.rhs(y, p, held, push), py.rhs(y, p, held, push)
        assert np.abs(dc - dn).max() <= 1e-12 * np.abs(dn).max()
        assert np.abs(lc - ln).max() <= 1e-12 * max(1.0, np.abs(ln).max())


def test_batched_numpy_evaluation_matches_single(ball, ball_models, rng):
    model = ball_models["floating", "numpy"]
    p = model.parameters(ball)
    states = [random_state(model, ball, rng) for _ in range(3)]
    Q, U = np.column_stack([s[0] for s in states]), np.column_stack([s[1] for s in states])
    batch = model.module.energies(Q, U, p)
    for k, (q, u) in enumerate(states):
        np.testing.assert_allclose(batch[:, k], model.energies(q, u, p), rtol=1e-14)


def test_floating_mass_matrix_is_symmetric_positive_definite(ball, ball_models, rng):
    model = ball_models["floating", "numpy"]
    p = model.parameters(ball)
    for _ in range(5):
        q, _ = random_state(model, ball, rng, scale=0.05)
        q[2] = rng.uniform(-np.pi, np.pi)
        M = model.mass_matrix(q, p)
        np.testing.assert_allclose(M, M.T, atol=1e-15)
        assert np.linalg.eigvalsh(M).min() > 0
    diagonal = ball_models["particles", "numpy"].mass_matrix(np.zeros(46), p)
    np.testing.assert_array_equal(diagonal, np.diag(np.full(46, 0.05)))


@pytest.mark.parametrize("damper", ["relative", "axial"])
def test_internal_forces_sum_to_zero_and_axial_dampers_have_no_moment(damper, rng):
    scene = make_scene(body(particles=None, links=None, shape="ring", count=7, radius=0.1, center=True,
                            damper=damper), gravity=[0.0, 0.0])
    model = load_model(scene, backend="numpy", formulation="particles")
    p = model.parameters(scene)
    q, u = random_state(model, scene, rng, scale=0.02)
    f = model.forcing(q, u, p).reshape(-1, 2)
    x = q.reshape(-1, 2)
    assert np.abs(f.sum(axis=0)).max() < 1e-12 * np.abs(f).max()
    moment = np.sum(x[:, 0] * f[:, 1] - x[:, 1] * f[:, 0])
    if damper == "axial":
        assert abs(moment) < 1e-12 * np.abs(f).max()
    # A rigid spin omega at rest shape: axial dampers see no stretching rate, while relative
    # dampers (eq. 3.8) brake the spin with the torque -c omega sum(L^2) (not a central force).
    omega = 3.0
    x0 = scene.initial_positions()
    spin = omega * np.column_stack([-(x0[:, 1] - x0[:, 1].mean()), x0[:, 0] - x0[:, 0].mean()])
    f = model.forcing(x0.ravel(), spin.ravel(), p).reshape(-1, 2)
    moment = np.sum(x0[:, 0] * f[:, 1] - x0[:, 1] * f[:, 0])
    lengths = scene.bodies[0].rest_lengths
    expected = 0.0 if damper == "axial" else -0.5 * omega * np.sum(lengths**2)
    assert moment == pytest.approx(expected, abs=1e-12)


@pytest.mark.parametrize("formulation", ["particles", "floating"])
def test_spring_energy_gradient_is_minus_the_spring_forces(ball, ball_models, rng, formulation):
    model = ball_models[formulation, "numpy"]
    p = model.parameters(ball)
    p[[model.p_names.index(n) for n in model.p_names if n[0] == "c" or n.startswith("g_")]] = 0.0
    q, _ = random_state(model, ball, rng, scale=0.01)
    u = np.zeros(model.nu)  # no velocity terms: F is the generalized spring force alone
    F = model.forcing(q, u, p)
    h = 1e-6
    grad = np.array([
        (model.energies(q + h * e, u, p)[1] - model.energies(q - h * e, u, p)[1]) / (2 * h) for e in np.eye(model.nq)
    ])
    np.testing.assert_allclose(grad, -F, atol=1e-6 * np.abs(F).max())


def test_forcing_jacobians_match_finite_differences(ball, ball_models, rng):
    model = ball_models["floating", "numpy"]
    p = model.parameters(ball)
    q, u = random_state(model, ball, rng)
    a = rng.standard_normal(model.nu)
    Jq, Ju = model.forcing_jacobians(q, u, p, a)

    def residual(q_, u_):
        return model.forcing(q_, u_, p) - model.mass_matrix(q_, p) @ a

    h = 1e-6
    fd_q = np.column_stack([(residual(q + h * e, u) - residual(q - h * e, u)) / (2 * h) for e in np.eye(model.nq)])
    fd_u = np.column_stack([(residual(q, u + h * e) - residual(q, u - h * e)) / (2 * h) for e in np.eye(model.nu)])
    np.testing.assert_allclose(Jq, fd_q, atol=1e-5 * np.abs(fd_q).max())
    np.testing.assert_allclose(Ju, fd_u, atol=1e-5 * np.abs(fd_u).max())


# ---------------------------------------------------------------- the readable equations (eom.md, show)
@pytest.mark.parametrize("formulation", ["particles", "floating"])
@pytest.mark.parametrize("damper", ["relative", "axial"])
def test_readable_equations_equal_kanes_symbolically(formulation, damper):
    """Named terms substituted back, every entry of M and F equals Kane's: simplify(a - b) == 0."""
    from derivation.mechanics import derive
    from derivation.readable import check_identity, readable

    scene = make_scene(body(particles=[[-0.1, 0.0], [0.1, 0.0], [0.0, 0.1]], links=[[0, 1], [1, 2], [2, 0]],
                            damper=damper))
    model = derive(scene.topology(), formulation)
    assert check_identity(model, readable(model)) == 0.0


@pytest.mark.parametrize("damper", ["relative", "axial"])
def test_readable_equations_of_a_rigid_body_beside_a_flexible_one_equal_kanes(damper):
    """A rigid triangle (its links only draw it: no spring, no damper in Kane's equations)
    beside a flexible bar: the readable rows carry no named term of the rigid body's links
    (they carried its dampers' torques, -c omega r^2 in the angle's row, that no run has) and
    equal Kane's symbolically."""
    from derivation.mechanics import derive
    from derivation.readable import check_identity, readable

    scene = make_scene(body(name="tri", shape="polygon", vertices=[[-0.1, 0.0], [0.1, 0.0], [0.0, 0.1]], rigid=True,
                            particles=None, links=None, stiffness=None, damping=None, damper=None, mass=0.1),
                       body(name="bar", particles=[[0.3, 0.0], [0.5, 0.0]], links=[[0, 1]], damper=damper))
    assert len(scene.bodies[0].links) == 3  # links 0, 1 and 2; the bar's is link 3
    model = derive(scene.topology(), "floating")
    eqs = readable(model)
    assert check_identity(model, eqs) == 0.0
    assert {re.search(r"\d+", str(s)).group() for s in eqs.terms} == {"3"}


def test_readable_equations_of_a_ring_equal_kanes_at_random_states():
    """A 7-particle ring in the floating frame: simplify over its 14 rows takes minutes, so compare
    numerically at random states (the expressions are rational in q, u, p, sin and cos: an error would
    show as an O(1) relative difference, not 1e-12)."""
    from derivation.mechanics import derive
    from derivation.readable import check_identity, readable

    scene = make_scene(body(particles=None, links=None, shape="ring", count=6, radius=0.1, center=True))
    model = derive(scene.topology(), "floating")
    assert check_identity(model, readable(model), points=5) < 1e-12


def test_readable_rigid_body_rows_have_no_internal_forces():
    from derivation.mechanics import derive
    from derivation.readable import readable

    model = derive(load_scene("dumbbell").topology(), "floating")
    eqs = readable(model)
    rows = dict(zip([u.name for u in model.u], eqs.rows_text()))
    raw_F = dict(zip([u.name for u in model.u], model.outputs["forcing"]))
    for rigid in ("vX0", "vY0"):
        assert "k0" in str(raw_F[rigid])  # Kane prints the link's force twice, with opposite signs
        assert not ({"k0", "c0", "fs0", "fd0_xi", "fd0_eta"} & set(rows[rigid].replace("*", " ").split()))
    # the spring is central: no spring moment in the rotation row, only the relative damper's
    assert "fs0" not in rows["omega0"] and "fd0_eta" in rows["omega0"]
    assert rows["vxi1"].startswith("m1*cos(theta0)*vX0' + m1*sin(theta0)*vY0' + m1*vxi1' = ")
    latex = eqs.rows_latex()
    assert "\\ddot{\\theta}_{0}" in latex[2] and "\\dot{\\theta}_{0}" in latex[2] and "omega0" not in latex[2]


@pytest.mark.parametrize("raw", [False, True])
def test_show_prints_readable_or_raw_equations(raw, capsys):
    from flexbody.cli import main

    assert main(["show", "dumbbell", "--formulation", "floating"] + (["--raw"] if raw else [])) == 0
    out = capsys.readouterr().out
    vX0 = next(line for line in out.splitlines() if line.startswith("[vX0]"))
    if raw:
        assert "Raw equations" in out and "k0*xi1*(L0 - Abs(xi1))/Abs(xi1)" in vX0
    else:
        assert "k0" not in vX0 and "fs0 = k0*(L0 - ell0)" in out and "ell0 = Abs(xi1)" in out


@pytest.mark.parametrize("backend", BACKENDS)
def test_floating_one_link_matches_hand_derivation(backend, rng):
    """Two particles, one link, floating frame: q = [X, Y, theta, xi1].  Particle 0 (the anchor)
    sits at T's origin r0 = (X, Y); particle 1 on T's x-axis, r1 = r0 + xi1 (cos theta, sin theta).
    Written out by hand: v_i = J_i u, M = sum_i m_i J_i^T J_i, and
    F = sum_i J_i^T (f_i + m_i g - m_i dJ_i/dt u) (d'Alembert / Kane, q' = u)."""
    m0, m1, k, c, L = 0.05, 0.08, 2000.0, 0.5, 0.25
    scene = make_scene(body(masses=[m0, m1], mass=None, stiffness=k, damping=c, rest_lengths=L), gravity=[0.7, -9.81])
    model = load_model(scene, backend=backend, formulation="floating")
    assert model.q_names == ("X0", "Y0", "theta0", "xi1")
    p = model.parameters(scene)
    g = np.array([0.7, -9.81])
    for _ in range(5):
        X, Y, th, xi = rng.uniform(-1, 1, 4) + [0, 0, 0, 0.3]
        vX, vY, w, vxi = rng.uniform(-2, 2, 4)
        cs, sn = np.cos(th), np.sin(th)
        J0 = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0]])
        J1 = np.array([[1.0, 0, -xi * sn, cs], [0, 1.0, xi * cs, sn]])
        u = np.array([vX, vY, w, vxi])
        v0, v1 = J0 @ u, J1 @ u
        # acceleration of particle 1 at u' = 0: d/dt(J1) u
        a1 = np.array([-2 * vxi * w * sn - xi * w**2 * cs, 2 * vxi * w * cs - xi * w**2 * sn])
        d = -xi * np.array([cs, sn])  # P_01 = r0 - r1
        r = np.linalg.norm(d)
        f0 = k * (L - r) * d / r + c * (v1 - v0)  # thesis eq. 3.7 + 3.8 on particle 0; -f0 on 1
        M = m0 * J0.T @ J0 + m1 * J1.T @ J1
        F = J0.T @ (f0 + m0 * g) + J1.T @ (-f0 + m1 * g - m1 * a1)
        q = np.array([X, Y, th, xi])
        np.testing.assert_allclose(model.mass_matrix(q, p), M, rtol=1e-12, atol=1e-12 * np.abs(M).max())
        np.testing.assert_allclose(model.forcing(q, u, p), F, rtol=1e-12, atol=1e-12 * np.abs(F).max())
        T, V, G, P = model.energies(q, u, p)
        assert T == pytest.approx(0.5 * (m0 * v0 @ v0 + m1 * v1 @ v1), rel=1e-12)
        assert V == pytest.approx(0.5 * k * (r - L) ** 2, rel=1e-12)
        assert G == pytest.approx(-(m0 * g @ q[:2] + m1 * g @ (q[:2] - d)), rel=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_particle_jacobian_and_bias_give_the_particles_motion(ball, ball_models, rng, backend):
    """On frames T the particles move as ``v = P u`` and ``a = P u' + particle_bias``: checked
    against the particle velocities and the accelerations the ground gaps' kinematics give."""
    model = ball_models["floating", backend]
    p = model.parameters(ball)
    for _ in range(3):
        q, u = random_state(model, ball, rng)
        P = model.particle_jacobian(q, p)
        np.testing.assert_allclose(P @ u, model.velocities(q, u, p).ravel(), rtol=1e-12, atol=1e-12)
        udot = model.rhs(np.concatenate([q, u, [0, 0]]), p, np.zeros(model.n_contacts, int),
                         np.zeros(model.n_contacts))[0][model.nq : model.nq + model.nu]
        acc = (P @ udot + model.particle_bias(q, u, p).ravel()).reshape(-1, 2)
        np.testing.assert_allclose(acc, particle_accelerations(model, q, u, p), rtol=1e-9, atol=1e-9)
