"""Pictures of a sweep: each observable against one varied field (lines) or two (heat maps).

Failed runs (status other than ``success``) are marked with a red cross: on the bottom
edge of a line plot, in their cell of a heat map or at their point of a sampled design.
Draws on matplotlib ``Figure`` objects (no pyplot state) and saves ``DIR/<observable>.png``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

FAILED = dict(marker="x", color="tab:red", linestyle="none", markersize=7, markeredgewidth=1.5)


def _coordinates(values: list) -> tuple[np.ndarray, list[str] | None, bool]:
    """Plot positions of a field's values, tick labels for non-numbers, and whether to use a log axis."""
    if all(isinstance(v, (int, float, np.number)) and not isinstance(v, bool) for v in values):
        x = np.asarray(values, dtype=float)
        positive = x[np.isfinite(x)]
        log = bool(len(positive)) and positive.min() > 0 and positive.max() / positive.min() >= 20
        return x, None, log
    labels = list(dict.fromkeys(str(v) for v in values))
    return np.array([labels.index(str(v)) for v in values], dtype=float), labels, False


def _spread(values: np.ndarray) -> bool:
    """Whether positive values span enough decades for a log axis."""
    finite = values[np.isfinite(values)]
    return bool(len(finite)) and finite.min() > 0 and finite.max() / finite.min() >= 100


def _axis(ax, which: str, field: str, labels: list[str] | None, log: bool) -> None:
    getattr(ax, f"set_{which}label")(field)
    if labels is not None:
        getattr(ax, f"set_{which}ticks")(range(len(labels)), labels)
    elif log:
        getattr(ax, f"set_{which}scale")("log")


def _edges(centres: np.ndarray, log: bool) -> np.ndarray:
    """Cell edges around sorted cell centres (geometric midpoints on a log axis)."""
    c = np.log(centres) if log else centres
    if len(c) == 1:
        e = np.array([c[0] - 0.5, c[0] + 0.5]) if not log else np.array([c[0] - 0.1, c[0] + 0.1])
    else:
        mid = (c[1:] + c[:-1]) / 2
        e = np.concatenate([[2 * c[0] - mid[0]], mid, [2 * c[-1] - mid[-1]]])
    return np.exp(e) if log else e


def draw(frame, axes, design: str, out: Path) -> list[Path]:
    """Save one PNG per observable into ``out``; nothing for more than two varied fields."""
    from matplotlib.figure import Figure

    from .sweep import OBSERVABLES

    fields = [a.field for a in axes]
    if len(fields) not in (1, 2) or frame.empty:
        return []
    failed = (frame["status"] != "success").to_numpy()
    coords = []
    for axis in axes:
        x, labels, log = _coordinates(frame[axis.field].tolist())
        coords.append((x, labels, log or (axis.log and labels is None)))
    paths = []
    for key, meaning in OBSERVABLES.items():
        z = frame[key].to_numpy(dtype=float, na_value=math.nan)
        z = np.where(failed, np.nan, z)  # a failed run's numbers describe a cut-short run: crossed out instead
        fig = Figure(figsize=(6.4, 4.4), layout="constrained")
        ax = fig.add_subplot()
        if len(fields) == 1:
            _line(ax, coords[0], fields[0], key, z, failed)
        elif design == "grid":
            _heat_map(fig, ax, coords, fields, key, z, failed)
        else:
            _scatter(fig, ax, coords, fields, key, z, failed)
        ax.set_title(f"{key}\n{meaning}", fontsize=9)
        path = out / f"{key}.png"
        fig.savefig(path, dpi=100)
        paths.append(path)
    return paths


def _line(ax, coord, field, key, z, failed) -> None:
    x, labels, log = coord
    order = np.argsort(x, kind="stable")
    ok = order[~failed[order]]
    ax.plot(x[ok], z[ok], "o-", ms=3, lw=1)
    if failed.any():
        # On the bottom edge: a failed run has no value to place.
        ax.plot(x[failed], np.zeros(failed.sum()), transform=ax.get_xaxis_transform(), clip_on=False,
                label=f"failed ({failed.sum()})", **FAILED)
        ax.legend(fontsize=8)
    _axis(ax, "x", field, labels, log)
    if _spread(z):
        ax.set_yscale("log")
    ax.set_ylabel(key)


def _heat_map(fig, ax, coords, fields, key, z, failed) -> None:
    (x, xl, xlog), (y, yl, ylog) = coords
    xs, ys = np.unique(x), np.unique(y)
    grid = np.full((len(ys), len(xs)), np.nan)
    grid[np.searchsorted(ys, y), np.searchsorted(xs, x)] = z
    norm = None
    if _spread(z):
        from matplotlib.colors import LogNorm

        norm = LogNorm()
    mesh = ax.pcolormesh(_edges(xs, xlog), _edges(ys, ylog), np.ma.masked_invalid(grid), norm=norm,
                         cmap="viridis")
    fig.colorbar(mesh, ax=ax, label=key)
    if failed.any():
        ax.plot(x[failed], y[failed], label=f"failed ({failed.sum()})", **FAILED)
        ax.legend(fontsize=8, loc="upper right")
    _axis(ax, "x", fields[0], xl, xlog)
    _axis(ax, "y", fields[1], yl, ylog)


def _scatter(fig, ax, coords, fields, key, z, failed) -> None:
    (x, xl, xlog), (y, yl, ylog) = coords
    norm = None
    if _spread(z):
        from matplotlib.colors import LogNorm

        norm = LogNorm()
    ok = ~failed & np.isfinite(z)
    points = ax.scatter(x[ok], y[ok], c=z[ok], norm=norm, cmap="viridis", s=30)
    fig.colorbar(points, ax=ax, label=key)
    if failed.any():
        ax.plot(x[failed], y[failed], label=f"failed ({failed.sum()})", **FAILED)
        ax.legend(fontsize=8, loc="upper right")
    _axis(ax, "x", fields[0], xl, xlog)
    _axis(ax, "y", fields[1], yl, ylog)
