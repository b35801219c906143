"""The Zeno stop of a coupled impact (:func:`flexbody.coupled.coupled_impact`).

A contact the impact (:func:`flexbody.coupled.coupled_impact`) leaves moving away slower
than a rebound that would rise 1e-9 of the scene is stopped with the held ones, unless that
stop takes more than ``STOP_ENERGY`` times the kinetic energy of the stopped rows' own
speeds: then the rows are nearly parallel (a crease bent by 1e-4 rad), and the slow leavers
leave.  Two rows at an angle ``a`` take ``1 / sin(a)^2`` times it, so the bound is an
angle: these tests put rows on both sides of it, and at the 15 degrees of two spheres of a
3D pile pressed face to face.  A stop within the energy of the rows' Zeno speeds is taken
whatever that ratio (rows at round-off speeds), and beyond both only the slow leaver whose
stop takes the most leaves, one at a time (two flexible boxes pushed face to face on the
ground).  The piles of 3D spheres where this mattered are in ``tests/test_piles3d.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

import flexbody
from flexbody.coupled import STOP_ENERGY, coupled_impact

from .conftest import reference_table

SLOWEST = 1e-4  # m/s: the Zeno speed of both contacts


class TwoSurfaces:
    """A unit point mass in 2D against two surfaces through one point, ``angle`` apart: what
    :func:`coupled_impact` asks of a model (its contact rows on the velocity, M = I)."""

    def __init__(self, angle: float) -> None:
        self.n_contacts, self.nq, self.nu, self.mu = 2, 2, 2, None
        self.J = np.array([[0.0, 1.0], [np.sin(angle), np.cos(angle)]])

    def contact_coupling(self, q, u, p, rows, tangents=False):
        J = self.J[rows]
        return J, slice(None), J @ J.T, lambda P: J.T @ P, np.zeros(len(rows))

    def energies(self, q, u, p):
        return np.array([0.5 * float(u @ u)])


def hit_beside_a_held_row(angle: float, approach: float):
    """Row 0 hit at ``approach`` (m/s) while row 1, ``angle`` from it, is held at rest: the
    model, the velocity after and which rows leave."""
    model = TwoSurfaces(angle)
    u = np.linalg.solve(model.J, [-approach, 0.0])
    y = np.concatenate([np.zeros(2), u, [0.0]])
    out = coupled_impact(model, y, np.zeros(0), np.ones(2, bool), np.zeros(2), np.full(2, SLOWEST))
    return model, out.y[2:4], out.leaving


def test_a_slow_leaver_fifteen_degrees_from_the_hit_row_is_stopped_with_it():
    """The plastic impact on row 0 pushes row 1 off at 5e-5 cos 15 deg m/s, below the Zeno
    speed: both rows are stopped and the particle is at rest (the stop takes 1 / sin^2 15 =
    14.9 times the slow leaver's energy; with the former bound, 10, it left, and two 3D
    spheres rocked on such rows, each impact lifting the other, until ``chattering``)."""
    model, u_after, leaving = hit_beside_a_held_row(np.radians(15.0), 5e-5)
    assert not leaving.any()
    assert np.abs(model.J @ u_after).max() < 1e-18
    assert np.abs(u_after).max() < 1e-18


@pytest.mark.parametrize("share", [0.8, 1.25])
def test_the_stop_takes_at_most_stop_energy_times_the_slow_leavers_energy(share):
    """Rows at the angle whose stop takes ``share`` times the bound: below it both stop (at
    rest), above it the slow leaver leaves at the plastic impact's speed, ``cos a`` times
    the approach, and the hit row stays stopped."""
    angle = np.arcsin(1.0 / np.sqrt(share * STOP_ENERGY))
    model, u_after, leaving = hit_beside_a_held_row(angle, 5e-5)
    rates = model.J @ u_after
    if share < 1.0:
        assert not leaving.any() and np.abs(rates).max() < 1e-18
    else:
        assert leaving.tolist() == [False, True]
        assert abs(rates[0]) < 1e-18
        assert rates[1] == pytest.approx(5e-5 * np.cos(angle), rel=1e-12)


def test_a_slow_leaver_on_a_nearly_parallel_row_leaves():
    """Rows 1e-3 rad apart (a bent crease): stopping both would take 1e6 times the slow
    leaver's energy, turning the motion along them; it leaves at 5e-5 cos(1e-3) m/s."""
    model, u_after, leaving = hit_beside_a_held_row(1e-3, 5e-5)
    rates = model.J @ u_after
    assert leaving.tolist() == [False, True]
    assert rates[1] == pytest.approx(5e-5 * np.cos(1e-3), rel=1e-12)


def test_a_leaver_at_round_off_on_a_nearly_parallel_row_is_stopped_within_its_zeno_energy():
    """Rows 1e-3 rad apart, row 0 hit at 1e-9 m/s: stopping both takes 1e6 times the slow
    leaver's energy but 1e-10 of the two rows' at their Zeno speed, a change of the motion
    the threshold neglects: both stop (it left before, and two flexible boxes pushed face
    to face lifted their corners off the ground and hit again 0.1 us later)."""
    model, u_after, leaving = hit_beside_a_held_row(1e-3, 1e-9)
    assert not leaving.any()
    assert np.abs(model.J @ u_after).max() < 1e-18  # from 1e-6 m/s along the rows: at rest to rounding
    assert np.abs(u_after).max() < 1e-15


class TwoParticles(TwoSurfaces):
    """:class:`TwoSurfaces` for a first unit point mass, and a second one on a surface of
    its own (row 2), apart from both: its row shares no coordinate with theirs."""

    def __init__(self, angle: float) -> None:
        super().__init__(angle)
        self.n_contacts, self.nq, self.nu = 3, 4, 4
        self.J = np.zeros((3, 4))
        self.J[:2, :2] = TwoSurfaces(angle).J
        self.J[2, 3] = 1.0


def test_only_the_slow_leaver_whose_stop_takes_the_energy_leaves():
    """Row 0 hit at 5e-5 m/s beside row 1 at 1e-3 rad (a crease: row 1 leaves, as above),
    while another particle rests on its own surface, moving off it at round-off (1e-15
    m/s).  Its stop takes nothing: it stays held and is stopped; before, every slow leaver
    left with the turned one (a corner held on the ground beside three nearly equal edge
    rows lifted off, and hit again 8e-8 s later)."""
    model = TwoParticles(1e-3)
    u = np.concatenate([np.linalg.solve(model.J[:2, :2], [-5e-5, 0.0]), [0.0, 1e-15]])
    y = np.concatenate([np.zeros(4), u, [0.0]])
    out = coupled_impact(model, y, np.zeros(0), np.ones(3, bool), np.zeros(3), np.full(3, SLOWEST))
    rates = model.J @ out.y[4:8]
    assert out.leaving.tolist() == [False, True, False]
    assert abs(rates[0]) < 1e-18 and rates[2] == 0.0
    assert rates[1] == pytest.approx(5e-5 * np.cos(1e-3), rel=1e-12)


def test_a_box_pushing_a_box_on_the_ground_keeps_its_corner_on_the_ground():
    """A fuzz's scene (tests/reference/fuzz_box_pushes_box_on_ground.json, cut to 6 ms: a
    flexible box sliding at 0.508 m/s on a frictionless ground into a second one resting
    1e-6 m beside it, e = 0 between them, `edges = true`).  Pressed face to face, corners
    and mid-edge vertices coincident, many rows hold one point: three edge rows of b1's
    vertex 27 against b0's edge [7, 11] differ by 1e-5 of their entries, and a plastic
    impact of one at 8.6e-7 m/s left the other two leaving that fast; stopping them took
    1.7 N s each way, so every slow leaver was let go, b0's corner 1 off the ground at
    1e-18 m/s among them, to hit again 8e-8 s later: `chattering` at 4.65 ms (1 972
    events).  Now it pushes b1 and they part (e = 0, the springs' rebound): momentum along
    x kept (the ground pushes along z only), the corner held on the ground throughout."""
    table = reference_table("fuzz_box_pushes_box_on_ground")
    r = flexbody.simulate(flexbody.load_scene(table), max_wall_time=120.0)
    assert r.status == "success", r.message
    assert r.stats["max_penetration_m"] < 1e-9 and r.stats["max_edge_crossing_m"] == 0.0  # measured 3.5e-12 m
    assert r.stats["energy_drift_relative"] < 1e-6  # measured 1.2e-8
    assert r.stats["warnings"] == []
    momentum = np.einsum("i,ti->t", r.masses, r.velocities[:, :, 0])
    np.testing.assert_allclose(momentum, 0.288 * 0.508, rtol=1e-11)  # measured 3e-13
    surface, particle = np.asarray(r.events_surface), np.asarray(r.events_particle)
    assert not ((surface == -1) & (particle == 1)).any()  # 166 lift-offs and impacts there before
    assert np.abs(r.positions[:, :4, 2]).max() < 1e-12  # b0's bottom stays on the ground
    speed = [np.einsum("i,i->", r.masses[k], r.velocities[-1, k, 0]) / r.masses[k].sum()
             for k in (slice(0, 12), slice(12, None))]
    assert 0.0 < speed[0] < speed[1] < 0.508  # measured 0.040 and 0.207 m/s: pushed, then parted
    assert r.kinetic[-1] < r.kinetic[0]


def test_a_ring_bouncing_on_a_rigid_block_at_e_0_9_ends_its_cascade_held():
    """A flexible ring dropped 1 cm onto a rigid block (e = 0.9 between them): its lowest
    particle, pressed by the ring's springs, bounces in a Zeno cascade, 69 impacts, up to
    37 of them within 1 ms (the chatter guard's default bound is 25).  Under a steady pull
    a rebound leaving at ``e v`` is back after ``2 e v / a`` at the same speed, so the
    intervals between impacts shrink by ``e`` each, and the threshold ends the cascade held.
    The guard counts no impact that comes in slower than 0.99 of the one before: the run
    reaches its end (it stopped `chattering` at 74 ms, the 26th impact within 1 ms)."""
    e = 0.9
    scene = flexbody.load_scene({
        "name": "ring_on_block", "gravity": [0.0, -9.81], "grounds": [{"point": [0.0, 0.0], "normal": [0.0, 1.0]}],
        "bodies": [{"name": "block", "shape": "polygon", "vertices": [[-0.2, 0.0], [0.2, 0.0], [0.2, 0.1], [-0.2, 0.1]],
                    "mass": 0.5, "rigid": True, "position": [0.0, 0.0]},
                   {"name": "ring", "shape": "ring", "count": 12, "radius": 0.05, "center": True, "mass": 0.05,
                    "stiffness": 6000.0, "damping": 0.5, "position": [0.0, 0.16], "angle": 0.1}],
        "contacts": [{"bodies": ["block", "ring"], "restitution": e}],
        "simulation": {"t_end": 0.1, "output_dt": 0.005}})
    r = flexbody.simulate(scene)
    assert r.status == "success", r.message
    assert r.stats["max_penetration_m"] <= 1e-9 and r.stats["energy_drift_relative"] <= 1e-7  # 4e-16 m, 1.9e-8
    kinds, particles = np.asarray(r.events_kind), np.asarray(r.events_particle)
    lowest = np.argmax(np.bincount(particles[kinds == "impact"]))
    mine = particles == lowest
    times, held = np.asarray(r.events_time)[mine & (kinds == "impact")], np.asarray(r.events_held)[mine & (kinds == "impact")]
    assert max(np.count_nonzero((times >= t) & (times < t + 1e-3)) for t in times) > 25  # measured 37
    assert held[-1] and not held[:-1].any()  # one cascade, ended held
    intervals = np.diff(times)
    np.testing.assert_allclose(intervals[-10:] / intervals[-11:-1], e, atol=1e-3)  # measured within 3e-4


def _bouncy_disc(e: float) -> dict:
    """A 19-particle lattice disc (10 000 N/m links) landing flat on a ground of restitution e."""
    return {"name": "bouncy_disc", "gravity": [0.0, -9.81],
            "grounds": [{"point": [0.0, 0.0], "normal": [0.0, 1.0], "restitution": e}],
            "bodies": [{"name": "disc", "shape": "disc", "count": 19, "radius": 0.06, "mass_total": 0.2,
                        "stiffness": 10000.0, "damping": 1.0, "damper": "axial", "position": [0.0, 0.3]}],
            "simulation": {"t_end": 0.5, "output_dt": 0.002}}


def test_a_lattice_disc_rattling_on_a_bouncy_ground_is_told_what_ends_it():
    """At e = 0.8 a bottom particle's rebounds, faster than the speed that rises 1e-9 of the
    scene against gravity, keep pace with the disc's vibration (68 in 1 ms, at 2e-4 m/s):
    `chattering`, and the message names the one remedy that works (a helper found the
    old one's, tolerances, damping and the bound, change nothing); at e = 0.6 it runs."""
    r = flexbody.simulate(flexbody.load_scene(_bouncy_disc(0.8)))
    assert r.status == "chattering"
    assert "with e = 0.8 every rebound faster than" in r.message and "lower this ground's restitution" in r.message
    assert "--rtol" not in r.message
    assert flexbody.simulate(flexbody.load_scene(_bouncy_disc(0.6))).status == "success"
