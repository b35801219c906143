"""No step carries a particle through another body unseen (BodyContactModel.step_reach):
thin bodies, and bodies at rest relative to each other that gravity sets apart.

Found by a fuzz of 2D scenes: a rigid bar released at rest 1 cm above a rigid block resting
on the ground fell through it in one step (no relative velocity at the step's start, so
no bound), and a 5 mm plate flying at 2 m/s crossed a block in one 5 cm step (the bound
was half the median element length, ten times the plate's width).  Neither run warned:
no particle ends inside the other body, the two surfaces cross.
"""

from __future__ import annotations

import numpy as np
import pytest

import flexbody
from flexbody.driver import initial_coordinates
from flexbody.model import load_model
from flexbody.surface_contact import thinnest_width

G = 9.81


def block_and_plate(dim: int, thickness: float, drop: float, speed: float = 0.0, gravity: bool = True) -> dict:
    """A rigid block (0.12 wide, 0.08 high) on the ground (without ``gravity``, 10 m above
    it) and a rigid plate (0.2 wide, ``thickness`` thick) ``drop`` above it, falling at
    ``speed``."""
    if dim == 2:
        block = {"shape": "polygon", "vertices": [[-0.06, 0.0], [0.06, 0.0], [0.06, 0.08], [-0.06, 0.08]],
                 "position": [0.0, 0.0]}
        plate = {"shape": "polygon", "vertices": [[-0.1, 0.0], [0.1, 0.0], [0.1, thickness], [-0.1, thickness]],
                 "position": [0.0, 0.08 + drop], "velocity": [0.0, -speed]}
    else:
        block = {"shape": "box", "size": [0.12, 0.12, 0.08], "count": [2, 2, 2], "position": [0.0, 0.0, 0.04]}
        plate = {"shape": "box", "size": [0.2, 0.2, thickness], "count": [2, 2, 2],
                 "position": [0.0, 0.0, 0.08 + drop + thickness / 2], "velocity": [0.0, 0.0, -speed]}
    down = [0.0] * (dim - 1) + [-G if gravity else 0.0]
    ground = [0.0] * (dim - 1) + [0.0 if gravity else -10.0]  # in space, far below
    return {"name": "block_and_plate", "gravity": down,
            "grounds": [{"point": ground, "normal": [0.0] * (dim - 1) + [1.0]}],
            "bodies": [dict(block, name="block", rigid=True, mass=0.1), dict(plate, name="plate", rigid=True, mass=0.1)],
            "contacts": [{"bodies": ["plate", "block"]}],
            "simulation": {"t_end": 0.3, "output_dt": 1e-3}}


def plate_bottom(result, dim: int) -> np.ndarray:
    """The plate's lowest particle height at each sample, shape (nt,): its particles follow
    the block's 4 (2D) or 8 (3D)."""
    return result.positions[:, 2 ** dim :, -1].min(axis=1)


@pytest.mark.parametrize("dim", [2, 3])
def test_a_plate_released_at_rest_above_a_resting_block_lands_on_it(dim):
    """Dropped 1 cm at rest onto a block resting on the ground, the plate (2 cm thick in 2D,
    5 mm in 3D) lands on the block's top (0.08 m) and stays there: before, it fell through
    the block to the ground in one step (bottom at 0 m at the end), status success."""
    scene = flexbody.load_scene(block_and_plate(dim, 0.02 if dim == 2 else 0.005, 0.01))
    result = flexbody.simulate(scene)
    assert result.status == "success"
    bottom = plate_bottom(result, dim)
    assert bottom.min() > 0.08 - 1e-9  # never below the block's top
    assert abs(bottom[-1] - 0.08) < 1e-9
    assert result.stats["max_penetration_m"] < 1e-9


def test_a_thin_plate_flying_at_a_block_hits_it_and_both_move_on():
    """In space (no gravity) a 5 mm rigid plate at 2 m/s hits a rigid block of the same
    mass: a plastic impact (e = 0) leaves both at 1 m/s, the plate on the block's top face.
    Before, the plate crossed the block in one 5 cm step: no event, 2 m/s at the end."""
    scene = flexbody.load_scene(block_and_plate(2, 0.005, 0.01, speed=2.0, gravity=False))
    result = flexbody.simulate(scene, t_end=0.05)
    assert result.status == "success" and len(result.events_time) >= 1
    v = result.velocities[-1, :, 1]
    np.testing.assert_allclose(v, -1.0, atol=1e-9)  # every particle of both: momentum shared
    top = result.positions[:, :4, 1].max(axis=1)  # the block's top corners
    np.testing.assert_array_less(top - 1e-9, result.positions[:, 4:, 1].min(axis=1))  # the plate stays above


def test_the_reach_is_the_thinnest_bodys_width_where_that_is_below_the_margin():
    """``thinnest_width``: a 5 mm plate beside a block reads 5 mm; a ring (no face across
    within the margin) reads the margin; the step's reach is STEP_REACH of it."""
    scene = flexbody.load_scene(block_and_plate(2, 0.005, 0.01))
    model = load_model(scene)
    x = scene.initial_positions().reshape(-1, 2)
    width = thinnest_width(x, model.elements, model.particle_body, model.element_body, model.margin)
    assert width == pytest.approx(0.005, rel=1e-9) and model.margin == pytest.approx(0.1)
    assert model.reach_length == pytest.approx(0.5 * 0.005, rel=1e-9)
    rings = flexbody.load_scene("colliding_rings")
    ring_model = load_model(rings)
    x = rings.initial_positions().reshape(-1, 2)
    assert thinnest_width(x, ring_model.elements, ring_model.particle_body, ring_model.element_body,
                          ring_model.margin) == ring_model.margin


def test_a_step_bound_counts_the_accelerations_a_resting_body_does_not_share():
    """At rest (no relative velocity) the bound comes from the relative acceleration alone:
    the plate falls at g while the block held on the ground does not, so a step may last
    sqrt(2 reach / g) (before: unbounded); without the rate, at rest, it is unbounded."""
    scene = flexbody.load_scene(block_and_plate(2, 0.02, 0.01))
    model = load_model(scene)
    p = model.parameters(scene)
    q, u = initial_coordinates(scene, model)
    y = np.concatenate([q, u, [0.0, 0.0]])
    held = np.zeros(model.n_contacts, np.intc)
    held[:4] = 1  # the block's corners on the ground (the plate's four come after: not on it)
    assert np.flatnonzero(model.contacts[:4, 0] < 4).size == 4  # (they are the block's particles)
    ydot = model.rhs(y, p, held, np.zeros(model.n_contacts))[0]
    assert model.step_reach(y, p) == np.inf
    np.testing.assert_allclose(model.step_reach(y, p, ydot), np.sqrt(2 * model.reach_length / G), rtol=1e-6)
