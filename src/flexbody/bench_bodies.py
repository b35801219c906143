"""``flexbody bench --study bodies``: many bodies that touch each other (issue 13, item 5).

Twenty flexible discs (``shape = "disc"``, about 200 particles each, the thesis ball's
lattice spacing and per-particle constants, as in :func:`flexbody.bench_scale.disc_scene_table`)
in two staggered rows, the upper row over the gaps of the lower, dropped onto the ground and
onto each other (a pile), and the same discs dropped side by side in one row, ``GAP``
apart.  Five runs, all with SciPy's RK45 (body contact runs with SciPy's steppers only, so
the ratios isolate the cost of contact, not of the stepper):

* ``collide`` — the pile with ``collide = true``: contacts between bodies (broad phase,
  closest features, coupled impacts and held forces, :mod:`flexbody.body_contact`);
* ``pass_through`` — the same 20 bodies with ``collide = false`` (they pass through each
  other and touch the ground only);
* ``separate`` — one body alone, run once per body position and summed: the "20 separate
  drops" of the issue;
* ``row_collide`` — the row with ``collide = true``: every contact the broad phase and the
  closest features watch, none made (the cost of watching);
* ``row_separate`` — its bodies alone, summed.

The pile's bodies make about ten times the events of its separate drops (each contact
between two discs opens, closes and chatters as the ground's do); the row's make the same
events as its separate drops, so its ratio is what watching for contact costs.

The five runs are made twice: with the thesis ball's link stiffness (2000 N/m), on which
the larger discs are soft (their lattice crushes under the pile), and with it scaled by
the full study's radius (:data:`STIFF`), so that its discs sag under their own weight as
the thesis ball does (``--quick``'s thesis-ball discs run at the same two stiffnesses).

Each run records its wall time (median over ``repeats`` where affordable), RHS
evaluations, events, maximum penetration, relative energy drift, the broad phase's
rebuilds and, when it stops early, the time it reached and why.  ``--quick`` runs four
discs of about 23 particles (the thesis ball's lattice) for 0.3 s.

The stiff pile and its separate drops are also run at the tighter tolerances of
``TOLERANCES`` (speed against accuracy): a pile's cost is its events, which do not depend
on the tolerance once it resolves them, while its drops' cost is their steps, which do.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np

from .scene import Scene, load_scene

#: The full study: 20 discs of about 200 particles (radius 0.1 m x sqrt(200 / 23)), 0.5 s.
#: ``smaller``: the stiff pile's sizes (bodies) run beside it, for how its cost grows with them.
FULL = {"bodies": 20, "count": 200, "t_end": 0.5, "smaller": (5, 10)}
#: ``--quick``: four thesis-ball discs (about 23 particles, radius 0.1 m), 0.3 s.
QUICK = {"bodies": 4, "count": 23, "t_end": 0.3, "smaller": (2, 3)}
#: The thesis ball's link stiffness (N/m), and the stiff set's: 2000 N/m x sqrt(200 / 23)
#: (a 2D lattice's modulus is its links' stiffness, while a disc's weight per unit width
#: grows with its radius), rounded.
STIFFNESS, STIFF = 2000.0, 6000.0
#: The study's tolerance (rtol; atol is RTOL_TO_ATOL times it), and the tighter ones at
#: which the stiff pile and its separate drops run again.
RTOL, TOLERANCES, RTOL_TO_ATOL = 1e-6, (1e-7, 1e-8), 1e-3
#: Gap between neighbouring discs and the height of the lowest point above the ground (m).
GAP = 0.02
LIFT = 0.05


def disc_radius(count: int) -> float:
    """Radius (m) of a disc of about ``count`` particles on the thesis ball's lattice spacing."""
    return 0.1 * (count / 23) ** 0.5


def row_positions(n_bodies: int, radius: float, gap: float = GAP, lift: float = LIFT) -> np.ndarray:
    """Centres of ``n_bodies`` discs side by side, ``gap`` apart, their lowest points ``lift``
    above the ground, shape (n_bodies, 2)."""
    return np.column_stack([np.arange(n_bodies) * (2 * radius + gap), np.full(n_bodies, radius + lift)])


def disc_positions(n_bodies: int, radius: float, gap: float = GAP, lift: float = LIFT) -> np.ndarray:
    """Centres of ``n_bodies`` (>= 2) discs in two staggered rows, shape (n_bodies, 2).

    The lower row holds ``n_bodies // 2 + 1`` discs; its discs are ``gap`` apart, their lowest points ``lift`` above the ground;
    each upper disc sits over the gap between two lower ones, ``gap`` from both, so it lands
    on them once they have stopped on the ground.
    """
    pitch = 2 * radius + gap
    per_row = n_bodies // 2 + 1  # one more below than above: every upper disc is over a gap
    rise = np.sqrt((2 * radius + gap) ** 2 - (pitch / 2) ** 2)  # centre distance 2 R + gap
    out = np.empty((n_bodies, 2))
    for k in range(n_bodies):
        row, col = divmod(k, per_row)
        out[k] = col * pitch + row * pitch / 2, radius + lift + row * rise
    return out


def bodies_scene_table(n_bodies: int, count: int, t_end: float, collide: bool,
                       only: int | None = None, stiffness: float = STIFFNESS, row: bool = False,
                       rtol: float = RTOL) -> dict:
    """The study's scene as a table: ``n_bodies`` discs of about ``count`` particles, 0.05 kg
    each, ``stiffness`` (N/m) and c = 0.5 N s/m per link (relative dampers), each turned by a
    different small angle so no two land alike, in a pile (:func:`disc_positions`) or with
    ``row`` side by side (:func:`row_positions`); ``only``: that body alone, where it is in
    the full scene; SciPy's RK45 at ``rtol`` (and atol ``RTOL_TO_ATOL`` times it)."""
    radius = disc_radius(count)
    centres = (row_positions if row else disc_positions)(n_bodies, radius)
    keep = range(n_bodies) if only is None else (only,)
    bodies = [{"name": f"disc{k}", "shape": "disc", "count": count, "radius": radius, "mass": 0.05,
               "stiffness": stiffness, "damping": 0.5, "damper": "relative", "position": centres[k].tolist(),
               "angle": 0.05 + 0.07 * k, "collide": collide} for k in keep]
    # output every 10 ms: the study times the integration, not the sampling
    name = f"bodies_{n_bodies}x{count}" + ("_row" if row else "") + ("" if stiffness == STIFFNESS else f"_k{stiffness:g}")
    return {"name": name + ("" if only is None else f"_{only}"), "bodies": bodies,
            "simulation": {"t_end": t_end, "output_dt": 1e-2, "method": "RK45", "rtol": rtol,
                           "atol": float(f"{rtol * RTOL_TO_ATOL:.12g}")}}  # 1e-11, not 1.0000000000000001e-11


def bodies_scene(n_bodies: int, count: int, t_end: float, collide: bool, only: int | None = None,
                 stiffness: float = STIFFNESS, row: bool = False, rtol: float = RTOL) -> Scene:
    """:func:`bodies_scene_table`, loaded (validated)."""
    return load_scene(bodies_scene_table(n_bodies, count, t_end, collide, only, stiffness, row, rtol))


#: Wall-time cap of one run (s): a run stopped by it reports the time it reached.
CAP = 600.0


def _measure(scene: Scene, repeats: int) -> dict:
    """Run ``scene`` ``repeats`` times (once if it stops early, or after :data:`CAP`); its
    numbers, the median wall time."""
    from .driver import simulate
    from .model import load_model

    times = []
    for _ in range(repeats):
        model = load_model(scene)  # a fresh broad phase per run: its rebuilds are this run's
        start = time.perf_counter()
        result = simulate(scene, model=model, max_wall_time=CAP)
        times.append(time.perf_counter() - start)
        if not result.success:
            break
    s = result.stats
    candidates = getattr(model, "_candidates", None)
    # the contacts of the run's table at its end (the pairs in reach: BodyContactModel.with_pairs)
    return {"particles": scene.n_particles, "contacts": s["contacts"], "contact_pairs": s["contact_pairs"],
            "status": result.status,
            "message": result.message,
            "t_reached_s": float(result.t[-1]), "wall_s": statistics.median(times), "repeats": len(times),
            "rhs_evaluations": s["rhs_evaluations"], "steps": s["steps"], "events": s["events"],
            "max_penetration_m": s["max_penetration_m"], "energy_drift_relative": s["energy_drift_relative"],
            "broadphase_rebuilds": None if candidates is None else int(candidates.rebuilds),
            # the last run's: its builds and filters, against its whole wall time
            "broadphase_s": None if candidates is None else float(candidates.seconds)}


def bodies_study(out: Path, quick: bool, repeats: int = 3) -> dict:
    """Run the study; print a table; save ``bodies.json`` and ``bodies.png`` in ``out``."""
    from . import runtime
    from .bench import _environment, _save

    runtime.library()  # compiled once per install, before anything is timed
    case = QUICK if quick else FULL
    n, count, t_end = case["bodies"], case["count"], case["t_end"]
    contact_repeats = 1 if not quick else repeats  # the full drop takes minutes: once
    print(f"bodies: {n} discs of about {count} particles dropped for {t_end:g} s, SciPy RK45 rtol {RTOL:g}")
    sets = {}
    for label, stiffness in (("soft", STIFFNESS), ("stiff", STIFF)):
        print(f" links {stiffness:g} N/m ({label})")
        sets[label] = _five_runs(n, count, t_end, stiffness, repeats, contact_repeats)
    print(f" the stiff pile by its number of bodies (links {STIFF:g} N/m)")
    scaling = _scaling(case["smaller"], count, t_end, repeats, contact_repeats, n, sets["stiff"]["runs"])
    print(f" the stiff pile by its tolerance (rtol; atol {RTOL_TO_ATOL:g} of it)")
    tolerance = _tolerances(n, count, t_end, repeats, contact_repeats, sets["stiff"]["runs"])
    data = {"bodies": n, "count": count, "t_end_s": t_end, "method": "RK45", "rtol": RTOL,
            "stiffness_N_per_m": STIFFNESS, **sets["soft"],
            "stiff": {"stiffness_N_per_m": STIFF, **sets["stiff"]}, "scaling": scaling, "tolerance": tolerance,
            "environment": _environment()}
    _save(out, "bodies", data, plot_bodies(data))
    return data


def _five_runs(n: int, count: int, t_end: float, stiffness: float, repeats: int, contact_repeats: int) -> dict:
    """The pile's ``collide``, ``pass_through`` and ``separate``, and the row's
    ``row_collide`` and ``row_separate``, at one link stiffness, printed as a table:
    ``{"runs": ..., "ratio_to_separate": ...}`` (the row's runs to ``row_separate``)."""
    runs = {"collide": _measure(bodies_scene(n, count, t_end, True, stiffness=stiffness), contact_repeats),
            "pass_through": _measure(bodies_scene(n, count, t_end, False, stiffness=stiffness), repeats),
            "separate": _separate(n, count, t_end, stiffness, repeats, row=False),
            # the row makes few contacts between bodies: seconds, so timed as often as the drops
            "row_collide": _measure(bodies_scene(n, count, t_end, True, stiffness=stiffness, row=True), repeats),
            "row_separate": _separate(n, count, t_end, stiffness, repeats, row=True)}
    ratios = {label: r["wall_s"] / runs["row_separate" if label.startswith("row") else "separate"]["wall_s"]
              for label, r in runs.items()}
    print(f"  {'run':14s} {'status':>11s} {'t reached':>9s} {'wall s':>8s} {'x separate':>10s} {'RHS evals':>9s} "
          f"{'events':>7s} {'penetration m':>13s} {'drift':>8s} {'rebuilds':>8s}")
    for label, r in runs.items():
        rebuilds = "-" if r["broadphase_rebuilds"] is None else str(r["broadphase_rebuilds"])
        print(f"  {label:14s} {r['status']:>11s} {r['t_reached_s']:9.3f} {r['wall_s']:8.2f} {ratios[label]:10.2f} "
              f"{r['rhs_evaluations']:9d} {r['events']:7d} {r['max_penetration_m']:13.2e} "
              f"{r['energy_drift_relative']:8.1e} {rebuilds:>8s}")
        if r["status"] != "success" and r.get("message"):
            print(f"    stopped: {r['message']}")
    return {"runs": runs, "ratio_to_separate": ratios}


def _scaling(smaller: tuple[int, ...], count: int, t_end: float, repeats: int, contact_repeats: int, n: int,
             runs: dict) -> list[dict]:
    """The stiff pile of each of ``smaller`` bodies and its separate drops, then the study's
    own ``n`` (its ``runs``), printed: whether the cost of an event grows with the bodies
    (the broad phase's and the instant's work over every contact) or only their events do.
    Each row: ``bodies``, ``collide`` and ``separate`` (as :func:`_measure`), ``ratio``."""
    rows = [{"bodies": k, "collide": _measure(bodies_scene(k, count, t_end, True, stiffness=STIFF), contact_repeats),
             "separate": _separate(k, count, t_end, STIFF, repeats, row=False)} for k in smaller]
    rows.append({"bodies": n, "collide": runs["collide"], "separate": runs["separate"]})
    print(f"  {'bodies':>6s} {'contacts':>8s} {'pile s':>8s} {'events':>7s} {'ms/event':>8s} {'separate s':>10s} "
          f"{'events':>7s} {'ms/event':>8s} {'x separate':>10s} {'broad phase s':>13s}")
    for row in rows:
        pile, alone = row["collide"], row["separate"]
        row["ratio"] = pile["wall_s"] / alone["wall_s"]
        share = f"{pile['broadphase_s']:.2f} ({100 * pile['broadphase_s'] / pile['wall_s']:.1f} %)"
        print(f"  {row['bodies']:6d} {pile['contacts']:8d} {pile['wall_s']:8.2f} {pile['events']:7d} "
              f"{_per_event(pile):8.2f} "
              f"{alone['wall_s']:10.2f} {alone['events']:7d} {_per_event(alone):8.2f} {row['ratio']:10.2f} {share:>13s}"
              + ("" if pile["status"] == "success" else f"  (pile {pile['status']} at {pile['t_reached_s']:.3f} s)"))
    return rows


def _tolerances(n: int, count: int, t_end: float, repeats: int, contact_repeats: int, runs: dict) -> list[dict]:
    """The stiff pile and its separate drops at the study's rtol (its ``runs``) and at each
    of ``TOLERANCES``, printed: events, penetration and wall times, and the ratio.  Each row:
    ``rtol``, ``collide`` and ``separate`` (as :func:`_measure`), ``ratio``."""
    rows = [{"rtol": RTOL, "collide": runs["collide"], "separate": runs["separate"]}]
    rows += [{"rtol": rtol,
              "collide": _measure(bodies_scene(n, count, t_end, True, stiffness=STIFF, rtol=rtol), contact_repeats),
              "separate": _separate(n, count, t_end, STIFF, repeats, row=False, rtol=rtol)} for rtol in TOLERANCES]
    print(f"  {'rtol':>6s} {'pile s':>8s} {'events':>7s} {'penetration m':>13s} {'drift':>8s} {'separate s':>10s} "
          f"{'events':>7s} {'x separate':>10s}")
    for row in rows:
        pile, alone = row["collide"], row["separate"]
        row["ratio"] = pile["wall_s"] / alone["wall_s"]
        print(f"  {row['rtol']:6.0e} {pile['wall_s']:8.2f} {pile['events']:7d} {pile['max_penetration_m']:13.2e} "
              f"{pile['energy_drift_relative']:8.1e} {alone['wall_s']:10.2f} {alone['events']:7d} {row['ratio']:10.2f}"
              + ("" if pile["status"] == "success" else f"  (pile {pile['status']} at {pile['t_reached_s']:.3f} s)"))
    return rows


def _per_event(run: dict) -> float:
    """A run's wall time per event (ms)."""
    return 1e3 * run["wall_s"] / max(run["events"], 1)


def _separate(n: int, count: int, t_end: float, stiffness: float, repeats: int, row: bool,
              rtol: float = RTOL) -> dict:
    """Each of the ``n`` bodies dropped alone where it is in the pile (or with ``row``, in the
    row), its numbers summed (maxima of the penetration and drift): the separate drops."""
    alone = [_measure(bodies_scene(n, count, t_end, False, only=k, stiffness=stiffness, row=row, rtol=rtol), repeats)
             for k in range(n)]
    return {"particles": sum(r["particles"] for r in alone), "contacts": sum(r["contacts"] for r in alone),
            "status": "success" if all(r["status"] == "success" for r in alone) else "failed",
            "t_reached_s": min(r["t_reached_s"] for r in alone),
            "wall_s": sum(r["wall_s"] for r in alone), "repeats": repeats,
            **{k: sum(r[k] for r in alone) for k in ("rhs_evaluations", "steps", "events")},
            "max_penetration_m": max(r["max_penetration_m"] for r in alone),
            "energy_drift_relative": max(r["energy_drift_relative"] for r in alone),
            "broadphase_rebuilds": None, "broadphase_s": None, "each_wall_s": [r["wall_s"] for r in alone]}


def plot_bodies(data: dict):
    """Wall time and RHS evaluations of the runs, side by side (log axes), for each link
    stiffness the JSON holds (the soft set; the stiff one where it was run); a study saved
    before the row was added has the pile's three runs only.  With the stiff pile's
    ``scaling`` (:func:`_scaling`), a panel of its wall time per event by its bodies; with
    its ``tolerance`` (:func:`_tolerances`), one of its and its drops' wall times by rtol."""
    from matplotlib.figure import Figure

    sets = [(f"{data.get('stiffness_N_per_m', STIFFNESS):g} N/m", data["runs"])]
    if "stiff" in data:
        sets.append((f"{data['stiff']['stiffness_N_per_m']:g} N/m", data["stiff"]["runs"]))
    labels = {"separate": f"pile:\n{data['bodies']} alone\n(summed)", "pass_through": "pile:\ncollide\nfalse",
              "collide": "pile:\ncollide\ntrue", "row_separate": f"row:\n{data['bodies']} alone\n(summed)",
              "row_collide": "row:\ncollide\ntrue"}
    order = ("separate", "pass_through", "collide", "row_separate", "row_collide")
    colours = {"separate": "C0", "pass_through": "C2", "collide": "C3", "row_separate": "C9", "row_collide": "C1"}
    # studies saved before these were added have neither
    extra = [(plot, data[key]) for key, plot in (("scaling", _plot_scaling), ("tolerance", _plot_tolerance))
             if data.get(key)]
    fig = Figure(figsize=(14 + 6 * len(extra), 5.5), layout="constrained")
    axes = fig.subplots(1, 2 + len(extra), width_ratios=[3, 3] + [2] * len(extra))
    for ax, (plot, rows) in zip(axes[2:], extra):
        plot(ax, rows)
    for ax, key, title in zip(axes, ("wall_s", "rhs_evaluations"),
                              ("wall time of the integration (s)", "RHS evaluations")):
        ticks, names = [], []
        for s, (stiffness, runs) in enumerate(sets):
            keys = [k for k in order if k in runs]
            at = [(len(order) + 1) * s + i for i in range(len(keys))]
            bars = ax.bar(at, [runs[k][key] for k in keys], color=[colours[k] for k in keys],
                          alpha=1.0 if s == 0 else 0.6)
            ticks += at
            names += [f"{labels[k]}\n{stiffness}" for k in keys]
            for bar, k in zip(bars, keys):
                r = runs[k]
                note = f"{r[key]:.3g}" + ("" if r["status"] == "success" else f"\n{r['status']}\nat {r['t_reached_s']:.2f} s")
                ax.annotate(note, (bar.get_x() + bar.get_width() / 2, bar.get_height()), ha="center", va="bottom",
                            fontsize=7)
        ax.set_yscale("log")
        ax.set_xticks(ticks, names, fontsize=7)
        ax.set_title(title, fontsize=10)
        ax.grid(True, axis="y", which="both", alpha=0.3)
    fig.suptitle(f"{data['bodies']} discs x about {data['count']} particles dropped for {data['t_end_s']:g} s "
                 f"(SciPy RK45, rtol {data['rtol']:g}); links soft, then stiff", fontsize=10)
    return fig


def _plot_scaling(ax, scaling: list[dict]) -> None:
    """The stiff pile against its separate drops by the number of bodies: wall time per
    event (ms, log), each pile point labelled with its events and its ratio to the drops."""
    bodies = [row["bodies"] for row in scaling]
    for key, colour, label in (("collide", "C3", "pile, collide = true"), ("separate", "C0", "alone (summed)")):
        ax.plot(bodies, [_per_event(row[key]) for row in scaling], "o-", color=colour, label=label)
    for row in scaling:
        ax.annotate(f"{row['collide']['events']} events\n{row['ratio']:.1f}x the drops",
                    (row["bodies"], _per_event(row["collide"])), textcoords="offset points", xytext=(0, 8),
                    ha="center", fontsize=7)
    ax.set_yscale("log")
    ax.margins(x=0.12, y=0.2)  # room for the labels
    ax.set_xticks(bodies)
    ax.set_xlabel("bodies in the pile")
    ax.set_title("stiff pile: wall time per event (ms)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)


def _plot_tolerance(ax, rows: list[dict]) -> None:
    """The stiff pile and its separate drops by rtol: wall time (s, log), each pile point
    labelled with its events, its penetration and its ratio to the drops."""
    rtols = [row["rtol"] for row in rows]
    for key, colour, label in (("collide", "C3", "pile, collide = true"), ("separate", "C0", "alone (summed)")):
        ax.plot(rtols, [row[key]["wall_s"] for row in rows], "o-", color=colour, label=label)
    for row in rows:
        pile = row["collide"]
        stopped = "" if pile["status"] == "success" else f"\n{pile['status']} at {pile['t_reached_s']:.2f} s"
        ax.annotate(f"{pile['events']} events\n{pile['max_penetration_m']:.1e} m\n{row['ratio']:.1f}x the drops{stopped}",
                    (row["rtol"], pile["wall_s"]), textcoords="offset points", xytext=(0, 8), ha="center", fontsize=7)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.invert_xaxis()  # tighter to the right
    ax.margins(x=0.15, y=0.35)
    ax.set_xlabel(f"rtol (atol {RTOL_TO_ATOL:g} of it)")
    ax.set_title("stiff pile: wall time by tolerance (s)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8, loc="center right")
