"""The ``flexbody`` command: run, derive, show, sweep, bench.

Every command is a thin wrapper over library functions.  A user mistake (bad scene,
bad option) prints one clear error and exits 2, without a traceback and without writing
anything; a failed simulation exits 1 and says why.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import warnings
from pathlib import Path

from .scene import BACKENDS, FORMULATIONS, IMPACT_MODES, METHODS, SceneError, load_scene

EXIT_FAILED, EXIT_USAGE = 1, 2


def _add_scene(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scene", metavar="SCENE", help="a scene file (TOML) or a bundled scene's name, e.g. thesis_ball")


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="flexbody",
        description="Flexible bodies as particles, springs and dampers: derive, inspect and simulate.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    run = sub.add_parser("run", help="simulate a scene and write result.npz, summary.json and figures",
                         description="Simulate a scene; write DIR/result.npz, DIR/summary.json and figures.")
    _add_scene(run)
    run.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    run.add_argument("--no-figures", action="store_true", help="skip the figures and the animation")
    run.add_argument("--method", choices=METHODS, help="integration method: dopri5 or dop853 (compiled C; default dopri5) or a SciPy solve_ivp method")
    run.add_argument("--rtol", type=float, help="relative tolerance")
    run.add_argument("--atol", type=float, help="absolute tolerance")
    run.add_argument("--backend", choices=BACKENDS, help="c (compiled, default) or numpy")
    run.add_argument("--formulation", choices=FORMULATIONS, help="particles (default) or floating")
    run.add_argument("--impact", choices=IMPACT_MODES, help="instant (default) or thesis (eq. 4.6)")
    run.add_argument("--impact-dt", type=float, help="ΔT of the thesis impact mode (s)")
    run.add_argument("--t-end", type=float, help="end time (s)")
    run.add_argument("--quiet", action="store_true", help="no progress bar")

    derive = sub.add_parser("derive", help="derive and generate a scene's model into generated/",
                            description="Derive the equations of motion (SymPy, Kane's method) and render "
                                        "the NumPy module, C source, eom.md and manifest into generated/.")
    _add_scene(derive)
    derive.add_argument("--formulation", choices=FORMULATIONS, action="append",
                        help="particles or floating (repeatable; default: both)")
    derive.add_argument("--out", type=Path, metavar="DIR", help="parent folder (default: the project's generated/)")
    derive.add_argument("--check", action="store_true", help="exit 1 if the generated files are stale; write nothing")

    show = sub.add_parser("show", help="print a scene's derived equations of motion",
                          description="Print the derived equations of motion M u' = F, row by row.")
    _add_scene(show)
    show.add_argument("--latex", action="store_true", help="print LaTeX instead of plain text")
    show.add_argument("--formulation", choices=FORMULATIONS, default=None, help="default: the scene's")

    _add_sweep(sub)

    bench = sub.add_parser("bench", help="speed and accuracy benchmarks (prints and saves numbers)",
                           description="Benchmarks, not tests: work-precision diagram (wp), stability map "
                                       "(stability) and resolution study (resolution); JSON and PNG in --out.")
    bench.add_argument("--study", choices=("wp", "stability", "resolution", "mujoco", "sweep"), action="append",
                       help="which study (repeatable; default: all; mujoco needs flexbody[mujoco])")
    bench.add_argument("--out", type=Path, default=Path("bench"), metavar="DIR", help="output folder")
    bench.add_argument("--repeats", type=int, default=5, help="timing repeats (median is reported)")
    bench.add_argument("--quick", action="store_true", help="fewer cases and repeats (about a minute)")
    return parser


def _add_sweep(sub) -> None:
    sweep = sub.add_parser("sweep", help="a parameter study on Dask: one row per varied scene",
                           description="Vary scene fields over a grid or a quasi-random design, run every scene "
                                       "on a Dask cluster, write DIR/sweep.parquet, sweep.csv, sweep.json and "
                                       "figures. Needs flexbody[sweep].")
    _add_scene(sweep)
    sweep.add_argument("--vary", action="append", required=True, metavar="FIELD=SPEC",
                       help="a dotted scene field and its values: a list 1e3,1e4,1e5; a range lo:hi:n or "
                            "lo:hi:n:log; with --samples, lo:hi or lo:hi:log (repeatable)")
    sweep.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    sweep.add_argument("--samples", type=int, metavar="N", help="number of runs of an lhs or sobol design")
    sweep.add_argument("--design", choices=("grid", "lhs", "sobol"), default="grid",
                       help="grid (every combination, default), lhs or sobol (needs --samples)")
    sweep.add_argument("--seed", type=int, default=0, help="seed of the lhs or sobol design")
    sweep.add_argument("--scheduler", metavar="ADDRESS", help="a running Dask scheduler, e.g. tcp://host:8786 "
                                                              "(default: a local cluster)")
    sweep.add_argument("--workers", type=int, metavar="N", help="local cluster size (default: one per core)")
    sweep.add_argument("--batch", type=int, metavar="N",
                       help="runs per Dask task (default: adaptive, tasks of about 0.25 s)")
    sweep.add_argument("--keep-results", action="store_true", help="save every run's result in DIR/runs/")
    sweep.add_argument("--resume", action="store_true", help="finish an interrupted sweep in DIR")
    sweep.add_argument("--max-wall-time", type=float, default=600.0, metavar="S",
                       help="a run taking longer stops as too_slow (default 600 s)")
    sweep.add_argument("--no-figures", action="store_true", help="skip the figures")
    sweep.add_argument("--quiet", action="store_true", help="no progress line")


def _derive(args: argparse.Namespace) -> int:
    command = [sys.executable, "-m", "derivation", args.scene]
    for formulation in args.formulation or []:
        command += ["--formulation", formulation]
    if args.out:
        command += ["--out", str(args.out)]
    if args.check:
        command.append("--check")
    return subprocess.call(command, env=dict(os.environ, PYTHONHASHSEED="0"))


def _show(args: argparse.Namespace) -> int:
    from .model import load_model

    scene = load_scene(args.scene)
    model = load_model(scene, backend="numpy", formulation=args.formulation)
    text = (model.directory / "eom.md").read_text()
    if args.latex:
        body = text.split("## Equations (LaTeX)", 1)[1].strip()
    else:
        body = text.split("```text", 1)[1].split("```", 1)[0].strip()
    header = text.split("## Symbols", 1)[0].split("-->", 1)[1].strip()
    symbols = text.split("## Symbols", 1)[1].split("## Equations", 1)[0].strip()
    print(f"{header}\n\n{symbols}\n\n{body}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("default")
            if args.command == "derive":
                return _derive(args)
            if args.command == "show":
                return _show(args)
            if args.command == "run":
                from .runner import run_command

                return run_command(args)
            if args.command == "sweep":
                from .sweep import sweep_command

                return sweep_command(args)
            if args.command == "bench":
                from .bench import bench_command

                return bench_command(args)
    except SceneError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
