"""What a run promises about itself: a closed ledger from t = 0, penetration measured where
it happens (held contacts of the floating formulation included), failures at an event
instant reported as statuses, and untrustworthy runs flagged."""

from __future__ import annotations

import numpy as np
import pytest

import flexbody
from flexbody.compiled import CompiledPath
from flexbody.contact import UnsettledInstant

from .conftest import body, make_scene, needs_cc


def test_ledger_is_closed_when_a_particle_starts_on_the_ground_approaching_it():
    """A dumbbell lying on the ground at gap 0 moving down at 2 m/s is stopped at t = 0: its
    whole kinetic energy goes to impact_loss, and the ledger is constant from sample 0."""
    scene = make_scene(body(position=[0.0, 0.0], velocity=[0.0, -2.0]), simulation={"t_end": 0.1})
    r = flexbody.simulate(scene)
    assert r.success, r.message
    assert r.kinetic[0] == pytest.approx(0.5 * 0.1 * 4.0)  # sample 0: the initial state as given
    assert r.impact_loss[1] == pytest.approx(0.5 * 0.1 * 4.0)
    total = r.total_energy
    assert np.abs(total - total[0]).max() <= 1e-12
    assert r.stats["energy_drift_relative"] <= 1e-10


@needs_cc
def test_floating_formulation_keeps_held_contacts_on_the_ground():
    """Coordinate projection: over 20 s (the ball ends at rest on the ground) no particle of
    the floating formulation is ever more than 1e-12 m below the ground, on the samples or
    at any step end, with the reference's 29 / 8 / 18 events in the first 2 s."""
    r = flexbody.simulate("thesis_ball", formulation="floating", t_end=20.0)
    assert r.success, r.message
    assert r.stats["max_penetration_m"] <= 1e-12
    assert r.positions[:, :, 1].min() >= -1e-12
    early = r.events_time < 2.0
    kinds = r.events_kind[early]
    assert (kinds == "impact").sum() == 29 and (kinds == "liftoff").sum() == 18


def test_a_loose_tolerance_run_is_flagged():
    """rtol 0.1: the event sequence and the ledger cannot be trusted, and the run says so."""
    r = flexbody.simulate("thesis_ball", rtol=0.1, atol=1e-9)
    assert r.success
    text = " ".join(r.stats["warnings"])
    assert "rtol = 0.1 is loose" in text and "energy ledger drifted" in text
    default = flexbody.simulate("thesis_ball")
    assert default.stats["warnings"] == []


def test_penetration_is_measured_on_the_samples_too():
    """The reported penetration is at least the deepest sampled gap (min over samples of y)."""
    r = flexbody.simulate("thesis_ball", rtol=0.1, atol=1e-9)
    assert r.stats["max_penetration_m"] >= -r.positions[:, :, 1].min() - 1e-18


@needs_cc
@pytest.mark.parametrize("error, status", [(FloatingPointError("mass or contact matrix not positive definite"),
                                            "blow_up"),
                                           (UnsettledInstant(0.5, 99), "no_progress")])
def test_a_failure_at_an_event_instant_is_a_status(monkeypatch, error, status):
    """A singular contact matrix or an unsettled fixed point at an instant ends the run with a
    status and a message, not a traceback."""
    def fail(self, *args, **kwargs):
        raise error

    monkeypatch.setattr(CompiledPath, "resolve", fail)
    r = flexbody.simulate("thesis_ball", t_end=1.0)
    assert r.status == status and not r.success
    assert str(error).split(":")[0] in r.message


@pytest.mark.parametrize("spacing, status", [(3.7e-12, "no_progress"), (2e-9, "success")])
def test_event_instants_that_keep_time_from_advancing_are_no_progress(monkeypatch, spacing, status):
    """Instants 3.7e-12 s apart, each firing the same held contact again (a corner handed
    between a slot and its twin lifted off so 4 000 times until the wall time ran out),
    end the run at the 200th with ``no_progress`` and a message; 2e-9 s apart they are
    time advancing, and the run goes on to its end."""
    from flexbody.driver import _Run, _Stop

    scene = make_scene(body(position=[0.0, 0.5]), simulation={"t_end": 1e-6, "output_dt": 1e-6})
    leaving = np.array([True, False])

    def segment(self, t0, t_bound):  # every segment ends at an event `spacing` later
        t = min(t0 + spacing, t_bound)
        return _Stop(t, np.zeros(2, bool), leaving, t < t_bound)

    monkeypatch.setattr(_Run, "segment", segment)
    monkeypatch.setattr(_Run, "resolve_at", lambda self, t, touching, leaving: [])
    r = flexbody.simulate(scene, backend="numpy", max_wall_time=60.0)
    assert r.status == status, r.message
    if status == "no_progress":
        assert "200 event instants in a row within 1e-09 s" in r.message
        stopped_at = float(r.message.split("at t = ")[1].split(" s")[0])
        assert stopped_at == pytest.approx(200 * spacing, rel=1e-6)  # time had not advanced


@needs_cc
def test_a_stiffness_the_integrator_cannot_step_ends_too_slow_inside_one_segment():
    """stiffness 1e20: steps of ~1e-11 s inside one C call; the integrator checks the
    wall-time budget itself and returns too_slow."""
    import tomllib
    from importlib import resources

    table = tomllib.loads((resources.files("flexbody") / "scenes" / "thesis_ball.toml").read_text())
    table["bodies"][0]["stiffness"] = 1e20
    scene = flexbody.load_scene(table)
    r = flexbody.simulate(scene, max_wall_time=1.0)
    assert r.status == "too_slow"
    assert r.stats["t_reached"] < 1e-3


@needs_cc
def test_a_stiffness_beyond_any_step_is_a_step_size_collapse():
    """stiffness 1e26 N/m: the stable step of dopri5 (~1e-14 s) is below 10 ulp of the
    segment's end, where no step can make progress: status step_size_collapse at once, with
    a message naming what to change."""
    import tomllib
    from importlib import resources

    table = tomllib.loads((resources.files("flexbody") / "scenes" / "thesis_ball.toml").read_text())
    table["bodies"][0]["stiffness"] = 1e26
    r = flexbody.simulate(flexbody.load_scene(table), max_wall_time=60.0)
    assert r.status == "step_size_collapse"
    assert "Radau" in r.message and "too stiff" in r.message


def test_a_contact_released_sunk_is_a_held_ones_sink_and_below_its_floor_a_missed_impact():
    """A free contact between its floor and the ground went there held: released at that
    gap, it is armed a tolerance below it.  Its depth is a held contact's sink (warned of
    beyond SINK_WARNING gap tolerances), not an impact missed between event checks (beyond
    10); below its floor it is one.  Measured: a row released 13 tolerances inside (1.4e-11
    m) was warned of as a missed impact.  The depth is reported either way."""
    from flexbody.assembly import assembled_model
    from flexbody.driver import _Run, _settings

    scene = make_scene(body(position=[0.0, 0.5]))  # a dumbbell: particles 0 and 1, each a ground contact
    run = _Run(scene, assembled_model(scene, "numpy"), _settings(scene, {"backend": "numpy"}), None, 10**6)
    tol = run.gap_tolerance
    y = run.y.copy()
    y[[1, 3]] = -13.0 * tol  # both 13 tolerances below the ground, both free
    run.phases.floor[:] = [-14.0 * tol, 0.0]  # 0 released there (armed below it), 1 armed at the ground
    run.track_gaps(y)
    assert run.min_gap == pytest.approx(-13.0 * tol, rel=1e-9)  # particle 1's: missed
    run.min_gap = np.inf
    run.phases.floor[1] = -14.0 * tol  # both released there
    run.track_gaps(y)
    assert run.min_gap == np.inf and run.min_held_gap == pytest.approx(-13.0 * tol, rel=1e-9)
    penetration, sink = max(0.0, -run.min_gap), max(0.0, -run.min_held_gap)
    assert not any("event checks" in w for w in run.untrustworthy(0.0, penetration, 0.0, sink))
    run.phases.floor[0] = -12.0 * tol  # below its floor: an impact missed
    run.track_gaps(y)
    assert run.min_gap == pytest.approx(-13.0 * tol, rel=1e-9)
    assert any("event checks" in w for w in run.untrustworthy(0.0, -run.min_gap, 0.0, sink))


def test_an_impact_that_adds_energy_is_warned_of():
    """A rigid bar spinning at 24 rad/s lands on one corner on a rough elastic ground (mu 0.6,
    e = 1): Newton's restitution with Coulomb friction adds 0.088 J (8.6 % of the energy),
    which the ledger's impact work counts (so its drift stays small) and nothing said
    (found by a fuzz).  Now a warning names the instant and the gain; without friction the
    same landing keeps the energy and nothing is said."""
    table = {"name": "rough_elastic_bar", "gravity": [0.0, -9.81],
             "grounds": [{"point": [0, 0.0], "normal": [0, 1.0], "friction": 0.6, "restitution": 1.0}],
             "bodies": [{"name": "b", "shape": "polygon", "rigid": True, "mass": 0.05,
                         "vertices": [[-0.1, -0.02], [0.1, -0.02], [0.1, 0.02], [-0.1, 0.02]], "position": [0, 0.15],
                         "angle": 0.8, "velocity": [0.5, -1.0], "angular_velocity": -24.0}],
             "simulation": {"t_end": 0.1, "output_dt": 5e-4}}
    result = flexbody.simulate(flexbody.load_scene(table))
    gained = float(-np.diff(result.impact_loss).min())  # the ledger's impact work fell: energy came in
    assert gained > 0.05
    [warning] = [w for w in result.stats["warnings"] if "impacts added energy" in w]
    assert f"({gained:.3g} J;" in warning
    assert abs(result.stats["energy_drift_relative"]) < 1e-6  # the ledger closes: it counts the gain
    table["grounds"][0]["friction"] = 0.0
    smooth = flexbody.simulate(flexbody.load_scene(table))
    assert not [w for w in smooth.stats["warnings"] if "impacts added energy" in w]
    assert np.diff(smooth.impact_loss).min() > -1e-12
