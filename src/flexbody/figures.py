"""The thesis's figures (5.1-5.4) and an animation of a run, drawn from a result and its grounds.

Each ``figure_*`` function returns a matplotlib ``Figure`` (object API, no pyplot, so no
display is needed); :func:`render_all` turns them into PNG/GIF bytes.  Heights are gaps
along the grounds' normals, ``min_g (x - point_g) . normal_g``, so tilted grounds and
corners draw and measure as flat ones do; every view is framed on the body's path.

The animation draws its static parts once and blits the moving ones onto a copy of them
for every frame, then hands the canvas buffer to Pillow: no per-frame redraw, no
temporary files.
"""

from __future__ import annotations

import io
from collections.abc import Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.patches import Polygon

from .result import SimulationResult

GROUND_COLOUR, CONTACT_COLOUR, BODY_COLOUR = "0.35", "tab:red", "tab:blue"
#: A gap below this (m) counts as penetration (the bench's stability map uses the same bound).
PENETRATION_TOLERANCE = 1e-6
PNG_DPI = 100


# ---------------------------------------------------------------------------- grounds and views


def ground_planes(grounds: Sequence | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The grounds as arrays: ``points (g, 2)`` and unit ``normals (g, 2)``.

    Parameters
    ----------
    grounds : sequence of objects with ``.point`` and ``.normal``, optional
        A scene's ``grounds``; default one ground through the origin with normal +y.
    """
    if not grounds:
        return np.zeros((1, 2)), np.array([[0.0, 1.0]])
    points = np.array([g.point for g in grounds], dtype=float)
    normals = np.array([g.normal for g in grounds], dtype=float)
    return points, normals / np.linalg.norm(normals, axis=1, keepdims=True)


def gaps(positions: np.ndarray, grounds: Sequence | None = None) -> np.ndarray:
    """Each particle's distance to the nearest ground along its normal (< 0: inside it).

    Parameters
    ----------
    positions : ndarray, shape (..., 2)
    grounds : see :func:`ground_planes`

    Returns
    -------
    ndarray, shape (...)
        ``min_g (x - point_g) . normal_g``.
    """
    points, normals = ground_planes(grounds)
    return (positions @ normals.T - np.sum(points * normals, axis=1)).min(axis=-1)


def view_box(positions: np.ndarray, pad: float = 0.08, right: float = 0.0) -> tuple[float, float, float, float]:
    """``(xmin, xmax, ymin, ymax)`` around every position, padded by ``pad`` of the larger side.

    ``positions`` has shape (..., 2); ``right`` is extra room on the right, as a fraction
    of the larger side (for labels).
    """
    x = positions.reshape(-1, 2)
    lo, hi = x.min(axis=0), x.max(axis=0)
    size = max(float((hi - lo).max()), 1e-3)
    p = pad * size
    return lo[0] - p, hi[0] + p + right * size, lo[1] - p, hi[1] + p


def _figure(size: tuple[float, float], *, left=0.8, right=0.2, bottom=0.55, top=0.35, grid=(1, 1),
            gap=(0.0, 0.0), dpi: int = PNG_DPI) -> Figure:
    """A figure with fixed margins and gaps between its ``grid = (columns, rows)`` panels (inches).

    Fixed margins instead of a layout engine: a layout engine measures every tick label in
    an extra pass before the real draw, about a third of a figure's drawing time.
    """
    fig = Figure(figsize=size, dpi=dpi)
    (w, h), (cols, rows) = size, grid
    # wspace and hspace are fractions of the mean panel width and height
    panel_w = (w - left - right - (cols - 1) * gap[0]) / cols
    panel_h = (h - top - bottom - (rows - 1) * gap[1]) / rows
    fig.subplots_adjust(left=left / w, right=1 - right / w, bottom=bottom / h, top=1 - top / h,
                        wspace=gap[0] / panel_w, hspace=gap[1] / panel_h)
    return fig


def _figsize(box, longest: float, shortest: float = 2.2, extra=(0.95, 0.9)) -> tuple[float, float]:
    """Inches for equal-aspect axes showing ``box``, plus room for the tick labels."""
    w, h = box[1] - box[0], box[3] - box[2]
    scale = longest / max(w, h)
    return max(w * scale, shortest) + extra[0], max(h * scale, shortest) + extra[1]


def _setup_view(ax, box, grounds) -> None:
    ax.set_xlim(box[0], box[1])
    ax.set_ylim(box[2], box[3])
    ax.set_aspect("equal", adjustable="box")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    _draw_grounds(ax, grounds, box)


def _draw_grounds(ax, grounds, box) -> None:
    """Each ground as its boundary line, hatched on the solid side, within a wide square around ``box``."""
    points, normals = ground_planes(grounds)
    centre = np.array([(box[0] + box[1]) / 2, (box[2] + box[3]) / 2])
    half = 2.0 * max(box[1] - box[0], box[3] - box[2])
    square = centre + half * np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]])
    for point, normal in zip(points, normals):
        solid = _clip(square, point, normal)
        if len(solid) >= 3:
            ax.add_patch(Polygon(solid, closed=True, facecolor="0.92", edgecolor="0.55", hatch="///", lw=0, zorder=0))
        tangent = np.array([-normal[1], normal[0]])
        s = tangent @ (centre - point)  # the boundary's point nearest the view's centre, then both ways
        line = point + np.outer([s - 2 * half, s + 2 * half], tangent)
        ax.plot(line[:, 0], line[:, 1], color=GROUND_COLOUR, lw=1.2, zorder=1)


def _clip(polygon: np.ndarray, point: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """The part of a convex ``polygon (k, 2)`` on the solid side ``(x - point) . normal <= 0``."""
    d = (polygon - point) @ normal
    out = []
    for i in range(len(polygon)):
        j = (i + 1) % len(polygon)
        if d[i] <= 0:
            out.append(polygon[i])
        if (d[i] < 0) != (d[j] < 0) and d[i] != d[j]:
            out.append(polygon[i] + (polygon[j] - polygon[i]) * d[i] / (d[i] - d[j]))
    return np.array(out).reshape(-1, 2)


def _draw_body(ax, x: np.ndarray, links: np.ndarray, *, colour=BODY_COLOUR, alpha=1.0, force=None) -> None:
    """Particles ``x (n, 2)`` and links; particles with a contact force are red."""
    ax.add_collection(LineCollection(x[links], colors=colour, linewidths=0.8, alpha=alpha))
    touching = np.zeros(len(x), bool) if force is None else force > 0
    ax.plot(x[~touching, 0], x[~touching, 1], "o", ms=3, color=colour, alpha=alpha)
    ax.plot(x[touching, 0], x[touching, 1], "o", ms=4, color=CONTACT_COLOUR, alpha=alpha)


def _centre(result: SimulationResult) -> np.ndarray:
    """The centre of mass over time, shape (nt, 2)."""
    m = result.masses
    return np.einsum("tnd,n->td", result.positions, m / m.sum())


def first_impact_index(result: SimulationResult) -> int | None:
    """The output sample at (or just after) the first impact; None if nothing hit."""
    impacts = result.events_time[result.events_kind == "impact"]
    if not len(impacts):
        return None
    return int(min(np.searchsorted(result.t, impacts[0]), len(result.t) - 1))


def _snapshots(x: np.ndarray, most: int = 6) -> list[int]:
    """Frames of ``x (m, n, 2)`` whose bounding boxes do not overlap: the first, the last, some between."""
    lo, hi = x.min(axis=1), x.max(axis=1)
    # room for a time label between snapshots, even for a flat body
    margin = max(0.05 * float((hi - lo).max()), 0.06 * float((hi.max(axis=0) - lo.min(axis=0)).max()))

    def apart(i: int, j: int) -> bool:
        return bool(np.any(lo[i] > hi[j] + margin) or np.any(lo[j] > hi[i] + margin))

    chosen = [0]
    for i in range(1, len(x)):
        if apart(chosen[-1], i):
            chosen.append(i)
    last = len(x) - 1
    if chosen[-1] != last:
        if len(chosen) > 1 and not apart(chosen[-1], last):
            chosen.pop()  # make room for the last frame, which must be shown
        chosen.append(last)
    if len(chosen) > most:
        chosen = [chosen[k] for k in np.linspace(0, len(chosen) - 1, most).round().astype(int)]
    return chosen


# ---------------------------------------------------------------------------- the thesis's figures


def figure_free_fall(result: SimulationResult, grounds: Sequence | None = None) -> Figure:
    """Thesis fig. 5.1: the body in free fall, snapshots that do not overlap, until it first touches."""
    hit = first_impact_index(result)
    end = len(result.t) - 1 if hit is None else hit
    x = result.positions[: end + 1]
    box = view_box(x, right=0.25)
    fig = _figure(_figsize(box, 5.0, extra=(0.95, 1.15)), left=0.75, right=0.2, top=0.6)
    ax = fig.add_subplot()
    _setup_view(ax, box, grounds)
    path = _centre(result)[: end + 1]
    ax.plot(path[:, 0], path[:, 1], ":", color="0.5", lw=1.0, label="centre of mass")
    frames = _snapshots(x)
    for k, i in enumerate(frames):
        _draw_body(ax, x[i], result.links, force=result.contact_force[i],
                   alpha=0.35 + 0.65 * k / max(len(frames) - 1, 1))
        ax.annotate(f"{result.t[i]:.3f} s", (x[i, :, 0].max(), x[i, :, 1].mean()), xytext=(6, 0),
                    textcoords="offset points", fontsize=8, va="center")
    ax.legend(loc="upper right", fontsize=7)
    what = "until the first impact" if hit is not None else "(no impact in this run)"
    ax.set_title(f"Free fall {what}\n(thesis fig. 5.1)", fontsize=10)
    return fig


def figure_impact(result: SimulationResult, grounds: Sequence | None = None) -> Figure:
    """Thesis fig. 5.2: the body at its first impact and at its largest contact force, with velocities."""
    hit = first_impact_index(result)
    low = int(np.argmin(gaps(result.positions, grounds).min(axis=1)))
    force = result.contact_force.sum(axis=1)
    panels = [(low, "closest approach (no impact)") if hit is None else (hit, "first impact"),
              (int(np.argmax(force)), "largest contact force") if force.max() > 0 else (low, "no contact force")]
    v = result.velocities[[i for i, _ in panels]]
    size = float(np.ptp(result.positions[panels[0][0]], axis=0).max()) or 0.1
    vmax = float(np.linalg.norm(v, axis=-1).max()) or 1.0
    scale = vmax / (0.35 * size)  # m/s per m: the fastest arrow is 35 % of the body's size
    key = _round_down(vmax / 2)
    fig = _figure((9, 4.4), left=0.75, right=0.15, top=0.75, grid=(2, 1), gap=(0.85, 0.0))
    for ax, (i, title) in zip(fig.subplots(1, 2), panels):
        x = result.positions[i]
        box = view_box(x[None], pad=0.45)
        _setup_view(ax, box, grounds)
        ax.locator_params(nbins=5)
        _draw_body(ax, x, result.links, force=result.contact_force[i])
        arrows = ax.quiver(x[:, 0], x[:, 1], result.velocities[i, :, 0], result.velocities[i, :, 1], angles="xy",
                           scale_units="xy", scale=scale, width=0.004, color="0.3", zorder=3)
        ax.quiverkey(arrows, 0.8, 0.93, key, f"{key:g} m/s", labelpos="W", coordinates="axes",
                     fontproperties={"size": 8})
        ax.set_title(f"{title}, t = {result.t[i]:.4f} s", fontsize=10)
    fig.suptitle("Impact phase (thesis fig. 5.2): red particles are held (pushed by a contact); arrows are velocities "
                 "(same scale in both panels)", fontsize=10)
    return fig


def _round_down(value: float) -> float:
    """The largest 1, 2 or 5 times a power of ten that is <= ``value`` (for a scale key)."""
    exponent = np.floor(np.log10(value))
    mantissa = value / 10**exponent
    return float(max(m for m in (1, 2, 5) if m <= mantissa) * 10**exponent)


def penetration_text(result: SimulationResult, grounds: Sequence | None = None) -> str:
    """One line on the lowest gap of any particle, along the grounds' normals, on the output grid."""
    lowest = float(gaps(result.positions, grounds).min())
    verdict = "no penetration" if lowest >= -PENETRATION_TOLERANCE else "PENETRATION"
    return f"{verdict}: lowest gap {lowest * 1e3:.3g} mm along the ground's normal (output grid)"


def figure_colliding_points(result: SimulationResult, grounds: Sequence | None = None) -> Figure:
    """Thesis fig. 5.3: heights above the ground (along its normal) of the particles that touch it."""
    fig = _figure((8, 5.5), top=0.3, grid=(1, 2), gap=(0.0, 0.35))
    top, bottom = fig.subplots(2, 1, sharex=True)
    h = gaps(result.positions, grounds)
    touched = np.unique(result.events_particle[result.events_surface < 0])  # a ground's events, not a body's
    shown = touched if len(touched) else np.argsort(h.min(axis=0))[:3]
    for i in shown:
        top.plot(result.t, h[:, i], lw=0.9, label=f"particle {i}")
        bottom.plot(result.t, h[:, i] * 1e3, lw=0.9)
    for ax in (top, bottom):
        ax.axhline(0, color=GROUND_COLOUR)
    top.set_ylabel("height above the ground (m)")
    what = "the particles that touch the ground" if len(touched) else "no particle touched the ground; the 3 lowest"
    top.set_title(f"Colliding points (thesis fig. 5.3): {what}", fontsize=10)
    if len(shown) <= 12:
        top.legend(fontsize=7, ncol=3)
    bottom.set_ylim(min(-1.0, 1.1e3 * float(h.min())), 15.0)
    bottom.set_ylabel("height (mm), near the ground")
    bottom.set_xlabel("t (s)")
    bottom.set_title(penetration_text(result, grounds), fontsize=9)
    return fig


def figure_energy(result: SimulationResult) -> Figure:
    """Thesis fig. 5.4: the energies over time, and the drift of their sum."""
    fig = _figure((8.8, 6), right=1.4, top=0.3, grid=(1, 2), gap=(0.0, 0.3))
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(3, 1))
    names = ("kinetic", "spring", "gravity", "damping_work", "impact_loss")
    if np.any(result.friction_work):
        names += ("friction_work",)
    for name in names:
        top.plot(result.t, getattr(result, name), lw=1.1, label=name.replace("_", " "))
    total = result.total_energy
    top.plot(result.t, total, "k--", lw=1.2, label="sum")
    top.set_ylabel("energy (J)")
    top.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    top.set_title("Energy of the system (thesis fig. 5.4): the sum is conserved")
    bottom.plot(result.t, total - total[0], "k", lw=0.8)
    bottom.set_ylabel("sum - initial (J)")
    bottom.set_xlabel("t (s)")
    bottom.ticklabel_format(axis="y", style="sci", scilimits=(-2, 2))
    return fig


def has_friction(result: SimulationResult) -> bool:
    """Whether a run had friction at work (a tangential contact force, or stick and slip events)."""
    return bool(np.any(result.friction_force) or np.isin(result.events_kind, ("stick", "slip")).any())


def figure_friction(result: SimulationResult, grounds: Sequence | None = None, most: int = 6) -> Figure:
    """Contact forces with friction: normal and tangential force of the particles that touch
    the ground (top) and each one's phase over time, free, sticking or sliding (bottom).

    A particle is sliding where it is held and its tangential speed is above 1e-6 m/s (its
    tangential velocity is zeroed when it sticks); stick and slip events are marked.
    """
    fig = _figure((8.8, 6), right=1.4, top=0.3, grid=(1, 2), gap=(0.0, 0.3))
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(3, 2))
    _, normals = ground_planes(grounds)
    touched = np.unique(result.events_particle) if len(result.events_particle) else np.flatnonzero(
        result.contact_force.max(axis=0) > 0)
    shown = touched[np.argsort(-result.contact_force[:, touched].max(axis=0))][:most] if len(touched) else touched
    tangential = np.linalg.norm(result.friction_force, axis=2)
    for row, i in enumerate(sorted(shown)):
        line, = top.plot(result.t, result.contact_force[:, i], lw=1.0, label=f"{i}: normal")
        top.plot(result.t, tangential[:, i], lw=1.0, ls="--", color=line.get_color(), label=f"{i}: tangential")
        held = result.contact_force[:, i] > 0
        v = result.velocities[:, i]
        # The tangential speed against the ground the particle is nearest to.
        n = normals[np.argmin((result.positions[:, i] @ normals.T).min(axis=0))] if len(normals) else np.array([0, 1])
        speed = np.linalg.norm(v - (v @ n)[:, None] * n, axis=1)
        for mask, colour in ((held & (speed <= 1e-6), "tab:green"), (held & (speed > 1e-6), "tab:orange")):
            bottom.fill_between(result.t, row - 0.35, row + 0.35, where=mask, color=colour, lw=0, step="mid")
        for kind, marker in (("stick", "v"), ("slip", "^")):
            at = result.events_time[(result.events_particle == i) & (result.events_kind == kind)]
            bottom.plot(at, np.full(len(at), row), marker, color="k", ms=4, ls="none")
    top.set_ylabel("contact force (N)")
    top.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    top.set_title("Contact forces with friction: normal (solid) and tangential (dashed)", fontsize=10)
    bottom.set_yticks(range(len(shown)), [f"particle {i}" for i in sorted(shown)], fontsize=7)
    bottom.set_ylim(-0.6, max(len(shown), 1) - 0.4)
    bottom.set_xlabel("t (s)")
    bottom.set_title("phase: sticking (green), sliding (orange), free (blank); events: stick v, slip ^", fontsize=9)
    return fig


# ---------------------------------------------------------------------------- the animation


def frame_schedule(t: np.ndarray, fps: int, speed: float, max_frames: int) -> tuple[float, np.ndarray]:
    """The playback speed and the output sample each frame shows, shape (frames,).

    Frames are ``speed / fps`` seconds of the run apart; ``speed`` is raised if the run
    would need more than ``max_frames`` frames.
    """
    span = float(t[-1] - t[0])
    speed = max(speed, span * fps / (max_frames - 1))
    count = int(np.floor(span * fps / speed + 1e-9)) + 1
    wanted = t[0] + np.arange(count) * speed / fps
    return speed, np.minimum(np.searchsorted(t, wanted - 1e-12), len(t) - 1)


class Animation:
    """The run as a GIF: a view of the whole path, frames ``speed / fps`` seconds of the run apart.

    Parameters
    ----------
    result : SimulationResult
    grounds : see :func:`ground_planes`
    fps : int
        Frames per second of playback; ``1000 / fps`` should be a whole number of 10 ms
        (GIF delays are in hundredths of a second).
    speed : float
        Seconds of the run per second of playback (1: real time); raised if the run would
        need more than ``max_frames`` frames.
    dpi : int
    max_frames : int

    Attributes
    ----------
    fig, ax : the figure and its axes (limits contain every position of every frame)
    index : ndarray of int, shape (frames,)
        The output sample shown by each frame.
    frame_ms : int
        How long each frame shows (ms).
    """

    def __init__(self, result: SimulationResult, grounds: Sequence | None = None, *, fps: int = 25,
                 speed: float = 1.0, dpi: int = 80, max_frames: int = 200) -> None:
        speed, self.index = frame_schedule(result.t, fps, speed, max_frames)
        self.result, self.speed, self.frame_ms = result, speed, round(1000 / fps)
        box = view_box(result.positions)
        self.fig = _figure(_figsize(box, 4.2, shortest=2.6), left=0.75, right=0.15, bottom=0.5, top=0.3, dpi=dpi)
        self.canvas = FigureCanvasAgg(self.fig)
        self.ax = ax = self.fig.add_subplot()
        _setup_view(ax, box, grounds)
        pace = "real time" if abs(speed - 1.0) < 1e-9 else f"{speed:.3g}x real time"
        ax.set_title(f"{result.stats.get('scene', 'run')}: played at {pace}", fontsize=9)
        self.links = LineCollection([], colors=BODY_COLOUR, linewidths=0.8, animated=True)
        ax.add_collection(self.links)
        (self.free,) = ax.plot([], [], "o", ms=3, color=BODY_COLOUR, animated=True)
        (self.held,) = ax.plot([], [], "o", ms=4, color=CONTACT_COLOUR, animated=True)
        self.label = ax.text(0.03, 0.97, "", transform=ax.transAxes, va="top", fontsize=9, animated=True,
                             bbox={"facecolor": "white", "edgecolor": "none", "alpha": 0.8, "pad": 1.5})
        self.canvas.draw()  # lays out and draws the static parts once
        self.background = self.canvas.copy_from_bbox(self.fig.bbox)

    def frame(self, k: int):
        """Frame ``k`` as an RGB ``PIL.Image``."""
        i = self.index[k]
        r = self.result
        x, touching = r.positions[i], r.contact_force[i] > 0
        self.canvas.restore_region(self.background)
        self.links.set_segments(x[r.links])
        self.free.set_data(x[~touching, 0], x[~touching, 1])
        self.held.set_data(x[touching, 0], x[touching, 1])
        self.label.set_text(f"t = {r.t[i]:.3f} s")
        for artist in (self.links, self.free, self.held, self.label):
            self.ax.draw_artist(artist)
        return _image(self.canvas)

    def gif(self) -> bytes:
        """The animated GIF: every frame shows ``frame_ms`` ms; it loops."""
        from PIL import Image

        frames = [self.frame(k) for k in range(len(self.index))]
        # One palette for every frame, from the first and last frames and the two body colours
        # (red particles may appear only later): no colour flicker, one quantisation method.
        swatch = np.concatenate([np.asarray(frames[0]), np.asarray(frames[-1]), _swatch(frames[0].width)])
        palette = Image.fromarray(swatch).quantize(colors=64, method=Image.Quantize.MEDIANCUT)
        colours = np.array(palette.getpalette()[: 3 * 64]).reshape(-1, 3)
        # median cut averages white with its neighbours, and Pillow's palette lookup is coarse:
        # make the near-whites white so the background stays white
        colours[colours.min(axis=1) >= 246] = 255
        palette.putpalette(colours.ravel().tolist())
        indexed = [f.quantize(palette=palette, dither=Image.Dither.NONE) for f in frames]
        buffer = io.BytesIO()
        indexed[0].save(buffer, format="GIF", save_all=True, append_images=indexed[1:], duration=self.frame_ms,
                        loop=0, optimize=False)
        return buffer.getvalue()


def _swatch(width: int) -> np.ndarray:
    """Rows of the body and contact colours blended into white (their antialiased edges), uint8."""
    from matplotlib.colors import to_rgb

    blend = np.linspace(0.0, 1.0, width)[:, None]
    rows = [255 * (1 - blend * (1 - np.array(to_rgb(c)))) for c in (BODY_COLOUR, CONTACT_COLOUR)]
    return np.repeat(np.array(rows), 4, axis=0).round().astype(np.uint8)


def animation_gif(result: SimulationResult, grounds: Sequence | None = None, **options) -> bytes:
    """An animated GIF of the run in real time (see :class:`Animation` for the options)."""
    return Animation(result, grounds, **options).gif()


def _image(canvas: FigureCanvasAgg):
    """The canvas's pixels as an RGB ``PIL.Image`` (one copy, done by Pillow)."""
    from PIL import Image

    return Image.frombuffer("RGBA", canvas.get_width_height(), canvas.buffer_rgba(), "raw", "RGBA", 0, 1).convert("RGB")


def _png(fig: Figure) -> bytes:
    """PNG bytes of ``fig`` after one draw (``savefig`` draws a second time for nothing)."""
    canvas = FigureCanvasAgg(fig)
    canvas.draw()
    buffer = io.BytesIO()
    _image(canvas).save(buffer, format="png", compress_level=3, dpi=(fig.dpi, fig.dpi))
    return buffer.getvalue()


def render_all(result: SimulationResult, grounds: Sequence | None = None) -> dict[str, bytes]:
    """File name -> bytes of every figure and the animation.

    Parameters
    ----------
    result : SimulationResult
        A run, complete or partial (a failed run's samples up to where it stopped).
    grounds : sequence of objects with ``.point`` and ``.normal``, optional
        The scene's grounds (``scene.grounds``); default the ground y = 0.
        A 3D result (positions of shape (nt, n, 3)) gets the 3D figures of
        :func:`flexbody.figures3d.render_all` instead.
    """
    if result.positions.shape[2] == 3:
        from .figures3d import render_all as render_all_3d

        return render_all_3d(result, grounds)
    figures = {
        "fig5_1_free_fall.png": _png(figure_free_fall(result, grounds)),
        "fig5_2_impact.png": _png(figure_impact(result, grounds)),
        "fig5_3_colliding_points.png": _png(figure_colliding_points(result, grounds)),
        "fig5_4_energy.png": _png(figure_energy(result)),
    }
    if has_friction(result):
        figures["friction.png"] = _png(figure_friction(result, grounds))
    return figures | {"drop.gif": animation_gif(result, grounds)}
