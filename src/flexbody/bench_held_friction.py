"""Benchmark ``held_friction``: the held contacts between bodies with friction solved in C
(:mod:`flexbody.held_rows`) against their NumPy rows, in the same process.

Three scenes whose contacts between bodies slide and stick: ``ring_stack`` (2D) with its
upper ring thrown sideways; two rough flexible spheres (3D) on a rough ground, the upper
one landing with a sideways speed (few held rows: most of the run is elsewhere); and a
stack of three rough flexible boxes, the upper two thrown sideways (many held rows).  Each
is run both ways, alternating, ``repeats`` times: the model's rows in C (with friction;
the frictionless ones and the instants' blocks were in C before) and all of them in NumPy
(the model without its :class:`flexbody.held_rows.CompiledHeldRows`, as the tests compare
them).  The medians of the wall time, the runs' events, steps, penetration and energy
drift (the trajectories differ in the last bits, so their event counts may too), how many
frictional solves C made and handed back to NumPy, and the ratio NumPy / C.  Printed, and
saved as ``held_friction.json`` and ``held_friction.png``.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

from .scene import Scene, load_scene

#: The rows in C (the model's own) and in NumPy.
BACKENDS = ("c", "numpy")


def ring_stack_thrown(t_end: float) -> Scene:
    """The bundled ``ring_stack`` to ``t_end`` (s), its upper ring thrown sideways at 0.3 m/s:
    it lands sliding on the lower ring (mu = 0.5) and sticks."""
    import tomllib

    from .scene import resolve_scene_path

    table = tomllib.loads(resolve_scene_path("ring_stack").read_text())
    table["simulation"]["t_end"] = t_end
    table["bodies"][2]["velocity"] = [0.3, 0.0]
    return load_scene(table)


def rough_spheres(t_end: float) -> Scene:
    """Two flexible spheres (30 particles, 0.5 kg, 2 000 N/m), the upper one landing on the
    lower at 0.4 m/s sideways; mu = 0.4 between them and on the ground."""
    spheres = [{"name": f"s{k}", "shape": "sphere", "count": 30, "radius": 0.1, "center": True, "mass_total": 0.5,
                "stiffness": 2000.0, "damping": 0.5, "damper": "relative",
                "position": [0.05 * k, 0.0, 0.15 + 0.22 * k], "rotation": [0.1 * k, 0.05, 0.0], "collide": True,
                **({"velocity": [0.4, 0.1, 0.0]} if k else {})} for k in range(2)]
    return load_scene({"name": "rough_spheres", "bodies": spheres, "gravity": [0.0, 0.0, -9.81],
                       "contacts": [{"bodies": ["s0", "s1"], "friction": 0.4}],
                       "grounds": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0], "friction": 0.4}],
                       "simulation": {"t_end": t_end, "output_dt": 0.01, "method": "RK45", "rtol": 1e-6,
                                      "atol": 1e-9}})


def rough_boxes(t_end: float) -> Scene:
    """Three flexible boxes (18 particles, 0.4 kg, 4 000 N/m) stacked on a rough ground, each
    smaller and turned a little more than the one below, the upper two thrown sideways (0.25
    and 0.5 m/s): faces sliding on faces, then sticking; mu = 0.4 between them, 0.5 on the
    ground.  Many held rows at once, unlike the spheres."""
    bodies = [{"name": f"box{k}", "shape": "box", "size": [0.2 - 0.03 * k, 0.16 - 0.02 * k, 0.06], "count": [3, 3, 2],
               "mass_total": 0.4, "stiffness": 4000.0, "damping": 0.3, "damper": "relative",
               "position": [0.0, 0.0, 0.031 + 0.061 * k], "rotation": [0.0, 0.0, 0.1 * k],
               "velocity": [0.25 * k, 0.1 * k, 0.0], "collide": True} for k in range(3)]
    pairs = [["box0", "box1"], ["box1", "box2"], ["box0", "box2"]]
    return load_scene({"name": "rough_boxes", "bodies": bodies, "gravity": [0.0, 0.0, -9.81],
                       "contacts": [{"bodies": pair, "friction": 0.4} for pair in pairs],
                       "grounds": [{"point": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0], "friction": 0.5}],
                       "simulation": {"t_end": t_end, "output_dt": 0.01, "method": "RK45", "rtol": 1e-6,
                                      "atol": 1e-9}})


def _run(scene: Scene, backend: str) -> dict:
    """One run with the rows in C or in NumPy: its wall time and numbers."""
    from .driver import simulate
    from .model import load_model

    model = load_model(scene)
    if backend == "numpy":
        model._held_rows = None  # the NumPy rows, as the tests compare them (flexbody.body_contact._solve)
    start = time.perf_counter()
    result = simulate(scene, model=model)
    wall = time.perf_counter() - start
    s = result.stats
    solved, handed_back = model._held_rows.friction_solves if backend == "c" else (0, 0)
    return {"wall_s": wall, "status": result.status, "events": s["events"], "steps": s["steps"],
            "rhs_evaluations": s["rhs_evaluations"], "max_penetration_m": s["max_penetration_m"],
            "energy_drift_relative": s["energy_drift_relative"], "solved_in_c": solved, "handed_back": handed_back}


def held_friction_study(out: Path, repeats: int, quick: bool) -> dict:
    """Run the study (see the module docstring); print a table; save JSON and PNG in ``out``."""
    from . import runtime
    from .bench import _environment, _save

    runtime.library()  # compiled once per install, before anything is timed
    scenes = {"ring_stack thrown (2D)": ring_stack_thrown(1.0 if quick else 3.0),
              "rough spheres (3D)": rough_spheres(0.15 if quick else 0.3),
              "rough boxes (3D)": rough_boxes(0.05 if quick else 0.2)}
    repeats = max(1, repeats)
    print(f"held_friction: the held rows with friction, C against NumPy, median of {repeats} (alternating)")
    print(f"  {'scene':24s} {'rows':>5s} {'status':>8s} {'wall s':>8s} {'events':>6s} {'steps':>6s} "
          f"{'penetration m':>13s} {'drift':>8s} {'C solves':>8s} {'back':>5s}")
    rows = []
    for name, scene in scenes.items():
        runs = {backend: [] for backend in BACKENDS}
        for _ in range(repeats):
            for backend in BACKENDS:
                runs[backend].append(_run(scene, backend))
        entry = {"scene": name, "t_end_s": scene.simulation.t_end}
        for backend in BACKENDS:
            last = runs[backend][-1]
            entry[backend] = {**last, "wall_s": statistics.median(r["wall_s"] for r in runs[backend]),
                              "walls_s": [r["wall_s"] for r in runs[backend]]}
            print(f"  {name:24s} {backend:>5s} {last['status']:>8s} {entry[backend]['wall_s']:8.2f} "
                  f"{last['events']:6d} {last['steps']:6d} {last['max_penetration_m']:13.2e} "
                  f"{last['energy_drift_relative']:8.1e} {last['solved_in_c']:8d} {last['handed_back']:5d}")
        entry["numpy_over_c"] = entry["numpy"]["wall_s"] / entry["c"]["wall_s"]
        print(f"  {'':24s} NumPy / C: {entry['numpy_over_c']:.2f}x")
        rows.append(entry)
    data = {"environment": _environment(), "repeats": repeats, "rows": rows}
    _save(out, "held_friction", data, plot_held_friction(data))
    return data


def plot_held_friction(data: dict):
    """Each scene's median wall time with the rows in C and in NumPy, the ratio above."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(9, 4.5), layout="constrained")
    ax = fig.subplots()
    for i, row in enumerate(data["rows"]):
        for j, (backend, colour) in enumerate(zip(BACKENDS, ("C3", "C0"))):
            r = row[backend]
            bar = ax.bar(3 * i + j, r["wall_s"], color=colour, label=f"rows in {backend}" if i == 0 else None)[0]
            ax.annotate(f"{r['wall_s']:.2f} s\n{r['events']} events", (bar.get_x() + bar.get_width() / 2,
                                                                         r["wall_s"]), ha="center", va="bottom",
                        fontsize=7)
    ax.set_xticks([3 * i + 0.5 for i in range(len(data["rows"]))],
                  [f"{row['scene']}, to {row['t_end_s']:g} s\nNumPy / C: {row['numpy_over_c']:.2f}x"
                   for row in data["rows"]], fontsize=8)
    ax.set_yscale("log")
    ax.set_ylim(top=3 * max(row[b]["wall_s"] for row in data["rows"] for b in BACKENDS))
    ax.set_ylabel("wall time of the run (s)")
    ax.set_title(f"held contacts with friction: C against NumPy rows (median of {data['repeats']})", fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(True, axis="y", which="both", alpha=0.3)
    return fig
