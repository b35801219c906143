"""``flexbody bench --study scale``: cost against size (a benchmark, not a test).

Filled discs (triangular lattices, :func:`flexbody.presets.disc`) of about 23, 100,
1 000 and 10 000 particles, each dropped for 1 s, with per-link constants so their
fastest mode, and so the explicit step size, does not change with size (output every
10 ms).  For each size:

* the first run of a never-seen topology end to end (a fresh process: load the scene,
  build the assembly, integrate, write the result; the runtime library already compiled)
  and the same run again, whose difference is what a new topology costs;
* the C right-hand side per link (timed inside C);
* the integration time of the 1 s drop, its RHS evaluations and events;
* the peak memory of that process (resident set, MB);
* beside them, the old whole-scene path where it finishes: deriving and rendering the
  scene's particles model with SymPy (sizes up to ``--derive-max``, default 100).

Each size runs in its own process, so its peak memory is its own.
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

SIZES = (23, 100, 1000, 10000)
QUICK_SIZES = (23, 100, 1000)
DERIVE_MAX = 100


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


# One size, in a process of its own: prints one JSON line.
_CHILD = r"""
import json, resource, sys, time
start = time.perf_counter()
import numpy as np
import flexbody
from flexbody.bench_scale import disc_scene_table
from flexbody.state import initial_coordinates
count = int(sys.argv[1])
scene = flexbody.load_scene(disc_scene_table(count))
loaded = time.perf_counter()
model = flexbody.load_model(scene)
built = time.perf_counter()
result = flexbody.simulate(scene, model=model)
simulated = time.perf_counter()
result.save(sys.argv[2])
saved = time.perf_counter()
p = model.parameters(scene)
q, u = initial_coordinates(scene, model)
y = np.concatenate([q, u, [0.0, 0.0]])
zeros = np.zeros(model.n_contacts)
rhs = sorted(model.time_rhs(y, p, zeros.astype(np.intc), zeros, calls=max(20, 2_000_000 // (len(model.links) + 1)))
             for _ in range(3))[1]
print(json.dumps({
    "particles": scene.n_particles, "links": int(len(model.links)), "status": result.status,
    "process_s": saved - start, "scene_s": loaded - start, "assembly_s": built - loaded,
    "integration_s": result.stats["wall_time_s"], "simulate_s": simulated - built, "save_s": saved - simulated,
    "rhs_s": rhs, "rhs_per_link_ns": rhs / max(len(model.links), 1) * 1e9,
    "rhs_evaluations": result.stats["rhs_evaluations"], "events": result.stats["events"],
    "max_penetration_m": result.stats["max_penetration_m"],
    "energy_drift_relative": result.stats["energy_drift_relative"],
    "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
}))
"""


def _child(count: int) -> dict:
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        run = subprocess.run([sys.executable, "-c", _CHILD, str(count), tmp], capture_output=True, text=True,
                             check=False)
        wall = time.perf_counter() - start
    if run.returncode != 0:
        raise RuntimeError(f"scale run of {count} particles failed:\n{run.stderr}")
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
    rows = []
    print("scale: discs dropped for 1 s (assembled particles formulation, compiled dopri5, rtol 1e-6)")
    print(f"  {'n':>6} {'links':>6} {'first run':>9} {'again':>7} {'new-topology cost':>17} {'ns/link':>8} "
          f"{'integrate':>9} {'RHS evals':>9} {'events':>6} {'peak MB':>8} {'whole-scene derive':>18}")
    for count in sizes:
        first = _child(count)  # never seen: nothing to reuse but the compiled runtime
        again = [_child(count) for _ in range(max(1, repeats - 1) if count <= 1000 else 1)]  # the largest: once
        derive = _derive_whole(count, timeout=600) if count <= DERIVE_MAX else None
        row = dict(first, again_wall_s=statistics.median(r["wall_s"] for r in again),
                   again_integration_s=statistics.median(r["integration_s"] for r in again),
                   again_rhs_per_link_ns=statistics.median(r["rhs_per_link_ns"] for r in again),
                   whole_scene_derive_s=derive)
        row["new_topology_overhead_s"] = row["wall_s"] - row["again_wall_s"]
        rows.append(row)
        print(f"  {row['particles']:>6} {row['links']:>6} {row['wall_s']:>8.2f}s {row['again_wall_s']:>6.2f}s "
              f"{row['new_topology_overhead_s']:>16.2f}s {row['again_rhs_per_link_ns']:>8.1f} "
              f"{row['again_integration_s']:>8.2f}s {row['rhs_evaluations']:>9} {row['events']:>6} "
              f"{row['peak_rss_mb']:>8.0f} " + (f"{derive:>17.1f}s" if derive else f"{'-':>18}"))
    data = {"environment": _environment(), "rows": rows}
    _save(out, "scale", data, _plot(rows))
    return data


def _plot(rows: list[dict]):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = [r["particles"] for r in rows]
    fig, (ax, mem) = plt.subplots(1, 2, figsize=(11, 4.2))
    ax.loglog(n, [r["again_wall_s"] for r in rows], "o-", label="whole process: scene, run 1 s, save")
    ax.loglog(n, [r["again_integration_s"] for r in rows], "s-", label="integration of the 1 s drop")
    ax.loglog(n, [r["again_rhs_per_link_ns"] * r["links"] * 1e-9 for r in rows], "^-", label="one RHS evaluation")
    derived = [(r["particles"], r["whole_scene_derive_s"]) for r in rows if r["whole_scene_derive_s"]]
    if derived:
        ax.loglog(*zip(*derived), "x--", color="k", label="old path: derive whole scene (SymPy), before any run")
    ax.set_xlabel("particles")
    ax.set_ylabel("time (s)")
    ax.set_title("Cost vs size (assembled element kernels)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    memory = [r["peak_rss_mb"] for r in rows]
    slope, base = np.polyfit(n, memory, 1)
    mem.plot(n, memory, "o", label="measured")
    mem.plot([0, max(n)], [base, base + slope * max(n)], "--", label=f"{base:.0f} MB + {slope * 1024:.1f} kB per particle")
    mem.set_xlabel("particles")
    mem.set_ylabel("peak resident memory of the process (MB)")
    mem.set_title("Memory vs size (linear axes)")
    mem.legend(fontsize=8)
    mem.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    return fig
