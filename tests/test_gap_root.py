"""A free contact's impact instant between bodies, searched in C on the step's dense output
(``fb_gap_root``, ``fb_dense_gaps``: :class:`flexbody.surface_contact.CompiledDenseGaps`).

References: the closed-form instant of a particle moving straight along a face's normal
onto it, and the Python search (:func:`flexbody.events._root` on the whole state,
``events.one``) and the whole state's gaps at every root and sample of piles in 2D and 3D.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate._ivp.rk import RkDenseOutput

import flexbody
from flexbody import events as located
from flexbody.bench_bodies import bodies_scene
from flexbody.model import load_model
from flexbody.scene import load_scene
from flexbody.state import initial_coordinates
from flexbody.surface_contact import FACE, VERTEX

from .conftest import HAS_CC
from .test_piles3d import sphere_pile

pytestmark = pytest.mark.skipif(not HAS_CC, reason="the search is in the compiled runtime library")


def _tolerance(t: float) -> float:
    """Where :func:`flexbody.events.first_fired` may stop after a crossing at ``t``."""
    return 2.0 * (located.ROOT_TIME + 4.0 * np.finfo(float).eps * abs(t))


def test_a_particle_moving_straight_onto_a_face_hits_at_the_closed_form_instant():
    scene = bodies_scene(2, 23, 0.1, True, stiffness=6000.0, row=True)
    model = load_model(scene)
    q, u = initial_coordinates(scene, model)
    y0 = np.concatenate([q, u, [0.0, 0.0]])  # the driver's state: then its two work terms
    n, d = model.n_particles, model.dim
    x = y0[: n * d].reshape(n, d)
    p = model.parameters(scene)
    # the left disc's particle nearest the right disc, and its slot against that disc
    left, right = np.flatnonzero(model.particle_body == 0), np.flatnonzero(model.element_body == 1)
    contact = model._closest_features(x, np.array([[i, e] for i in left for e in right]))
    row = int(np.argmin(contact.gap))
    particle = int(contact.particle[row])
    c = model.n_ground_contacts + int(np.flatnonzero((model.slot_particle == particle) & (model.slot_body == 1))[0])
    # moving along its normal, straight at its closest face or vertex, it keeps that
    # feature and its gap falls linearly
    assert contact.kind[row] in (FACE, VERTEX)
    gap0, normal = float(contact.gap[row]), contact.normal[row]
    assert gap0 > 0.0  # (farther than margin the gap reads margin: it falls linearly from there on)
    t_old, h = 0.3, 0.02
    speed = gap0 / (0.4 * h)  # the particle alone moves, straight at the feature
    Q = np.zeros((len(y0), 4))
    Q[particle * d : particle * d + d, 0] = -speed * normal
    output = RkDenseOutput(t_old, t_old + h, y0, Q)
    exact = t_old + gap0 / speed
    assert t_old < exact < t_old + h
    for floor in (0.0, 1e-6):  # (inside, a vertex's gap is not linear: a floor above 0 tests the offset)
        root = model.gap_root(output, c, floor, t_old, t_old + h, located.ROOT_TIME)
        assert root is not None
        assert exact - floor / speed <= root <= exact - floor / speed + _tolerance(exact) + 1e-16
        # the Python event function has fired there, and not a picosecond before
        assert model.gap(output(root)[: model.nq], p, c) - floor <= 0.0
        assert model.gap(output(root - 1e-12)[: model.nq], p, c) - floor > 0.0
    # none within the step: the step's end
    assert model.gap_root(output, c, 0.0, t_old, t_old + 0.5 * (exact - t_old), located.ROOT_TIME) == \
        t_old + 0.5 * (exact - t_old)
    # not above its floor at the start: the Python search decides (None)
    assert model.gap_root(output, c, gap0 + 1e-6, t_old, t_old + h, located.ROOT_TIME) is None


def test_another_steppers_dense_output_or_a_large_surface_is_left_to_python(monkeypatch):
    scene = bodies_scene(2, 23, 0.1, True, stiffness=6000.0, row=True)
    model = load_model(scene)
    c = model.n_ground_contacts + int(np.flatnonzero(model.slot_body == 1)[0])

    class OtherOutput:  # not SciPy's RkDenseOutput: its formula is not the one in C
        Q, y_old, t_old, h = np.zeros((1, 4)), np.zeros(1), 0.0, 1.0

    assert model.gap_root(OtherOutput(), c, 0.0, 0.0, 1.0, located.ROOT_TIME) is None
    assert model.gap_root(None, c, 0.0, 0.0, 1.0, located.ROOT_TIME) is None
    monkeypatch.setattr(model._dense_gaps, "searched", np.zeros_like(model._dense_gaps.searched))
    y0 = np.zeros(model.ny)
    assert model.gap_root(RkDenseOutput(0.0, 1.0, y0, np.zeros((model.ny, 4))), c, 0.0, 0.0, 1.0,
                          located.ROOT_TIME) is None
    # a ground contact has no such search
    assert model.gap_root(RkDenseOutput(0.0, 1.0, y0, np.zeros((model.ny, 4))), 0, 0.0, 0.0, 1.0,
                          located.ROOT_TIME) is None


@pytest.mark.parametrize("table", [
    pytest.param(lambda: bodies_scene(4, 23, 0.3, True, stiffness=6000.0), id="2d discs"),
    pytest.param(lambda: load_scene(sphere_pile(0.16, count=60)), id="3d spheres"),
])
def test_every_root_in_c_equals_the_python_search_along_a_pile(monkeypatch, table):
    scene = table()
    model = load_model(scene)
    search = located._root
    compared = []

    def both(events, dense, c, ta, tb, start=np.inf):
        root = search(events, dense, c, ta, tb, start)
        if events.free[c] and model.gap_root(getattr(dense, "output", None), c, float(events.phases.floor[c]), ta, tb,
                                             located.ROOT_TIME) is not None:
            kept, model._dense_gaps = model._dense_gaps, None  # the Python search, on the whole state
            try:
                compared.append((root, search(events, dense, c, ta, tb, start)))
            finally:
                model._dense_gaps = kept
        return root

    monkeypatch.setattr(located, "_root", both)
    result = flexbody.simulate(scene, model=model)
    assert result.status == "success", result.message
    roots = np.array(compared)
    assert len(roots) >= 20  # impacts between bodies were searched in C
    misses = np.abs(roots[:, 0] - roots[:, 1]) - _tolerance(roots[:, 1])
    assert misses.max() <= 0.0, f"C and Python roots apart by {np.abs(roots[:, 0] - roots[:, 1]).max():.3g} s"


@pytest.mark.parametrize("table", [
    pytest.param(lambda: bodies_scene(4, 23, 0.3, True, stiffness=6000.0), id="2d discs"),
    pytest.param(lambda: load_scene(sphere_pile(0.16, count=60)), id="3d spheres"),
])
def test_every_sample_in_c_equals_the_whole_states_gaps_along_a_pile(monkeypatch, table):
    """The event functions event location samples a step with (a just-released contact's
    dips, a crossing's contacts), in C, equal those of the whole interpolated state."""
    scene = table()
    model = load_model(scene)
    sample = located._free_gaps_at
    compared = []

    def both(events, dense, t, only):
        g = sample(events, dense, t, only)
        watched = np.flatnonzero(events.free & only)
        if getattr(dense, "output", None) is not None and model.dense_gaps(
                dense.output, watched, events.phases.floor[watched], t) is not None:
            compared.append((g[watched], events.free_gaps(dense(t), only)[watched]))
            assert np.isinf(np.delete(g, watched)).all()
        return g

    monkeypatch.setattr(located, "_free_gaps_at", both)
    result = flexbody.simulate(scene, model=model)
    assert result.status == "success", result.message
    assert len(compared) >= 20
    c, python = (np.concatenate(z) for z in zip(*compared))
    # C sums the interpolation in order, NumPy through BLAS: positions can differ by an ulp
    size = float(np.abs(result.positions).max())
    np.testing.assert_allclose(c, python, rtol=0.0, atol=8 * np.finfo(float).eps * size)
