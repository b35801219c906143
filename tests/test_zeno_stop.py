"""The Zeno stop of a coupled impact (:func:`flexbody.coupled.coupled_impact`).

A contact the impact (:func:`flexbody.coupled.coupled_impact`) leaves moving away slower
than a rebound that would rise 1e-9 of the scene is stopped with the held ones, unless that
stop takes more than ``STOP_ENERGY`` times the kinetic energy of the stopped rows' own
speeds: then the rows are nearly parallel (a crease bent by 1e-4 rad), and the slow leavers
leave.  Two rows at an angle ``a`` take ``1 / sin(a)^2`` times it, so the bound is an
angle: these tests put rows on both sides of it, and at the 15 degrees of two spheres of a
3D pile pressed face to face.  The piles of 3D spheres where this mattered are in
``tests/test_piles3d.py``.
"""

from __future__ import annotations

import numpy as np
import pytest

from flexbody.coupled import STOP_ENERGY, coupled_impact

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
