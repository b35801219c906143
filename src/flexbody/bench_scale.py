"""``flexbody bench --study scale``: cost against size (a benchmark, not a test).

Filled discs (2D, triangular lattices, :func:`flexbody.presets.disc`) and filled cubes
(3D, braced cubic lattices, :func:`flexbody.presets.box`) of about 23, 100, 1 000 and
10 000 particles, each dropped for 1 s, with per-link constants and the same lattice
spacing so their fastest mode, and so the explicit step size, does not change with size
(output every 10 ms).  For each dimension and size:

* the first run of a never-seen topology end to end (a fresh process: load the scene,
  build the assembly, integrate, write the result; the runtime library already compiled)
  and the same run again, whose difference is what a new topology costs;
* the C right-hand side per link (timed inside C);
* the integration time of the 1 s drop, its RHS evaluations and events;
* the threads its right-hand side used (OpenMP: one per 4096 links, up to the cores) and,
  where that is more than one, the same integration on one thread (``OMP_NUM_THREADS=1``);
* the peak memory of that process (resident set, MB);
* beside them, the old whole-scene path where it finishes: deriving and rendering the
  scene's particles model with SymPy (2D sizes up to :data:`DERIVE_MAX`, or
  :data:`QUICK_DERIVE_MAX` with ``--quick``).

Each size runs in its own process, so its peak memory is its own.  Every row has a
``dim`` (2 or 3); the 2D rows mean what they meant before 3D joined.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from .scene import rotation_matrix

SIZES = (23, 100, 1000, 10000)  # about: the lattices hold the nearest number that fills them
QUICK_SIZES = (23, 100, 1000)
DIMS = (2, 3)
DERIVE_MAX = 100
QUICK_DERIVE_MAX = 23  # the whole-scene derivation of 100 particles alone takes minutes
#: The thesis-ball disc's lattice spacing (m): 0.1 x sqrt(pi / (23 x sqrt(3) / 2)).
SPACING = 0.1 * (np.pi / (23 * 3**0.5 / 2)) ** 0.5


def scene_table(dim: int, count: int) -> dict:
    """The study's body of about ``count`` particles in ``dim`` dimensions (a scene table)."""
    return disc_scene_table(count) if dim == 2 else cube_scene_table(count)


def disc_scene_table(count: int) -> dict:
    """A disc of about ``count`` particles, 0.05 kg each, k = 2000 N/m and c = 0.5 N s/m per
    link (the thesis ball's constants), radius 0.1 m x sqrt(count / 23), dropped from 0.3 m."""
    from .presets import disc

    radius = 0.1 * (count / 23) ** 0.5
    points, links = disc(count, radius)
    return {
        "name": f"disc_{count}",
        "bodies": [{"name": "disc", "particles": points.tolist(), "links": [list(x) for x in links],
                    "mass": 0.05, "stiffness": 2000.0, "damping": 0.5, "damper": "relative",
                    "position": [0.0, radius + 0.3], "angle": 0.05}],
        "simulation": {"t_end": 1.0, "output_dt": 1e-2},  # 101 samples: the study times the simulation
    }


def cube_scene_table(count: int) -> dict:
    """A braced cubic lattice of ``m**3`` particles, ``m = round(count ** (1/3))`` (27, 125, 1000,
    10 648 for the study's sizes), ``SPACING`` apart, with the disc's per-particle and per-link
    constants, turned 0.07 rad about (1, 1, 0) so it lands on a corner, which starts 0.3 m up."""
    m = max(2, round(count ** (1 / 3)))
    side = (m - 1) * SPACING
    rotation = [0.05, 0.05, 0.0]
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * side / 2
    lowest = float((corners @ rotation_matrix(rotation).T)[:, 2].min())
    return {
        "name": f"cube_{m ** 3}",
        "gravity": [0.0, 0.0, -9.81],
        "bodies": [{"name": "cube", "shape": "box", "count": [m, m, m], "size": [side] * 3,
                    "mass": 0.05, "stiffness": 2000.0, "damping": 0.5, "damper": "relative",
                    "position": [0.0, 0.0, 0.3 - lowest], "rotation": rotation}],
        "simulation": {"t_end": 1.0, "output_dt": 1e-2},
    }


# One size, in a process of its own: prints one JSON line.
_CHILD = r"""
import json, resource, sys, time
start = time.perf_counter()
import numpy as np
import flexbody
from flexbody.bench_scale import scene_table
from flexbody.state import initial_coordinates
dim, count = int(sys.argv[1]), int(sys.argv[2])
scene = flexbody.load_scene(scene_table(dim, count))
loaded = time.perf_counter()
model = flexbody.load_model(scene)
built = time.perf_counter()
result = flexbody.simulate(scene, model=model)
simulated = time.perf_counter()
result.save(sys.argv[3])
saved = time.perf_counter()
p = model.parameters(scene)
q, u = initial_coordinates(scene, model)
y = np.concatenate([q, u, [0.0, 0.0]])
zeros = np.zeros(model.n_contacts)
rhs = sorted(model.time_rhs(y, p, zeros.astype(np.intc), zeros, calls=max(20, 2_000_000 // (len(model.links) + 1)))
             for _ in range(3))[1]
print(json.dumps({
    "dim": dim, "particles": scene.n_particles, "links": int(len(model.links)), "threads": result.stats["threads"],
    "status": result.status,
    "process_s": saved - start, "scene_s": loaded - start, "assembly_s": built - loaded,
    "integration_s": result.stats["wall_time_s"], "simulate_s": simulated - built, "save_s": saved - simulated,
    "rhs_s": rhs, "rhs_per_link_ns": rhs / max(len(model.links), 1) * 1e9,
    "rhs_evaluations": result.stats["rhs_evaluations"], "events": result.stats["events"],
    "max_penetration_m": result.stats["max_penetration_m"],
    "energy_drift_relative": result.stats["energy_drift_relative"],
    "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
}))
"""


def _child(dim: int, count: int, threads: int | None = None) -> dict:
    """One size's run in a fresh process (on ``threads`` threads if given: OMP_NUM_THREADS)."""
    env = dict(os.environ, OMP_NUM_THREADS=str(threads)) if threads else None
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        run = subprocess.run([sys.executable, "-c", _CHILD, str(dim), str(count), tmp], capture_output=True,
                             text=True, check=False, env=env)
        wall = time.perf_counter() - start
    if run.returncode != 0:
        raise RuntimeError(f"scale run of about {count} particles in {dim}D failed:\n{run.stderr}")
    row = json.loads(run.stdout.strip().splitlines()[-1])
    row["wall_s"] = wall
    return row


def _derive_whole(count: int, timeout: float) -> float | None:
    """Seconds to derive and render the whole-scene particles model (SymPy), or None if it
    takes longer than ``timeout``."""
    code = ("import sys, flexbody\nfrom derivation.writer import render_scene\n"
            "from flexbody.bench_scale import disc_scene_table\n"
            "render_scene(flexbody.load_scene(disc_scene_table(int(sys.argv[1]))), 'particles', source='x', command='x')\n")
    start = time.perf_counter()
    try:
        subprocess.run([sys.executable, "-c", code, str(count)], check=True, capture_output=True, timeout=timeout,
                       env={"PYTHONHASHSEED": "0", **__import__("os").environ})
    except subprocess.TimeoutExpired:
        return None
    return time.perf_counter() - start


def scale_study(out: Path, quick: bool, repeats: int = 3) -> dict:
    """Run the study; print a table; save ``scale.json`` and ``scale.png`` in ``out``."""
    from . import runtime
    from .bench import _environment, _save

    runtime.library()  # compiled once per install, before anything is timed
    sizes = QUICK_SIZES if quick else SIZES
    derive_max = QUICK_DERIVE_MAX if quick else DERIVE_MAX
    rows = []
    print("scale: 2D discs and 3D cubes dropped for 1 s (assembled particles formulation, compiled dopri5, "
          "rtol 1e-6)")
    print(f"  {'dim':>3} {'n':>6} {'links':>6} {'first run':>9} {'again':>7} {'new-topology cost':>17} "
          f"{'ns/link':>8} {'integrate':>9} {'threads':>7} {'on one':>7} {'RHS evals':>9} {'events':>6} "
          f"{'peak MB':>8} {'whole-scene derive':>18}")
    for dim, count in ((dim, count) for dim in DIMS for count in sizes):
        first = _child(dim, count)  # never seen: nothing to reuse but the compiled runtime
        again = [_child(dim, count) for _ in range(max(1, repeats - 1) if count <= 1000 else 1)]  # the largest: once
        derive = _derive_whole(count, timeout=600) if dim == 2 and count <= derive_max else None
        row = dict(first, again_wall_s=statistics.median(r["wall_s"] for r in again),
                   again_integration_s=statistics.median(r["integration_s"] for r in again),
                   again_rhs_per_link_ns=statistics.median(r["rhs_per_link_ns"] for r in again),
                   whole_scene_derive_s=derive)
        row["new_topology_overhead_s"] = row["wall_s"] - row["again_wall_s"]
        if row["threads"] > 1:  # beside it, the same run on one thread
            single = _child(dim, count, threads=1)
            row.update(one_thread_integration_s=single["integration_s"],
                       one_thread_rhs_per_link_ns=single["rhs_per_link_ns"])
        rows.append(row)
        print(f"  {dim:>3} {row['particles']:>6} {row['links']:>6} {row['wall_s']:>8.2f}s {row['again_wall_s']:>6.2f}s "
              f"{row['new_topology_overhead_s']:>16.2f}s {row['again_rhs_per_link_ns']:>8.1f} "
              f"{row['again_integration_s']:>8.2f}s {row['threads']:>7} "
              + (f"{row['one_thread_integration_s']:>6.2f}s " if row["threads"] > 1 else f"{'-':>7} ")
              + f"{row['rhs_evaluations']:>9} {row['events']:>6} "
              f"{row['peak_rss_mb']:>8.0f} " + (f"{derive:>17.1f}s" if derive else f"{'-':>18}"))
    data = {"environment": _environment(), "rows": rows}
    _save(out, "scale", data, _plot(rows))
    return data


#: How each dimension is drawn: the same colour per quantity, a line style and marker per dimension.
_STYLE = {2: dict(ls="-", mfc=None), 3: dict(ls="--", mfc="none")}
_LABEL = {2: "2D discs", 3: "3D cubes"}


def _plot(rows: list[dict]):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    fig, (ax, mem) = plt.subplots(1, 2, figsize=(11, 5.0))
    quantities = (("o", "C0", "whole process: scene, run 1 s, save", lambda r: r["again_wall_s"]),
                  ("s", "C1", "integration of the 1 s drop", lambda r: r["again_integration_s"]),
                  ("v", "C3", "the same on one thread", lambda r: r.get("one_thread_integration_s")),
                  ("^", "C2", "one RHS evaluation", lambda r: r["again_rhs_per_link_ns"] * r["links"] * 1e-9))
    dims = sorted({r.get("dim", 2) for r in rows})  # rows saved before 3D joined are 2D
    for dim in dims:
        mine = [r for r in rows if r.get("dim", 2) == dim]
        n = [r["particles"] for r in mine]
        for marker, colour, _, value in quantities:
            points = [(k, value(r)) for k, r in zip(n, mine) if value(r) is not None]
            if points:
                ax.loglog(*zip(*points), marker=marker, color=colour, **_STYLE[dim])
        derived = [(r["particles"], r["whole_scene_derive_s"]) for r in mine if r.get("whole_scene_derive_s")]
        if derived:
            ax.loglog(*zip(*derived), "x", color="k", **_STYLE[dim])
        memory = [r["peak_rss_mb"] for r in mine]
        (points,) = mem.plot(n, memory, "o", mfc=_STYLE[dim]["mfc"])
        if len(n) > 1:
            slope, base = np.polyfit(n, memory, 1)
            mem.plot([0, max(n)], [base, base + slope * max(n)], ls=_STYLE[dim]["ls"], color=points.get_color(),
                     label=f"{_LABEL[dim]}: {base:.0f} MB + {slope * 1024:.1f} kB per particle")
    handles = [Line2D([], [], marker=m, color=c, label=label) for m, c, label, _ in quantities]
    if any(r.get("whole_scene_derive_s") for r in rows):
        handles.append(Line2D([], [], marker="x", color="k",
                              label="old path: derive whole scene (SymPy), before any run"))
    handles += [Line2D([], [], color="0.4", marker="o", label=_LABEL[d], **_STYLE[d]) for d in dims]
    ax.set_xlabel("particles")
    ax.set_ylabel("time (s)")
    ax.set_title("Cost vs size (assembled element kernels)")
    ax.grid(True, which="both", alpha=0.3)
    fig.legend(handles=handles, fontsize=8, loc="lower center", ncol=3)  # below both panels: off the lines
    mem.set_xlabel("particles")
    mem.set_ylabel("peak resident memory of the process (MB)")
    mem.set_title("Memory vs size (linear axes)")
    mem.legend(fontsize=8)
    mem.grid(True, which="both", alpha=0.3)
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    return fig
