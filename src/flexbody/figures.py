"""The thesis's figures (5.1-5.4) and an animation of a run, drawn from a result.

Each ``figure_*`` function returns a matplotlib ``Figure`` (object API, no pyplot, so
no display is needed); :func:`render_all` turns them into PNG/GIF bytes.
"""

from __future__ import annotations

import io
import tempfile
from pathlib import Path

import numpy as np
from matplotlib.animation import FuncAnimation, PillowWriter
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure

from .result import SimulationResult

GROUND_COLOUR, CONTACT_COLOUR = "0.35", "tab:red"


def _draw_body(ax, x: np.ndarray, links: np.ndarray, *, colour="tab:blue", alpha=1.0, force=None) -> None:
    """Particles ``x (n, 2)`` and links; particles with a contact force are red."""
    ax.add_collection(LineCollection(x[links], colors=colour, linewidths=0.8, alpha=alpha))
    touching = np.zeros(len(x), bool) if force is None else force > 0
    ax.plot(x[~touching, 0], x[~touching, 1], "o", ms=3, color=colour, alpha=alpha)
    ax.plot(x[touching, 0], x[touching, 1], "o", ms=4, color=CONTACT_COLOUR, alpha=alpha)


def _ground(ax, xmin: float, xmax: float) -> None:
    ax.axhline(0.0, color=GROUND_COLOUR, lw=1.2)
    ax.fill_between([xmin, xmax], [0, 0], [-0.02, -0.02], color="0.85", zorder=0)


def _frame(ax, result: SimulationResult, pad: float = 0.05) -> None:
    x = result.positions
    ax.set_xlim(x[..., 0].min() - pad, x[..., 0].max() + pad)
    ax.set_ylim(-0.02, x[..., 1].max() + pad)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    _ground(ax, x[..., 0].min() - pad, x[..., 0].max() + pad)


def first_impact_time(result: SimulationResult) -> float:
    impacts = result.events_time[result.events_kind == "impact"]
    return float(impacts[0]) if len(impacts) else float(result.t[-1])


def figure_free_fall(result: SimulationResult, links: np.ndarray) -> Figure:
    """Thesis fig. 5.1: the body in free fall, snapshots until it touches the ground."""
    fig = Figure(figsize=(4.5, 5.5), layout="constrained")
    ax = fig.add_subplot()
    t_hit = first_impact_time(result)
    for k, t in enumerate(np.linspace(0.0, t_hit, 5)):
        i = min(np.searchsorted(result.t, t), len(result.t) - 1)
        _draw_body(ax, result.positions[i], links, alpha=0.25 + 0.75 * k / 4)
        ax.annotate(f"{result.t[i]:.3f} s", result.positions[i].max(axis=0), fontsize=7, xytext=(4, 0),
                    textcoords="offset points")
    _frame(ax, result)
    ax.set_title("Free fall (thesis fig. 5.1)")
    return fig


def figure_impact(result: SimulationResult, links: np.ndarray) -> Figure:
    """Thesis fig. 5.2: the body at its first impact and at its deepest compression."""
    fig = Figure(figsize=(8, 3.6), layout="constrained")
    t_hit = first_impact_time(result)
    i_hit = min(np.searchsorted(result.t, t_hit), len(result.t) - 1)
    i_max = int(np.argmax(result.contact_force.sum(axis=1)))
    for ax, i, title in zip(fig.subplots(1, 2), (i_hit, i_max), ("first impact", "largest contact force")):
        x = result.positions[i]
        _draw_body(ax, x, links, force=result.contact_force[i])
        v = result.velocities[i]
        ax.quiver(x[:, 0], x[:, 1], v[:, 0], v[:, 1], angles="xy", scale_units="xy", scale=40, width=0.004,
                  color="0.4")
        centre = x.mean(axis=0)
        size = np.ptp(x, axis=0).max() * 0.75 + 0.02
        ax.set_xlim(centre[0] - size, centre[0] + size)
        ax.set_ylim(-0.02, 2 * size - 0.02)
        ax.set_aspect("equal")
        _ground(ax, centre[0] - size, centre[0] + size)
        ax.set_title(f"{title}, t = {result.t[i]:.4f} s")
        ax.set_xlabel("x (m)")
    fig.axes[0].set_ylabel("y (m)")
    fig.suptitle("Impact phase (thesis fig. 5.2): red particles are held by the ground; arrows are velocities")
    return fig


def figure_colliding_points(result: SimulationResult) -> Figure:
    """Thesis fig. 5.3: heights of the particles that touch the ground, over time."""
    fig = Figure(figsize=(8, 5.5), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True)
    touched = np.unique(result.events_particle)
    y = result.positions[:, :, 1]
    for i in touched:
        top.plot(result.t, y[:, i], lw=0.9, label=f"particle {i}")
        bottom.plot(result.t, y[:, i] * 1e3, lw=0.9)
    top.axhline(0, color=GROUND_COLOUR)
    bottom.axhline(0, color=GROUND_COLOUR)
    top.set_ylabel("height (m)")
    top.set_title("Colliding points (thesis fig. 5.3)")
    if len(touched) <= 12:
        top.legend(fontsize=7, ncol=3)
    bottom.set_ylim(-1.0, 15.0)
    bottom.set_ylabel("height (mm), near the ground")
    bottom.set_xlabel("t (s)")
    depth = max(0.0, -float(y[:, touched].min())) if len(touched) else 0.0
    bottom.set_title(f"no penetration: lowest point {-depth * 1e3:.2g} mm on the output grid", fontsize=9)
    return fig


def figure_energy(result: SimulationResult) -> Figure:
    """Thesis fig. 5.4: the energies over time, and the drift of their sum."""
    fig = Figure(figsize=(8, 6), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(3, 1))
    for name in ("kinetic", "spring", "gravity", "damping_work", "impact_loss"):
        top.plot(result.t, getattr(result, name), lw=1.1, label=name.replace("_", " "))
    total = result.total_energy
    top.plot(result.t, total, "k--", lw=1.2, label="sum")
    top.set_ylabel("energy (J)")
    top.legend(fontsize=8, ncol=3)
    top.set_title("Energy of the system (thesis fig. 5.4): the sum is conserved")
    bottom.plot(result.t, total - total[0], "k", lw=0.8)
    bottom.set_ylabel("sum - initial (J)")
    bottom.set_xlabel("t (s)")
    bottom.ticklabel_format(axis="y", style="sci", scilimits=(-2, 2))
    return fig


def animation_gif(result: SimulationResult, links: np.ndarray, *, frames: int = 100, fps: int = 25) -> bytes:
    """An animated GIF of the run, ``frames`` frames evenly spaced in time."""
    fig = Figure(figsize=(4.5, 4.5), dpi=80, layout="constrained")
    ax = fig.add_subplot()
    _frame(ax, result)
    index = np.unique(np.linspace(0, len(result.t) - 1, frames).round().astype(int))
    lines = LineCollection([], colors="tab:blue", linewidths=0.8)
    ax.add_collection(lines)
    (free,) = ax.plot([], [], "o", ms=3, color="tab:blue")
    (held,) = ax.plot([], [], "o", ms=4, color=CONTACT_COLOUR)
    label = ax.text(0.02, 0.96, "", transform=ax.transAxes, va="top", fontsize=9)

    def draw(i):
        x = result.positions[i]
        touching = result.contact_force[i] > 0
        lines.set_segments(x[links])
        free.set_data(x[~touching, 0], x[~touching, 1])
        held.set_data(x[touching, 0], x[touching, 1])
        label.set_text(f"t = {result.t[i]:.3f} s")
        return lines, free, held, label

    movie = FuncAnimation(fig, draw, frames=index, blit=False)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "drop.gif"
        movie.save(path, writer=PillowWriter(fps=fps))
        return path.read_bytes()


def _png(fig: Figure) -> bytes:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=120)
    return buffer.getvalue()


def render_all(result: SimulationResult, links: np.ndarray) -> dict[str, bytes]:
    """File name -> bytes of every figure and the animation."""
    return {
        "fig5_1_free_fall.png": _png(figure_free_fall(result, links)),
        "fig5_2_impact.png": _png(figure_impact(result, links)),
        "fig5_3_colliding_points.png": _png(figure_colliding_points(result)),
        "fig5_4_energy.png": _png(figure_energy(result)),
        "drop.gif": animation_gif(result, links),
    }
