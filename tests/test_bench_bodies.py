"""The bodies benchmark's scene builder (flexbody.bench_bodies): geometry and flags only, no timing."""

from __future__ import annotations

import numpy as np
import pytest

from flexbody.bench_bodies import GAP, LIFT, bodies_scene, disc_positions, disc_radius


def _centre_distances(centres: np.ndarray) -> np.ndarray:
    d = np.linalg.norm(centres[:, None] - centres[None], axis=2)
    return d[np.triu_indices(len(centres), 1)]


@pytest.mark.parametrize("n", [4, 5, 20])
def test_discs_are_gap_apart_or_farther_and_each_upper_one_rests_on_two_lower_ones(n):
    radius = 0.3
    centres = disc_positions(n, radius)
    lower, upper = centres[: n // 2 + 1], centres[n // 2 + 1 :]
    assert _centre_distances(centres).min() == pytest.approx(2 * radius + GAP)
    np.testing.assert_allclose(lower[:, 1], radius + LIFT)
    for c in upper:  # over a gap of the lower row: 2 R + gap from its two neighbours below
        d = np.sort(np.linalg.norm(lower - c, axis=1))[:2]
        np.testing.assert_allclose(d, 2 * radius + GAP)


def test_the_scene_holds_its_discs_apart_above_the_ground_with_the_asked_flags():
    scene = bodies_scene(4, 23, 0.3, collide=True)
    x = scene.initial_positions()
    owner = np.repeat(np.arange(len(scene.bodies)), [b.n_particles for b in scene.bodies])
    assert len(scene.bodies) == 4 and all(b.collide for b in scene.bodies)
    assert len(scene.contacts) == 4 * 3 // 2  # every pair may touch
    assert x[:, 1].min() >= LIFT - 1e-12  # every particle within the disc's radius of its centre
    other = owner[:, None] != owner[None]
    gaps = np.linalg.norm(x[:, None] - x[None], axis=2)[other]
    assert gaps.min() >= GAP - 1e-12
    apart = bodies_scene(4, 23, 0.3, collide=False)
    assert not any(b.collide for b in apart.bodies) and not apart.contacts
    assert apart.n_particles == scene.n_particles


def test_one_body_alone_is_where_it_is_in_the_full_scene():
    full = bodies_scene(4, 23, 0.3, collide=False)
    offsets = np.cumsum([0] + [b.n_particles for b in full.bodies])
    for k in range(4):
        alone = bodies_scene(4, 23, 0.3, collide=False, only=k)
        np.testing.assert_array_equal(alone.initial_positions(),
                                      full.initial_positions()[offsets[k] : offsets[k + 1]])


def test_the_radius_keeps_the_thesis_ball_lattice_spacing():
    assert disc_radius(23) == pytest.approx(0.1)
    assert disc_radius(200) ** 2 / 200 == pytest.approx(0.1**2 / 23)  # same area per particle


def test_the_stiff_set_changes_the_links_stiffness_only():
    from flexbody.bench_bodies import STIFF, STIFFNESS

    soft, stiff = bodies_scene(4, 23, 0.3, collide=True), bodies_scene(4, 23, 0.3, collide=True, stiffness=STIFF)
    assert STIFFNESS == 2000.0 and STIFF == pytest.approx(STIFFNESS * (200 / 23) ** 0.5, rel=0.02)
    assert all(np.all(b.stiffness == STIFFNESS) for b in soft.bodies)
    assert all(np.all(b.stiffness == STIFF) for b in stiff.bodies)
    np.testing.assert_array_equal(soft.initial_positions(), stiff.initial_positions())
    assert soft.name != stiff.name


def test_the_row_holds_its_discs_gap_apart_side_by_side_at_the_piles_lift():
    from flexbody.bench_bodies import row_positions

    radius = disc_radius(23)
    centres = row_positions(5, radius)
    np.testing.assert_allclose(np.diff(centres[:, 0]), 2 * radius + GAP)
    np.testing.assert_allclose(centres[:, 1] - radius, LIFT)  # lowest points LIFT above the ground
    row = bodies_scene(5, 23, 0.3, collide=True, row=True)
    spans = [(b.initial_positions()[:, 0].min(), b.initial_positions()[:, 0].max()) for b in row.bodies]
    assert all(right[0] - left[1] >= GAP - 1e-12 for left, right in zip(spans, spans[1:]))  # apart
    assert row.name != bodies_scene(5, 23, 0.3, collide=True).name


def test_one_body_alone_is_where_it_is_in_the_row():
    full = bodies_scene(4, 23, 0.3, collide=False, row=True)
    offsets = np.cumsum([0] + [b.n_particles for b in full.bodies])
    for k in range(4):
        alone = bodies_scene(4, 23, 0.3, collide=False, only=k, row=True)
        np.testing.assert_array_equal(alone.initial_positions(),
                                      full.initial_positions()[offsets[k] : offsets[k + 1]])


def test_the_quick_study_saves_five_runs_a_set_and_the_stiff_row_touches_nothing(tmp_path):
    """``--quick`` (4 thesis-ball discs, 0.3 s): five runs per stiffness, each ratio against
    its own layout's separate drops; side by side the stiff discs make no contact between
    bodies, so the row's run has exactly its separate drops' events.  The stiff pile is also
    run with 2 and 3 discs: 2 lie side by side (the drops' events exactly), 3 land on each
    other; each row's broad-phase time lies within its run's."""
    import json

    from flexbody.bench_bodies import bodies_study

    bodies_study(tmp_path, quick=True, repeats=1)
    data = json.loads((tmp_path / "bodies.json").read_text())
    assert (tmp_path / "bodies.png").stat().st_size > 0
    for runs, ratios in ((data["runs"], data["ratio_to_separate"]),
                         (data["stiff"]["runs"], data["stiff"]["ratio_to_separate"])):
        assert set(runs) == {"collide", "pass_through", "separate", "row_collide", "row_separate"}
        assert all(r["status"] == "success" for r in runs.values())
        assert ratios["row_collide"] == pytest.approx(runs["row_collide"]["wall_s"] / runs["row_separate"]["wall_s"])
        assert ratios["collide"] == pytest.approx(runs["collide"]["wall_s"] / runs["separate"]["wall_s"])
    stiff = data["stiff"]["runs"]
    assert stiff["row_collide"]["events"] == stiff["row_separate"]["events"] > 0
    assert stiff["collide"]["events"] > stiff["separate"]["events"]  # the pile's discs land on each other
    # the stiff pile by its bodies: 2 (one row, nothing lands on anything), 3, then the study's own 4
    scaling = data["scaling"]
    assert [row["bodies"] for row in scaling] == [2, 3, 4]
    assert scaling[-1]["collide"] == stiff["collide"] and scaling[-1]["separate"] == stiff["separate"]
    assert scaling[0]["collide"]["events"] == scaling[0]["separate"]["events"] > 0
    assert scaling[1]["collide"]["events"] > scaling[1]["separate"]["events"]
    for row in scaling:
        assert row["ratio"] == pytest.approx(row["collide"]["wall_s"] / row["separate"]["wall_s"])
        assert 0.0 < row["collide"]["broadphase_s"] < row["collide"]["wall_s"]


def test_the_tolerance_sets_rtol_and_atol_and_nothing_else():
    from flexbody.bench_bodies import RTOL, RTOL_TO_ATOL, bodies_scene_table

    study, tight = bodies_scene_table(4, 23, 0.3, True), bodies_scene_table(4, 23, 0.3, True, rtol=1e-8)
    assert (study["simulation"]["rtol"], study["simulation"]["atol"]) == (RTOL, RTOL * RTOL_TO_ATOL) == (1e-6, 1e-9)
    assert (tight["simulation"]["rtol"], tight["simulation"]["atol"]) == (1e-8, 1e-11)
    assert {k: v for k, v in tight["simulation"].items() if k not in ("rtol", "atol")} == \
        {k: v for k, v in study["simulation"].items() if k not in ("rtol", "atol")}
    assert tight["bodies"] == study["bodies"]


def _run(wall: float, events: int) -> dict:
    return {"wall_s": wall, "events": events, "rhs_evaluations": 10 * events, "status": "success",
            "t_reached_s": 0.3, "max_penetration_m": 1e-12}


@pytest.mark.parametrize("panels", [(), ("scaling",), ("scaling", "tolerance")])
def test_the_chart_draws_a_panel_for_each_part_the_study_saved(panels):
    """A study saved before its scaling or tolerance parts were added is drawn again
    (`flexbody bench` re-plots a saved JSON) with the panels it has."""
    from flexbody.bench_bodies import plot_bodies

    runs = {k: _run(1.0, 10) for k in ("separate", "pass_through", "collide", "row_separate", "row_collide")}
    data = {"bodies": 4, "count": 23, "t_end_s": 0.3, "rtol": 1e-6, "runs": runs}
    rows = [{"collide": _run(2.0, 30), "separate": _run(1.0, 10), "ratio": 2.0}]
    if "scaling" in panels:
        data["scaling"] = [dict(rows[0], bodies=4)]
    if "tolerance" in panels:  # the tighter run stopped by the wall-time cap: its point says so
        capped = dict(_run(600.0, 5000), status="too_slow", t_reached_s=0.21)
        data["tolerance"] = [rows[0], dict(rows[0], rtol=1e-7, collide=capped)]
        data["tolerance"][0]["rtol"] = 1e-6
    axes = plot_bodies(data).axes
    assert len(axes) == 2 + len(panels)
    titles = [ax.get_title() for ax in axes]
    assert any("per event" in t for t in titles) == ("scaling" in panels)
    assert any("by tolerance" in t for t in titles) == ("tolerance" in panels)
    if "tolerance" in panels:
        labels = [text.get_text() for text in axes[-1].texts]
        assert sum("too_slow at 0.21 s" in label for label in labels) == 1
