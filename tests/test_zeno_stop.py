"""Accumulations of impacts: the Zeno stop of a coupled impact and the chatter guard.

A contact the impact (:func:`flexbody.coupled.coupled_impact`) leaves moving away slower
than a rebound that would rise 1e-9 of the scene is stopped with the held ones, unless that
stop takes more than ``STOP_ENERGY`` times the kinetic energy of the stopped rows' own
speeds: then the rows are nearly parallel (a crease bent by 1e-4 rad), and the slow leavers
leave.  Two rows at an angle ``a`` take ``1 / sin(a)^2`` times it, so the bound is an
angle: these tests put rows on both sides of it, and at the 15 degrees of two spheres of a
3D pile pressed face to face.  The chatter guard stops a run where a particle is impacted
more than 25 times within 1 ms in a row without being held, or is held and released again
more than 25 times; cascades of rebounds that end held are no chattering (a pile of 3D
spheres with e = 0.5 between them).
"""

from __future__ import annotations

import numpy as np
import pytest

import flexbody
from flexbody.coupled import STOP_ENERGY, coupled_impact
from flexbody.scene import load_scene

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


def sphere_pile(t_end: float, count: int = 100, restitution: float | None = None) -> dict:
    """Five spheres of ``count`` particles (0.1 m, 0.5 kg, 2000 N/m, relative dampers 0.5 N
    s/m): three in a row 2 cm apart, 5 cm above the ground, two above their gaps, each turned
    differently; every pair may touch, with ``restitution`` if given."""
    radius, gap, lift = 0.1, 0.02, 0.05
    pitch = 2 * radius + gap
    rise = np.sqrt(pitch**2 - (pitch / 2) ** 2)
    centres = [[i * pitch, 0.0, radius + lift] for i in range(3)]
    centres += [[(i + 0.5) * pitch, 0.0, radius + lift + rise] for i in range(2)]
    bodies = [{"name": f"s{i}", "shape": "sphere", "count": count, "radius": radius, "center": True,
               "mass_total": 0.5, "stiffness": 2000.0, "damping": 0.5, "damper": "relative", "position": c,
               "rotation": [0.1 * i, 0.05 * i, 0.0], "collide": True} for i, c in enumerate(centres)]
    table = {"name": "sphere_pile", "gravity": [0.0, 0.0, -9.81], "bodies": bodies,
             "simulation": {"t_end": t_end, "output_dt": 0.01, "method": "RK45", "rtol": 1e-6, "atol": 1e-9}}
    if restitution is not None:
        table["contacts"] = [{"bodies": [f"s{i}", f"s{j}"], "restitution": restitution}
                             for i in range(len(bodies)) for j in range(i + 1, len(bodies))]
    return table


@pytest.mark.slow
def test_a_pile_of_3d_spheres_lands_on_each_other_without_chattering():
    """The upper spheres land on the lower ones at 0.14 s; at 0.147 s two of them press two
    faces 15 degrees apart together, each face touching the other sphere near its vertex.
    With the former bound the pile stopped there, ``chattering`` (26 impacts of one particle
    within 1 ms).  Now it runs on: no particle inside another body or the ground by more
    than 1e-9 m, and the energy ledger closed."""
    r = flexbody.simulate(load_scene(sphere_pile(0.2)))
    assert r.status == "success", r.message
    assert r.stats["max_penetration_m"] < 1e-9
    assert r.stats["energy_drift_relative"] < 1e-6


@pytest.mark.slow
def test_a_pile_of_3d_spheres_with_rebounds_between_them_lands_without_chattering():
    """With e = 0.5 between five 60-particle spheres, a particle of an upper sphere landing on
    a lower one rebounds in cascades (0.15, 0.075, ... m/s, the seventh held by the Zeno
    threshold), and its neighbours' impacts release it again: 4 cascades, 26 impacts within
    1 ms at 0.140 s, which the guard took for chattering.  Each cascade ends held, so the
    pile runs on: no penetration above 1e-9 m, the energy ledger closed."""
    r = flexbody.simulate(load_scene(sphere_pile(0.2, count=60, restitution=0.5)))
    assert r.status == "success", r.message
    assert r.stats["max_penetration_m"] < 1e-9
    assert r.stats["energy_drift_relative"] < 1e-6
