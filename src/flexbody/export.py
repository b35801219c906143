"""A run as files other programs read: a VTK time series for ParaView.

:func:`export_vtk` writes a folder::

    run.pvd                  the collection: one <DataSet timestep="t" file="frames/frame_00000.vtu"/> per sample
    frames/frame_00000.vtu   the body at that time (VTK XML unstructured grid, written with meshio)
    grounds.vtu              the grounds as quads around the body's path (only when grounds are given)

Open ``run.pvd`` in ParaView: the time slider steps through the samples at their real times.
Each frame holds

* points: the particles' positions (m), shape (n, 3); a 2D run is padded with z = 0;
* cells: one ``vertex`` per particle (so a particle without links is drawn), then one ``line``
  per link, in the order of ``result.links``;
* point data: ``velocity`` (m/s, (n, 3)), ``contact_force`` (N, (n,), the normal force of the
  ground, summed over grounds), ``phase`` ((n,), int: 1 where the particle is held by a
  ground, i.e. its contact force is > 0, else 0: free or at the instant of an impact), ``mass``
  (kg, (n,)).
"""

from __future__ import annotations

import zipfile
from collections.abc import Sequence
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from .errors import InputError
from .result import SimulationResult

FRAMES = "frames"
COLLECTION = "run.pvd"
GROUNDS = "grounds.vtu"


def sample_indices(nt: int, every: int = 1) -> np.ndarray:
    """The samples exported with ``every``: ``0, every, 2 every, …`` and always the last one, shape (k,)."""
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise InputError(f"`every` = {every!r}: must be a whole number >= 1")
    index = np.arange(0, nt, every)
    return index if index[-1] == nt - 1 else np.append(index, nt - 1)


def _pad3(x: np.ndarray) -> np.ndarray:
    """``x (..., d)`` with d = 2 or 3 as ``(..., 3)``: z = 0 added to 2D."""
    if x.shape[-1] == 3:
        return np.ascontiguousarray(x, dtype=float)
    return np.concatenate([x, np.zeros(x.shape[:-1] + (3 - x.shape[-1],))], axis=-1)


def frame_mesh(result: SimulationResult, i: int):
    """Sample ``i`` of ``result`` as a ``meshio.Mesh`` (see the module docstring for its contents)."""
    import meshio

    n = result.positions.shape[1]
    force = np.asarray(result.contact_force[i], dtype=float)
    cells = [("vertex", np.arange(n).reshape(-1, 1))]
    if len(result.links):
        cells.append(("line", np.asarray(result.links, dtype=np.int64).reshape(-1, 2)))
    return meshio.Mesh(
        _pad3(result.positions[i]), cells,
        point_data={"velocity": _pad3(result.velocities[i]), "contact_force": force,
                    "phase": (force > 0).astype(np.int32), "mass": np.asarray(result.masses, dtype=float)},
    )  # fmt: skip


def collection_xml(times: Sequence[float], files: Sequence[str]) -> str:
    """The ``.pvd`` text listing ``files`` at ``times`` (written with ``repr``: read back exactly)."""
    rows = "".join(f'    <DataSet timestep="{float(t)!r}" group="" part="0" file={quoteattr(f)}/>\n'
                   for t, f in zip(times, files, strict=True))
    return ('<?xml version="1.0"?>\n<VTKFile type="Collection" version="0.1" byte_order="LittleEndian">\n'
            f"  <Collection>\n{rows}  </Collection>\n</VTKFile>\n")


def export_vtk(result: SimulationResult, folder: str | Path, grounds: Sequence | None = None, *,
               every: int = 1) -> Path:
    """Write the run as ``folder/run.pvd`` and ``folder/frames/frame_*.vtu`` (and ``grounds.vtu``).

    Parameters
    ----------
    result : SimulationResult
        A 2D or 3D run; positions of shape (nt, n, d).
    folder : str or Path
        Created if needed; files of the same names are overwritten (callers that want the
        folder replaced whole write into a staged folder, as ``flexbody export`` does).
    grounds : sequence of objects with ``.point`` and ``.normal``, optional
        The scene's grounds; given, each is written to ``grounds.vtu`` as a quad around the path.
    every : int
        Export every ``every``-th sample (and the last one).

    Returns
    -------
    Path
        ``folder/run.pvd``.
    """
    import meshio

    index = sample_indices(len(result.t), every)
    folder = Path(folder)
    (folder / FRAMES).mkdir(parents=True, exist_ok=True)
    digits = max(5, len(str(len(result.t) - 1)))
    files = []
    for i in index:
        name = f"{FRAMES}/frame_{i:0{digits}d}.vtu"
        meshio.write(folder / name, frame_mesh(result, int(i)), file_format="vtu", binary=True, compression=None)
        files.append(name)
    if grounds:
        meshio.write(folder / GROUNDS, ground_mesh(result, grounds), file_format="vtu", binary=True, compression=None)
    (folder / COLLECTION).write_text(collection_xml(result.t[index], files))
    return folder / COLLECTION


def ground_mesh(result: SimulationResult, grounds: Sequence):
    """The grounds as one quad each, square, centred under the path's centre, twice its size."""
    import meshio

    x = _pad3(result.positions).reshape(-1, 3)
    centre = (x.min(axis=0) + x.max(axis=0)) / 2
    half = max(float(np.ptp(x, axis=0).max()), 0.1)
    points, quads = [], []
    for g in grounds:
        p, n = _pad3(np.asarray(g.point, float)), _pad3(np.asarray(g.normal, float))
        n /= np.linalg.norm(n)
        if len(np.asarray(g.normal)) == 2:  # a 2D ground is a line: extrude it along z
            u, v = np.array([-n[1], n[0], 0.0]), np.array([0.0, 0.0, 1.0])
        else:
            u = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
            u /= np.linalg.norm(u)
            v = np.cross(n, u)
        foot = centre - ((centre - p) @ n) * n  # the path's centre projected onto the ground
        quads.append(len(points) + np.arange(4))
        points += [foot + half * (a * u + b * v) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    return meshio.Mesh(np.array(points), [("quad", np.array(quads))])


def export_folder(result_dir: str | Path, every: int = 1, fmt: str = "vtk") -> tuple[Path, int]:
    """``flexbody export DIR``: write ``DIR/vtk/`` from ``DIR/result.npz``, replacing it whole.

    Everything is checked before anything is written; the folder is written beside its
    place and renamed into it (:func:`flexbody.paths.staged_folder`), so an existing
    ``DIR/vtk`` is either kept or replaced whole, never mixed.

    Returns
    -------
    (Path, int)
        ``DIR/vtk/run.pvd`` and the number of frames written.

    Raises
    ------
    flexbody.errors.InputError
        ``DIR`` is not a readable result folder, ``every`` is not a whole number >= 1, or
        ``DIR/vtk`` exists and is not a folder.
    """
    from .errors import shown
    from .paths import staged_folder
    from .result import load_result

    def refuse(why: str) -> InputError:
        return InputError(f"`DIR` = {shown(str(result_dir))}: {why}")

    if fmt != "vtk":
        raise InputError(f"`--format` = {shown(fmt)}: must be vtk")
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise InputError(f"`--every` = {shown(every)}: must be a whole number >= 1")
    folder = Path(result_dir)
    if not folder.exists():
        raise refuse("no such folder; give the folder of a run (flexbody run SCENE --out DIR)")
    if not folder.is_dir():
        raise refuse("is not a folder; give the folder of a run (flexbody run SCENE --out DIR)")
    missing = [name for name in ("result.npz", "summary.json") if not (folder / name).is_file()]
    if missing:
        raise refuse(f"holds no {' and no '.join(missing)}, so it is not the folder of a run "
                     "(flexbody run SCENE --out DIR writes them)")
    target = folder / "vtk"
    if target.is_symlink() or (target.exists() and not target.is_dir()):
        raise refuse(f"{target} exists and is not a folder; it would be replaced by the export, so move it away")
    try:
        result = load_result(folder)
    except (OSError, ValueError, KeyError, TypeError, zipfile.BadZipFile) as exc:  # damaged or foreign files
        raise refuse(f"its result cannot be read ({type(exc).__name__}: {exc})") from None
    count = len(sample_indices(len(result.t), every))
    with staged_folder(target) as staging:
        export_vtk(result, staging, every=every)
    return target / COLLECTION, count
