"""Benchmarks of friction and restitution on ``ball_on_incline`` (the thesis ball on a 20°
incline): printed tables, JSON and PNG in ``--out``.

* ``friction_wp`` — work-precision: every method's error against wall time over rtol
  1e-3 ... 1e-10, against a dop853 reference at rtol 1e-12 (the thesis ball's study, on
  the incline with mu = 0.6; the floating formulation has no friction and is left out).
* ``friction_map`` — stability over Coulomb's mu and Newton's e: for each (mu, e) and each
  method at rtol 1e-6, the wall time of a good run or why it failed (status, penetration,
  energy drift or error against a tight reference), beside the stiffness x damping map.
"""

from __future__ import annotations

from pathlib import Path

from .bench import (
    _classify,
    _environment,
    _save,
    _scene_variant,
    verdict_grids,
    work_precision,
)
from .driver import simulate
from .scene import Scene, load_scene

FRICTIONS = (0.0, 0.2, 0.6, 1.5)
RESTITUTIONS = (0.0, 0.5, 0.9)
METHODS = ("dopri5", "dop853", "RK45", "Radau", "LSODA")


def incline(friction: float, restitution: float, **simulation) -> Scene:
    """The bundled ``ball_on_incline`` with its ground's mu and e (and simulation fields) set."""
    return _scene_variant("ball_on_incline", simulation, ground={"friction": friction, "restitution": restitution})


def friction_work_precision(out: Path, repeats: int, quick: bool) -> dict:
    """The work-precision study on ``ball_on_incline``; saves ``work_precision_incline``.  The
    reference runs at rtol 1e-12: at 1e-13 dop853's step collapses at the ball's first slip."""
    return work_precision(out, repeats, quick, scene=load_scene("ball_on_incline"), name="work_precision_incline",
                          reference_rtol=1e-12)


def friction_map(out: Path, quick: bool) -> dict:
    """Each method on the incline for every (mu, e); saves ``friction_map``.json/png."""
    frictions = (0.0, 0.6) if quick else FRICTIONS
    restitutions = (0.0, 0.5) if quick else RESTITUTIONS
    methods = ("dopri5", "RK45", "Radau") if quick else METHODS
    cap = 20.0 if quick else 60.0
    print(f"friction map: ball_on_incline for 0.5 s, rtol 1e-6, mu x e; cap {cap:g} s per run")
    cells = []
    for e in restitutions:
        for mu in frictions:
            scene = incline(mu, e, t_end=0.5)
            reference = simulate(scene, method="dop853", rtol=1e-11, atol=1e-14, max_wall_time=10 * cap)
            e0 = float(reference.total_energy[0])
            for method in methods:
                result = simulate(scene, method=method, rtol=1e-6, atol=1e-9, max_wall_time=cap)
                verdict, error = _classify(result, reference, e0) if reference.success else _unreferenced(result)
                s = result.stats
                kinds = list(result.events_kind)
                cells.append({"friction": mu, "restitution": e, "method": method, "verdict": verdict,
                              "status": result.status, "message": "" if result.success else result.message,
                              "time_s": s["wall_time_s"], "rhs_evaluations": s["rhs_evaluations"], "error_m": error,
                              "max_penetration_m": s["max_penetration_m"], "energy_drift_J": s["energy_drift_J"],
                              "impacts": kinds.count("impact"), "sticks": kinds.count("stick"),
                              "slips": kinds.count("slip")})
                print(f"  e {e:3.1f} mu {mu:3.1f} {method:7s} {verdict:13s} {s['wall_time_s']:8.3f} s "
                      f"nfev {s['rhs_evaluations']:8d} error {error:9.2e} impacts {kinds.count('impact'):4d} "
                      f"stick {kinds.count('stick'):4d} slip {kinds.count('slip'):4d}")
    data = {"cells": cells, "environment": _environment()}
    _save(out, "friction_map", data, plot_friction_map(data))
    return data


def _unreferenced(result) -> tuple[str, float]:
    """Verdict where the tight reference itself failed: the run's own failure, if any."""
    return ("no_reference" if result.success else result.status), float("nan")


def plot_friction_map(data: dict):
    """Per restitution e, a method x mu grid: the wall time of each good run, or why it failed."""
    return verdict_grids(data["cells"], "restitution", "friction", lambda e: f"restitution e = {e:g}",
                         "Coulomb friction mu", "Friction map: wall time of each run, or why it failed "
                         "(ball_on_incline, 20° incline, rtol 1e-6, 0.5 s; compiled C right-hand side)")
