"""The table of contacts between bodies grows with the pairs in reach, not with the square
of the bodies (BodyContactModel.with_pairs, the driver's _Run.grow).

A run starts with slots for the scene's pairs whose bodies' boxes lie within
``pairs_ahead`` of each other and gives a pair its slots at the end of the step that
brings it there; a step that ends with a pair without slots within ``pairs_late`` is taken
again with them.  The runs below are compared with the same scenes run on the whole table
(``grows = False``): the same numbers, bit for bit, where the growth happens at a step's
end; the same events to the event tolerance where a step is taken again.
"""

from __future__ import annotations

import copy
import tomllib
from importlib import resources

import numpy as np
import pytest

import flexbody
from flexbody import body_contact, driver
from flexbody.bench_bodies import bodies_scene_table
from flexbody.contact import Phases
from flexbody.model import load_model
from flexbody.scene import load_scene
from flexbody.samples import ContactSamples

ARRAYS = ("t", "positions", "velocities", "contact_force", "friction_force", "kinetic", "spring", "gravity",
          "damping_work", "impact_loss", "friction_work", "events_time", "events_particle", "events_kind",
          "events_held", "events_surface")


def rings_far_apart(friction: float = 0.0, offset: float = 0.0) -> dict:
    """Two flexible rings 0.8 m apart in free flight, meeting head-on at 2 m/s at t ~ 0.4 s
    (``offset``: the right one that much higher, a glancing meeting), ``friction`` between them."""
    def ring(name, x, y, v):
        return {"name": name, "shape": "ring", "count": 11, "radius": 0.1, "center": True, "mass": 0.05,
                "stiffness": 2000.0, "damping": 0.5, "damper": "axial", "position": [x, y], "velocity": [v, 0.0]}
    return {"name": "rings_far_apart", "gravity": [0.0, 0.0],
            "grounds": [{"point": [0.0, -10.0], "normal": [0.0, 1.0]}],
            "bodies": [ring("left", -0.5, 0.0, 1.0), ring("right", 0.5, offset, -1.0)],
            "contacts": [{"bodies": ["left", "right"], "friction": friction}],
            "simulation": {"t_end": 0.5, "output_dt": 0.002, "rtol": 1e-9, "atol": 1e-12}}


def run_both(table: dict) -> tuple:
    """``table`` run with a growing contact table, with the growths it made (time, pairs),
    and on the whole table."""
    scene = load_scene(table)
    growths = []
    grow = driver._Run.grow

    def spy(run, pairs):
        growths.append(np.asarray(pairs).tolist())
        grow(run, pairs)

    driver._Run.grow = spy
    try:
        grown = flexbody.simulate(scene)
    finally:
        driver._Run.grow = grow
    whole_model = load_model(scene)
    whole_model.grows = False
    whole = flexbody.simulate(scene, model=whole_model)
    return grown, whole, growths


def assert_same_run(a, b) -> None:
    assert a.status == b.status == "success"
    for name in ARRAYS:
        assert np.array_equal(getattr(a, name), getattr(b, name)), name


@pytest.mark.parametrize("friction, offset", [(0.0, 0.0), (0.4, 0.12)])
def test_a_pair_gets_its_slots_as_it_comes_near_and_the_run_is_the_same(friction, offset):
    """Rings 0.8 m apart start without slots; their pair gets them once, at a step's end
    before they touch, and the run is the whole table's bit for bit (head-on, and glancing
    with friction: its slips are recorded per sample)."""
    grown, whole, growths = run_both(rings_far_apart(friction, offset))
    assert growths == [[0]]
    assert grown.stats["contact_pairs"] == whole.stats["contact_pairs"] == 1
    assert grown.stats["segments"] == whole.stats["segments"] + 1  # the growth's stop
    assert grown.stats["steps_retaken_for_pairs"] == 0
    assert grown.stats["model_digest"] == whole.stats["model_digest"]
    assert len(grown.events_time) and (grown.events_surface >= 0).all()
    if friction:
        assert grown.friction_work[-1] > 0.0
    assert_same_run(grown, whole)


def test_slots_made_before_a_growth_move_with_their_events_and_samples():
    """Three rings in a row: the left one hits the middle one, whose pair then holds and
    releases contacts, and the middle one carries on into the right one.  That pair is
    listed first, so its slots come first in the table: the earlier pair's slots, their
    events, phases and samples all move when it gets them, and the run is the whole
    table's bit for bit."""
    table = rings_far_apart()
    table["bodies"][1]["position"], table["bodies"][1]["velocity"] = [0.0, 0.0], [0.0, 0.0]
    table["bodies"].append(dict(table["bodies"][1], name="far", position=[0.6, 0.0]))
    table["contacts"] = [{"bodies": ["right", "far"]}, {"bodies": ["left", "right"]}]
    table["simulation"]["t_end"] = 1.6
    grown, whole, growths = run_both(table)
    assert growths == [[1], [0]]
    # the left ring's particle 1 hits the middle ring and leaves it, then the middle one's particle 13 the far one
    assert grown.events_surface.tolist() == [1, 1, 2, 2] and grown.events_particle.tolist() == [1, 1, 13, 13]
    assert_same_run(grown, whole)


def test_a_pile_gives_slots_to_the_pairs_that_come_near_only():
    """Six small discs in a pile (15 pairs may touch): the neighbours' pairs get slots, the
    run is the whole table's bit for bit, and its table is a fraction of the whole's."""
    grown, whole, _ = run_both(bodies_scene_table(6, 23, 0.3, True, stiffness=2e4))
    assert grown.stats["contact_pairs_in_scene"] == 15
    assert 0 < grown.stats["contact_pairs"] < 15
    assert grown.stats["events"] > 50 and (grown.events_surface >= 0).any()  # they land on each other
    assert_same_run(grown, whole)


def plate_on_block() -> dict:
    """A rigid plate dropped 0.3 m onto a rigid block resting on the ground."""
    return {"name": "plate_on_block", "gravity": [0.0, -9.81],
            "grounds": [{"point": [0.0, 0.0], "normal": [0.0, 1.0]}],
            "bodies": [{"name": "block", "shape": "polygon", "rigid": True, "mass": 0.1, "position": [0.0, 0.0],
                        "vertices": [[-0.06, 0.0], [0.06, 0.0], [0.06, 0.08], [-0.06, 0.08]]},
                       {"name": "plate", "shape": "polygon", "rigid": True, "mass": 0.1, "position": [0.01, 0.38],
                        "vertices": [[-0.1, 0.0], [0.1, 0.0], [0.1, 0.02], [-0.1, 0.02]]}],
            "contacts": [{"bodies": ["plate", "block"]}],
            "simulation": {"t_end": 0.4, "output_dt": 1e-3}}


def test_a_rigid_plate_dropped_from_afar_onto_a_rigid_block_gets_its_slots_on_the_way():
    """Rigid bodies (the floating formulation's frames): a plate dropped 0.3 m onto a block
    resting on the ground gets its pair's slots in flight and lands as on the whole table."""
    grown, whole, growths = run_both(plate_on_block())
    assert growths == [[0]]
    assert (grown.positions[-1, 4:, 1] > 0.08 - 1e-9).all()  # the plate rests on the block's top
    assert_same_run(grown, whole)


def test_a_segments_step_bound_goes_on_past_the_stop_where_pairs_get_slots(monkeypatch):
    """A step of the segment in which the plate falls is taken again shorter (the block's
    held contacts sank: forced here, once in each run, halfway to the pair's growth), which
    bounds the segment's later steps.  The stop where the pair gets its slots is no event:
    the next segment keeps that bound, and the run is the whole table's bit for bit (where
    that stop dropped it, the steps after it were longer and the landing differed)."""
    stops = []
    segment = driver._Run.segment

    def spy(run, t0, t_bound):
        stop = segment(run, t0, t_bound)
        stops.append((stop.t, stop.grow is not None))
        return stop

    monkeypatch.setattr(driver._Run, "segment", spy)
    flexbody.simulate(load_scene(plate_on_block()))
    (t_growth,) = [t for t, grew in stops if grew]
    assert not [t for t, grew in stops if 0.5 * t_growth <= t < t_growth]  # one segment from halfway to it
    sank, forced = driver._Run.sank, []

    def sinks_once(run, drift, dense, t_start, t_end, rows=None):
        if t_start > 0.5 * t_growth and not getattr(run, "forced", False):
            run.forced = True
            forced.append(t_start)
            return True
        return sank(run, drift, dense, t_start, t_end, rows)

    monkeypatch.setattr(driver._Run, "sank", sinks_once)
    grown, whole, growths = run_both(plate_on_block())
    assert growths == [[0]]
    assert len(forced) == 2 and forced[0] == forced[1] < t_growth  # the same step in both runs
    assert_same_run(grown, whole)


def test_a_sphere_dropped_onto_another_gets_its_slots_on_the_way():
    """3D: a sphere dropped 0.5 m onto another resting on the ground gets its pair's slots
    in flight and lands, bounces and rests on it as on the whole table."""
    spheres = [{"name": f"s{k}", "shape": "sphere", "count": 30, "radius": 0.1, "center": True, "mass_total": 0.5,
                "stiffness": 2000.0, "damping": 0.5, "damper": "relative",
                "position": [0.03 * k, 0.0, 0.1 + 0.6 * k], "collide": True} for k in range(2)]
    table = {"name": "spheres", "bodies": spheres, "gravity": [0.0, 0.0, -9.81],
             "grounds": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0]}],
             "simulation": {"t_end": 0.45, "output_dt": 0.005, "method": "RK45", "rtol": 1e-6, "atol": 1e-9}}
    grown, whole, growths = run_both(table)
    assert growths == [[0]]
    assert (grown.events_surface >= 0).sum() > 100  # it lands on the other and rests there
    assert_same_run(grown, whole)


@pytest.mark.slow
def test_a_disc_dropped_from_higher_onto_the_seesaw_gets_its_slots_on_the_way():
    """Rigid frames beside a flexible disc (flexbody.mixed): the seesaw's disc, dropped from
    0.23 m higher, gets its pair with the plank in flight (the wedge's and the plank's has
    them from the start) and tips the plank as on the whole table (7 s)."""
    table = tomllib.loads((resources.files("flexbody") / "scenes" / "seesaw.toml").read_text())
    table["bodies"][2]["position"] = [-0.42, 0.75]
    table["simulation"]["t_end"] = 0.4
    grown, whole, growths = run_both(table)
    assert growths == [[1]] and grown.stats["contact_pairs"] == 2
    assert (grown.events_surface >= 0).sum() > 20
    assert_same_run(grown, whole)


def test_a_step_that_ends_with_a_pair_near_and_without_slots_is_taken_again(monkeypatch):
    """With no lead (``PAIRS_AHEAD`` = ``PAIRS_LATE``), the rings' pair first comes near at
    the end of a step taken without its slots: the step is taken again with them, and the
    meeting is the whole table's to the event tolerance, no deeper."""
    monkeypatch.setattr(body_contact, "PAIRS_AHEAD", body_contact.PAIRS_LATE)
    grown, whole, growths = run_both(rings_far_apart())
    assert growths == [[0]]
    assert grown.stats["steps_retaken_for_pairs"] == 1
    assert grown.status == whole.status == "success"
    assert len(grown.events_time) == len(whole.events_time)
    assert np.array_equal(grown.events_particle, whole.events_particle)
    assert np.abs(grown.events_time - whole.events_time).max() < 1e-9
    assert grown.stats["max_penetration_m"] < 1e-9


def test_slots_map_by_particle_body_and_twin_and_carry_their_state():
    """``contact_map`` finds each contact of a smaller table in a larger one by its particle,
    body and corner twin (the grounds' in place), -1 where the other has none; ``with_pairs``
    carries the held element, margin floor and slip direction of every slot it keeps."""
    table = bodies_scene_table(3, 23, 0.1, True)
    whole = load_model(load_scene(table))
    part = whole.with_pairs([1])
    assert part.pairs.tolist() == [1] and part.waiting.tolist() == [0, 2] and part.digest == whole.digest
    ng = whole.n_ground_contacts
    into_whole = whole.contact_map(part)
    assert np.array_equal(into_whole[:ng], np.arange(ng))
    assert len(np.unique(into_whole)) == part.n_contacts and (into_whole >= 0).all()
    assert np.array_equal(whole.contacts[into_whole], part.contacts)
    slots = into_whole[ng:] - ng
    assert np.array_equal(slots // whole.n_primary, np.arange(part.n_slots) // part.n_primary)  # the same twin
    into_part = part.contact_map(whole)
    assert (into_part[ng:] >= 0).sum() == part.n_slots
    assert np.array_equal(whole.slot_pair[into_part[ng:] >= 0], np.ones(part.n_slots, int))
    part.element_of[3], part.margin_floor[3], part._slip[ng + 3] = 7, -1e-12, [0.6, 0.8]
    grown = part.with_pairs([0, 1, 2])
    assert grown.n_slots == whole.n_slots
    at = grown.contact_map(part)[ng + 3] - ng
    assert (grown.element_of[at], grown.margin_floor[at], grown._slip[ng + at].tolist()) == (7, -1e-12, [0.6, 0.8])
    assert (np.delete(grown.element_of, at) == -1).all()


def test_pair_separations_are_the_gaps_between_the_bodies_boxes():
    """Against the boxes computed body by body: the widest gap along an axis, <= 0 where
    they overlap."""
    scene = load_scene(bodies_scene_table(4, 23, 0.1, True))
    model = load_model(scene)
    p = model.parameters(scene)
    q = np.random.default_rng(1).normal(0.0, 0.3, model.nq)
    x = q.reshape(-1, 2)
    pairs = np.arange(len(model.pairs))
    expected = []
    for a, b in model._pair_bodies.T:
        xa, xb = x[model.particle_body == a], x[model.particle_body == b]
        expected.append(np.maximum(xa.min(0) - xb.max(0), xb.min(0) - xa.max(0)).max())
    assert np.allclose(model.pair_separations(q, p, pairs), expected, rtol=0, atol=1e-15)
    near = model.pairs_in_reach(q, p, 0.0)
    assert np.array_equal(near, np.flatnonzero(np.array(expected) <= 0.0))


def test_phases_and_samples_move_to_a_larger_table():
    """Each contact's phase and each sample's entries land at their new index; the new
    contacts read free (armed at 0, no push, no element)."""
    phases = Phases.all_free(3)
    phases.phase[:] = [0, 1, 3]
    phases.floor[:] = [-1e-12, 0.0, 0.0]
    phases.push_until[2] = 0.5
    phases.implied[0] = True
    moved = phases.moved(np.array([0, 2, 4]), 5)
    assert moved.phase.tolist() == [0, 0, 1, 0, 3] and moved.floor.tolist() == [-1e-12, 0, 0, 0, 0]
    assert moved.push_until.tolist() == [np.inf, np.inf, np.inf, np.inf, 0.5]
    assert moved.implied.tolist() == [True, False, False, False, False]
    samples = ContactSamples(3, 1, 2, False)
    samples.keep(0, 2, np.array([0, 1, 0], np.intc), np.zeros(3), elements=np.array([4]))
    samples.keep(2, 3, np.array([0, 0, 3], np.intc), np.array([0.0, 0.0, 2.0]), elements=np.array([-1]))
    before = copy.deepcopy(samples)
    samples.move(np.array([0, 3, 4]), 5, np.array([2]), 3)
    dense, old = samples.dense(slice(0, 3)), before.dense(slice(0, 3))
    assert dense.held.tolist() == [[0, 0, 0, 1, 0], [0, 0, 0, 1, 0], [0, 0, 0, 0, 3]]
    assert np.array_equal(dense.held[:, [0, 3, 4]], old.held) and np.array_equal(dense.push[:, [0, 3, 4]], old.push)
    assert dense.elements.tolist() == [[-1, -1, 4], [-1, -1, 4], [-1, -1, -1]]
    samples.keep(3, 4, np.array([0, 1, 0, 0, 0], np.intc), np.zeros(5), elements=np.array([-1, 6, -1]))
    samples.move(np.array([0, 1, 2, 4, 5]), 6, np.array([0, 1, 3]), 4)  # a second move: the first runs go through both
    dense = samples.dense(slice(0, 4))
    assert dense.held.tolist() == [[0, 0, 0, 0, 1, 0], [0, 0, 0, 0, 1, 0], [0, 0, 0, 0, 0, 3], [0, 1, 0, 0, 0, 0]]
    assert dense.push[2].tolist() == [0, 0, 0, 0, 0, 2.0]
    assert dense.elements.tolist() == [[-1, -1, -1, 4], [-1, -1, -1, 4], [-1, -1, -1, -1], [-1, 6, -1, -1]]
