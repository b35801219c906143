"""``flexbody run``: check everything, simulate, then write the result folder in one step.

The order is the contract of the command line: the output folder and every option are
checked before any work (a mistake costs nothing and writes nothing), then the model is
loaded (derived and compiled if needed), then the run, then the figures, then one
rename puts the folder in place.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager

from .driver import _settings, simulate
from .errors import InputError
from .model import load_model
from .paths import check_output_dir
from .progress import ProgressBar
from .scene import Scene, load_scene

#: Slots between bodies beyond which ``flexbody run`` notes how to have fewer (see
#: :func:`contact_table_note`): a pile of 10 discs of 199 particles has 8 640.
LARGE_CONTACT_TABLE = 10_000


def contact_table_note(scene: Scene, model) -> str | None:
    """A note for a scene whose ``collide = true`` bodies make more than
    :data:`LARGE_CONTACT_TABLE` slots (each surface vertex has one, and a corner twin, for
    each other body it may touch: they grow with the square of the bodies, and so does the
    work at each instant) where its table is laid out whole (self-contact or edge contacts:
    else a run gives slots to the pairs in reach only,
    :meth:`flexbody.body_contact.BodyContactModel.with_pairs`), or None."""
    colliding = sum(body.collide for body in scene.bodies)
    slots = model.n_slots
    if colliding < 3 or slots <= LARGE_CONTACT_TABLE or getattr(model, "grows", False):
        return None
    return (f"{colliding} bodies with collide = true make {slots} contact slots (each surface vertex has one, "
            "and a corner twin, for each other body it may touch); where only some of them can meet, list those "
            "pairs in [[contacts]] (and leave collide false): fewer contacts run faster (README: \"Many bodies\")")


def _max_wall_time(value: float) -> float:
    if not value > 0:  # nan fails too; inf means no limit
        raise InputError(f"`--max-wall-time` = {value!r}: must be > 0 (s), or inf for no limit")
    return value


def run_command(args: argparse.Namespace) -> int:
    """Run a scene from the command line; returns the exit code (0, or 1 if it failed).

    Raises
    ------
    flexbody.errors.InputError
        For a bad output folder, scene or option, before any work.
    """
    out = check_output_dir(args.out)
    max_wall_time = _max_wall_time(args.max_wall_time)
    scene = load_scene(args.scene)
    overrides = dict(method=args.method, rtol=args.rtol, atol=args.atol, t_end=args.t_end,
                     output_dt=args.output_dt, backend=args.backend, formulation=args.formulation,
                     impact=args.impact, impact_dt=args.impact_dt, chatter_impacts=args.chatter_impacts)
    settings = _settings(scene, overrides)  # every option checked before deriving or compiling
    model = load_model(scene, backend=settings.backend, formulation=settings.formulation)
    notes = [contact_table_note(scene, model)]
    if args.formulation and settings.formulation != args.formulation:  # asked for, and not what runs
        notes.append(f"`--formulation {args.formulation}`: a scene of rigid bodies alone runs on their frames T, "
                     f"derived whole ({settings.formulation})")
    for note in notes:
        if note and not args.quiet:
            print(f"note: {note}", file=sys.stderr)
    bar = None if args.quiet else ProgressBar()
    with _interrupt_kills():  # the wall-time budget is checked by the driver and inside the C integrator
        result = simulate(scene, model=model, **overrides, max_wall_time=max_wall_time, progress=bar)
    if bar:
        bar.close()
    if not result.success:
        print(f"error: simulation failed ({result.status}): {result.message}\nnothing was written to {out}",
              file=sys.stderr)
        return 1
    extra = {}
    if not args.no_figures:
        from .figures import render_all

        extra = render_all(result, scene.grounds)
    if args.vtk:
        from .export import export_vtk

        extra["vtk"] = lambda folder: export_vtk(result, folder, scene.grounds)
    try:
        result.save(out, extra_files=extra)
    except OSError as exc:  # the folder was checked before the run; something changed since
        print(f"error: could not write {out}: {exc}\nnothing was written", file=sys.stderr)
        return 1
    s = result.stats
    print(
        f"{s['scene']}: {s['method']} rtol={s['rtol']:g} atol={s['atol']:g} ({s['backend']}, {s['formulation']}, "
        f"impact {s['impact']})\n"
        f"  integrated {s['t_end']:g} s in {s['wall_time_s']:.3f} s wall: {s['rhs_evaluations']} RHS evaluations, "
        f"{s['steps']} steps\n"
        f"  {s['impacts']} impacts ({s['not_held']} not held), {s['liftoffs']} lift-offs"
        + (f", {s['sticks']} sticks, {s['slips']} slips (friction work {s['friction_work_J']:.3g} J)"
           if s.get("sticks") or s.get("slips") or s.get("friction_work_J") else "") + "; "
        f"max penetration {s['max_penetration_m']:.2g} m; energy drift {s['energy_drift_J']:.2g} J "
        f"({s['energy_drift_relative']:.2g} of E0)\n"
        + (f"  contacts between bodies: {s['contact_pairs']} of the scene's {s['contact_pairs_in_scene']} pairs had "
           f"slots (those that came within reach; {s['contacts']} contacts at the end)\n"
           if s.get("contact_pairs_in_scene") else "")
        + f"  wrote {out}/result.npz, summary.json" + (", figures and drop.gif" if not args.no_figures else "")
        + (", vtk/run.pvd (ParaView)" if args.vtk else "")
    )
    for warning in s["warnings"]:
        print(f"warning: {warning}", file=sys.stderr)
    return 0


@contextmanager
def _interrupt_kills() -> Iterator[None]:
    """Let Ctrl-C end the run at once, even inside a C call (Python's handler waits for it
    to return); nothing is lost, the result folder is only written after the run."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_DFL)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
