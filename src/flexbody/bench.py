"""``flexbody bench``: speed and accuracy, charted (a benchmark, not a test).

The studies, each printed as a table and saved as JSON and PNG in ``--out``:

* ``wp`` — work-precision diagram on the thesis ball: error against wall time over
  methods, backends, formulations and tolerances, against a tight reference run.  The
  SciPy + NumPy baseline runs in the same process and the speed ratios are printed, with
  each run's distance from the limit ``RHS evaluations x C RHS cost``.
* ``stability`` — where methods fail: stiffness 1e2..1e7 N/m x damping ratio x method,
  then the thesis impact ΔT and the tolerance; success, time, error, penetration and
  energy drift, or the failure and its cause.
* ``resolution`` — model no more than a scene needs: the ball with 6 to 64 perimeter
  particles; how rebound height, contact duration and peak contact force converge, what
  each costs, and the coarsest model within 1 %.
* ``mujoco`` — the same ball in MuJoCo (optional extra ``flexbody[mujoco]``): time,
  penetration, rebound height and height error against the tight flexbody reference.
* ``mujoco3d`` — the same for the 3D sphere of ``sphere_drop`` (201 particles) on level
  ground.
* ``run`` — the whole default command ``flexbody run thesis_ball --out DIR`` in fresh
  processes, with and without figures, its imports, and each figure drawn alone.
* ``scale`` — cost against size, 2D discs and 3D cubes (:mod:`flexbody.bench_scale`).
* ``sweep`` — a 200-run stiffness x damping sweep of the ball on a 2-worker Dask cluster
  against a serial loop and plain processes (optional extra ``flexbody[sweep]``):
  speed-up, per-run overhead.
* ``bodies`` — 20 discs of about 200 particles that touch each other against the same
  bodies passing through each other and 20 separate drops (:mod:`flexbody.bench_bodies`).
* ``friction_wp``, ``friction_map`` — work-precision on ``ball_on_incline`` and the
  methods over Coulomb's mu x Newton's e (:mod:`flexbody.bench_friction`).
* ``lcp`` — Lemke's method compiled against its NumPy path on the LCPs the fuzzes saved:
  one path and the whole solve with its rescues, bit for bit the same answers.
* ``held_friction`` — the held contacts between bodies with friction, their rows in C
  against NumPy, on three scenes (one 2D, two 3D) that slide and stick
  (:mod:`flexbody.bench_held_friction`).

Each chart is drawn from its study's JSON alone (:data:`PLOTS`): ``python -m
flexbody.bench [FOLDER]`` redraws the PNGs beside the JSON files without running anything.

Timings are medians over ``--repeats`` runs (the machine is shared and noisy).
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import time
import warnings
from pathlib import Path

import numpy as np

from .driver import simulate
from .model import load_model
from .scene import Scene, load_scene

TOLERANCES = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9, 1e-10)


def _environment() -> dict:
    import scipy

    return {"python": platform.python_version(), "numpy": np.__version__, "scipy": scipy.__version__,
            "machine": platform.machine(), "cpus": os.cpu_count(), "processor": platform.processor()}


def _save(out: Path, name: str, data: dict, fig=None) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / f"{name}.json").write_text(json.dumps(data, indent=1) + "\n")
    if fig is not None:
        fig.savefig(out / f"{name}.png", dpi=110)
    print(f"  saved {out / name}.json" + (f" and {name}.png" if fig is not None else ""))


def _timed(scene, repeats: int, **options):
    """Run ``repeats`` times; return the last result and the median integration wall time."""
    times, result = [], None
    for _ in range(repeats):
        result = simulate(scene, **options)
        times.append(result.stats["wall_time_s"])
        if not result.success:
            break
    return result, statistics.median(times)


def _sequence(result) -> list:
    return list(zip(result.events_particle.tolist(), result.events_kind.tolist()))


def _rhs_cost(model, scene, t_end: float) -> float:
    """Mean C RHS cost (s) per evaluation of a compiled dopri5 run at rtol 1e-6.

    Each segment's evaluations are costed at that segment's start state with its own
    contact set (timed inside C): evaluations in contact phases, which also solve for the
    contact forces, cost more, and steps are shorter there.
    """
    from .driver import _Run, _settings

    run = _Run(scene, model, _settings(scene, {"method": "dopri5", "t_end": t_end}), None, 10**6)
    run.segment_log = []
    run.run()
    p = run.p
    passes = [sum(n * model.time_rhs(y, p, held.astype(np.intc), push, calls=5000)
                  for n, y, held, push in run.segment_log) for _ in range(3)]  # the median of 3: noisy machine
    return statistics.median(passes) / sum(n for n, *_ in run.segment_log)


# ---------------------------------------------------------------------------- work-precision


def work_precision(out: Path, repeats: int, quick: bool, scene: Scene | None = None,
                   name: str = "work_precision", reference_rtol: float = 1e-13) -> dict:
    """Error against wall time for each method over rtol 1e-3 ... 1e-10 (``scene``: the thesis
    ball by default), against a dop853 reference at ``reference_rtol`` (cross-checked by
    SciPy's DOP853 at ten times it); saves ``name``.json/png."""
    scene = scene or load_scene("thesis_ball")
    t_end = 1.0 if quick else scene.simulation.t_end
    tolerances = TOLERANCES[1:-1:2] if quick else TOLERANCES
    print(f"work-precision: {scene.name}, {t_end:g} s; reference dop853 at rtol {reference_rtol:g}")
    reference = simulate(scene, t_end=t_end, method="dop853", rtol=reference_rtol, atol=reference_rtol * 1e-3)
    check = simulate(scene, t_end=t_end, method="DOP853", rtol=10 * reference_rtol, atol=reference_rtol * 1e-2)
    if not (reference.success and check.success):
        raise RuntimeError(f"the reference runs failed: {reference.message} / {check.message}")
    ref_gap = float(np.abs(check.positions - reference.positions).max())
    print(f"  reference cross-check (SciPy DOP853, rtol {10 * reference_rtol:g}): max position difference "
          f"{ref_gap:.2g} m")
    configs = [
        ("C dopri5", "dopri5", "c", "particles", tolerances, repeats),
        ("C dop853", "dop853", "c", "particles", tolerances, repeats),
        ("C dopri5, floating", "dopri5", "c", "floating", tolerances, repeats),
        ("C dop853, floating", "dop853", "c", "floating", tolerances, repeats),
        ("SciPy RK45 + C RHS", "RK45", "c", "particles", tolerances, max(1, repeats // 2)),
        ("SciPy DOP853 + C RHS", "DOP853", "c", "particles", tolerances, max(1, repeats // 2)),
        ("SciPy LSODA + C RHS", "LSODA", "c", "particles", tolerances[:-2], 1),
        ("SciPy Radau + C RHS + Jacobian", "Radau", "c", "particles", tolerances[1:-3], 1),
        ("SciPy RK45 + NumPy RHS (baseline)", "RK45", "numpy", "particles", tolerances[:-2], 1 if quick else 3),
    ]
    formulations = ("particles", "floating")
    if any(g.friction > 0 for g in scene.grounds):  # the floating frame has no friction (a clear error)
        configs = [c for c in configs if c[3] != "floating"]
        formulations = ("particles",)
    cost = {f: _rhs_cost(load_model(scene, "c", f), scene, t_end) for f in formulations}
    print("  C RHS cost per evaluation, weighted by the contact phases: "
          + ", ".join(f"{cost[f] * 1e6:.3f} us ({f})" for f in formulations))
    rows = []
    print(f"  {'configuration':36s} {'rtol':>7s} {'time ms':>9s} {'nfev':>7s} {'error m':>9s} {'limit x':>8s}  events")
    for label, method, backend, formulation, tols, reps in configs:
        for rtol in tols:
            result, wall = _timed(scene, reps, t_end=t_end, method=method, backend=backend,
                                  formulation=formulation, rtol=rtol, atol=rtol * 1e-3, max_wall_time=120.0)
            s = result.stats
            ok = result.success and len(result.t) == len(reference.t)
            error = float(np.abs(result.positions - reference.positions).max()) if ok else float("nan")
            same = ok and _sequence(result) == _sequence(reference)
            evals = s["rhs_evaluations"] + s.get("event_rhs_evaluations", 0)
            limit = evals * cost[formulation]
            row = {"label": label, "method": method, "backend": backend, "formulation": formulation, "rtol": rtol,
                   "time_s": wall, "rhs_evaluations": s["rhs_evaluations"], "event_rhs_evaluations":
                   s.get("event_rhs_evaluations", 0), "steps": s["steps"], "error_m": error,
                   "events_match_reference": same, "status": result.status,
                   "energy_drift_J": s["energy_drift_J"], "max_penetration_m": s["max_penetration_m"],
                   "rhs_limit_s": limit, "time_over_limit": wall / limit}
            rows.append(row)
            print(f"  {label:36s} {rtol:7.0e} {wall * 1e3:9.2f} {s['rhs_evaluations']:7d} {error:9.2e} "
                  f"{wall / limit:8.2f}  {'same' if same else 'DIFFERENT' if ok else result.status}")
    ratios = _ratios(rows)
    for line in ratios["lines"]:
        print("  " + line)
    data = {"scene": scene.name, "t_end": t_end,
            "reference": {"method": "dop853", "rtol": reference_rtol, "cross_check_m": ref_gap},
            "rhs_cost_s": cost, "rows": rows, "ratios": ratios, "environment": _environment()}
    _save(out, name, data, plot_work_precision(data))
    return data


def _ratios(rows: list[dict]) -> dict:
    """Speed ratios at equal rtol (the same steps, hence the same error) and at equal error."""
    by = {(r["label"], r["rtol"]): r for r in rows if r["status"] == "success"}
    base = "SciPy RK45 + NumPy RHS (baseline)"
    lines: list[str] = []
    out: dict = {"same_rtol": {}, "lines": lines}
    for label in ("C dopri5", "C dop853", "SciPy RK45 + C RHS"):
        for rtol in (1e-6, 1e-8):
            if (label, rtol) in by and (base, rtol) in by:
                r = by[base, rtol]["time_s"] / by[label, rtol]["time_s"]
                out["same_rtol"][f"{label} @ {rtol:g}"] = r
                lines.append(f"{label} is {r:.0f}x faster than the baseline at rtol {rtol:g} "
                             f"(errors {by[label, rtol]['error_m']:.1e} and {by[base, rtol]['error_m']:.1e} m)")
    best = {}
    for r in rows:
        if r["status"] == "success" and np.isfinite(r["error_m"]) and r["events_match_reference"]:
            best.setdefault(r["label"], []).append((r["error_m"], r["time_s"]))
    if base in best and "C dop853" in best:
        for target in (1e-6, 1e-8):
            t_base = _time_at_error(best[base], target)
            t_fast = min(_time_at_error(best[k], target) for k in ("C dopri5", "C dop853") if k in best)
            if np.isfinite(t_base) and np.isfinite(t_fast):
                out[f"equal_error_{target:g}"] = t_base / t_fast
                lines.append(f"at equal error {target:g} m the best compiled method is {t_base / t_fast:.0f}x faster "
                             f"than the baseline")
    out["over_limit"] = {}
    for label in ("C dopri5", "C dop853", "C dopri5, floating", "C dop853, floating"):
        over = {rtol: r["time_over_limit"] for (lab, rtol), r in by.items() if lab == label}
        if over:
            out["over_limit"][label] = {f"{rtol:g}": x for rtol, x in sorted(over.items(), reverse=True)}
            lines.append(f"{label}: time / RHS-count limit " + ", ".join(
                f"{x:.2f} (rtol {rtol:g})" for rtol, x in sorted(over.items(), reverse=True)))
    return out


def _time_at_error(points: list[tuple[float, float]], target: float) -> float:
    """Time to reach ``target`` error, interpolated log-log between measured points."""
    points = sorted(points)
    for (e0, t0), (e1, t1) in zip(points, points[1:]):
        if e0 <= target <= e1 and e1 > e0:
            w = np.log(target / e0) / np.log(e1 / e0)
            return float(np.exp(np.log(t0) + w * (np.log(t1) - np.log(t0))))
    return float("nan")


def plot_work_precision(data: dict):
    """Error against time, one line per configuration, each end labelled with its rtol (from the JSON)."""
    from matplotlib.figure import Figure

    rows = data["rows"]
    fig = Figure(figsize=(11, 6), layout="constrained")
    ax = fig.add_subplot()
    for label in dict.fromkeys(r["label"] for r in rows):
        mine = [r for r in rows if r["label"] == label and r["status"] == "success" and np.isfinite(r["error_m"])]
        if not mine:
            continue
        t = [r["time_s"] for r in mine]
        e = [r["error_m"] for r in mine]
        (line,) = ax.loglog(t, e, marker="o", ms=4, label=label, lw=1.2, ls="--" if "floating" in label else "-")
        wrong = [r for r in mine if not r["events_match_reference"]]
        ax.loglog([r["time_s"] for r in wrong], [r["error_m"] for r in wrong], "x", ms=9, color=line.get_color())
        for r in (mine[0], mine[-1]):
            ax.annotate(f"{r['rtol']:.0e}".replace("e-0", "e-"), (r["time_s"], r["error_m"]), xytext=(4, 2),
                        textcoords="offset points", fontsize=6, color=line.get_color())
    ax.set_xlabel("wall time of the integration (s)")
    ax.set_ylabel("max position error vs reference (m)")
    what = data.get("scene", "thesis_ball").replace("_", " ")
    ax.set_title(f"Work-precision, {what}: each line runs rtol 1e-3 ... 1e-10 (atol = 1e-3 rtol), its ends "
                 f"labelled;\nreference dop853 at rtol {data['reference']['rtol']:g}; x: the event sequence differs "
                 "from the reference's", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return fig


# ---------------------------------------------------------------------------- stability map


def _ball(k: float, zeta: float, **simulation) -> Scene:
    """The thesis ball with stiffness k and the damping c = 2 zeta sqrt(k mu) of a link (mu = m/2)."""
    c = 2.0 * zeta * np.sqrt(k * 0.05 / 2.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # critically damped cells are part of the sweep
        return _ball_variant({"t_end": 0.5, "output_dt": 1e-3, **simulation}, stiffness=k, damping=c)


def _classify(result, reference, energy0: float) -> tuple[str, float]:
    if not result.success:
        return result.status, float("nan")
    if len(result.t) != len(reference.t):
        return "incomplete", float("nan")
    error = float(np.abs(result.positions - reference.positions).max())
    if result.stats["max_penetration_m"] > 1e-6:
        return "penetration", error
    if result.stats["energy_drift_J"] > 1e-3 * energy0:
        return "energy_drift", error
    if error > 1e-3:
        return "inaccurate", error
    return "ok", error


def stability_map(out: Path, quick: bool) -> dict:
    stiffness = (1e2, 1e4, 1e6) if quick else (1e2, 1e3, 1e4, 1e5, 1e6, 1e7)
    zetas = (0.05,) if quick else (0.005, 0.05, 0.5)
    methods = ("dopri5", "dop853", "Radau", "LSODA") if quick else ("dopri5", "dop853", "RK45", "Radau", "BDF", "LSODA")
    cap = 20.0 if quick else 60.0
    print(f"stability map: thesis ball for 0.5 s, rtol 1e-6; cap {cap:g} s per run")
    cells = []
    for zeta in zetas:
        for k in stiffness:
            scene = _ball(k, zeta)
            reference = simulate(scene, method="dop853", rtol=1e-11, atol=1e-14, max_wall_time=10 * cap)
            e0 = float(reference.total_energy[0])
            for method in methods:
                result = simulate(scene, method=method, rtol=1e-6, atol=1e-9, max_wall_time=cap)
                verdict, error = _classify(result, reference, e0) if reference.success else ("no_reference", np.nan)
                s = result.stats
                cells.append({"zeta": zeta, "stiffness": k, "method": method, "verdict": verdict, "status": result.status,
                              "message": result.message if not result.success else "", "time_s": s["wall_time_s"],
                              "rhs_evaluations": s["rhs_evaluations"], "error_m": error,
                              "max_penetration_m": s["max_penetration_m"], "energy_drift_J": s["energy_drift_J"]})
                print(f"  zeta {zeta:5.3f} k {k:7.0e} {method:7s} {verdict:13s} {s['wall_time_s']:8.3f} s "
                      f"nfev {s['rhs_evaluations']:8d} error {error:9.2e}")
    sweeps = _impact_and_tolerance_sweeps(quick)
    data = {"cells": cells, "sweeps": sweeps, "environment": _environment()}
    _save(out, "stability_map", data, plot_stability(data))
    return data


def _impact_and_tolerance_sweeps(quick: bool) -> list[dict]:
    scene = _ball(2000.0, 0.5 / (2 * np.sqrt(2000.0 * 0.025)))
    reference = simulate(scene, method="dop853", rtol=1e-11, atol=1e-14)
    e0 = float(reference.total_energy[0])
    rows = []
    for dt in ((1e-3, 1e-5) if quick else (1e-2, 1e-3, 1e-4, 1e-5, 1e-6)):
        r = simulate(scene, method="dopri5", rtol=1e-8, atol=1e-11, impact="thesis", impact_dt=dt, max_wall_time=60)
        verdict, error = _classify(r, reference, e0)
        rows.append({"sweep": "impact_dt", "value": dt, "verdict": verdict, "error_m": error, "time_s":
                     r.stats["wall_time_s"], "max_penetration_m": r.stats["max_penetration_m"]})
        print(f"  thesis impact dT {dt:7.0e}: {verdict:13s} error vs instant {error:9.2e} m, "
              f"penetration {r.stats['max_penetration_m']:.2e} m")
    for method in ("dopri5", "RK45", "LSODA"):
        for rtol in ((1e-2, 1e-4) if quick else (1e-1, 1e-2, 1e-3, 1e-4)):
            r = simulate(scene, method=method, rtol=rtol, atol=rtol * 1e-3, max_wall_time=60)
            verdict, error = _classify(r, reference, e0)
            rows.append({"sweep": "rtol", "method": method, "value": rtol, "verdict": verdict, "error_m": error,
                         "time_s": r.stats["wall_time_s"], "events": r.stats["events"]})
            print(f"  {method:7s} rtol {rtol:7.0e}: {verdict:13s} error {error:9.2e} m, {r.stats['events']} events")
    return rows


#: How each method of the stability map runs (all with the compiled C right-hand side).
LOOPS = {"dopri5": "compiled loop", "dop853": "compiled loop"}


def plot_stability(data: dict):
    """Per damping ratio, a method x stiffness grid: the wall time of each good run, or why it failed."""
    return verdict_grids(data["cells"], "zeta", "stiffness", lambda z: f"damping ratio {z:g}", "stiffness k (N/m)",
                         "Stability map: wall time of each run, or why it failed (thesis ball, rtol 1e-6, 0.5 s; "
                         "every method uses the compiled C right-hand side)", column_format="{:.0e}")


def _duration(seconds: float) -> str:
    return f"{seconds * 1e3:.3g} ms" if seconds < 1 else f"{seconds:.3g} s"


def verdict_grids(cells: list[dict], panel: str, column: str, panel_title, column_label: str, title: str,
                  column_format: str = "{:g}"):
    """One method x ``column`` grid per value of ``panel``: each cell the wall time of a good
    run (``verdict`` "ok"), or why it failed."""
    from matplotlib.figure import Figure

    panels = list(dict.fromkeys(c[panel] for c in cells))
    columns = sorted(dict.fromkeys(c[column] for c in cells))
    methods = list(dict.fromkeys(c["method"] for c in cells))
    fig = Figure(figsize=(3.6 + 3.4 * len(panels), 1.0 + 0.55 * len(methods)), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, len(panels), sharey=True))
    for ax, value in zip(axes, panels):
        grid = np.full((len(methods), len(columns)), np.nan)
        for c in cells:
            if c[panel] != value:
                continue
            i, j = methods.index(c["method"]), columns.index(c[column])
            ok = c["verdict"] == "ok"
            grid[i, j] = np.log10(c["time_s"]) if ok else np.nan
            text = _duration(c["time_s"]) if ok else c["verdict"].replace("_", "\n")
            ax.text(j, i, text, ha="center", va="center", fontsize=6.5,
                    color="white" if ok and np.log10(c["time_s"]) < -0.5 else "black")
        image = ax.imshow(grid, cmap="viridis", aspect="auto", vmin=-3, vmax=2)
        ax.set_xticks(range(len(columns)), [column_format.format(k) for k in columns], fontsize=7)
        ax.set_yticks(range(len(methods)), [f"{m} ({LOOPS.get(m, 'SciPy loop')})" for m in methods], fontsize=8)
        ax.set_xlabel(column_label)
        ax.set_title(panel_title(value), fontsize=9)
    fig.colorbar(image, ax=list(axes), label="log10 wall time (s), successful runs")
    fig.suptitle(title, fontsize=10)
    return fig


# ---------------------------------------------------------------------------- resolution


def _resolution_ball(n: int, k22: float = 2000.0, c22: float = 0.5) -> Scene:
    """A ball of n perimeter particles + centre with the thesis ball's mass and radius.

    The centre keeps its 0.05 kg and the perimeter shares the other 1.1 kg, so the mass
    distribution does not change with n.  Stiffness and damping are scaled so the body
    keeps the same elastic character: spokes act in parallel (k ~ 22/n), rim links in
    series around the perimeter (k ~ n/22).
    """
    links = [(0, i) for i in range(1, n + 1)] + [(i, i % n + 1) for i in range(1, n + 1)]
    k = [k22 * 22 / n] * n + [k22 * n / 22] * n
    c = [c22 * 22 / n] * n + [c22 * n / 22] * n
    angles = 2 * np.pi * np.arange(n) / n
    points = [[0.0, 0.0]] + [[0.1 * np.cos(a), 0.1 * np.sin(a)] for a in angles]
    table = {"name": f"resolution_ball_{n}",
             "bodies": [{"name": "ball", "particles": points, "links": [list(x) for x in links],
                         "masses": [0.05] + [1.1 / n] * n, "stiffness": k, "damping": c, "damper": "relative",
                         "position": [0.0, 0.5], "angle": 0.05}],
             "simulation": {"t_end": 1.0, "output_dt": 1e-4}}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_scene(table)


def _observables(result) -> dict:
    force = result.contact_force.sum(axis=1)
    first = result.events_time[0]
    touching = force > 0
    after = np.flatnonzero((result.t > first) & ~touching)
    end_contact = result.t[after[0]] if len(after) else result.t[-1]
    rebound = _rebound(result.t, result.positions[:, :, 1], result.masses)["rebound_height_m"]
    return {"rebound_height_m": rebound, "contact_duration_s": float(end_contact - first),
            "peak_contact_force_N": float(force.max())}


def resolution_study(out: Path, quick: bool) -> dict:
    counts = (6, 11, 22, 32) if quick else (6, 8, 11, 16, 22, 32, 45, 64)
    print(f"resolution study: ball with {counts} perimeter particles, same mass and radius, dopri5 rtol 1e-8")
    rows = []
    for n in counts:
        scene = _resolution_ball(n)
        start = time.perf_counter()
        load_model(scene, "c")  # derive and compile on demand (cached): reported apart from the run
        prepare = time.perf_counter() - start
        result = simulate(scene, method="dopri5", rtol=1e-8, atol=1e-11)
        row = {"perimeter_particles": n, "dof": 2 * (n + 1), "status": result.status, "time_s":
               result.stats["wall_time_s"], "rhs_evaluations": result.stats["rhs_evaluations"],
               "model_prepare_s": prepare, **(_observables(result) if result.success else {})}
        rows.append(row)
        print(f"  n {n:3d}: {result.status}, {row['time_s'] * 1e3:8.1f} ms, rebound "
              f"{row.get('rebound_height_m', np.nan):.4f} m, contact {row.get('contact_duration_s', np.nan):.4f} s, "
              f"peak force {row.get('peak_contact_force_N', np.nan):8.2f} N (model ready in {prepare:.1f} s)")
    finest = rows[-1]
    keys = ("rebound_height_m", "contact_duration_s", "peak_contact_force_N")
    for row in rows:
        row["relative_change_vs_finest"] = {k: abs(row[k] / finest[k] - 1.0) for k in keys if k in row}
    within = [r["perimeter_particles"] for r in rows if r["relative_change_vs_finest"]
              and max(r["relative_change_vs_finest"].values()) <= 0.01]
    coarsest = min(within) if within else None
    print(f"  coarsest model within 1 % of n = {finest['perimeter_particles']} on all three observables: "
          f"{coarsest if coarsest is not None else 'none'}")
    data = {"rows": rows, "coarsest_within_1_percent": coarsest, "environment": _environment()}
    _save(out, "resolution", data, plot_resolution(data))
    return data


def plot_resolution(data: dict):
    """Each observable and the cost against the number of perimeter particles, with the finest's 1 % band."""
    from matplotlib.figure import Figure

    rows = data["rows"]
    panels = (("rebound_height_m", "rebound height (m)"), ("contact_duration_s", "contact duration (s)"),
              ("peak_contact_force_N", "peak contact force (N)"))
    fig = Figure(figsize=(12, 3.4), layout="constrained")
    axes = fig.subplots(1, len(panels) + 1)
    n = [r["perimeter_particles"] for r in rows]
    for ax, (key, label) in zip(axes, panels):
        ax.plot(n, [r.get(key, np.nan) for r in rows], "o-")
        finest = rows[-1].get(key, np.nan)
        ax.axhspan(0.99 * finest, 1.01 * finest, color="0.85", zorder=0, label=f"within 1 % of n = {n[-1]}")
        ax.set_ylabel(label)
    axes[0].legend(fontsize=7)
    axes[-1].plot(n, [r["time_s"] for r in rows], "o-")
    axes[-1].set_yscale("log")
    axes[-1].set_ylabel("wall time of the run (s)")
    for ax in axes:
        ax.set_xscale("log")
        ax.set_xticks(n, [str(x) for x in n], fontsize=7)
        ax.minorticks_off()
        ax.set_xlabel("perimeter particles n")
    coarsest = data.get("coarsest_within_1_percent")
    verdict = (f"the coarsest within 1 % of n = {n[-1]} on all three is n = {coarsest}" if coarsest not in (None, n[-1])
               else f"no coarser ball is within 1 % of n = {n[-1]} on all three")
    fig.suptitle(f"Resolution: the ball with n perimeter particles (same mass and radius); {verdict}", fontsize=10)
    return fig


# ---------------------------------------------------------------------------- MuJoCo side by side


def mujoco_comparison(out: Path, quick: bool) -> dict | None:
    """The thesis ball (axial dampers, as MuJoCo's tendons) in flexbody and in MuJoCo."""
    return _side_by_side(out, "mujoco", _ball_variant(damper="axial"), quick,
                         "Thesis ball (axial dampers)", "thesis ball with axial dampers")


def mujoco3d_comparison(out: Path, quick: bool) -> dict | None:
    """The ``sphere_drop`` sphere (201 particles, axial dampers) dropped on level ground,
    in flexbody and in MuJoCo.  Level, not tilted as in the bundled scene: on a slope the
    centre's height mixes the rebound with the slide downhill."""
    scene = _scene_variant("sphere_drop", {"output_dt": 1e-3}, drop=("grounds",), damper="axial")
    return _side_by_side(out, "mujoco3d", scene, quick, "3D sphere, 201 particles (axial dampers), level ground",
                         "the sphere_drop sphere with axial dampers on level ground")


def _side_by_side(out: Path, name: str, scene: Scene, quick: bool, title: str, what: str) -> dict | None:
    """``scene`` in flexbody (dopri5, dop853) and in MuJoCo (1 ms, 0.1 ms steps) against a tight
    flexbody reference: time, penetration, centre-of-mass rebound, height error; saves ``name``."""
    try:
        from . import mujoco_compare
        import mujoco  # noqa: F401
    except ImportError:
        print(f"{name} comparison skipped: MuJoCo is not installed (pip install 'flexbody[mujoco]')")
        return None
    repeats = 3 if quick else 7
    print(f"MuJoCo side by side: {what}, {scene.simulation.t_end:g} s")
    up = -np.asarray(scene.gravity) / np.linalg.norm(scene.gravity)
    rows, curves = [], {}
    reference = simulate(scene, method="dop853", rtol=1e-11, atol=1e-14)
    ref_heights = reference.positions @ up
    curves["reference: flexbody dop853 rtol 1e-11"] = (reference.t, ref_heights @ scene.masses / scene.masses.sum())
    for label, options in (("flexbody dopri5 rtol 1e-6", dict(method="dopri5", rtol=1e-6, atol=1e-9)),
                           ("flexbody dop853 rtol 1e-9", dict(method="dop853", rtol=1e-9, atol=1e-12))):
        result, wall = _timed(scene, repeats, **options)
        y = result.positions @ up
        rows.append({"label": label, "time_s": wall, "max_penetration_m": result.stats["max_penetration_m"],
                     "diverged_at_s": None, **_rebound(result.t, y, result.masses),
                     "max_height_error_m": float(np.abs(y - ref_heights).max())})
        curves[label] = (result.t, y @ result.masses / result.masses.sum())
    for dt in (1e-3, 1e-4):
        m = mujoco_compare.run(scene, dt, repeats)
        ref_y = np.array([np.interp(m["t"], reference.t, ref_heights[:, i]) for i in range(scene.n_particles)]).T
        stable = m["diverged_at_s"] is None
        rows.append({"label": f"MuJoCo {m['version']} dt {dt:g} s", "time_s": m["time_s"],
                     "max_penetration_m": m["max_penetration_m"], "diverged_at_s": m["diverged_at_s"],
                     **(_rebound(m["t"], m["heights"], scene.masses) if stable else
                        {"rebound_height_m": float("nan"), "lowest_centre_m": float("nan")}),
                     "max_height_error_m": float(np.abs(m["heights"] - ref_y).max()) if stable else float("nan")})
        if stable:  # a diverged run's heights are meaningless before MuJoCo even notices
            curves[rows[-1]["label"]] = (m["t"], m["heights"] @ scene.masses / scene.masses.sum())
    print(f"  {'run':32s} {'time ms':>9s} {'penetration m':>14s} {'rebound m':>10s} {'height error m':>15s}")
    for r in rows:
        diverged = f"  unstable: MuJoCo reset its state at t = {r['diverged_at_s']:g} s" if r["diverged_at_s"] else ""
        print(f"  {r['label']:32s} {r['time_s'] * 1e3:9.2f} {r['max_penetration_m']:14.2e} "
              f"{r['rebound_height_m']:10.4f} {r['max_height_error_m']:15.2e}{diverged}")
    grid = np.arange(0.0, scene.simulation.t_end + 1e-9, 2e-3)
    data = {"title": title, "scene": scene.name, "particles": scene.n_particles, "links": len(scene.links()),
            "rows": rows, "curves": {"t": grid.tolist(), "centre_height_m": {
                label: np.interp(grid, t, y).tolist() for label, (t, y) in curves.items()}},
            "environment": _environment()}
    _save(out, name, data, plot_mujoco(data))
    return data


def _ball_variant(simulation: dict | None = None, **body) -> Scene:
    """The bundled thesis ball (from its TOML) with some body and simulation fields changed."""
    return _scene_variant("thesis_ball", simulation, **body)


def _scene_variant(name: str, simulation: dict | None = None, drop: tuple[str, ...] = (),
                   ground: dict | None = None, **body) -> Scene:
    """A bundled single-body scene (from its TOML) with some body, simulation and first-ground
    fields changed and the top-level tables in ``drop`` removed (``grounds``: the default
    level ground)."""
    import tomllib

    from .scene import resolve_scene_path

    table = tomllib.loads(resolve_scene_path(name).read_text())
    for key in drop:
        table.pop(key, None)
    table["bodies"][0].update(body)
    table["simulation"].update(simulation or {})
    if ground:
        table["grounds"][0].update(ground)
    return load_scene(table)


def _rebound(t: np.ndarray, heights: np.ndarray, masses: np.ndarray) -> dict:
    y_cm = heights @ masses / masses.sum()
    bottom = int(np.argmin(y_cm))
    return {"rebound_height_m": float(y_cm[bottom:].max()), "lowest_centre_m": float(y_cm[bottom])}


def plot_mujoco(data: dict):
    """Centre-of-mass height of each run, and its distance from the reference (which separates them all)."""
    from matplotlib.figure import Figure

    t = np.array(data["curves"]["t"])
    curves = {label: np.array(y) for label, y in data["curves"]["centre_height_m"].items()}
    (ref_label, reference), *runs = curves.items()
    fig = Figure(figsize=(8, 6), layout="constrained")
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(3, 2))
    top.plot(t, reference, color="0.6", lw=3.0, label=ref_label)
    styles = ("-", "--", "-", "-")
    for (label, y), style in zip(runs, styles):
        (line,) = top.plot(t, y, style, lw=1.1, label=label)
        bottom.semilogy(t, np.abs(y - reference), style, lw=0.9, color=line.get_color())
    for row in data["rows"]:
        if row.get("diverged_at_s"):
            top.plot([], [], " ", label=f"{row['label']}: unstable, reset at t = {row['diverged_at_s']:g} s "
                                        "(not drawn)")
    top.set_ylabel("height of the centre of mass (m)")
    top.legend(fontsize=8)
    title = data.get("title", "Thesis ball (axial dampers)")  # a mujoco.json saved before titles were
    top.set_title(f"{title}: flexbody (exact contact) and MuJoCo (soft contact)", fontsize=10)
    bottom.set_ylabel("|height - reference| (m)")
    bottom.set_xlabel("t (s)")
    bottom.set_title("flexbody dopri5 and dop853 coincide above; here they separate", fontsize=9)
    bottom.set_ylim(bottom=1e-15)  # below that the differences are round-off
    bottom.grid(True, which="major", alpha=0.3)
    return fig


#: The chart of each study, drawn from its saved JSON alone.
def _plot_bodies(data: dict):
    from .bench_bodies import plot_bodies

    return plot_bodies(data)


def _plot_held_friction(data: dict):
    from .bench_held_friction import plot_held_friction

    return plot_held_friction(data)


def _plot_friction_map(data: dict):
    from .bench_friction import plot_friction_map

    return plot_friction_map(data)


PLOTS = {"work_precision": plot_work_precision, "stability_map": plot_stability, "resolution": plot_resolution,
         "mujoco": plot_mujoco, "mujoco3d": plot_mujoco, "work_precision_incline": plot_work_precision,
         "friction_map": _plot_friction_map, "bodies": _plot_bodies, "held_friction": _plot_held_friction}


def replot(folder: Path) -> list[Path]:
    """Redraw each study's PNG in ``folder`` from its JSON there (no benchmark is run)."""
    written = []
    for name, plot in PLOTS.items():
        source = folder / f"{name}.json"
        data = json.loads(source.read_text()) if source.exists() else None
        if data is None or (name.startswith("mujoco") and "curves" not in data):
            continue  # a mujoco.json from before the curves were saved cannot be redrawn
        plot(data).savefig(folder / f"{name}.png", dpi=110)
        written.append(folder / f"{name}.png")
    return written


# ---------------------------------------------------------------------------- the whole `run` command


def _child(code: str, *args: str) -> tuple[float, float, str]:
    """Run ``python -c code args`` in a fresh process: its wall time, CPU time (s) and stdout."""
    import resource
    import subprocess
    import sys

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True,
                          env=dict(os.environ, PYTHONWARNINGS="ignore"))
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode:
        raise RuntimeError(f"`python -c {code!r} {' '.join(args)}` failed:\n{done.stderr}")
    cpu = after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime
    return wall, cpu, done.stdout


_CLI = "import sys; from flexbody.cli import main; sys.exit(main(sys.argv[1:]))"
_IMPORTS = """import time
t0 = time.perf_counter()
import flexbody.runner
t1 = time.perf_counter()
import flexbody.figures
t2 = time.perf_counter()
print(t1 - t0, t2 - t1)"""


def run_study(out: Path, repeats: int) -> dict:
    """``flexbody run thesis_ball --out DIR``, whole and in parts: process, imports, each figure."""
    import tempfile

    from . import figures

    print(f"run command: `flexbody run thesis_ball --out DIR --quiet` in fresh processes, median of {repeats}")
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        _child(_CLI, "run", "thesis_ball", "--out", f"{tmp}/warm", "--quiet")  # compile the model once, outside
        for label, extra in (("whole command", ()), ("without figures", ("--no-figures",))):
            runs = [_child(_CLI, "run", "thesis_ball", "--out", f"{tmp}/run{k}", "--quiet", *extra)
                    for k in range(repeats)]
            rows[label] = {"wall_s": statistics.median(r[0] for r in runs), "cpu_s": statistics.median(r[1] for r in runs)}
    runs = [_child("pass") for _ in range(repeats)]
    rows["python start-up"] = {"wall_s": statistics.median(r[0] for r in runs), "cpu_s": statistics.median(r[1] for r in runs)}
    parts = [tuple(map(float, _child(_IMPORTS)[2].split())) for _ in range(repeats)]
    rows["import flexbody.runner (numpy, scipy, the runtime)"] = {"wall_s": statistics.median(p[0] for p in parts)}
    rows["import flexbody.figures (matplotlib, on top)"] = {"wall_s": statistics.median(p[1] for p in parts)}

    scene = load_scene("thesis_ball")
    result = simulate(scene)
    draws = {
        "fig5_1_free_fall.png": lambda: figures._png(figures.figure_free_fall(result, scene.grounds)),
        "fig5_2_impact.png": lambda: figures._png(figures.figure_impact(result, scene.grounds)),
        "fig5_3_colliding_points.png": lambda: figures._png(figures.figure_colliding_points(result, scene.grounds)),
        "fig5_4_energy.png": lambda: figures._png(figures.figure_energy(result)),
        "drop.gif": lambda: figures.animation_gif(result, scene.grounds),
    }
    for name, draw in draws.items():
        times = []
        for _ in range(repeats):
            start = time.perf_counter()
            draw()
            times.append(time.perf_counter() - start)
        rows[f"draw {name} (in process, warm)"] = {"wall_s": statistics.median(times)}
    for label, row in rows.items():
        cpu = f"   cpu {row['cpu_s']:6.3f} s" if "cpu_s" in row else ""
        print(f"  {label:52s} {row['wall_s']:6.3f} s{cpu}")
    data = {"command": "flexbody run thesis_ball --out DIR --quiet", "repeats": repeats, "rows": rows,
            "environment": _environment()}
    _save(out, "run", data)
    return data


def sweep_benchmark(out: Path, quick: bool) -> dict | None:
    """200 thesis-ball runs on a 2-worker Dask LocalCluster against a serial loop (flexbody[sweep])."""
    try:
        from .sweep import _require_extra, benchmark

        _require_extra()
    except (ImportError, ValueError):
        print("sweep benchmark skipped: Dask is not installed (pip install 'flexbody[sweep]')")
        return None
    return benchmark(out, quick)


def _scale(out: Path, quick: bool) -> dict:
    from .bench_scale import scale_study

    return scale_study(out, quick)


def _bodies(out: Path, quick: bool) -> dict:
    from .bench_bodies import bodies_study

    return bodies_study(out, quick)


def _held_friction(out: Path, repeats: int, quick: bool) -> dict:
    from .bench_held_friction import held_friction_study

    return held_friction_study(out, repeats, quick)


def _friction_wp(out: Path, repeats: int, quick: bool) -> dict:
    from .bench_friction import friction_work_precision

    return friction_work_precision(out, repeats, quick)


def _friction_map(out: Path, quick: bool) -> dict:
    from .bench_friction import friction_map

    return friction_map(out, quick)


def lcp_study(out: Path, repeats: int, quick: bool) -> dict | None:
    """Lemke's method compiled against its NumPy path (:mod:`flexbody.lcp`) on the LCPs the
    fuzzes saved (``tests/reference/lcp_*.npz``: frictional impacts and forces of piles and
    rows, 11 to 77 rows): one path from the covering vector of ones, and the whole
    :func:`flexbody.lcp.solve_lcp` (with its rescues where the path ends on a ray), both
    ways in this process, medians over ``repeats``; the answers must agree bit for bit."""
    from . import lcp
    from .paths import PROJECT_ROOT

    saved = sorted((PROJECT_ROOT / "tests" / "reference").glob("lcp_*.npz"))
    if not saved:
        print("lcp study skipped: the saved problems (tests/reference/lcp_*.npz) are in the checkout only")
        return None
    compiled = lcp._compiled_path()
    if compiled is None:
        print("lcp study skipped: no C compiler builds the runtime library")
        return None
    repeats = max(repeats, 3 if quick else 7)

    def median_time(call) -> tuple[float, object]:
        times, answer = [], None
        for _ in range(repeats):
            start = time.perf_counter()
            answer = call()
            times.append(time.perf_counter() - start)
        return statistics.median(times), answer

    rows = []
    print(f"lcp study: Lemke's method, NumPy against C, on {len(saved)} saved LCPs, median of {repeats}")
    print(f"  {'problem':36s} {'n':>3s} {'pivots':>6s} {'path NumPy':>11s} {'path C':>9s} {'x':>4s}"
          f" {'solve NumPy':>12s} {'solve C':>9s} {'x':>4s}  status")
    for file in saved:
        M, q = (np.load(file)[k] for k in ("M", "q"))
        ones = np.ones(q.size)

        def path(walk):
            T, basis, _ = lcp._start(M, q, ones)
            return walk(T, basis, ones, 100 * (q.size + 1), lcp.PIVOT_TOL), T, basis

        path_numpy, (end, T, basis) = median_time(lambda: path(lcp._path))
        path_c, (end_c, T_c, basis_c) = median_time(lambda: path(compiled))
        solve_numpy, answer = median_time(lambda: lcp.solve_lcp(M, q, compiled=False))
        solve_c, answer_c = median_time(lambda: lcp.solve_lcp(M, q))
        same = (end == end_c and T.tobytes() == T_c.tobytes() and np.array_equal(basis, basis_c)
                and answer.z.tobytes() == answer_c.z.tobytes() and answer.status == answer_c.status)
        rows.append({"problem": file.stem, "n": int(q.size), "pivots": end[1], "path_end": end[0],
                     "path_numpy_s": path_numpy, "path_c_s": path_c, "solve_numpy_s": solve_numpy,
                     "solve_c_s": solve_c, "status": answer.status, "solve_pivots": answer.pivots,
                     "bit_for_bit": bool(same)})
        print(f"  {file.stem:36s} {q.size:3d} {end[1]:6d} {path_numpy * 1e3:8.2f} ms {path_c * 1e3:6.3f} ms"
              f" {path_numpy / path_c:4.0f} {solve_numpy * 1e3:9.2f} ms {solve_c * 1e3:6.3f} ms"
              f" {solve_numpy / solve_c:4.0f}  {answer.status}{'' if same else '  DIFFERENT'}")
    data = {"environment": _environment(), "repeats": repeats, "rows": rows}
    _save(out, "lcp", data)
    return data


STUDIES = {"wp": work_precision, "stability": stability_map, "resolution": resolution_study,
           "mujoco": mujoco_comparison, "mujoco3d": mujoco3d_comparison, "run": run_study, "scale": _scale,
           "sweep": sweep_benchmark, "friction_wp": _friction_wp, "friction_map": _friction_map, "bodies": _bodies,
           "lcp": lcp_study, "held_friction": _held_friction}


def bench_command(args) -> int:
    """Run the chosen studies; print and save their numbers and charts."""
    out = Path(args.out)
    for name in args.study or list(STUDIES):
        start = time.perf_counter()
        if name in ("wp", "friction_wp", "lcp", "held_friction"):
            STUDIES[name](out, args.repeats if not args.quick else 1, args.quick)
        elif name == "run":
            run_study(out, args.repeats if not args.quick else 3)
        else:
            STUDIES[name](out, args.quick)
        print(f"  ({name} took {time.perf_counter() - start:.0f} s)\n")
    return 0


if __name__ == "__main__":  # python -m flexbody.bench [FOLDER]: redraw the charts from their JSON alone
    import sys

    from .paths import generated_root

    for written in replot(Path(sys.argv[1]) if len(sys.argv) > 1 else generated_root() / "figures"):
        print(f"redrew {written}")
