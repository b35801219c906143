"""The ``flexbody`` command: run, export, derive, show, sweep, bench.

Every command is a thin wrapper over library functions.  Exit codes:

* 0: done;
* 2: a user mistake (bad scene, option or output folder, :class:`flexbody.errors.InputError`):
  one clear error, no traceback, nothing written;
* 1: a failed simulation, derivation or compilation (it says why; nothing written), or a
  bug in flexbody (any other exception: its traceback and a request to report it).

Only the standard library is imported until a command runs, so ``--help`` and argument
errors answer at once.
"""

from __future__ import annotations

import argparse
import sys
import traceback
import warnings

from .choices import BACKENDS, CASCADE_FALL, CHATTER_IMPACTS, CHATTER_WINDOW, DEFAULT_MAX_WALL_TIME, FORMULATIONS, IMPACT_MODES, METHODS
from .errors import InputError

EXIT_FAILED, EXIT_USAGE, EXIT_INTERRUPTED = 1, 2, 130
BUG = "this is a bug in flexbody: please report it with the command and scene"
#: Options that take a number, which may be negative (``--rtol -1e-6`` must reach the range check).
NUMERIC_OPTIONS = ("--rtol", "--atol", "--impact-dt", "--t-end", "--output-dt", "--max-wall-time", "--repeats",
                   "--every", "--chatter-impacts")


def _add_scene(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", metavar="SCENE", help="a scene file (TOML) or a bundled scene's name, e.g. thesis_ball")


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="flexbody",
        description="Flexible bodies as particles, springs and dampers: derive, inspect and simulate.",
        epilog="Exit codes: 0 done; 1 the simulation (or derivation) failed; 2 a mistake in the scene or options.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    run = sub.add_parser(
        "run", help="simulate a scene and write result.npz, summary.json and figures",
        description="Simulate a scene; write DIR/result.npz, DIR/summary.json and figures.  DIR is replaced "
                    "whole, in one step, when the run succeeds: it must be new, empty or an earlier result.  "
                    "Options override the scene's [simulation] table and are checked before any work.",
    )  # fmt: skip
    _add_scene(run)
    run.add_argument("--out", required=True, metavar="DIR",
                     help="output folder (new, empty, or an earlier result, which is replaced)")
    run.add_argument("--no-figures", action="store_true", help="skip the figures and the animation")
    run.add_argument("--method", choices=METHODS, help="integration method: dopri5 or dop853 (compiled C) or a SciPy solve_ivp method; default dopri5 where the compiled loop runs the scene (grounds only, C backend), else RK45 (the same Dormand-Prince pair: bodies that may touch each other, rigid bodies beside flexible ones, a rigid body on a rough ground)")
    run.add_argument("--rtol", type=float, metavar="X", help="relative tolerance, in [1e-14, 1)")
    run.add_argument("--atol", type=float, metavar="X", help="absolute tolerance, in (0, 1)")
    run.add_argument("--backend", choices=BACKENDS, help="c (compiled, default) or numpy")
    run.add_argument("--formulation", choices=FORMULATIONS, help="particles (default) or floating")
    run.add_argument("--impact", choices=IMPACT_MODES, help="instant (default) or thesis (eq. 4.6)")
    run.add_argument("--impact-dt", type=float, metavar="S",
                     help="ΔT of the thesis impact mode (s, > 0); only with impact thesis (from --impact or the "
                          "scene), an error otherwise")
    run.add_argument("--t-end", type=float, metavar="S", help="end time (s)")
    run.add_argument("--output-dt", type=float, metavar="S",
                     help="output sample interval (s), <= t_end; at most 10 million samples")
    run.add_argument("--max-wall-time", type=float, default=DEFAULT_MAX_WALL_TIME, metavar="S",
                     help=f"stop a run that takes longer than this (s; default {DEFAULT_MAX_WALL_TIME:g}; 'inf' for "
                          "no limit) with status too_slow and exit 1")
    run.add_argument("--chatter-impacts", type=int, metavar="N",
                     help=f"stop with status chattering where one particle impacts more than N (an integer >= 1) "
                          f"times within {CHATTER_WINDOW * 1e3:g} ms, in a row or each held and released (a rebound "
                          f"slower than {CASCADE_FALL:g} of the last is a Zeno cascade's, not counted; default: the "
                          f"scene's simulation.chatter_impacts, else {CHATTER_IMPACTS}); raise it where a burst of "
                          "impacts ends (a pile settling)")
    run.add_argument("--quiet", action="store_true", help="no progress bar")
    run.add_argument("--vtk", action="store_true",
                     help="also write DIR/vtk/: the run as a ParaView time series (as flexbody export DIR does)")

    export = sub.add_parser(
        "export", help="write a run's result for other programs: a VTK time series for ParaView",
        description="Read DIR/result.npz (written by flexbody run) and write DIR/vtk/: run.pvd (open it in "
                    "ParaView) and frames/frame_*.vtu with the particles, the links as lines, and point data "
                    "velocity, contact_force, phase (1 held, by a ground or another body; 0 free) and mass.  An existing DIR/vtk "
                    "is replaced whole, in one step.",
    )  # fmt: skip
    export.add_argument("dir", metavar="DIR", help="a run's folder (flexbody run SCENE --out DIR)")
    export.add_argument("--format", choices=("vtk",), default="vtk", help="file format (only vtk for now)")
    export.add_argument("--every", type=int, default=1, metavar="K",
                        help="export every K-th output sample, and the last one (default 1: all)")

    derive = sub.add_parser("derive", help="derive and generate a scene's model into generated/",
                            description="Derive the equations of motion (SymPy, Kane's method) and render "
                                        "the NumPy module, C source, eom.md and manifest into generated/.")
    derive.add_argument("scene", metavar="SCENE", nargs="?",
                        help="a scene file (TOML) or a bundled scene's name; omit it (or give --runtime) for the "
                             "element kernels and the runtime")
    derive.add_argument("--runtime", action="store_true",
                        help="derive the element kernels and render the runtime (generated/kernels, generated/runtime)")
    derive.add_argument("--formulation", choices=FORMULATIONS, action="append",
                        help="particles or floating (repeatable; default: both)")
    derive.add_argument("--out", metavar="DIR", help="parent folder (default: the project's generated/)")
    derive.add_argument("--check", action="store_true", help="exit 1 if the generated files are stale; write nothing")

    show = sub.add_parser("show", help="print a scene's derived equations of motion",
                          description="Print the derived equations of motion M u' = F, row by row.")
    _add_scene(show)
    show.add_argument("--latex", action="store_true", help="print LaTeX instead of plain text")
    show.add_argument("--formulation", choices=FORMULATIONS, default=None, help="default: the scene's")
    show.add_argument("--force", action="store_true",
                      help="derive a large scene's equations even when that takes minutes")
    show.add_argument("--raw", action="store_true", help="the equations as derived, unsimplified (for debugging)")

    _add_sweep(sub)

    bench = sub.add_parser("bench", help="speed and accuracy benchmarks (prints and saves numbers)",
                           description="Benchmarks, not tests: work-precision diagram (wp), stability map "
                                       "(stability), resolution study (resolution), MuJoCo side by side in 2D (mujoco) and "
                                       "3D (mujoco3d), the whole run command (run), cost vs size (scale), Dask sweeps "
                                       "(sweep), friction: work-precision on the incline (friction_wp) and the mu x e map "
                                       "(friction_map), bodies that touch each other (bodies), Lemke's method in C against NumPy (lcp), "
                                       "held contacts with friction in C against NumPy (held_friction); "
                                       "each writes its numbers as JSON in --out, and its charts as PNG where it draws any.")
    bench.add_argument("--study", choices=("wp", "stability", "resolution", "mujoco", "mujoco3d", "run", "scale", "sweep",
                                           "friction_wp", "friction_map", "bodies", "lcp", "held_friction"),
                       action="append",
                       help="which study (repeatable; default: all; mujoco and mujoco3d need flexbody[mujoco])")
    bench.add_argument("--out", default="bench", metavar="DIR", help="output folder (default: bench/ in the current folder)")
    bench.add_argument("--repeats", type=int, default=5, help="timing repeats (median is reported)")
    bench.add_argument("--quick", action="store_true", help="fewer cases and repeats (about a minute)")
    return parser


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _attach_negative_numbers(argv: list[str]) -> list[str]:
    """``--rtol -1e-6`` -> ``--rtol=-1e-6``.

    argparse takes ``-1e-6`` for an option and says "expected one argument"; joined, the
    value reaches the range check and gets the same message as any other bad value.
    """
    out: list[str] = []
    k = 0
    while k < len(argv):
        if argv[k] == "--":
            return out + argv[k:]
        if argv[k] in NUMERIC_OPTIONS and k + 1 < len(argv) and argv[k + 1].startswith("-") and _is_number(argv[k + 1]):
            out.append(f"{argv[k]}={argv[k + 1]}")
            k += 2
        else:
            out.append(argv[k])
            k += 1
    return out


def _add_sweep(sub) -> None:
    sweep = sub.add_parser("sweep", help="a parameter study on Dask: one row per varied scene",
                           description="Vary scene fields over a grid or a quasi-random design, run every scene "
                                       "on a Dask cluster, write DIR/sweep.parquet, sweep.csv, sweep.json and "
                                       "figures. Needs flexbody[sweep].")
    _add_scene(sweep)
    sweep.add_argument("--vary", action="append", required=True, metavar="FIELD=SPEC",
                       help="a dotted scene field and its values: a list 1e3,1e4,1e5; a range lo:hi:n or "
                            "lo:hi:n:log; with --samples, lo:hi or lo:hi:log (repeatable)")
    sweep.add_argument("--out", required=True, metavar="DIR", help="output folder")
    sweep.add_argument("--samples", type=int, metavar="N", help="number of runs of an lhs or sobol design")
    sweep.add_argument("--design", choices=("grid", "lhs", "sobol"), default="grid",
                       help="grid (every combination, default), lhs or sobol (needs --samples)")
    sweep.add_argument("--seed", type=int, default=0, help="seed of the lhs or sobol design")
    sweep.add_argument("--scheduler", metavar="ADDRESS", help="a running Dask scheduler, e.g. tcp://host:8786 "
                                                              "(default: a local cluster)")
    sweep.add_argument("--workers", type=int, metavar="N", help="local cluster size (default: one per core)")
    sweep.add_argument("--batch", type=int, metavar="N",
                       help="runs per Dask task (default: adaptive, tasks of about 0.5 s of CPU)")
    sweep.add_argument("--keep-results", action="store_true", help="save every run's result in DIR/runs/")
    sweep.add_argument("--resume", action="store_true", help="finish an interrupted sweep in DIR")
    sweep.add_argument("--max-wall-time", type=float, default=600.0, metavar="S",
                       help="a run taking longer stops as too_slow (default 600 s)")
    sweep.add_argument("--no-figures", action="store_true", help="skip the figures")
    sweep.add_argument("--quiet", action="store_true", help="no progress line")


def _derive(args: argparse.Namespace) -> int:
    import os

    from .subprocesses import run_tied

    if args.check and not args.out and args.scene:
        note = _outside_package_note(args.scene)
        if note:
            print(note)
            return 0
    command = [args.scene] if args.scene else []
    if args.runtime:
        command.append("--runtime")
    for formulation in args.formulation or []:
        command += ["--formulation", formulation]
    if args.out:
        command += ["--out", str(args.out)]
    if args.check:
        command.append("--check")
    return run_tied("derivation", command, env=dict(os.environ, PYTHONHASHSEED="0")).returncode


def _outside_package_note(scene_arg: str) -> str:
    """For ``derive --check`` of a user's own scene: where its model lives; "" for a bundled scene.

    Only the bundled scenes have committed models in ``generated/``; any other scene's
    model is derived on demand into the cache and has nothing there to be stale against.
    """
    from importlib import resources
    from pathlib import Path

    from .model import FLOATING_MAX_PARTICLES, find_model_dir
    from .paths import cache_root
    from .scene import load_scene, resolve_scene_path

    from .paths import generated_root

    bundled = Path(str(resources.files("flexbody") / "scenes")).resolve()
    scene = load_scene(scene_arg)
    if resolve_scene_path(scene_arg).resolve().parent == bundled:
        if any((generated_root() / f"{scene.name}_{f}").is_dir() for f in ("particles", "floating")):
            return ""
        what = "a bundled scene without committed whole-scene models (it runs assembled)"
    else:
        what = "not a bundled scene"
    lines = [f"{scene_arg}: {what}, so it has no committed model in generated/ to check."]
    lines.append("  particles: runs assembled from the element kernels (generated/kernels): nothing to derive or "
                 "check; `flexbody show` derives its equations whole on request")
    folder = find_model_dir(scene, "floating")
    if scene.n_particles > FLOATING_MAX_PARTICLES:
        where = f"not offered above {FLOATING_MAX_PARTICLES} particles (it is derived whole per topology)"
    elif folder:
        where = f"derived, in {folder}"
    else:
        where = f"not derived yet; `flexbody run --formulation floating` derives it on first use into {cache_root() / 'models'}/"
    lines.append(f"  floating: {where}")
    lines.append("Models in the cache are keyed by the scene's topology (particles, links, dampers, grounds) and are "
                 "never stale for it; to write the files somewhere to read or commit, use "
                 f"`flexbody derive {scene_arg} --out DIR` (then `--check --out DIR` compares against DIR).")
    return "\n".join(lines)


def _show(args: argparse.Namespace) -> int:
    from .model import SHOW_MAX_PARTICLES, derivation_seconds, find_model_dir, load_derived_model
    from .scene import load_scene

    scene = load_scene(args.scene)
    formulation = args.formulation or ("floating" if scene.rigid_bodies else scene.simulation.formulation)
    if scene.n_particles > SHOW_MAX_PARTICLES and not args.force and find_model_dir(scene, formulation) is None:
        print(f"error: {scene.source} has {scene.n_particles} particles: deriving its equations whole ({formulation}) "
              f"would take about {derivation_seconds(scene.n_particles, formulation, scene.dim):.0f} s. Running it needs no "
              "derivation (the particles formulation is assembled from element kernels); to print the equations "
              "anyway, add --force.", file=sys.stderr)
        return EXIT_USAGE
    model = load_derived_model(scene, backend="numpy", formulation=formulation)
    text = (model.directory / "eom.md").read_text()
    sections = dict(part.split("\n", 1) for part in text.split("\n## ")[1:])  # title -> body
    title = f"{'Raw equations' if args.raw else 'Equations'} ({'LaTeX' if args.latex else 'plain text'})"
    if title not in sections:
        print(f"error: {model.directory / 'eom.md'} has no '{title}' section; regenerate it with "
              f"`flexbody derive {args.scene}`", file=sys.stderr)
        return EXIT_FAILED
    body = "\n".join(line for line in sections[title].strip().splitlines() if not line.startswith("```"))
    header = text.split("## Symbols", 1)[0].split("-->", 1)[1].strip()
    print(f"{header}\n\n## Symbols\n{sections['Symbols'].strip()}\n\n## {title}\n\n{body}")
    return 0


def _run(args: argparse.Namespace) -> int:
    from .runner import run_command

    return run_command(args)


def _export(args: argparse.Namespace) -> int:
    from .export import export_folder

    try:
        pvd, count = export_folder(args.dir, every=args.every, fmt=args.format)
    except OSError as exc:  # the folder was checked; writing failed (disk full, permissions)
        print(f"error: could not write {args.dir}/vtk: {exc}\nnothing was written", file=sys.stderr)
        return EXIT_FAILED
    print(f"wrote {pvd} and {count} frames in {pvd.parent / 'frames'}/; open {pvd.name} in ParaView")
    return 0


def _bench(args: argparse.Namespace) -> int:
    from pathlib import Path

    from .bench import bench_command

    args.out = Path(args.out)
    return bench_command(args)


def _sweep(args: argparse.Namespace) -> int:
    from .sweep import sweep_command

    return sweep_command(args)


COMMANDS = {"run": _run, "export": _export, "derive": _derive, "show": _show, "bench": _bench, "sweep": _sweep}


def _show_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A warning as one line for a user, without the source line Python would print."""
    print(f"warning: {message}", file=sys.stderr)


def _known_failure(exc: Exception) -> bool:
    """A failure flexbody reports on purpose (not a bug): a derivation or a compilation failed."""
    known = [getattr(sys.modules.get("flexbody.model"), "ModelError", None),
             getattr(sys.modules.get("flexbody.cbuild"), "CompilationError", None)]
    return any(isinstance(exc, kind) for kind in known if kind is not None)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    args = _parser().parse_args(_attach_negative_numbers(argv))
    try:
        with warnings.catch_warnings():  # restores showwarning afterwards
            warnings.simplefilter("default")  # each distinct warning once
            warnings.showwarning = _show_warning
            return COMMANDS[args.command](args)
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("\ninterrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except Exception as exc:  # noqa: BLE001 - the last resort: tell a failure from a bug
        if _known_failure(exc):
            print(f"error: {exc}", file=sys.stderr)
        else:
            traceback.print_exc()
            print(f"error: {BUG}", file=sys.stderr)
        return EXIT_FAILED


if __name__ == "__main__":
    sys.exit(main())
