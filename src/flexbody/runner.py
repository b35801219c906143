"""``flexbody run``: simulate, then write the result, its summary and the figures atomically."""

from __future__ import annotations

import argparse
import sys

from .driver import simulate
from .progress import ProgressBar
from .scene import load_scene


def run_command(args: argparse.Namespace) -> int:
    """Run a scene from the command line; returns the exit code (0, or 1 if it failed)."""
    scene = load_scene(args.scene)
    for note in scene.warnings:
        print(f"warning: {note}", file=sys.stderr)
    if args.out.exists() and not args.out.is_dir():
        raise ValueError(f"`--out` = {str(args.out)!r}: exists and is not a folder")
    bar = None if args.quiet else ProgressBar()
    result = simulate(
        scene, method=args.method, rtol=args.rtol, atol=args.atol, t_end=args.t_end, backend=args.backend,
        formulation=args.formulation, impact=args.impact, impact_dt=args.impact_dt, progress=bar,
    )
    if bar:
        bar.close()
    if not result.success:
        print(f"error: simulation failed ({result.status}): {result.message}\nnothing was written to {args.out}",
              file=sys.stderr)
        return 1
    extra = {}
    if not args.no_figures:
        from .figures import render_all

        extra = render_all(result, scene.grounds)
    result.save(args.out, extra_files=extra)
    s = result.stats
    print(
        f"{s['scene']}: {s['method']} rtol={s['rtol']:g} atol={s['atol']:g} ({s['backend']}, {s['formulation']}, "
        f"impact {s['impact']})\n"
        f"  integrated {s['t_end']:g} s in {s['wall_time_s']:.3f} s wall: {s['rhs_evaluations']} RHS evaluations, "
        f"{s['steps']} steps\n"
        f"  {s['impacts']} impacts ({s['not_held']} not held), {s['liftoffs']} lift-offs; "
        f"max penetration {s['max_penetration_m']:.2g} m; energy drift {s['energy_drift_J']:.2g} J "
        f"({s['energy_drift_relative']:.2g} of E0)\n"
        f"  wrote {args.out}/result.npz, summary.json" + (", figures and drop.gif" if extra else "")
    )
    return 0
