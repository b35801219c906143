"""Coulomb friction between bodies and at a rigid body's ground contacts (2D; coupled stick
and slip, flexbody.coupled and flexbody.body_contact).

References: closed forms of rigid boxes sliding and resting under Coulomb's law: a box
sliding on a block that slides on a frictionless ground (the relative speed falls at
mu g (1 + m/M) until they stick, then they move together with the momentum's speed; the
energy lost is the closed form's), a box resting on a wedge where mu > tan(slope) and
sliding down it at g (sin - mu cos) where mu < tan(slope), the wedge held on a rough ground
(statics of the wedge: its ground carries its weight and the box's).
"""

from __future__ import annotations

import numpy as np
import pytest

import flexbody

G = 9.81


def _box(name: str, corner, angle: float, side: float, mass: float, velocity=(0.0, 0.0)) -> dict:
    """A rigid square, counter-clockwise from its bottom-left ``corner``, turned by ``angle``."""
    c, s = np.cos(angle), np.sin(angle)
    along, up = np.array([c, s]), np.array([-s, c])
    bottom = np.asarray(corner, float)
    vertices = [bottom, bottom + side * along, bottom + side * (along + up), bottom + side * up]
    return {"name": name, "shape": "polygon", "rigid": True, "mass": mass, "position": [0.0, 0.0],
            "vertices": [v.tolist() for v in vertices], "velocity": list(velocity)}


SLIDE = {
    "name": "box_slides_on_block",
    "grounds": [{"point": [0.0, 0.0], "normal": [0.0, 1.0]}],
    "bodies": [
        {"name": "block", "shape": "polygon", "rigid": True, "mass": 0.5, "position": [0.0, 0.0],
         "vertices": [[-0.5, 0.0], [0.5, 0.0], [0.5, 0.1], [-0.5, 0.1]]},
        _box("box", [-0.25, 0.1], 0.0, 0.1, 0.1, velocity=(1.0, 0.0)),
    ],
    "contacts": [{"bodies": ["block", "box"], "friction": 0.3}],
    "simulation": {"t_end": 0.6, "output_dt": 0.005, "rtol": 1e-10, "atol": 1e-12},
}


def test_a_box_sliding_on_a_free_block_takes_the_closed_form_until_they_stick():
    r = flexbody.simulate(flexbody.load_scene(SLIDE))
    assert r.status == "success", r.message
    mu, v0 = 0.3, 1.0
    M, m = r.masses[:4].sum(), r.masses[4:].sum()  # 2.0 and 0.4 kg (the mass is per particle)
    t_stick = v0 / (mu * G * (1 + m / M))
    box, block = r.velocities[:, 4:, 0].mean(axis=1), r.velocities[:, :4, 0].mean(axis=1)
    common = m * v0 / (m + M)
    np.testing.assert_allclose(box, np.where(r.t < t_stick, v0 - mu * G * r.t, common), atol=1e-9)
    np.testing.assert_allclose(block, np.where(r.t < t_stick, mu * G * m / M * r.t, common), atol=1e-9)
    sticks = r.events_time[r.events_kind == "stick"]
    assert len(sticks) == 2 and np.abs(sticks - t_stick).max() < 1e-9  # both corners, at once
    # the energy friction took is the closed form's, and the ledger is closed
    assert r.friction_work[-1] == pytest.approx(0.5 * m * v0**2 - 0.5 * (m + M) * common**2, rel=1e-9)
    assert r.stats["energy_drift_relative"] < 1e-9
    # while sliding: each corner's friction is -mu times its normal force, the normal forces
    # carry the box's weight and balance the friction's moment about its centre
    sliding = (r.t > 0.01) & (r.t < t_stick - 0.01)
    normal, friction = r.contact_force[sliding][:, 4:6], r.friction_force[sliding][:, 4:6, 0]
    np.testing.assert_allclose(friction, -mu * normal, rtol=1e-9)
    np.testing.assert_allclose(normal.sum(axis=1), m * G, rtol=1e-9)
    height = 0.05  # the friction acts 0.05 m below the box's centre; the corners are 0.1 m apart
    np.testing.assert_allclose((normal[:, 1] - normal[:, 0]) * 0.05, mu * m * G * height, rtol=1e-9)
    assert r.stats["max_penetration_m"] < 1e-9


SLOPE = np.radians(20.0)


def _wedge_scene(mu: float) -> dict:
    width = 0.6
    top = width * np.tan(SLOPE)
    normal = np.array([-np.sin(SLOPE), np.cos(SLOPE)])
    corner = np.array([-0.1, (0.2) * np.tan(SLOPE)]) + 1e-6 * normal  # 1 um above the slope
    return {
        "name": "box_on_wedge",
        "grounds": [{"point": [0.0, 0.0], "normal": [0.0, 1.0], "friction": 1.0}],
        "bodies": [
            {"name": "wedge", "shape": "polygon", "rigid": True, "mass": 1.0, "position": [0.0, 0.0],
             "vertices": [[-width / 2, 0.0], [width / 2, 0.0], [width / 2, top]]},
            _box("box", corner, SLOPE, 0.05, 0.05),
        ],
        "contacts": [{"bodies": ["wedge", "box"], "friction": mu}],
        "simulation": {"t_end": 0.3, "output_dt": 0.002, "rtol": 1e-10, "atol": 1e-12},
    }


def test_a_box_rests_on_a_wedge_where_friction_can_hold_it():
    """mu = 0.5 > tan 20 deg: after landing the box sticks; at rest the slope carries its
    weight, normal m g cos and friction m g sin; the rough ground carries both bodies."""
    r = flexbody.simulate(flexbody.load_scene(_wedge_scene(0.5)))
    assert r.status == "success", r.message
    late = r.t > 0.1
    assert np.abs(r.velocities[late]).max() < 1e-9
    m = r.masses[3:].sum()
    along = np.array([np.cos(SLOPE), np.sin(SLOPE)])
    normal = r.contact_force[late][:, 3:].sum(axis=1)
    friction = r.friction_force[late][:, 3:] @ along
    np.testing.assert_allclose(normal, m * G * np.cos(SLOPE), rtol=1e-9)
    np.testing.assert_allclose(friction.sum(axis=1), m * G * np.sin(SLOPE), rtol=1e-9)
    np.testing.assert_allclose(r.contact_force[late][:, :3].sum(axis=1), r.masses.sum() * G, rtol=1e-9)
    # the two corners' rows are dependent: each carries friction in proportion to its normal
    # force, so both are equally near Coulomb's limit (and would slip together)
    ratio = friction[:, :2] / r.contact_force[late][:, 3:5]  # the box's bottom corners
    np.testing.assert_allclose(ratio, np.tan(SLOPE), rtol=1e-9)
    assert r.stats["max_penetration_m"] < 1e-9


def test_a_box_slides_down_a_wedge_at_the_closed_form_acceleration():
    """mu = 0.2 < tan 20 deg: the box slides down at g (sin - mu cos) along the slope while the
    rough ground (mu = 1) holds the wedge still; the ledger closes with friction's work."""
    mu = 0.2
    r = flexbody.simulate(flexbody.load_scene(_wedge_scene(mu)))
    assert r.status == "success", r.message
    along = np.array([np.cos(SLOPE), np.sin(SLOPE)])
    late = r.t > 0.05
    speed = r.velocities[late][:, 3:].mean(axis=1) @ along
    accel = np.diff(speed) / np.diff(r.t[late])
    np.testing.assert_allclose(accel, -G * (np.sin(SLOPE) - mu * np.cos(SLOPE)), rtol=1e-7)
    assert np.abs(r.velocities[:, :3]).max() < 1e-9  # the wedge stays put
    assert r.stats["energy_drift_relative"] < 1e-8
    assert r.friction_work[-1] > 0.0
    assert r.stats["max_penetration_m"] < 1e-9


def _rod(mu: float, v: float) -> dict:
    """A rigid rod of two equal point masses at 45 deg, its lower end 1 nm above a rough
    ground, sliding along it at ``v``."""
    low = np.array([0.0, 1e-9])
    high = low + np.array([np.cos(np.pi / 4), np.sin(np.pi / 4)])
    return {"name": "painleve_rod", "grounds": [{"point": [0.0, 0.0], "normal": [0.0, 1.0], "friction": mu}],
            "bodies": [{"name": "rod", "rigid": True, "particles": [low.tolist(), high.tolist()], "links": [[0, 1]],
                        "masses": [0.5, 0.5], "position": [0.0, 0.0], "velocity": [v, 0.0]}],
            "simulation": {"t_end": 0.2, "output_dt": 0.001}}


def _rod_on_ground(mu: float, v: float) -> dict:
    """:func:`_rod` with its lower end on the ground at the start."""
    table = _rod(mu, v)
    table["bodies"][0]["particles"] = [[0.0, 0.0], [np.cos(np.pi / 4), np.sin(np.pi / 4)]]
    return table


def test_painleves_rod_is_reported_not_approximated():
    """Two point masses at the ends of a rod: the lower end's W_nn - mu W_nt is (1 + cos^2 -
    mu sin cos) / m, negative at 45 deg above mu = 3 when it slides ahead of the rod (v < 0,
    away from its upper end).  Starting on the ground so, with its free normal acceleration
    -g, no contact force is consistent (Painlevé's paradox): the run stops at once, status
    ``unsupported``, saying so.  Sliding the other way, or with mu = 2, it runs: it slides
    until its slip stops, and sticks there."""
    r = flexbody.simulate(flexbody.load_scene(_rod_on_ground(4.0, -1.0)))
    assert r.status == "unsupported"
    assert "Painlevé: no consistent contact force" in r.message and r.stats["t_reached"] == 0.0
    for mu, v in ((4.0, 1.0), (2.0, -1.0)):
        r = flexbody.simulate(flexbody.load_scene(_rod_on_ground(mu, v)))
        assert r.status == "success", (mu, v, r.message)
        assert r.events_kind.tolist() == ["slip", "stick"], (mu, v)
        assert r.stats["energy_drift_relative"] < 1e-6


@pytest.mark.parametrize("backend", ["numpy", "c"])
def test_a_slide_that_stops_sticks_on_either_backend(backend):
    """The rod landing on its lower end and sliding on (mu = 4, v = 1, not Painlevé's way)
    slows to a stop, where sticking needs a third of the normal force along the ground
    (well within mu).  At the stop's instant its slip is round-off, not 0: the force problem
    read it as still sliding, along whatever sign the round-off had, and the NumPy backend
    (the C one too, on another machine) stopped the run there as Painlevé's.  A slip within
    the speed tolerance is at its stop: the contact sticks, on both backends alike."""
    table = _rod(4.0, 1.0)
    table["simulation"]["backend"] = backend
    r = flexbody.simulate(flexbody.load_scene(table))
    assert r.status == "success", r.message
    assert r.events_kind.tolist() == ["impact", "stick"]
    assert r.events_time[1] == pytest.approx(0.0566766, rel=1e-5)  # measured on both backends
    after = r.t > r.events_time[1] + 1e-3
    assert np.abs(r.velocities[after, 0, 0]).max() < 1e-9  # the lower end stays where it stopped


@pytest.mark.parametrize("v", [1.0, -1.0])
def test_painleves_indeterminate_case_is_reported_with_the_forces_found(v):
    """The rod's end on the ground, sliding, spinning at 8 rad/s: its free normal acceleration
    is ω² L/2 sin 45° - g = 12.8 m/s² (away from the ground), so no force is needed.  Sliding
    with the end leading (towards -x, the rod leaning back over it; mu = 4: W_nn + W_nt D =
    (1.5 - 0.5 mu) / m < 0) a push along with its friction, which would pull the end down,
    is consistent too: the release says both (it lifts off, and the note names the case).
    Sliding the other way the answer is unique: lift-off, no note."""
    from flexbody.constants import SLIDING
    from flexbody.contact_problems import INDETERMINATE
    from flexbody.coupled import coupled_release
    from flexbody.model import load_model
    from flexbody.state import initial_coordinates

    table = _rod(4.0, v)
    table["bodies"][0]["particles"] = [[0.0, 0.0], [np.cos(np.pi / 4), np.sin(np.pi / 4)]]  # on the ground
    table["bodies"][0]["angular_velocity"] = 8.0
    scene = flexbody.load_scene(table)
    model = load_model(scene)
    assert model.coupled and model.n_contacts == 2  # each end on the one ground
    p = model.parameters(scene)
    q, u = initial_coordinates(scene, model)
    y = np.concatenate([q, u, [0.0, 0.0]])
    assert model.gaps(q, p)[0] == pytest.approx(0.0, abs=1e-15)
    held, codes = np.array([True, False]), np.array([SLIDING, 0], np.intc)
    notes: list[str] = []
    release, _ = coupled_release(model, y, p, held, np.zeros(2), np.zeros(2, bool), np.full(2, 1e-10), codes, notes)
    assert release.tolist() == [True, False]
    if v < 0:
        assert len(notes) == 1 and INDETERMINATE in notes[0] and "held contacts [0]" in notes[0]
    else:
        assert notes == []


def test_a_rigid_box_sliding_down_a_rough_incline_balances_force_and_moment_per_corner():
    """A rigid square on a rough 30 deg ground slides down from rest (both corners sliding
    from rest, no stored direction): acceleration g (sin - mu cos) from the first sample on;
    each corner's friction is mu times its normal force; the normals carry m g cos and the
    friction's moment about the centre (the downhill corner more: N_down - N_up = F)."""
    slope, mu = np.radians(30.0), 0.2
    normal, along = np.array([-np.sin(slope), np.cos(slope)]), np.array([np.cos(slope), np.sin(slope)])
    box = _box("box", 1e-7 * normal, slope, 0.1, 0.1)
    table = {"name": "rough_incline", "grounds": [{"point": [0.0, 0.0], "normal": normal.tolist(), "friction": mu}],
             "bodies": [box], "simulation": {"t_end": 0.1, "output_dt": 0.01, "rtol": 1e-10, "atol": 1e-12}}
    r = flexbody.simulate(flexbody.load_scene(table))
    assert r.status == "success", r.message
    m = r.masses.sum()
    speed = r.velocities.mean(axis=1) @ along
    accel = np.diff(speed[1:]) / np.diff(r.t[1:])
    np.testing.assert_allclose(accel, -G * (np.sin(slope) - mu * np.cos(slope)), rtol=1e-8)
    N, F = r.contact_force[1:, :2], r.friction_force[1:, :2] @ along  # corners 0 (downhill) and 1
    np.testing.assert_allclose(F, mu * N, rtol=1e-9)  # up the slope, against the slide
    np.testing.assert_allclose(N.sum(axis=1), m * G * np.cos(slope), rtol=1e-9)
    np.testing.assert_allclose(N[:, 0] - N[:, 1], F.sum(axis=1), rtol=1e-9)


def test_a_rocking_box_landing_on_a_rough_ground_keeps_its_corners_stuck():
    """A rigid box pivoting on one bottom corner (held, sticking, mu = 1) lands on the other
    at 1e-5 m/s.  The impact LCP stops both (plastic, within the cone), and what it leaves
    slower than the Zeno speed is stopped too, with the sticking rows kept: afterwards both
    corners are at rest, normal and tangential (a stop along the normals alone would turn
    the box and slide the corners at ~1e-6 m/s, and the rocking never ended)."""
    from flexbody.coupled import coupled_impact
    from flexbody.model import load_model
    from flexbody.state import initial_coordinates

    table = {"name": "rocking", "grounds": [{"point": [0.0, 0.0], "normal": [0.0, 1.0], "friction": 1.0}],
             "bodies": [_box("box", [0.0, 0.0], 0.0, 0.05, 0.05)], "simulation": {"t_end": 0.1}}
    scene = flexbody.load_scene(table)
    model = load_model(scene)
    p = model.parameters(scene)
    q, u = initial_coordinates(scene, model)
    # turning clockwise about corner 0 (T's anchor: q = its place and the angle): corner 1
    # comes down at 1e-5 m/s
    u = np.array([0.0, 0.0, -1e-5 / 0.05])
    y = np.concatenate([q, u, [0.0, 0.0]])
    v = model.inner.velocities(q, u, p)
    assert np.abs(v[0]).max() < 1e-18 and v[1] == pytest.approx([0.0, -1e-5], abs=1e-18)
    touching = np.zeros(model.n_contacts, bool)
    touching[:2] = True  # the two bottom corners: 0 held, 1 hit
    out = coupled_impact(model, y, p, touching, np.zeros(model.n_contacts), np.full(model.n_contacts, 1e-3))
    v = model.inner.velocities(out.y[: model.nq], out.y[model.nq : model.nq + model.nu], p)
    assert np.abs(v[:2]).max() < 1e-15, v[:2]
    assert not out.leaving[:2].any()  # both stay held


def test_a_run_whose_forces_were_indeterminate_says_when_in_its_warnings():
    """The instants' notes reach the run's warnings: the first instant, how many later."""
    from flexbody.driver import _Run, _settings
    from flexbody.model import load_model

    scene = flexbody.load_scene(_rod(4.0, -1.0))
    run = _Run(scene, load_model(scene), _settings(scene, {}), None, 100)
    assert run.untrustworthy(0.0, 0.0, 0.0) == []
    note = "held contacts [0]: Painlevé: the contact force may not be unique (...); one solution returned."
    run.indeterminate = [(0.125, note), (0.125, note), (0.25, note.replace("[0]", "[1]"))]
    (warning,) = run.untrustworthy(0.0, 0.0, 0.0)
    assert warning.startswith(f"at t = 0.125 s (and at 1 later instant), {note[:-1]}: the run went on")
    assert warning.endswith("(Painlevé's indeterminate case)")
    # end to end: the rod starting on the ground, spinning, sliding end first (and not)
    for v in (-1.0, 1.0):
        table = _rod(4.0, v)
        table["bodies"][0]["particles"] = [[0.0, 0.0], [np.cos(np.pi / 4), np.sin(np.pi / 4)]]
        table["bodies"][0]["angular_velocity"] = 8.0
        table["simulation"]["t_end"] = 0.02
        r = flexbody.simulate(flexbody.load_scene(table))
        assert r.status == "success" and r.events_kind.tolist() == ["liftoff"] and r.events_time[0] == 0.0
        flagged = [w for w in r.stats["warnings"] if "Painlevé's indeterminate case" in w]
        assert len(flagged) == (v < 0), r.stats["warnings"]


def test_a_held_contact_that_drifts_is_kept_on_its_surface_or_reported_as_such(monkeypatch):
    """A rigid rod spinning at -8 rad/s lands on its upper end and pivots on it: held on a
    floating frame's coordinates, the contact's gap is not linear in them and drifts by the
    integrator's error.  A step that lets it sink more than ``SINK_GAPS`` gap tolerances is
    taken again shorter: at the default tolerances it sinks 6.9e-11 m (1.2e-8 m before; 4e-12
    m at rtol 1e-10).  Without that (``SINK_GAPS`` infinite) the warning names a held
    contact sinking, not a missed impact."""
    from flexbody import driver

    table = _rod(4.0, 1.0)
    table["bodies"][0]["particles"] = [[0.0, 0.0], [np.cos(np.pi / 4), np.sin(np.pi / 4)]]
    table["bodies"][0]["angular_velocity"] = -8.0
    for shortened in (True, False):
        if not shortened:
            monkeypatch.setattr(driver, "SINK_GAPS", np.inf)
        r = flexbody.simulate(flexbody.load_scene(table))
        assert r.status == "success" and r.events_kind.tolist() == ["liftoff", "impact"]
        assert not any("impact was missed" in w for w in r.stats["warnings"])
        sank = [w for w in r.stats["warnings"] if w.startswith("a held contact sank")]
        assert len(sank) == (not shortened) and (r.stats["max_penetration_m"] > 1e-9) == (not shortened)
        assert (r.stats["steps_shortened"] > 0) == shortened
    table["simulation"].update(rtol=1e-10, atol=1e-12)
    monkeypatch.undo()
    r = flexbody.simulate(flexbody.load_scene(table))
    assert r.stats["max_penetration_m"] < 1e-11 and r.stats["steps_shortened"] == 0 and r.stats["warnings"] == []


def test_a_slide_from_rest_with_a_round_off_slip_starts_along_its_pull():
    """Three braced rings on a rough ground, touching each other (found by a fuzz of random
    piles): at 0.0345 s an instant sets a ring particle sliding from rest on the ground with
    a tangential velocity of 6.8e-49 m/s left by round-off, against its pull.  Its slide's
    direction is its pull's (the force that would hold it, reversed), not that round-off
    velocity's: before, friction pushed the slide on (12 N for 0.35 ms) and the ledger's
    friction work fell by 1.9e-4 J.  Friction only ever takes energy."""
    ring = {"shape": "ring", "center": True, "damper": "relative"}
    scene = flexbody.load_scene({
        "name": "three_rings", "gravity": [0.0, -9.81],
        "grounds": [{"point": [0.0, 0.0], "normal": [0.0, 1.0], "friction": 0.3, "restitution": 0.3}],
        "bodies": [
            {**ring, "name": "a", "count": 12, "radius": 0.11756567694762257, "mass_total": 0.5124,
             "stiffness": 5735.9, "damping": 0.053, "position": [-0.186782, 0.130219], "angle": -0.1244,
             "velocity": [-0.6595, -0.9019], "angular_velocity": -1.5898},
            {**ring, "name": "b", "count": 13, "radius": 0.10020167032520416, "mass_total": 0.1184,
             "stiffness": 3511.9, "damping": 0.186, "position": [-0.19763, 0.505348], "angle": -0.2602,
             "velocity": [0.278, 0.1778], "angular_velocity": 1.0915},
            {**ring, "name": "c", "count": 8, "radius": 0.05429865590047294, "mass_total": 0.5623,
             "stiffness": 3474.5, "damping": 0.974, "position": [0.141376, 0.115429], "angle": 0.0647,
             "velocity": [-0.4215, 0.3969], "angular_velocity": -0.3389}],
        "contacts": [{"bodies": ["a", "b"]}, {"bodies": ["a", "c"], "friction": 0.8},
                     {"bodies": ["b", "c"], "friction": 0.8}],
        "simulation": {"t_end": 0.04, "output_dt": 1e-4}})
    r = flexbody.simulate(scene)
    assert r.success, r.message
    assert (r.events_kind == "slip").any() and r.friction_work[-1] > 0.0
    assert np.diff(r.friction_work).min() >= 0.0
    assert r.stats["energy_drift_relative"] < 1e-5
