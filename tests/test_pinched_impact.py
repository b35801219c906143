"""Impacts that Newton's law cannot resolve (:func:`flexbody.coupled.coupled_impact`).

Newton's law per contact asks each hit contact to leave at ``e`` times its approach.  A body
held between two others, hit on one side (``e > 0``) while touching the other (``e = 0``),
would have to leave both: the LCP is infeasible (with ``z = (1, 1)`` on the two opposed
rows, ``J^T z = 0`` and ``q . z = -e v < 0``), and Lemke's method ends on a secondary ray.
The impact then follows Poisson's two phases (compression and restitution, each a plastic
impact), which always have an answer; where Newton's law has one it is used unchanged.
"""

from __future__ import annotations

import numpy as np
import pytest

from flexbody.contact_problems import solve_impact
from flexbody.coupled import POISSON, coupled_impact


class PointBetween:
    """A unit point mass in 2D with contact rows ``normals`` (k, 2) on its velocity (M = I),
    and with ``mu`` their tangents (the normals turned left) below them: what
    :func:`coupled_impact` asks of a model."""

    dim = 2

    def __init__(self, normals, mu=None) -> None:
        self.N = np.asarray(normals, float)
        self.n_contacts, self.nq, self.nu = len(self.N), 2, 2
        self.mu = None if mu is None else np.asarray(mu, float)

    def contact_coupling(self, q, u, p, rows, tangents=False):
        n = self.N[rows]
        J = np.vstack([n, n @ np.array([[0.0, 1.0], [-1.0, 0.0]])]) if tangents else n
        return J, slice(None), J @ J.T, lambda P: J.T @ P, np.zeros(len(J))

    def energies(self, q, u, p):
        return np.array([0.5 * float(u @ u)])


def impact(model, u, e, notes):
    y = np.concatenate([np.zeros(2), np.asarray(u, float), [0.0]])
    k = model.n_contacts
    return coupled_impact(model, y, np.zeros(0), np.ones(k, bool), np.asarray(e, float), np.zeros(k), notes=notes)


def test_newtons_law_has_no_answer_for_a_point_pinched_between_two_walls():
    W = np.array([[1.0, -1.0], [-1.0, 1.0]])  # floor below, ceiling above, both touching
    solution = solve_impact(W, np.array([-1.0, 1.0]), np.array([0.5, 0.0]))
    assert not solution.solved and "secondary ray" in solution.message


@pytest.mark.parametrize("e", [0.5, 1.0])
def test_a_pinched_point_hit_on_one_side_stops_in_the_normal_and_slides_on(e):
    """Floor (e) and ceiling (e = 0) through the point: falling at 1 m/s and sliding at 0.3
    m/s, it cannot bounce up into the ceiling.  Poisson's phases stop its normal motion;
    without friction its slide is untouched and the kinetic energy lost is the fall's."""
    notes: list[str] = []
    out = impact(PointBetween([[0.0, 1.0], [0.0, -1.0]]), [0.3, -1.0], [e, 0.0], notes)
    np.testing.assert_allclose(out.y[2:4], [0.3, 0.0], atol=1e-15)
    assert out.loss == pytest.approx(0.5, rel=1e-12)
    assert not out.leaving.any()
    assert len(notes) == 1 and POISSON in notes[0] and "secondary ray" in notes[0]


def test_where_newtons_law_has_an_answer_it_is_used():
    """A floor (e = 0.5) and a wall (e = 0) at right angles, both hit: each contact its own
    law (the point leaves the floor at half its fall and stops against the wall), no note."""
    notes: list[str] = []
    out = impact(PointBetween([[0.0, 1.0], [1.0, 0.0]]), [-2.0, -1.0], [0.5, 0.0], notes)
    np.testing.assert_allclose(out.y[2:4], [0.0, 0.5], atol=1e-15)
    assert out.leaving.tolist() == [True, False] and notes == []


def test_the_two_phases_keep_a_frictional_pinch_within_coulombs_cone():
    """The same pinch with friction (mu = 0.2 on both walls): the normal motion stops, the
    slide slows, the total impulse of each wall lies in its cone, and no energy is made."""
    model = PointBetween([[0.0, 1.0], [0.0, -1.0]], mu=[0.2, 0.2])
    notes: list[str] = []
    u = np.array([0.3, -1.0])
    out = impact(model, u, [0.5, 0.0], notes)
    after = out.y[2:4]
    assert abs(after[1]) < 1e-15 and 0.0 <= after[0] < 0.3
    assert out.loss > 0.5 - 1e-12
    # the walls' impulses: normal (out.impulses) and tangential (the rest of the momentum change)
    change = after - u
    tangential = -change[0]  # both tangents are along x, up to sign: their sum took this much
    assert abs(tangential) <= 0.2 * out.impulses.sum() + 1e-12
    assert len(notes) == 1 and POISSON in notes[0]
