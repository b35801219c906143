"""The event-driven runtime against closed forms, invariants and an independent reference."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

import flexbody
from flexbody.contact import Event
from flexbody.driver import SimulationFailed, _Run, _settings
from flexbody.model import load_model

from .conftest import BACKENDS, body, make_scene, needs_cc

TIGHT = dict(method="DOP853", rtol=1e-11, atol=1e-13)


def single_particle(h=1.0, mass=0.3, t_end=1.0):
    return make_scene(body(particles=[[0.0, 0.0]], links=[], stiffness=[], damping=[], mass=mass, position=[0.0, h]),
                      simulation={"t_end": t_end, "output_dt": 1e-3})


@pytest.mark.parametrize("backend", BACKENDS)
def test_free_fall_impact_time_and_resting_contact_force(backend):
    h, m, g = 1.0, 0.3, 9.81
    r = flexbody.simulate(single_particle(h, m), backend=backend, **TIGHT)
    assert r.success, r.message
    assert list(r.events_kind) == ["impact"] and r.events_held.all()
    assert r.events_time[0] == pytest.approx(np.sqrt(2 * h / g), abs=1e-12)
    after = r.t > r.events_time[0]
    np.testing.assert_allclose(r.positions[after, 0, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(r.contact_force[after, 0], m * g, rtol=1e-12)
    assert r.impact_loss[-1] == pytest.approx(m * g * h, rel=1e-10)  # all kinetic energy lost: plastic impact


@needs_cc
def test_vertical_dumbbell_lifts_off_at_the_closed_form_time():
    """contact.md §4.3: m1 = 1 below m2 = 2, k = 400, L0 = 0.5, released at H = 1."""
    scene = make_scene(body(particles=[[0.0, 0.0], [0.0, 0.5]], masses=[1.0, 2.0], mass=None, stiffness=400.0,
                            damping=0.0, position=[0.0, 1.0]), simulation={"t_end": 0.75})
    r = flexbody.simulate(scene, **TIGHT)
    assert r.success, r.message
    assert list(zip(r.events_particle, r.events_kind)) == [(0, "impact"), (0, "liftoff")]
    assert r.events_time[0] == pytest.approx(0.451523640986, abs=1e-11)
    assert r.events_time[1] == pytest.approx(0.701213600681, abs=1e-9)
    model = load_model(scene, backend="numpy")
    run = _Run(scene, model, _settings(scene, dict(TIGHT, t_end=0.701213600681)), None, 100)
    run.run()
    v2 = run.Y[run.n_samples - 1][model.nq + 3]
    assert v2 == pytest.approx(4.361023317411, abs=1e-7)


@pytest.mark.parametrize("n, restitution, contact_time", [(2, 0.5, np.pi), (3, 0.649210, 5.268542),
                                                          (4, 0.728018, 7.288611)])
@needs_cc
def test_falling_chain_restitution_matches_reference(n, restitution, contact_time):
    """contact.md §4.5: a vertical chain of N equal particles, g = 0, lands at v0 plastically.

    Spacing 1 m: the compression (~v0 / omega = 0.1 m) never folds the chain."""
    k, m, v0 = 100.0, 1.0, 1.0
    scene = make_scene(
        body(particles=[[0.0, 1.0 * i] for i in range(n)], links=[[i, i + 1] for i in range(n - 1)], mass=m,
             stiffness=k, damping=0.0, position=[0.0, 0.001], velocity=[0.0, -v0]),
        gravity=[0.0, 0.0], simulation={"t_end": 1.5, "output_dt": 1e-4},
    )
    r = flexbody.simulate(scene, **TIGHT)
    assert r.success, r.message
    t_impact, t_liftoff = r.events_time[0], r.events_time[r.events_kind == "liftoff"][-1]
    v_cm = r.velocities[-1, :, 1].mean()
    assert v_cm / v0 == pytest.approx(restitution, abs=2e-6)
    assert (t_liftoff - t_impact) * np.sqrt(k / m) == pytest.approx(contact_time, abs=2e-6)


@needs_cc
def test_two_particle_link_oscillates_at_the_damped_frequency():
    """Thesis eq. 3.10 with the reduced mass mu: mu x'' + c x' + k x = 0 along the link."""
    m1, m2, k, c, L = 0.05, 0.08, 2000.0, 0.5, 0.2
    mu = m1 * m2 / (m1 + m2)
    x0 = 0.01
    scene = make_scene(body(particles=[[0.0, 0.0], [L + x0, 0.0]], masses=[m1, m2], mass=None, stiffness=k, damping=c,
                            rest_lengths=L, position=[0.0, 1.0]), gravity=[0.0, 0.0],
                       simulation={"t_end": 0.2, "output_dt": 1e-4})
    r = flexbody.simulate(scene, **TIGHT)
    x = np.linalg.norm(r.positions[:, 1] - r.positions[:, 0], axis=1) - L
    w0, zeta = np.sqrt(k / mu), c / (2 * np.sqrt(k * mu))
    wd = np.sqrt(4 * k * mu - c**2) / (2 * mu)
    expected = x0 * np.exp(-zeta * w0 * r.t) * (np.cos(wd * r.t) + zeta * w0 / wd * np.sin(wd * r.t))
    np.testing.assert_allclose(x, expected, atol=1e-9)


def level_ring(angle_offset=0.0, order=None):
    """The thesis ball turned so a face (two mirror particles) lands flat."""
    angle = -np.pi / 2 + np.pi / 22 + angle_offset
    table = body(particles=None, links=None, shape="ring", count=22, radius=0.1, center=True, angle=angle,
                 position=[0.0, 0.3])
    if order is not None:  # the same body with its particles listed in another order
        s = make_scene(table)
        pts = s.bodies[0].points
        inverse = np.argsort(order)
        table = body(particles=pts[order].tolist(), links=[[int(inverse[i]), int(inverse[j])] for i, j in s.bodies[0].links],
                     angle=angle, position=[0.0, 0.3])
    return make_scene(table, simulation={"t_end": 0.45, "output_dt": 1e-3})


@needs_cc
def test_flat_landing_hits_several_particles_at_once_symmetrically():
    r = flexbody.simulate(level_ring(), **TIGHT)
    assert r.success, r.message
    first = r.events_time == r.events_time[0]
    assert sorted(r.events_particle[first]) == [1, 22] and (r.events_kind[first] == "impact").all()
    # mirror symmetry about the vertical through the centre: particle k <-> 23 - k
    mirror = np.r_[0, 23 - np.arange(1, 23)]
    x = r.positions
    np.testing.assert_allclose(x[:, mirror, 0], -x[:, :, 0], atol=1e-10)
    np.testing.assert_allclose(x[:, mirror, 1], x[:, :, 1], atol=1e-10)
    assert r.stats["max_penetration_m"] < 1e-11
    assert r.positions[:, :, 1].min() > -1e-11
    assert r.stats["energy_drift_J"] < 1e-8 * r.stats["energy_initial_J"]


@needs_cc
def test_result_does_not_depend_on_particle_order():
    order = np.r_[0, np.arange(22, 0, -1)]  # perimeter listed clockwise instead
    a = flexbody.simulate(level_ring(), **TIGHT)
    b = flexbody.simulate(level_ring(order=order), **TIGHT)
    np.testing.assert_allclose(b.positions, a.positions[:, order], atol=1e-10)
    np.testing.assert_allclose(b.events_time, a.events_time, atol=1e-12)


@needs_cc
def test_near_simultaneous_impacts_are_continuous_with_simultaneous():
    exact = flexbody.simulate(level_ring(), **TIGHT)
    for offset in (1e-13, 1e-10, 1e-8):
        near = flexbody.simulate(level_ring(angle_offset=offset), **TIGHT)
        assert near.success
        assert np.abs(near.positions - exact.positions).max() < 1e3 * offset + 1e-10
        assert near.stats["max_penetration_m"] < 1e-11


@needs_cc
def test_thesis_impact_mode_converges_to_instant_at_first_order():
    """Eq. 4.6 spreads each impulse over dT: the trajectory error is O(dT).  The slopes are taken
    where the error is far above the integration error (1e-12) and below dT ~ 1e-3, where
    the windows of neighbouring impacts overlap."""
    scene = flexbody.load_scene("thesis_ball")
    tight = dict(method="dop853", rtol=1e-12, atol=1e-14, t_end=0.4)
    reference = flexbody.simulate(scene, **tight)
    steps = np.array([3e-4, 1e-4, 3e-5, 1e-5])
    errors = []
    for dt in steps:
        r = flexbody.simulate(scene, impact="thesis", impact_dt=dt, **tight)
        assert r.success, r.message
        errors.append(np.abs(r.positions - reference.positions).max())
        total = r.total_energy
        assert np.abs(total - total[0]).max() < 1e-8 * total[0]  # the window's work is in the ledger
    slopes = np.diff(np.log(errors)) / np.diff(np.log(steps))
    assert ((0.9 <= slopes) & (slopes <= 1.1)).all(), slopes
    assert errors[-1] < 1e-4


@pytest.mark.parametrize("backend", BACKENDS)
def test_particles_and_floating_formulations_agree(ball, backend):
    a = flexbody.simulate(ball, t_end=0.8, formulation="particles", backend=backend, **TIGHT)
    b = flexbody.simulate(ball, t_end=0.8, formulation="floating", backend=backend, **TIGHT)
    assert list(zip(a.events_particle, a.events_kind)) == list(zip(b.events_particle, b.events_kind))
    np.testing.assert_allclose(a.events_time, b.events_time, atol=1e-9)
    np.testing.assert_allclose(a.positions, b.positions, atol=1e-8)
    np.testing.assert_allclose(a.contact_force, b.contact_force, atol=1e-5 * a.contact_force.max())


@needs_cc
@pytest.mark.parametrize("rtol", [1e-6, 1e-9])
def test_energy_balance_on_the_thesis_ball(ball, rtol):
    r = flexbody.simulate(ball, method="DOP853", rtol=rtol, atol=rtol * 1e-3)
    assert r.success
    total = r.total_energy
    assert np.abs(total - total[0]).max() <= 10 * rtol * total[0]
    assert (np.diff(r.damping_work) >= -1e-12).all() and (np.diff(r.impact_loss) >= 0).all()
    assert r.stats["max_penetration_m"] < 1e-10
    assert (r.contact_force >= 0).all()


REFERENCE_EVENTS = json.loads((Path(__file__).parent / "reference" / "thesis_ball_events.json").read_text())
SLOW = pytest.mark.slow


@needs_cc
@pytest.mark.parametrize("formulation", ["particles", "floating"])
@pytest.mark.parametrize("method", ["dopri5", "dop853", "DOP853", pytest.param("RK45", marks=SLOW),
                                    pytest.param("RK23", marks=SLOW), pytest.param("Radau", marks=SLOW),
                                    pytest.param("BDF", marks=SLOW), pytest.param("LSODA", marks=SLOW)])
def test_thesis_ball_events_match_the_reference(ball, method, formulation):
    """Every method the README names, at rtol 1e-9, in both formulations: the same (particle,
    kind, held) events as tests/reference/thesis_ball_events.json (29 impacts, 8 not held, 18
    lift-offs: the independent implementation of contact.md), at the same times.  The two
    tight reference runs differ by 3.2e-9 s on one grazing lift-off, hence 1e-8 s."""
    r = flexbody.simulate(ball, method=method, rtol=1e-9, atol=1e-12, formulation=formulation)
    assert r.success, r.message
    expected = [(e["particle"], e["kind"], e["held"]) for e in REFERENCE_EVENTS["events"]]
    assert list(zip(r.events_particle.tolist(), r.events_kind.tolist(), r.events_held.tolist())) == expected
    times = np.array([e["time"] for e in REFERENCE_EVENTS["events"]])
    np.testing.assert_allclose(r.events_time, times, rtol=0, atol=1e-8)
    assert (r.stats["impacts"], r.stats["not_held"], r.stats["liftoffs"]) == (29, 8, 18)


@needs_cc
def test_every_scipy_method_gives_the_same_events(ball):
    reference = flexbody.simulate(ball, t_end=0.7, **TIGHT)
    for method in ("RK45", "RK23", "Radau", "BDF", "LSODA"):
        r = flexbody.simulate(ball, t_end=0.7, method=method, rtol=1e-7, atol=1e-10)
        assert r.success, (method, r.message)
        assert list(zip(r.events_particle, r.events_kind)) == list(zip(reference.events_particle,
                                                                       reference.events_kind)), method
        np.testing.assert_allclose(r.events_time, reference.events_time, atol=1e-6, err_msg=method)
        assert np.abs(r.positions - reference.positions).max() < 1e-5, method


@needs_cc
def test_max_events_stops_with_status_and_message(ball):
    r = flexbody.simulate(ball, max_events=5)
    assert r.status == "max_events" and not r.success
    assert "max_events" in r.message and len(r.events_time) >= 5


@pytest.mark.parametrize("backend, method", [("numpy", "RK45")] + ([("c", "dopri5")] if "c" in BACKENDS else []))
def test_max_wall_time_stops_a_real_run_with_status_too_slow(ball, backend, method):
    """max_wall_time = 1e-9 s (0 is refused: no run could keep it): the deadline has passed at
    the first check (after a SciPy step, or after the compiled path's first segment); the
    arrays keep what was computed until then."""
    r = flexbody.simulate(ball, backend=backend, method=method, max_wall_time=1e-9)
    assert r.status == "too_slow" and not r.success
    assert "max_wall_time" in r.message
    assert r.stats["t_reached"] < 2.0 and len(r.t) < 2001


def test_chattering_is_reported_not_spun_on(ball):
    model = load_model(ball, backend="numpy")
    run = _Run(ball, model, _settings(ball, {}), None, 10**6)
    impacts = [Event(0.5 + 1e-5 * k, 3, "impact", -1e-7) for k in range(30)]
    for e in impacts[:25]:  # 25 impacts within 1 ms are tolerated
        run.check_guards(e.t, [e])
    with pytest.raises(SimulationFailed) as info:
        run.check_guards(impacts[25].t, [impacts[25]])
    assert info.value.status == "chattering"
    assert "particle 3 impacted 26 times" in info.value.message and "rtol" in info.value.message
    assert "chatter_impacts" in info.value.message and "now 25" in info.value.message


@pytest.mark.parametrize("given", ["scene", "option"])
def test_the_chatter_bound_is_the_scenes_or_the_options(ball, given):
    """``simulation.chatter_impacts`` (or the option ``chatter_impacts``) moves the guard's
    bound: 40 impacts within 1 ms pass under a bound of 40, the 41st stops the run."""
    if given == "scene":
        table = {"name": "ball", "bodies": [{"name": "b", "particles": [[0.0, 0.0], [0.1, 0.0]], "links": [[0, 1]],
                                              "mass": 0.1, "stiffness": 1000.0, "damping": 0.1,
                                              "position": [0.0, 0.3]}],
                 "simulation": {"t_end": 1.0, "chatter_impacts": 40}}
        scene = flexbody.load_scene(table)
        assert scene.simulation.chatter_impacts == 40
        settings, model = _settings(scene, {"backend": "numpy"}), load_model(scene, backend="numpy")
    else:
        scene, settings = ball, _settings(ball, {"chatter_impacts": 40, "backend": "numpy"})
        model = load_model(ball, backend="numpy")
    run = _Run(scene, model, settings, None, 10**6)
    impacts = [Event(0.5 + 1e-5 * k, 1, "impact", -1e-7) for k in range(41)]
    for e in impacts[:40]:
        run.check_guards(e.t, [e])
    with pytest.raises(SimulationFailed) as info:
        run.check_guards(impacts[40].t, [impacts[40]])
    assert "impacted 41 times" in info.value.message and "now 40" in info.value.message


def test_a_run_records_its_chatter_bound(ball):
    assert flexbody.simulate(ball, t_end=0.05, chatter_impacts=60).stats["chatter_impacts"] == 60
    assert flexbody.simulate(ball, t_end=0.05).stats["chatter_impacts"] == 25


@needs_cc
def test_result_contract(ball, tmp_path):
    r = flexbody.simulate(ball, t_end=0.5)
    out = r.save(tmp_path / "run")
    back = flexbody.load_result(out)
    nt, n = len(back.t), 23
    assert back.positions.shape == back.velocities.shape == (nt, n, 2)
    assert back.contact_force.shape == (nt, n)
    for key in ("kinetic", "spring", "gravity", "damping_work", "impact_loss"):
        assert getattr(back, key).shape == (nt,)
    assert set(back.events_kind) == {"impact", "liftoff"}
    assert back.events_time.shape == back.events_particle.shape == back.events_kind.shape
    np.testing.assert_array_equal(back.events_surface, np.full(len(back.events_time), -1))  # every one a ground's
    np.testing.assert_array_equal(back.masses, np.full(n, 0.05))
    for key in ("scene", "method", "rtol", "atol", "backend", "formulation", "wall_time_s", "rhs_evaluations",
                "steps", "events", "max_penetration_m", "energy_drift_J", "versions"):
        assert key in back.stats
    assert back.t[0] == 0.0 and back.t[-1] == pytest.approx(0.5)


@pytest.mark.skipif("c" not in BACKENDS, reason="no C compiler")
@pytest.mark.parametrize("compiled, scipy_method", [("dopri5", "RK45"), ("dop853", "DOP853")])
@pytest.mark.parametrize("formulation", ["particles", "floating"])
def test_compiled_integrator_reproduces_the_scipy_path(ball, compiled, scipy_method, formulation):
    """Same tableau and step-size controller: the same events and trajectory, and the same
    steps up to rounding (C and NumPy sum the stages in different orders, which can flip a
    step that is accepted by a hair)."""
    options = dict(rtol=1e-7, atol=1e-10, t_end=0.8, formulation=formulation)
    a = flexbody.simulate(ball, method=compiled, **options)
    b = flexbody.simulate(ball, method=scipy_method, **options)
    assert a.success and b.success
    assert list(zip(a.events_particle, a.events_kind)) == list(zip(b.events_particle, b.events_kind))
    np.testing.assert_allclose(a.events_time, b.events_time, atol=1e-10)
    np.testing.assert_allclose(a.positions, b.positions, atol=1e-9)
    assert abs(a.stats["steps"] - b.stats["steps"]) <= 0.01 * b.stats["steps"]
    # The compiled floating path projects held contacts onto the ground after each step and
    # evaluates the right-hand side again there: at most one more evaluation per step.
    extra = a.stats["steps"] if formulation == "floating" else 0
    assert abs(a.stats["rhs_evaluations"] - b.stats["rhs_evaluations"]) <= 0.02 * b.stats["rhs_evaluations"] + extra


def test_compiled_methods_need_the_c_backend(ball):
    with pytest.raises(ValueError, match="`method` = 'dopri5': is compiled C and needs backend 'c'"):
        flexbody.simulate(ball, method="dopri5", backend="numpy")
    assert flexbody.simulate(ball, backend="numpy", t_end=0.05).stats["method"] == "RK45"


@needs_cc
@pytest.mark.parametrize("method", ["RK45", "dopri5"])
def test_stiff_lift_off_is_located_on_the_released_side(method):
    """At k = 1e7 N/m the contact force moves ~1e-8 N within the root's 1e-15 s: the event
    must be reported where the force already pulls, or the restart finds it again.  The
    event function of a held contact is its constraint force lam + tolerance: at every
    reported lift-off, with the contact set it had, it must be <= 0."""
    from flexbody.bench import _ball

    scene = _ball(1e7, 0.005)
    model = load_model(scene, backend="c")
    run = _Run(scene, model, _settings(scene, dict(method=method, rtol=1e-6, atol=1e-9, t_end=0.3)), None, 10**5,
               max_wall_time=120)
    seen = []  # (contact, lam + tolerance) just before each lift-off is applied
    resolve_at = run.resolve_at

    def spy(t, touching, leaving):
        _, lam = model.rhs(run.y.copy(), run.p, run.phases.held.copy(), run.phases.push.copy())
        g = lam + run.force_tolerance
        events = resolve_at(t, touching, leaving)
        seen.extend((e.contact, g[e.contact], run.force_tolerance[e.contact]) for e in events if e.kind == "liftoff")
        return events

    run.resolve_at = spy
    status, message = run.run()
    assert status == "success", message
    assert len(seen) >= 1
    for contact, g, tolerance in seen:
        assert g <= 0.0, (contact, g)  # the released side: the force would pull
        assert g > -1e3 * tolerance, (contact, g)  # and located at the crossing, not long after


@needs_cc
def test_particle_slides_down_a_frictionless_incline():
    """Inclined ground (normal at angle th): the contact force is m g cos th and the slide
    along the slope is s = g sin th t^2 / 2, from rest, whatever the impact did."""
    th, m, g, lift = 0.3, 0.2, 9.81, 1e-3
    n, s_dir = np.array([-np.sin(th), np.cos(th)]), np.array([np.cos(th), np.sin(th)])
    scene = make_scene(body(particles=[[0.0, 0.0]], links=[], stiffness=[], damping=[], mass=m,
                            position=(lift * n).tolist()),
                       grounds=[{"point": [0.0, 0.0], "normal": n.tolist()}], simulation={"t_end": 0.5})
    r = flexbody.simulate(scene, **TIGHT)
    assert r.success and list(r.events_kind) == ["impact"]
    assert r.events_time[0] == pytest.approx(np.sqrt(2 * lift / (g * np.cos(th))), abs=1e-12)
    after = r.t > r.events_time[0]
    np.testing.assert_allclose(r.contact_force[after, 0], m * g * np.cos(th), rtol=1e-12)
    np.testing.assert_allclose(r.positions[after, 0] @ n, 0.0, atol=1e-12)
    np.testing.assert_allclose(r.positions[:, 0] @ s_dir, -0.5 * g * np.sin(th) * r.t**2, atol=1e-10)


@needs_cc
def test_particle_lands_in_a_corner_of_two_grounds():
    scene = make_scene(body(particles=[[0.0, 0.0]], links=[], stiffness=[], damping=[], mass=0.2,
                            position=[0.1, 0.1], velocity=[-1.0, 0.0]),
                       grounds=[{"point": [0.0, 0.0], "normal": [0.0, 1.0]}, {"point": [0.0, 0.0], "normal": [1.0, 0.0]}],
                       simulation={"t_end": 0.5})
    r = flexbody.simulate(scene, **TIGHT)
    assert r.success and list(r.events_kind) == ["impact", "impact"]
    np.testing.assert_allclose(r.events_time, [0.1, np.sqrt(0.2 / 9.81)], atol=1e-12)
    np.testing.assert_allclose(r.positions[-1, 0], [0.0, 0.0], atol=1e-12)
    assert r.contact_force[-1, 0] == pytest.approx(0.2 * 9.81, rel=1e-12)  # the floor's; the wall's is 0


@needs_cc
@pytest.mark.parametrize("formulation", ["particles", "floating"])
def test_two_bodies_move_independently(formulation):
    a, b = body(name="a"), body(name="b", position=[1.0, 0.5], angle=0.2)
    both = flexbody.simulate(make_scene(a, b, simulation={"t_end": 0.6}), formulation=formulation, **TIGHT)
    alone_a = flexbody.simulate(make_scene(a, simulation={"t_end": 0.6}), formulation=formulation, **TIGHT)
    alone_b = flexbody.simulate(make_scene(b, simulation={"t_end": 0.6}), formulation=formulation, **TIGHT)
    np.testing.assert_allclose(both.positions[:, :2], alone_a.positions, atol=1e-11)
    np.testing.assert_allclose(both.positions[:, 2:], alone_b.positions, atol=1e-11)
    assert sorted(both.events_time) == pytest.approx(sorted(np.r_[alone_a.events_time, alone_b.events_time]), abs=1e-11)


def test_a_model_loaded_for_another_scene_is_refused_naming_what_differs():
    """A model keeps the contact laws and masses of the scene it was loaded for: passed to
    ``simulate`` with a scene whose ground has another friction it would run with the old
    one, silently; it is refused, naming the difference.  The same scene with other settings
    (t_end) reuses it."""
    import tomllib

    from flexbody.scene import resolve_scene_path

    table = tomllib.loads(resolve_scene_path("ball_on_incline").read_text())
    rough = flexbody.load_scene(dict(table, grounds=[dict(table["grounds"][0], friction=0.9)] + table["grounds"][1:]))
    model = flexbody.load_model("ball_on_incline")
    with pytest.raises(flexbody.InputError, match="other contact laws than"):
        flexbody.simulate(rough, model=model)
    assert flexbody.simulate("ball_on_incline", model=model, t_end=0.05).success
