"""The samples' contact sets kept sparse (flexbody.samples) and the outputs built from them a
few samples at a time: the same arrays as dense storage, whatever the chunk size."""

from __future__ import annotations

import numpy as np
import pytest

import flexbody
from flexbody import samples
from flexbody.samples import ContactSamples

from .conftest import HAS_CC


def test_kept_contact_sets_read_back_as_the_dense_arrays_they_replace(rng):
    """Random contact sets kept over random runs of samples (held codes, pushes, tangential
    pushes, slots' elements, some entries at their fill): every slice of samples reads back
    as the dense arrays a (samples, contacts) store would hold, and so does each sample."""
    n, nc, ns, dim = 57, 40, 24, 3
    store = ContactSamples(nc, ns, dim, tangential=True)
    dense = {"held": np.zeros((n, nc), np.intc), "push": np.zeros((n, nc)), "tangential": np.zeros((n, nc, dim)),
             "elements": np.full((n, ns), -1, np.intp)}
    bounds = np.unique(np.concatenate([[0, n], rng.integers(0, n, 12)]))
    for start, stop in zip(bounds[:-1], bounds[1:]):
        on = rng.random(nc) < 0.2
        held = np.where(on, rng.integers(1, 4, nc), 0).astype(np.intc)
        push = np.where(rng.random(nc) < 0.1, rng.uniform(0.1, 5.0, nc), 0.0)
        tangential = np.where((rng.random(nc) < 0.1)[:, None], rng.normal(size=(nc, dim)), 0.0)
        tangential[0, 1] = 0.5  # a row with some components at the fill
        elements = np.where(rng.random(ns) < 0.3, rng.integers(0, 50, ns), -1)
        store.keep(int(start), int(stop), held, push, tangential, elements)
        store.keep(int(stop), int(stop), held + 1, push, tangential, elements)  # no samples: nothing kept
        for name, value in (("held", held), ("push", push), ("tangential", tangential), ("elements", elements)):
            dense[name][start:stop] = value
    for rows in (slice(0, n), slice(3, 4), slice(10, 41), *store.chunks(n)):
        got = store.dense(rows)
        for name in dense:
            np.testing.assert_array_equal(getattr(got, name), dense[name][rows], err_msg=f"{name} at {rows}")
        assert got.held.dtype == np.intc and got.elements.dtype == np.intp
    one = store.dense(slice(17, 18))
    np.testing.assert_array_equal(one.tangential[0], dense["tangential"][17])
    np.testing.assert_array_equal(one.elements[0], dense["elements"][17])


def test_samples_kept_again_take_the_new_set():
    """Sample 0 is kept as given, then again with the instant at t = 0's outcome: the later
    set replaces the earlier for the samples it covers, partly or wholly, and the others keep
    theirs; a set kept inside an earlier run, not reaching its end, is refused."""
    store = ContactSamples(4, 0, 2, tangential=False)
    codes = [np.array([k, 0, 0, 0], np.intc) for k in range(5)]
    store.keep(0, 1, codes[1], np.zeros(4))
    store.keep(0, 1, codes[2], np.zeros(4))  # the same sample again
    store.keep(1, 6, codes[3], np.zeros(4))
    store.keep(4, 8, codes[4], np.zeros(4))  # the run's last two samples again, and two more
    np.testing.assert_array_equal(store.dense(slice(0, 8)).held[:, 0], [2, 3, 3, 3, 4, 4, 4, 4])
    with pytest.raises(ValueError, match="keep them in order"):
        store.keep(5, 6, codes[1], np.zeros(4))


def test_chunks_cover_every_sample_once_within_their_budget(monkeypatch):
    """The chunks are consecutive, cover the first n samples exactly once, hold at most the
    budget's entries (or one sample), and n = 0 gives one empty slice."""
    monkeypatch.setattr(samples, "CHUNK_ENTRIES", 100)
    store = ContactSamples(30, 0, 2, tangential=False)
    chunks = list(store.chunks(47))
    assert chunks[0].start == 0 and chunks[-1].stop == 47
    assert all(a.stop == b.start for a, b in zip(chunks, chunks[1:]))
    assert all(0 < (c.stop - c.start) * 30 <= 100 for c in chunks)
    assert [(c.start, c.stop) for c in store.chunks(0)] == [(0, 0)]
    wide = ContactSamples(1000, 0, 2, tangential=False)
    assert [(c.start, c.stop) for c in wide.chunks(3)] == [(0, 1), (1, 2), (2, 3)]  # one sample over budget


@pytest.mark.skipif(not HAS_CC, reason="no C compiler")
@pytest.mark.parametrize("name, options", [("box_on_wedge", {}), ("ball_on_incline", {"t_end": 0.3}),
                                           ("colliding_rings", {})])
def test_outputs_do_not_depend_on_how_many_samples_are_built_at_once(name, options, monkeypatch):
    """Contacts between bodies with friction (box_on_wedge), the thesis mode's windows with
    friction (ball_on_incline: tangential pushes) and a head-on collision: built one sample at
    a time, every output array and number equals the run built in one chunk, bit for bit."""
    whole = flexbody.simulate(name, **options)
    monkeypatch.setattr(samples, "CHUNK_ENTRIES", 1)  # one sample per chunk
    single = flexbody.simulate(name, **options)
    assert whole.status == single.status == "success"
    for key in ("t", "positions", "velocities", "contact_force", "friction_force", "kinetic", "spring",
                "impact_loss", "friction_work"):
        np.testing.assert_array_equal(getattr(single, key), getattr(whole, key), err_msg=key)
    for key in ("max_penetration_m", "min_held_contact_force_N", "energy_drift_relative", "events", "warnings"):
        assert single.stats[key] == whole.stats[key], key
    assert np.abs(whole.contact_force).max() > 0.0  # something was held: the chunks had forces to build


@pytest.mark.skipif(not HAS_CC, reason="no C compiler")
def test_a_fine_output_grid_of_many_bodies_keeps_only_their_held_contacts():
    """Eight discs side by side dropped onto the ground, 2 001 samples: each sample's contacts
    (2 000 of them, most slots between the discs) are kept as the held ones and their slots'
    elements only, a few percent of the dense store's entries."""
    from flexbody.bench_bodies import bodies_scene_table
    from flexbody.driver import _Run

    kept = []
    original = _Run.result

    def result(self, *args):
        kept.append(self.samples)
        return original(self, *args)

    table = bodies_scene_table(8, 23, 0.3, True, row=True)
    table["simulation"]["output_dt"] = 0.3 / 2000
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(_Run, "result", result)
        run = flexbody.simulate(flexbody.load_scene(table))
    assert run.success and run.stats["impacts"] > 0
    store = kept[0]
    entries = sum(len(kept.at) for record in store._records for kept in record.values())
    assert entries < 0.02 * len(run.t) * store.n_contacts
