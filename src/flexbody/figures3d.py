"""Figures and an animation of a 3D run, drawn from a result and its grounds.

The same rules as the 2D figures (:mod:`flexbody.figures`): heights are gaps along the
grounds' normals, ``min_g (x - point_g) . normal_g``; the real grounds are drawn (here as
translucent patches, each plane cut to the view's box); every view is framed on the
body's path, with one scale on all three axes.  Each ``figure_*`` function returns a
matplotlib ``Figure`` (object API, Agg, no display); :func:`render_all` turns them into
PNG and GIF bytes.  The energy ledger is dimension-free and is drawn by
:func:`flexbody.figures.figure_energy`.

The animation keeps one camera for the whole run (a view of the whole path), draws the
grounds and axes once and blits the body onto a copy of them for every frame, as the
2D animation does.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d.art3d import Line3DCollection, Poly3DCollection

from . import figures
from .figures import BODY_COLOUR, CONTACT_COLOUR, GROUND_COLOUR, PNG_DPI, _figure, _png
from .result import SimulationResult

#: Camera of every 3D view: elevation and azimuth (degrees), and the perspective's focal length
#: (1 is a 90° field of view; larger is flatter).
ELEVATION, AZIMUTH, FOCAL_LENGTH = 18.0, -60.0, 2.0
#: The lowest-gap figure's zoom: this far above the ground (mm).
NEAR_GROUND_MM = 15.0


@dataclass(frozen=True)
class Plane:
    """A ground as the figures need it: a point on it and its normal (pointing out of the solid)."""

    point: tuple[float, ...]
    normal: tuple[float, ...]


#: With no grounds given: the plane z = 0, solid below.
DEFAULT_GROUNDS = (Plane((0.0, 0.0, 0.0), (0.0, 0.0, 1.0)),)


def planes(grounds: Sequence | None = None) -> Sequence:
    """``grounds`` (objects with ``.point`` and ``.normal``, 3-vectors), or :data:`DEFAULT_GROUNDS`."""
    return tuple(grounds) if grounds else DEFAULT_GROUNDS


def gaps(positions: np.ndarray, grounds: Sequence | None = None) -> np.ndarray:
    """Each particle's distance to the nearest ground along its normal, shape ``positions.shape[:-1]``.

    Parameters
    ----------
    positions : ndarray, shape (..., 3)
    grounds : sequence of objects with ``.point`` and ``.normal``, optional
        Default :data:`DEFAULT_GROUNDS`.
    """
    return figures.gaps(positions, planes(grounds))


def penetration_text(result: SimulationResult, grounds: Sequence | None = None) -> str:
    """One line on the lowest gap of any particle along the grounds' normals (as the 2D fig. 5.3)."""
    return figures.penetration_text(result, planes(grounds))


def view_box(positions: np.ndarray, pad: float = 0.08) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)``, shape (3,) each: a box around every position, padded by ``pad`` of its largest side.

    Every side is at least ``2 pad`` of the largest (a flat or straight path keeps some depth).
    """
    x = positions.reshape(-1, 3)
    lo, hi = x.min(axis=0), x.max(axis=0)
    p = pad * max(float((hi - lo).max()), 1e-3)
    return lo - p, hi + p


def plane_in_box(point: np.ndarray, normal: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """The polygon where the plane ``(x - point) . normal = 0`` cuts the box ``[lo, hi]``.

    Returns
    -------
    ndarray, shape (k, 3)
        Its corners in order around it (k = 3 to 6), or shape (0, 3) if the plane misses the box.
    """
    point, normal = np.asarray(point, float), np.asarray(normal, float)
    corners = np.array([[hi[0] if i & 1 else lo[0], hi[1] if i & 2 else lo[1], hi[2] if i & 4 else lo[2]]
                        for i in range(8)])
    d = (corners - point) @ normal
    cuts = []
    for i in range(8):
        for axis in range(3):  # the box's 12 edges: corner i to the corner one step along each axis
            j = i | (1 << axis)
            if j == i:
                continue
            if d[i] == 0:
                cuts.append(corners[i])
            elif d[i] * d[j] < 0:
                cuts.append(corners[i] + (corners[j] - corners[i]) * d[i] / (d[i] - d[j]))
    if d[7] == 0:
        cuts.append(corners[7])
    if len(cuts) < 3:
        return np.zeros((0, 3))
    cuts = np.unique(np.round(np.array(cuts), 12), axis=0)
    centre = cuts.mean(axis=0)
    u = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    v = np.cross(normal, u)
    angle = np.arctan2((cuts - centre) @ v, (cuts - centre) @ u)
    return cuts[np.argsort(angle)]


def ground_patches(grounds: Sequence | None, lo: np.ndarray, hi: np.ndarray) -> list[np.ndarray]:
    """The grounds as drawn: each plane cut to the view's box ``[lo, hi]`` (those that cross it), (k, 3) each."""
    patches = []
    for ground in planes(grounds):
        normal = np.asarray(ground.normal, float)
        patch = plane_in_box(np.asarray(ground.point, float), normal / np.linalg.norm(normal), lo, hi)
        if len(patch):
            patches.append(patch)
    return patches


def _view_axes(fig: Figure, lo: np.ndarray, hi: np.ndarray, grounds, rect=None):
    """A perspective 3D axes showing exactly the box ``[lo, hi]`` at one scale, with the grounds drawn."""
    ax = fig.add_subplot(projection="3d") if rect is None else fig.add_axes(rect, projection="3d")
    ax.set_proj_type("persp", focal_length=FOCAL_LENGTH)
    ax.view_init(elev=ELEVATION, azim=AZIMUTH)
    for set_lim, (a, b) in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), zip(lo, hi, strict=True), strict=True):
        set_lim(a, b, view_margin=0)
    ax.set_box_aspect(hi - lo, zoom=0.8)
    ax.set_xlabel("x (m)", labelpad=2)
    ax.set_ylabel("y (m)", labelpad=2)
    ax.set_zlabel("z (m)", labelpad=2)
    ax.tick_params(labelsize=7, pad=0)
    ax.locator_params(nbins=4)
    for patch in ground_patches(grounds, lo, hi):
        ax.add_collection3d(Poly3DCollection([patch], facecolors="0.55", edgecolors=GROUND_COLOUR, alpha=0.25,
                                                 linewidths=0.8), autolim=False)
    return ax


def _draw_body(ax, x: np.ndarray, links: np.ndarray, force: np.ndarray, alpha: float = 1.0) -> None:
    """Particles ``x (n, 3)`` and links; particles with a contact force are red."""
    ax.add_collection3d(Line3DCollection(x[links], colors=BODY_COLOUR, linewidths=0.8, alpha=alpha), autolim=False)
    touching = force > 0
    ax.plot(*x[~touching].T, "o", ms=2.5, color=BODY_COLOUR, alpha=alpha)
    ax.plot(*x[touching].T, "o", ms=3.5, color=CONTACT_COLOUR, alpha=alpha)


def snapshot_indices(result: SimulationResult, most: int = 5) -> list[int]:
    """The samples shown in :func:`figure_snapshots`, in time order.

    Candidates, first come first kept: the first sample, the last, the first impact, the
    largest contact force, then samples evenly spaced along the centre of mass's path; a
    candidate is dropped when its centre is within 1.2 body sizes of a kept one (a
    resting body is drawn once, not five times on top of itself).
    """
    x = result.positions
    centre = np.einsum("tnd,n->td", x, result.masses / result.masses.sum())
    size = float(np.ptp(x[0], axis=0).max()) or 1e-3
    candidates = [0, len(x) - 1]
    hit = figures.first_impact_index(result)
    if hit is not None:
        candidates.append(hit)
    force = result.contact_force.sum(axis=1)
    if force.max() > 0:
        candidates.append(int(np.argmax(force)))
    travelled = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(centre, axis=0), axis=1))])
    candidates += list(np.searchsorted(travelled, np.linspace(0, travelled[-1], 4 * most)))
    kept: list[int] = []
    for i in candidates:
        i = int(min(i, len(x) - 1))
        if len(kept) < most and all(np.linalg.norm(centre[i] - centre[j]) >= 1.2 * size for j in kept):
            kept.append(i)
    return sorted(kept)


def body_count(result: SimulationResult) -> int:
    """How many bodies the run has: the connected components of its particles and links
    (a rigid body's are drawn linked too)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    n, links = len(result.masses), np.asarray(result.links, np.intp).reshape(-1, 2)
    graph = coo_matrix((np.ones(len(links)), (links[:, 0], links[:, 1])), shape=(n, n))
    return int(connected_components(graph, directed=False)[0])


def strip_indices(result: SimulationResult, most: int = 4) -> list[int]:
    """The samples of :func:`figure_snapshots` for several bodies, in time order: the first,
    the first impact, the largest contact force and the last, then samples evenly spaced in
    time, ``most`` distinct ones at most."""
    last = len(result.t) - 1
    hit = figures.first_impact_index(result)
    force = result.contact_force.sum(axis=1)
    candidates = [0, *([hit] if hit is not None else []), *([int(np.argmax(force))] if force.max() > 0 else []), last]
    candidates += [int(i) for i in np.linspace(0, last, 2 * most + 1).round()]
    kept: list[int] = []
    for i in candidates:
        if i not in kept and len(kept) < most:
            kept.append(i)
    return sorted(kept)


def _film_strip(result: SimulationResult, grounds: Sequence | None) -> Figure:
    """Several bodies at a few times, one panel each (drawn over each other they would hide
    what happens between them: bodies meeting move less than their size)."""
    lo, hi = view_box(result.positions)
    frames = strip_indices(result)
    fig = Figure(figsize=(9.0, 7.6), dpi=PNG_DPI)
    rects = [(0.0, 0.47, 0.5, 0.44), (0.5, 0.47, 0.5, 0.44), (0.0, 0.0, 0.5, 0.44), (0.5, 0.0, 0.5, 0.44)]
    for i, rect in zip(frames, rects):
        ax = _view_axes(fig, lo, hi, grounds, rect=rect)
        _draw_body(ax, result.positions[i], result.links, result.contact_force[i])
        ax.set_title(f"t = {result.t[i]:.4g} s", fontsize=9)
    fig.suptitle(f"{result.stats.get('scene', 'run')}: the bodies at {len(frames)} time{'s' * (len(frames) != 1)}; "
                 "red particles are in contact (a ground or another body)", fontsize=10)
    return fig


def figure_snapshots(result: SimulationResult, grounds: Sequence | None = None) -> Figure:
    """The body in perspective at a few times (later ones darker), on its grounds; several
    bodies in a panel per time (:func:`strip_indices`)."""
    if body_count(result) > 1:
        return _film_strip(result, grounds)
    lo, hi = view_box(result.positions)
    fig = Figure(figsize=(6.4, 6.0), dpi=PNG_DPI)
    ax = _view_axes(fig, lo, hi, grounds, rect=(0.0, 0.0, 1.0, 0.9))
    frames = snapshot_indices(result)
    for k, i in enumerate(frames):
        x = result.positions[i]
        _draw_body(ax, x, result.links, result.contact_force[i], alpha=0.3 + 0.7 * k / max(len(frames) - 1, 1))
        top = x[np.argmax(x[:, 2])]
        ax.text(*top, f" {result.t[i]:.3f} s", fontsize=7)
    path = np.einsum("tnd,n->td", result.positions, result.masses / result.masses.sum())
    ax.plot(*path.T, ":", color="0.5", lw=1.0, label="centre of mass")
    ax.legend(loc="upper right", fontsize=7)
    fig.suptitle(f"{result.stats.get('scene', 'run')}: the body at {len(frames)} time{'s' * (len(frames) != 1)}; "
                 "red particles are held by the ground", fontsize=10)
    return fig


def figure_lowest_gap(result: SimulationResult, grounds: Sequence | None = None) -> Figure:
    """The lowest gap (over particles and grounds, along each ground's normal) against time.

    The lower panel zooms on the ground (mm) and its title says whether anything went through.
    """
    h = gaps(result.positions, grounds)
    lowest = h.min(axis=1)
    fig = _figure((8, 5.5), top=0.3, grid=(1, 2), gap=(0.0, 0.35))
    top, bottom = fig.subplots(2, 1, sharex=True)
    top.plot(result.t, lowest, color=BODY_COLOUR, lw=1.0, label="lowest particle")
    centre = np.einsum("tn,n->t", h, result.masses / result.masses.sum())
    top.plot(result.t, centre, ":", color="0.4", lw=1.0, label="mass-weighted mean of the particles' gaps")
    top.legend(fontsize=7)
    top.set_ylabel("gap along the normal (m)")
    top.set_title("Lowest point above the ground, along the nearest ground's normal", fontsize=10)
    bottom.plot(result.t, lowest * 1e3, color=BODY_COLOUR, lw=0.9)
    bottom.set_ylim(min(-1.0, 1.1e3 * float(lowest.min())), NEAR_GROUND_MM)
    if lowest.min() * 1e3 > NEAR_GROUND_MM:  # an empty zoom would look like a plotting failure
        bottom.text(0.5, 0.5, f"no particle came within {NEAR_GROUND_MM:g} mm of a ground "
                    f"(nearest {lowest.min():.3g} m)", transform=bottom.transAxes, ha="center", va="center",
                    fontsize=9)
    bottom.set_ylabel("lowest gap near the ground (mm)")
    bottom.set_xlabel("t (s)")
    bottom.set_title(penetration_text(result, grounds), fontsize=9)
    for ax in (top, bottom):
        ax.axhline(0, color=GROUND_COLOUR)
    return fig


def figure_contact_force(result: SimulationResult) -> Figure:
    """The total contact force against time, and each force of the particles that touched."""
    fig = _figure((8, 5.5), right=1.5, top=0.3, grid=(1, 2), gap=(0.0, 0.35))
    top, bottom = fig.subplots(2, 1, sharex=True)
    force = result.contact_force
    top.plot(result.t, force.sum(axis=1), "k", lw=1.0)
    top.set_ylabel("total contact force (N)")
    touched = np.flatnonzero((force > 0).any(axis=0))
    what = f"{len(touched)} particles touched" if len(touched) else "no particle touched the ground"
    top.set_title(f"Contact force of the ground (normal, summed over grounds): {what}", fontsize=10)
    for i in touched:
        bottom.plot(result.t, force[:, i], lw=0.9, label=f"particle {i}")
    if 0 < len(touched) <= 16:
        bottom.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    bottom.set_ylabel("per particle (N)")
    bottom.set_xlabel("t (s)")
    return fig


# ---------------------------------------------------------------------------- the animation


class Animation(figures.Animation):
    """The 3D run as a GIF: one camera framing the whole path, frames ``speed / fps`` s of the run apart.

    Same parameters and attributes as :class:`flexbody.figures.Animation` (``ax`` is a 3D axes
    whose limits contain every position of every frame).
    """

    def __init__(self, result: SimulationResult, grounds: Sequence | None = None, *, fps: int = 25,
                 speed: float = 1.0, dpi: int = 80, max_frames: int = 200) -> None:
        speed, self.index = figures.frame_schedule(result.t, fps, speed, max_frames)
        self.result, self.speed, self.frame_ms = result, speed, round(1000 / fps)
        lo, hi = view_box(result.positions)
        self.fig = Figure(figsize=(4.8, 4.6), dpi=dpi)
        self.canvas = FigureCanvasAgg(self.fig)
        self.ax = ax = _view_axes(self.fig, lo, hi, grounds, rect=(0.0, 0.0, 1.0, 0.93))
        pace = "real time" if abs(speed - 1.0) < 1e-9 else f"{speed:.3g}x real time"
        self.fig.suptitle(f"{result.stats.get('scene', 'run')}: played at {pace}", fontsize=9)
        self.links = Line3DCollection([], colors=BODY_COLOUR, linewidths=0.8, animated=True)
        ax.add_collection3d(self.links, autolim=False)
        (self.free,) = ax.plot([], [], [], "o", ms=2.5, color=BODY_COLOUR, animated=True)
        (self.held,) = ax.plot([], [], [], "o", ms=3.5, color=CONTACT_COLOUR, animated=True)
        self.label = ax.text2D(0.02, 0.97, "", transform=ax.transAxes, va="top", fontsize=9, animated=True,
                               bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.8, "pad": 1.5})
        self.canvas.draw()  # fixes the camera (ax.M) and draws the static parts once
        self.background = self.canvas.copy_from_bbox(self.fig.bbox)

    def frame(self, k: int):
        """Frame ``k`` as an RGB ``PIL.Image``."""
        i = self.index[k]
        r = self.result
        x, touching = r.positions[i], r.contact_force[i] > 0
        self.canvas.restore_region(self.background)
        self.links.set_segments(x[r.links])
        self.links.do_3d_projection()  # a collection projects only when asked; Line3D does it in draw
        self.free.set_data_3d(*x[~touching].T)
        self.held.set_data_3d(*x[touching].T)
        self.label.set_text(f"t = {r.t[i]:.3f} s")
        for artist in (self.links, self.free, self.held, self.label):
            self.ax.draw_artist(artist)
        return figures._image(self.canvas)


def animation_gif(result: SimulationResult, grounds: Sequence | None = None, **options) -> bytes:
    """An animated GIF of the 3D run in real time (see :class:`Animation` for the options)."""
    return Animation(result, grounds, **options).gif()


def render_all(result: SimulationResult, grounds: Sequence | None = None) -> dict[str, bytes]:
    """File name -> bytes of every 3D figure and the animation.

    Parameters
    ----------
    result : SimulationResult
        A 3D run (positions of shape (nt, n, 3)), complete or partial.
    grounds : sequence of objects with ``.point`` and ``.normal`` (3-vectors), optional
        The scene's grounds; default :data:`DEFAULT_GROUNDS`.
    """
    out = {
        "fig3d_snapshots.png": _png(figure_snapshots(result, grounds)),
        "fig3d_lowest_gap.png": _png(figure_lowest_gap(result, grounds)),
        "fig3d_contact_force.png": _png(figure_contact_force(result)),
        "fig5_4_energy.png": _png(figures.figure_energy(result)),
    }
    if figures.has_friction(result):
        out["friction.png"] = _png(figures.figure_friction(result, grounds or DEFAULT_GROUNDS))
    return out | {"drop.gif": animation_gif(result, grounds)}
