"""3D figures and animation, on synthetic 3D results whose motion is known in closed form.

A cube of 8 particles falls (free fall, closed form) onto a plane, stops there (a plastic
impact of its bottom face) and rests, its bottom particles carrying its weight.  The plane
may be tilted: the whole picture is rotated, gravity with it.  References are independent
NumPy computations and the GIF's metadata read back with Pillow.
"""

from __future__ import annotations

import io
import re
from dataclasses import dataclass

import numpy as np
import pytest
from PIL import Image

from flexbody import figures, figures3d
from flexbody.result import SimulationResult

G, SIDE, MASS = 9.81, 0.1, 0.05


@dataclass(frozen=True)
class Ground:
    point: tuple[float, ...]
    normal: tuple[float, ...]


def _rotation(axis, angle: float) -> np.ndarray:
    """Rodrigues: the rotation by ``angle`` about ``axis``, shape (3, 3)."""
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def falling_cube(height: float = 0.4, t_end: float = 1.0, dt: float = 0.005, tilt: float = 0.0,
                 point=(0.0, 0.0, 0.0), dip: float = 0.0) -> tuple[SimulationResult, list[Ground]]:
    """A cube dropped with its bottom face ``height`` above a plane; it stops on it and rests.

    In the plane's frame (normal e_z): bottom face at ``height - g t^2 / 2`` until
    ``t1 = sqrt(2 height / g)``, then at 0.  The frame is rotated by ``tilt`` about (1, 1, 0)
    and moved to ``point``.  ``dip`` pushes particle 0 that far into the ground while it rests
    (to see penetration reported).  The ground's normal is given 3 times too long, on purpose.
    """
    R = _rotation([1.0, 1.0, 0.0], tilt)
    t = np.arange(0.0, t_end + dt / 2, dt)
    t1 = np.sqrt(2 * height / G)
    corners = SIDE * np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], float)
    links = np.array([(i, i | 1 << a) for i in range(8) for a in range(3) if not i & 1 << a])  # the 12 edges
    falling = t < t1
    z = np.where(falling, height - 0.5 * G * t**2, 0.0)
    vz = np.where(falling, -G * t, 0.0)
    local = corners[None] + np.stack([np.zeros_like(t), np.zeros_like(t), z], axis=1)[:, None]
    resting = ~falling
    local[resting, 0, 2] -= dip
    velocity = np.zeros_like(local)
    velocity[..., 2] = vz[:, None]
    force = np.zeros((len(t), 8))
    force[resting[:, None] & (corners[:, 2] == 0)[None]] = 2 * MASS * G  # 4 particles carry 8 m g
    n_total = 8 * MASS
    centre_z = z + SIDE / 2
    result = SimulationResult(
        t=t, positions=np.asarray(point) + local @ R.T, velocities=velocity @ R.T, contact_force=force,
        kinetic=0.5 * n_total * vz**2, spring=np.zeros_like(t), gravity=n_total * G * centre_z,
        damping_work=np.zeros_like(t), impact_loss=np.where(falling, 0.0, n_total * G * height),
        events_time=np.full(4, t1), events_particle=np.flatnonzero(corners[:, 2] == 0),
        events_kind=np.array(["impact"] * 4), events_held=np.ones(4, bool), masses=np.full(8, MASS), links=links,
        stats={"scene": "falling_cube"},
    )  # fmt: skip
    return result, [Ground(tuple(point), tuple(3.0 * R[:, 2]))]


def _lowest_gap(result, grounds) -> float:
    """min over time, particles and grounds of (x - point) . normal / |normal|, written out independently."""
    return min(float(np.min((result.positions - g.point) @ (np.array(g.normal) / np.linalg.norm(g.normal))))
               for g in grounds)


def _shown_gap(text: str) -> float:
    return float(re.search(r"lowest gap (\S+) mm", text).group(1)) * 1e-3


@pytest.mark.parametrize("dip", [0.0, 2e-4])
def test_penetration_text_is_the_lowest_gap_along_a_tilted_normal(dip):
    result, grounds = falling_cube(tilt=np.radians(35.0), point=(0.3, -0.2, 0.1), dip=dip)
    text = figures3d.figure_lowest_gap(result, grounds).axes[1].get_title()
    lowest = _lowest_gap(result, grounds)
    assert lowest == pytest.approx(-dip, abs=1e-12)  # the tilt is undone exactly by the along-normal gap
    assert _shown_gap(text) == pytest.approx(lowest, rel=5e-3, abs=1e-15)
    assert text.startswith("PENETRATION" if dip else "no penetration")
    # heights measured in z above the ground's point would be far off: the tilt matters
    assert abs((result.positions[..., 2] - 0.1).min() - lowest) > 0.03


def test_the_curve_is_the_lowest_gap_at_every_sample():
    result, grounds = falling_cube(tilt=np.radians(50.0), point=(0.0, 0.5, -0.3))
    top = figures3d.figure_lowest_gap(result, grounds).axes[0]
    t, shown = top.lines[0].get_data()
    # in the ground's frame the bottom face is at height - g t^2 / 2, then at 0
    expected = np.maximum(0.4 - 0.5 * G * result.t**2, 0.0)
    expected[result.t >= np.sqrt(2 * 0.4 / G)] = 0.0
    np.testing.assert_allclose(shown, expected, atol=1e-12)


def test_default_ground_is_z_0():
    result, _ = falling_cube()
    np.testing.assert_allclose(figures3d.gaps(result.positions), result.positions[..., 2], atol=0)


def test_views_contain_every_particle_of_every_frame_and_frame_the_path():
    result, grounds = falling_cube(tilt=np.radians(35.0), point=(0.3, -0.2, 0.1))
    x = result.positions.reshape(-1, 3)
    for ax in (figures3d.Animation(result, grounds).ax, figures3d.figure_snapshots(result, grounds).axes[0]):
        limits = np.array([ax.get_xlim3d(), ax.get_ylim3d(), ax.get_zlim3d()])  # (3, 2)
        assert np.all(limits[:, 0] < x.min(axis=0)) and np.all(x.max(axis=0) < limits[:, 1])
        # ... framed on the path, not on the ground: at most 25 % larger than the path along each axis
        assert np.all(np.diff(limits, axis=1).ravel() < 1.25 * np.ptp(x, axis=0) + 0.01)


def test_the_ground_patch_lies_in_the_ground_plane_inside_the_view():
    result, grounds = falling_cube(tilt=np.radians(35.0), point=(0.3, -0.2, 0.1))
    ax = figures3d.figure_snapshots(result, grounds).axes[0]
    lo, hi = figures3d.view_box(result.positions)
    assert sum(type(c).__name__ == "Poly3DCollection" for c in ax.collections) == len(grounds)
    (corners,) = figures3d.ground_patches(grounds, lo, hi)
    n = np.array(grounds[0].normal) / np.linalg.norm(grounds[0].normal)
    np.testing.assert_allclose((corners - grounds[0].point) @ n, 0.0, atol=1e-9)
    assert np.all(corners >= lo - 1e-9) and np.all(corners <= hi + 1e-9) and len(corners) >= 3


@pytest.mark.parametrize("normal", [(0.0, 0.0, 1.0), (0.3, -0.5, 1.0), (1.0, 1.0, 1.0)])
def test_plane_in_box_is_the_cross_section(normal, rng):
    """The polygon's corners lie on the plane and on the box's faces; its area is the cross-section's."""
    lo, hi = np.array([-1.0, -0.5, 0.0]), np.array([1.0, 0.5, 0.7])
    point = np.array([0.1, 0.0, 0.3])
    n = np.array(normal) / np.linalg.norm(normal)
    poly = figures3d.plane_in_box(point, n, lo, hi)
    np.testing.assert_allclose((poly - point) @ n, 0.0, atol=1e-12)
    on_face = np.isclose(poly, lo, atol=1e-12) | np.isclose(poly, hi, atol=1e-12)
    assert on_face.any(axis=1).all()
    area = 0.5 * np.linalg.norm(sum(np.cross(poly[k], poly[(k + 1) % len(poly)]) for k in range(len(poly))))
    # Monte Carlo: the box's volume within a thin slab around the plane, divided by the slab's width
    x = lo + (hi - lo) * rng.random((400_000, 3))
    width = 0.02
    slab = np.prod(hi - lo) * np.mean(np.abs((x - point) @ n) < width / 2) / width
    assert area == pytest.approx(slab, rel=0.03)


def test_contact_force_figure_shows_the_particles_that_touched():
    result, grounds = falling_cube()
    fig = figures3d.figure_contact_force(result)
    top, bottom = fig.axes
    np.testing.assert_allclose(top.lines[0].get_ydata()[-1], 8 * MASS * G)  # the weight, at rest
    assert [line.get_label() for line in bottom.lines] == [f"particle {i}" for i in (0, 1, 2, 3)]
    assert all(ax.get_ylabel().endswith("(N)") for ax in (top, bottom)) and top.get_xlabel() == ""
    assert bottom.get_xlabel() == "t (s)"


def test_every_axis_has_a_unit():
    result, grounds = falling_cube()
    figs = [figures3d.figure_snapshots(result, grounds), figures3d.figure_lowest_gap(result, grounds),
            figures3d.figure_contact_force(result), figures.figure_energy(result)]
    for fig in figs:
        for ax in fig.axes:
            labels = [ax.get_xlabel(), ax.get_ylabel()] + ([ax.get_zlabel()] if hasattr(ax, "get_zlabel") else [])
            for label in filter(None, labels):
                assert re.search(r"\((m|mm|s|N|J)\)$", label), label
    assert [figs[0].axes[0].get_xlabel(), figs[0].axes[0].get_zlabel()] == ["x (m)", "z (m)"]


def test_energy_figure_is_dimension_free():
    """The 2D energy figure draws a 3D ledger: its sum line is constant (free fall + plastic stop)."""
    result, _ = falling_cube()
    top, bottom = figures.figure_energy(result).axes
    drift = bottom.lines[0].get_ydata()
    assert np.abs(drift).max() < 1e-12 * result.total_energy[0]


def test_gif_plays_in_real_time_with_its_frame_count_and_durations():
    result, grounds = falling_cube(t_end=2.0, dt=0.001, tilt=np.radians(20.0))
    gif = Image.open(io.BytesIO(figures3d.animation_gif(result, grounds, fps=25)))
    assert gif.n_frames == 51  # 0, 0.04, ..., 2 s
    durations = []
    for k in range(gif.n_frames):
        gif.seek(k)
        durations.append(gif.info["duration"])
    assert set(durations) == {40} and sum(durations) == 51 * 40


def test_gif_frames_show_the_body_moving():
    """The first frame (body high) and a late one (body resting) differ; two resting frames do not."""
    result, grounds = falling_cube(t_end=1.0, dt=0.001)
    animation = figures3d.Animation(result, grounds)
    first, late, last = (np.asarray(animation.frame(k), dtype=int) for k in (0, 23, 25))
    assert np.abs(first - late).sum() > 1000 * 255
    box = animation.label.get_window_extent()  # pixels, from the bottom
    rows = slice(len(last) - int(np.ceil(box.y1)), len(last) - int(box.y0))
    late[rows], last[rows] = 0, 0
    assert np.abs(late - last).max() == 0  # apart from the time label, nothing moved


def test_render_all_dispatches_on_the_dimension():
    result, grounds = falling_cube(t_end=0.3)
    files = figures.render_all(result, grounds)
    assert set(files) == {"fig3d_snapshots.png", "fig3d_lowest_gap.png", "fig3d_contact_force.png",
                          "fig5_4_energy.png", "drop.gif"}
    assert all(files[name][:8] == b"\x89PNG\r\n\x1a\n" for name in files if name.endswith(".png"))


def test_snapshots_show_the_first_and_last_sample_and_never_stack_a_resting_body():
    result, _ = falling_cube(t_end=2.0, dt=0.001)
    chosen = figures3d.snapshot_indices(result)
    assert chosen[0] == 0 and chosen[-1] == len(result.t) - 1
    resting = result.t >= np.sqrt(2 * 0.4 / G)
    assert sum(resting[i] for i in chosen) == 1  # 1.7 s at rest, drawn once
    bottom = result.positions[chosen, 0, 2]
    assert np.all(np.diff(-bottom) >= SIDE)  # a cube's height apart: they do not overlap


def test_every_3d_figure_draws_a_run_without_contact_and_a_body_without_links():
    result, grounds = falling_cube(t_end=0.1)  # still falling: no force; drop the events it would have later
    assert not result.contact_force.any()
    result.events_time, result.events_particle = result.events_time[:0], result.events_particle[:0]
    result.events_kind, result.events_held = result.events_kind[:0], result.events_held[:0]
    single = SimulationResult(**{**result.arrays(), "positions": result.positions[:, :1],
                                 "velocities": result.velocities[:, :1], "contact_force": result.contact_force[:, :1],
                                 "masses": result.masses[:1], "links": np.zeros((0, 2), int)})
    for r in (result, single):
        files = figures.render_all(r, grounds)
        assert Image.open(io.BytesIO(files["drop.gif"])).n_frames == 3  # 0, 0.04, 0.08 s
    title = figures3d.figure_contact_force(result).axes[0].get_title()
    assert "no particle touched the ground" in title


def _two_cubes(gap: float = 0.05) -> SimulationResult:
    """The falling cube and a copy of it ``gap`` beside it, 1 cm higher: two bodies, the
    second's impact 1 cm of fall later."""
    result, _ = falling_cube(t_end=0.5)
    other = result.positions + np.array([SIDE + gap, 0.0, 0.01])
    arrays = result.arrays()
    return SimulationResult(**{**arrays, "positions": np.concatenate([result.positions, other], axis=1),
                               "velocities": np.concatenate([result.velocities] * 2, axis=1),
                               "contact_force": np.concatenate([result.contact_force] * 2, axis=1),
                               "masses": np.concatenate([result.masses] * 2),
                               "links": np.concatenate([result.links, result.links + 8])})


def test_several_bodies_are_drawn_a_panel_per_time_from_the_first_impact_to_the_end():
    """Bodies that meet move less than their size: drawn over each other they would hide it,
    so each time gets its panel (the first sample, the first impact, the largest force, the
    last); one body is still drawn in one view."""
    result = _two_cubes()
    assert figures3d.body_count(result) == 2 and figures3d.body_count(falling_cube()[0]) == 1
    chosen = figures3d.strip_indices(result)
    assert chosen == sorted(set(chosen)) and len(chosen) == 4
    assert chosen[0] == 0 and chosen[-1] == len(result.t) - 1 and figures.first_impact_index(result) in chosen
    fig = figures3d.figure_snapshots(result)
    assert [ax.get_title() for ax in fig.axes] == [f"t = {result.t[i]:.4g} s" for i in chosen]
    assert "the bodies at 4 times" in fig._suptitle.get_text()
    assert len(figures3d.figure_snapshots(falling_cube()[0]).axes) == 1


def test_the_lowest_gap_zoom_says_when_nothing_came_near_a_ground():
    result, grounds = falling_cube(height=0.4, t_end=0.1)  # 0.4 - g 0.1^2 / 2 = 0.35 m above it at the end
    bottom = figures3d.figure_lowest_gap(result, grounds).axes[1]
    (note,) = [t.get_text() for t in bottom.texts]
    assert note == f"no particle came within 15 mm of a ground (nearest {_lowest_gap(result, grounds):.3g} m)"
    landed, grounds = falling_cube(t_end=0.5)
    assert not figures3d.figure_lowest_gap(landed, grounds).axes[1].texts
