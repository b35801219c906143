"""Figures and animation on any 2D scene: tilted grounds, corners, no events, failed runs.

The references are independent NumPy computations from the result and the scene's
grounds (gaps along the normals), and the GIF's own metadata read back with Pillow.
"""

from __future__ import annotations

import io
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest
from matplotlib.collections import LineCollection
from matplotlib.patches import Polygon
from PIL import Image

import flexbody
from flexbody import figures
from tests.conftest import body, make_scene

SLOPE = np.radians(20.0)


def _thesis_ball(**simulation) -> dict:
    """The bundled thesis ball's TOML table, with some simulation settings changed."""
    table = tomllib.loads(Path(flexbody.load_scene("thesis_ball").source).read_text())
    table["simulation"].update(simulation)
    return table


@pytest.fixture(scope="module")
def tilted():
    """The thesis ring on a 20° ground through the origin (it lands, then slides down to x, y < 0)."""
    table = _thesis_ball(t_end=1.0)
    table["grounds"] = [{"point": [0.0, 0.0], "normal": [-np.sin(SLOPE), np.cos(SLOPE)]}]
    scene = flexbody.load_scene(table)
    return scene, flexbody.simulate(scene)


@pytest.fixture(scope="module")
def corner():
    """A dumbbell thrown right, into the corner of a floor and a wall at x = 0.3."""
    scene = make_scene(body(velocity=[1.5, 0.0]), grounds=[{"point": [0.0, 0.0], "normal": [0.0, 1.0]},
                                                           {"point": [0.3, 0.0], "normal": [-1.0, 0.0]}])
    return scene, flexbody.simulate(scene, backend="numpy", t_end=0.6)


def _lowest_gap(result, scene) -> float:
    """min over time, particles and grounds of (x - point) . normal, written out independently."""
    return min(float(np.min((result.positions - np.array(g.point)) @ np.array(g.normal))) for g in scene.grounds)


def test_penetration_text_reports_the_gap_along_the_ground_normal(tilted):
    scene, result = tilted
    assert result.success and len(result.events_time) > 0
    assert result.positions[..., 1].min() < -0.05  # below y = 0: a height in y would read as deep penetration
    fig = figures.figure_colliding_points(result, scene.grounds)
    text = fig.axes[1].get_title()
    shown = float(re.search(r"lowest gap (\S+) mm", text).group(1)) * 1e-3
    lowest = _lowest_gap(result, scene)
    assert shown == pytest.approx(lowest, rel=5e-3, abs=1e-15)
    assert text.startswith("no penetration") and lowest > -1e-9


def test_heights_are_gaps_along_each_normal_minimum_over_grounds(corner):
    scene, result = corner
    h = figures.gaps(result.positions, scene.grounds)
    x, y = result.positions[..., 0], result.positions[..., 1]
    np.testing.assert_allclose(h, np.minimum(y, 0.3 - x), atol=1e-15)
    assert result.success and len(result.events_time) > 0
    assert (0.3 - x).min() < 1e-9  # it did reach the wall


@pytest.mark.parametrize("case", ["tilted", "corner"])
def test_views_contain_every_particle_of_every_frame(case, request):
    scene, result = request.getfixturevalue(case)
    animation = figures.Animation(result, scene.grounds)
    (x0, x1), (y0, y1) = animation.ax.get_xlim(), animation.ax.get_ylim()
    x, y = result.positions[..., 0], result.positions[..., 1]
    assert x0 < x.min() and x.max() < x1 and y0 < y.min() and y.max() < y1
    # ... and frame the path, not the ground: the view is at most 25 % wider than the path in each direction
    assert x1 - x0 < 1.25 * np.ptp(x) + 0.05 and y1 - y0 < 1.25 * np.ptp(y) + 0.05

    fig = figures.figure_free_fall(result, scene.grounds)
    hit = figures.first_impact_index(result)
    ax = fig.axes[0]
    falling = result.positions[: hit + 1]
    assert ax.get_xlim()[0] < falling[..., 0].min() and falling[..., 0].max() < ax.get_xlim()[1]
    assert ax.get_ylim()[0] < falling[..., 1].min() and falling[..., 1].max() < ax.get_ylim()[1]


@pytest.mark.parametrize("case", ["tilted", "corner"])
def test_each_ground_is_hatched_on_its_solid_side(case, request):
    scene, result = request.getfixturevalue(case)
    ax = figures.figure_free_fall(result, scene.grounds).axes[0]
    solids = [p for p in ax.patches if isinstance(p, Polygon)]
    assert len(solids) == len(scene.grounds)
    for patch, ground in zip(solids, scene.grounds):
        assert patch.get_hatch()
        side = (patch.get_xy() - np.array(ground.point)) @ np.array(ground.normal)
        assert side.max() < 1e-9 and side.min() < -0.1  # all of it in the solid, and not a sliver


def test_free_fall_snapshots_do_not_overlap():
    scene = flexbody.load_scene("thesis_ball")
    result = flexbody.simulate(scene, t_end=0.5)
    ax = figures.figure_free_fall(result, scene.grounds).axes[0]
    bodies = [np.array(c.get_segments()).reshape(-1, 2) for c in ax.collections if isinstance(c, LineCollection)]
    assert len(bodies) >= 2
    boxes = [(b.min(axis=0), b.max(axis=0)) for b in bodies]
    for k, (lo, hi) in enumerate(boxes):
        for lo2, hi2 in boxes[k + 1:]:
            assert np.any(lo > hi2) or np.any(lo2 > hi), "two snapshots overlap"


def test_gif_plays_in_real_time_with_its_frame_count_and_durations(tilted):
    scene, result = tilted
    gif = Image.open(io.BytesIO(figures.animation_gif(result, scene.grounds, fps=25)))
    span = result.t[-1] - result.t[0]  # 1 s
    assert gif.n_frames == int(np.floor(span * 25 + 1e-9)) + 1 == 26
    durations = []
    for k in range(gif.n_frames):
        gif.seek(k)
        durations.append(gif.info["duration"])
    assert set(durations) == {40}
    assert abs(sum(durations) - 1000 * span) <= 40  # real time, to one frame


def test_a_long_run_is_played_faster_and_says_so(tilted):
    scene, result = tilted
    animation = figures.Animation(result, scene.grounds, fps=25, max_frames=11)
    assert animation.speed == pytest.approx(2.5)  # 1 s in 10 frame intervals of 40 ms
    assert len(animation.index) == 11
    assert "2.5x real time" in animation.ax.get_title()
    shown = result.t[animation.index]
    np.testing.assert_allclose(np.diff(shown), 0.1, atol=result.t[1] - result.t[0])


def test_every_figure_draws_a_run_without_events():
    scene = flexbody.load_scene("thesis_ball")
    result = flexbody.simulate(scene, t_end=0.1)
    assert result.success and len(result.events_time) == 0
    files = figures.render_all(result, scene.grounds)
    assert all(files[name][:8] == b"\x89PNG\r\n\x1a\n" for name in files if name.endswith(".png"))
    assert Image.open(io.BytesIO(files["drop.gif"])).n_frames == 3  # 0, 0.04, 0.08 s
    title = figures.figure_colliding_points(result, scene.grounds).axes[0].get_title()
    assert "no particle touched the ground" in title


def test_every_figure_draws_a_failed_partial_run(corner):
    scene, _ = corner
    result = flexbody.simulate(scene, backend="numpy", t_end=0.6, max_events=1)
    assert not result.success and result.t[-1] < 0.6
    files = figures.render_all(result, scene.grounds)
    assert set(files) == {"fig5_1_free_fall.png", "fig5_2_impact.png", "fig5_3_colliding_points.png",
                          "fig5_4_energy.png", "drop.gif"}


def test_bench_charts_redraw_from_the_committed_json_with_every_axis_labelled():
    import json

    from flexbody import bench
    from flexbody.paths import generated_root

    folder = generated_root() / "figures"
    for name in ("work_precision", "resolution", "mujoco"):
        fig = bench.PLOTS[name](json.loads((folder / f"{name}.json").read_text()))
        assert all(ax.get_ylabel() for ax in fig.axes), f"{name}: a panel has no y label"
    rows = [t.get_text() for t in bench.plot_stability(json.loads((folder / "stability_map.json").read_text()))
            .axes[0].get_yticklabels()]
    assert "dopri5 (compiled loop)" in rows and "RK45 (SciPy loop)" in rows


def test_the_friction_figure_is_drawn_for_a_run_with_friction_only():
    from flexbody.driver import simulate
    from flexbody.figures import figure_friction, has_friction, render_all

    scene = flexbody.load_scene({
        "name": "slide", "grounds": [{"point": [0.0, 0.0], "normal": [0.0, 1.0], "friction": 0.5}],
        "bodies": [{"name": "p", "particles": [[0.0, 0.0]], "links": [], "stiffness": [], "damping": [],
                    "mass": 0.1, "position": [0.0, 0.0], "velocity": [1.0, 0.0]}],
        "simulation": {"t_end": 0.3, "output_dt": 1e-3},
    })
    r = simulate(scene)
    assert has_friction(r)
    fig = figure_friction(r, scene.grounds)
    bottom = fig.axes[1]
    assert [t.get_text() for t in bottom.get_yticklabels()] == ["particle 0"]
    assert "friction.png" in render_all(r, scene.grounds)
    assert not has_friction(simulate("thesis_ball", t_end=0.3))
    # In 3D too (the z = 0 plane's slide, the 3D figures' set).
    space = flexbody.load_scene({
        "name": "slide3d", "gravity": [0.0, 0.0, -9.81],
        "bodies": [{"name": "p", "particles": [[0.0, 0.0, 0.0]], "links": [], "stiffness": [], "damping": [],
                    "mass": 0.1, "position": [0.0, 0.0, 0.0], "velocity": [0.6, 0.8, 0.0],
                    "rotation": [0.0, 0.0, 0.0], "angular_velocity": [0.0, 0.0, 0.0]}],
        "grounds": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0], "friction": 0.5}],
        "simulation": {"t_end": 0.3, "output_dt": 1e-3},
    })
    assert "friction.png" in render_all(simulate(space), space.grounds)
