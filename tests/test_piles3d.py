"""Piles of 3D bodies landing on each other: what vertex-face contacts between triangle
meshes meet there, each case a run that used to stop.

* Two spheres pressing two faces 15 degrees apart together, each face touching the other
  sphere near its vertex, rock on the two rows (the Zeno stop's bound,
  ``tests/test_zeno_stop.py``).
* With e = 0.5 between spheres a particle rebounds in cascades that end held and are
  released again by its neighbours' impacts (the chatter guard counts a cascade ending
  held as its hold).
* A stack of flexible boxes with e = 0.5 between them: an impact whose LCP answer misses
  its final check by rounding is taken when Newton's law holds with the restitution.
"""

from __future__ import annotations

import numpy as np
import pytest

import flexbody
from flexbody.scene import load_scene

from .conftest import reference_table


def run_to(table: dict) -> flexbody.SimulationResult:
    """``table`` simulated; it must succeed with no particle inside another body or the
    ground by more than 1e-9 m and its energy ledger closed to 1e-6."""
    r = flexbody.simulate(load_scene(table))
    assert r.status == "success", r.message
    assert r.stats["max_penetration_m"] < 1e-9
    assert r.stats["energy_drift_relative"] < 1e-6
    return r


def every_pair(bodies: list[dict], restitution: float) -> list[dict]:
    """A ``[[contacts]]`` entry with ``restitution`` for every pair of ``bodies``."""
    return [{"bodies": [a["name"], b["name"]], "restitution": restitution}
            for k, a in enumerate(bodies) for b in bodies[k + 1 :]]


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
    return pile(bodies, t_end, restitution)


def pile(bodies: list[dict], t_end: float, restitution: float | None) -> dict:
    """A 3D scene of ``bodies`` on the default ground, every pair may touch (with
    ``restitution`` if given); SciPy RK45 at rtol 1e-6."""
    table = {"name": "pile", "gravity": [0.0, 0.0, -9.81], "bodies": bodies,
             "simulation": {"t_end": t_end, "output_dt": 0.01, "method": "RK45", "rtol": 1e-6, "atol": 1e-9}}
    if restitution is not None:
        table["contacts"] = every_pair(bodies, restitution)
    return table


@pytest.mark.slow
def test_a_pile_of_3d_spheres_lands_on_each_other_without_chattering():
    """The upper spheres land on the lower ones at 0.14 s; at 0.147 s two of them press two
    faces 15 degrees apart together, each face touching the other sphere near its vertex.
    With the Zeno stop's former bound (10) the pile stopped there, ``chattering`` (26
    impacts of one particle within 1 ms)."""
    run_to(sphere_pile(0.2))


@pytest.mark.slow
def test_a_pile_of_3d_spheres_with_rebounds_between_them_lands_without_chattering():
    """With e = 0.5 between five 60-particle spheres, a particle of an upper sphere landing on
    a lower one rebounds in cascades (0.15, 0.075, ... m/s, the seventh held by the Zeno
    threshold), and its neighbours' impacts release it again: 4 cascades, 26 impacts within
    1 ms at 0.140 s, which the former guard took for chattering."""
    run_to(sphere_pile(0.2, count=60, restitution=0.5))


@pytest.mark.slow
def test_a_stack_of_flexible_boxes_with_rebounds_between_them_comes_down():
    """Three flexible boxes (3 x 3 x 2 particles, 0.3 x 0.3 x 0.1 m, 1 kg, 4000 N/m) stacked
    13 cm apart, each offset and turned, e = 0.5 between them.  At 0.5225 s an impact of 15
    contacts had an LCP answer that missed Lemke's final check by 9e-13 m/s (a contact at
    rest left approaching); the rounding check read the rebounding contact's velocity after,
    e |v-|, as a complementarity error (0.0117 m/s) and stopped the stack with
    ``unsupported``: it reads ``v+ + e v-`` now."""
    boxes = [{"name": f"b{i}", "shape": "box", "count": [3, 3, 2], "size": [0.3, 0.3, 0.1], "mass_total": 1.0,
              "stiffness": 4000.0, "damping": 0.5, "damper": "relative",
              "position": [0.03 * i, 0.02 * i, 0.06 + 0.13 * i], "rotation": [0.02 * i, 0.03 * i, 0.3 * i]}
             for i in range(3)]
    run_to(pile(boxes, 0.55, 0.5))


@pytest.mark.slow
@pytest.mark.parametrize("count, restitution", [(200, None), (100, 0.5)])
def test_finer_3d_spheres_stop_in_a_burst_of_impacts_that_a_raised_chatter_bound_lets_settle(count, restitution):
    """Five 200-particle spheres (plastic) and five 100-particle spheres with e = 0.5 between
    them: at 0.135 s two spheres press faces together, each held by its vertices on the
    other's faces, and the patch takes turns (each impact lifts its neighbours off at 4e-3 to
    5e-2 m/s, far above the Zeno speed): one particle is held and released again more than 25
    times within 1 ms, and the default guard stops the pile with ``chattering``.  The burst
    ends: with ``simulation.chatter_impacts = 100`` the pile runs on, nothing inside anything
    by 1e-9 m and the ledger closed to 1e-6."""
    table = sphere_pile(0.2, count=count, restitution=restitution)
    stopped = flexbody.simulate(load_scene(table))
    assert stopped.status == "chattering" and "held and released again" in stopped.message
    assert 0.13 < stopped.events_time[-1] < 0.14
    table["simulation"]["chatter_impacts"] = 100
    run_to(table)


@pytest.mark.slow
@pytest.mark.parametrize("count, t_end", [(60, 0.145), (100, 0.2)])
def test_piles_of_spheres_with_edge_contacts_keep_edges_out_of_each_other(count, t_end):
    """The five-sphere pile with ``edges = true`` on every pair: no edge passes through a
    triangle of another sphere (without edge contacts they cross by millimetres: 2.6 mm and
    1.8 mm measured), nothing is inside anything by 1e-9 m and the ledger closes to 1e-6.
    The 100-particle pile read 5.1e-7 m inside when a sphere's nearly flat edges (4e-5 rad)
    counted as creased only past 6.3e-5 rad, and 2e-9 m with two rows per edge."""
    table = sphere_pile(t_end, count=count)
    table["simulation"]["chatter_impacts"] = 100
    without = flexbody.simulate(load_scene(table))
    assert without.success and without.stats["max_edge_crossing_m"] > 1e-3
    table["contacts"] = [dict(pair, edges=True) for pair in every_pair(table["bodies"], 0.0)]
    assert run_to(table).stats["max_edge_crossing_m"] == 0.0


@pytest.mark.slow  # a rigid box derived whole (cold cache); the run ~15 s
def test_a_held_contact_is_kept_on_its_surface_inside_a_step_not_only_at_its_ends():
    """A fuzz's pile (tests/reference/fuzz_pile_sink_inside_a_step.json: a soft sphere, three
    flexible boxes and a rigid one, frictionless, `edges = true`).  An impact fell inside an
    RK45 step whose held contacts were 3e-11 m off their surfaces at its end and midpoint,
    but 1.2e-9 m at 3/8 of it on the dense output (less accurate inside a step): the instant
    started from there, 1.07e-9 m inside (warned: "a held contact sank").  The step's
    quarter points are checked too: such a step is taken again, shorter."""
    table = reference_table("fuzz_pile_sink_inside_a_step")
    r = flexbody.simulate(load_scene(table), max_wall_time=120.0)
    assert r.status == "success", r.message
    assert r.stats["max_penetration_m"] < 1e-9  # measured 3.2e-11 m
    assert not any("sank" in w or "between event checks" in w for w in r.stats["warnings"])
    assert r.stats["energy_drift_relative"] < 1e-6
