"""The broad phase of body-body contact against brute force and geometry.

Both indexes (k-d tree, uniform grid) must give exactly the pairs that testing every
particle against every grown box gives; and every particle within ``margin`` of another
body's element (its true distance, computed independently) must be among them.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from flexbody.broadphase import METHODS, benchmark_scenes, brute_force_pairs, candidate_pairs, main
from flexbody.surface_contact import point_edge


def random_bodies(rng, dim: int, bodies: int = 6, per_body: int = 40):
    """Bodies of random particles in overlapping clouds; random elements of each body's own
    particles (segments in 2D, triangles in 3D), some long, so boxes differ in size."""
    k = 2 if dim == 2 else 3
    x, elements, body = [], [], []
    for b in range(bodies):
        centre = rng.uniform(-1, 1, dim)
        x.append(centre + rng.normal(scale=rng.uniform(0.05, 0.4), size=(per_body, dim)))
        count = int(rng.integers(5, 30))
        elements.append(b * per_body + np.array([rng.choice(per_body, k, replace=False) for _ in range(count)]))
        body.append(np.full(per_body, b))
    return np.vstack(x), np.vstack(elements), np.concatenate(body)


@pytest.mark.parametrize("prune", [True, False])
@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("method", METHODS)
def test_candidates_equal_brute_force_on_random_configurations(rng, dim, method, prune, monkeypatch):
    if not prune:  # the path of scenes with more bodies than the body-box pruning handles
        monkeypatch.setattr("flexbody.broadphase.MAX_BODIES_PRUNED", 0)
    for trial in range(15):
        x, elements, body = random_bodies(rng, dim)
        margin = float(rng.choice([0.0, 0.01, 0.2]))
        for self_contact in (False, True):
            got = candidate_pairs(x, elements, body, margin, self_contact=self_contact, method=method)
            expected = brute_force_pairs(x, elements, body, margin, self_contact=self_contact)
            np.testing.assert_array_equal(got, expected, err_msg=f"trial {trial}, self_contact {self_contact}")
        assert len(expected) > 0  # the clouds overlap: the comparison is not of two empty sets


def test_the_measured_scenes_give_the_brute_force_pairs():
    for name, (x, elements, body, margin) in benchmark_scenes().items():
        for self_contact in (False, True):
            expected = brute_force_pairs(x, elements, body, margin, self_contact=self_contact)
            assert len(expected) > 0, name
            for method in METHODS:
                got = candidate_pairs(x, elements, body, margin, self_contact=self_contact, method=method)
                np.testing.assert_array_equal(got, expected, err_msg=f"{name}, {method}, self contact {self_contact}")


def test_exclusions_own_body_and_own_vertices():
    """Two crossing segments of bodies 0 and 1, and a particle of body 0 on its own segment."""
    x = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, 0.0], [0.5, -0.5], [0.5, 0.5]])
    elements = np.array([[0, 1], [3, 4]])
    body = np.array([0, 0, 0, 1, 1])
    pairs = candidate_pairs(x, elements, body, margin=0.0)
    # Body 1's particles are not within segment 0's (flat) box; particle 2 is in segment 1's box.
    np.testing.assert_array_equal(pairs, [[2, 1]])
    with_self = candidate_pairs(x, elements, body, margin=0.0, self_contact=True)
    np.testing.assert_array_equal(with_self, [[2, 0], [2, 1]])  # never 0 or 1 against segment 0
    grown = candidate_pairs(x, elements, body, margin=0.6)
    np.testing.assert_array_equal(grown, [[0, 1], [1, 1], [2, 1], [3, 0], [4, 0]])


@pytest.mark.parametrize("method", METHODS)
def test_every_particle_within_the_margin_of_an_element_is_a_candidate(rng, method):
    """Conservative: the true distance (closest point of the segment) <= margin implies a pair."""
    near_pairs = 0
    for _ in range(10):
        x, elements, body = random_bodies(rng, 3, bodies=4)
        elements = elements[:, :2]  # segments in 3D: the distance is point_edge's
        margin = 0.1
        pairs = {tuple(p) for p in candidate_pairs(x, elements, body, margin, method=method)}
        p, e = np.indices((len(x), len(elements))).reshape(2, -1)
        dist, _, _ = point_edge(x[p], x[elements[e, 0]], x[elements[e, 1]])
        near = (dist <= margin) & (body[p] != body[elements[e, 0]]) & np.all(elements[e] != p[:, None], axis=1)
        near_pairs += int(near.sum())
        assert {(int(i), int(j)) for i, j in zip(p[near], e[near])} <= pairs
    assert near_pairs > 20  # the test saw pairs to find


def test_bad_arguments_name_the_field():
    x = np.zeros((3, 2))
    with pytest.raises(ValueError, match="`method` must be one of kdtree, grid; got 'octree'"):
        candidate_pairs(x, np.array([[0, 1]]), np.zeros(3, int), method="octree")
    with pytest.raises(ValueError, match="`margin` must be a finite length >= 0"):
        candidate_pairs(x, np.array([[0, 1]]), np.zeros(3, int), margin=-1.0)
    with pytest.raises(ValueError, match=r"`elements` must be an \(m, k\) array of particle indices in \[0, 3\)"):
        candidate_pairs(x, np.array([[0, 3]]), np.zeros(3, int))
    with pytest.raises(ValueError, match=r"`particle_body` must have shape \(3,\)"):
        candidate_pairs(x, np.array([[0, 1]]), np.zeros(2, int))
    with pytest.raises(ValueError, match="`element_body` must have shape"):
        candidate_pairs(x, np.array([[0, 1]]), np.zeros(3, int), element_body=np.array([7]))


def test_benchmark_command_prints_and_saves(tmp_path, capsys, monkeypatch):
    one = dict(list(benchmark_scenes().items())[:1])  # the first case only: this is not a timing test
    monkeypatch.setattr("flexbody.broadphase.benchmark_scenes", lambda: one)
    out = tmp_path / "broadphase.json"
    assert main(["--repeats", "1", "--out", str(out)]) == 0
    assert "kdtree" in capsys.readouterr().out
    rows = json.loads(out.read_text())
    assert [(row["case"], row["self_contact"]) for row in rows] == [(*one, False), (*one, True)]
    assert all(row["kdtree_ms"] > 0 and row["grid_ms"] > 0 and row["kept_rebuilds"] >= 1 for row in rows)
    assert main(["--repeats", "0"]) == 2
    assert "--repeats must be >= 1; got 0" in capsys.readouterr().err


@pytest.mark.parametrize("dim", [2, 3])
def test_the_kept_candidate_list_equals_a_fresh_search_at_every_step(rng, dim):
    """Along a random motion (each particle its own velocity, bodies drifting into each
    other), the Verlet list's pairs equal the brute force's at every step, with far fewer
    index builds than steps."""
    from flexbody.broadphase import CandidateList

    x, elements, body = random_bodies(rng, dim, bodies=5)
    drift = -0.5 * (x - x.mean(axis=0))  # the clouds close in on each other
    jitter = rng.normal(scale=0.3, size=x.shape)
    kept = CandidateList(elements, body, margin=0.02, skin=0.05)
    steps, dt = 200, 2e-3
    seen = 0
    for k in range(steps):
        now = x + drift * k * dt + 0.01 * jitter * np.sin(40 * k * dt)  # about 1 mm per step
        pairs = kept.pairs(now)
        np.testing.assert_array_equal(pairs, brute_force_pairs(now, elements, body, 0.02), err_msg=f"step {k}")
        some = np.sort(rng.choice(len(x), size=len(x) // 4, replace=False))  # a few particles' pairs
        np.testing.assert_array_equal(kept.pairs(now, some), pairs[np.isin(pairs[:, 0], some)])
        seen += len(pairs)
    assert seen > 0
    assert 2 <= kept.rebuilds < steps / 10
    with pytest.raises(ValueError, match="`skin` must be a finite length > 0"):
        CandidateList(elements, body, margin=0.02, skin=0.0)


def test_the_kept_list_holds_when_a_particle_and_an_element_rush_at_each_other():
    """The worst case of the rebuild rule: a particle and a segment approach head-on, each
    moving up to skin / 2 between rebuilds; from a range of starting gaps (so the rebuilds
    fall at every phase of the approach) the pair must appear the step the particle enters
    the margin, never later, and leave when it is through."""
    from flexbody.broadphase import CandidateList

    elements, body = np.array([[0, 1]]), np.array([0, 0, 1, 1])  # segment 0-1 of body 0; particle 2 of body 1
    margin, skin, step = 0.01, 0.04, 0.000471  # no step lands on the margin exactly
    for start in np.linspace(0.3, 0.35, 17):
        x0 = np.array([[-1.0, 0.0], [1.0, 0.0], [0.0, start], [5.0, 5.0]])
        kept = CandidateList(elements, body, margin=margin, skin=skin)
        for k in range(int((start + 2 * margin) / (2 * step)) + 2):
            x = x0.copy()
            x[:2, 1] += k * step  # the segment rises ...
            x[2, 1] -= k * step  # ... as the particle falls
            gap = x[2, 1] - x[0, 1]
            found = len(kept.pairs(x)) == 1
            assert found == (abs(gap) <= margin), f"start {start}, step {k}: gap {gap}, found {found}"
        assert gap < -margin and kept.rebuilds > 5
