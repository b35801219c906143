"""``python -m derivation SCENE [--formulation F] [--out DIR] [--check]`` or ``--runtime``.

Derives a scene's equations of motion and renders them into ``generated/<scene>_<F>/``;
with ``--runtime``, derives the element kernels and renders them with the
model-independent runtime into ``generated/kernels/`` and ``generated/runtime/``.  With
``--check``, compares instead of writing and exits 1 when anything is stale.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from flexbody.paths import generated_root, model_dir_name
from flexbody.scene import FORMULATIONS, SceneError, load_scene

from .writer import check_model, render_scene, write_model


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="flexbody derive", description=__doc__.splitlines()[2].strip())
    parser.add_argument("scene", nargs="?", help="scene file or bundled scene name")
    parser.add_argument("--runtime", action="store_true",
                        help="the element kernels and the runtime (generated/kernels, generated/runtime) instead")
    parser.add_argument("--formulation", choices=FORMULATIONS, action="append",
                        help="particles or floating (repeatable; default: both)")
    parser.add_argument("--out", type=Path, help="parent folder (default: the project's generated/)")
    parser.add_argument("--check", action="store_true", help="fail if generated files are stale; write nothing")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    if os.environ.get("PYTHONHASHSEED") != "0":
        # SymPy's CSE output can depend on hash order: run with a fixed seed for byte-stable files.
        import subprocess

        env = dict(os.environ, PYTHONHASHSEED="0")
        return subprocess.call([sys.executable, "-m", "derivation", *(argv or sys.argv[1:])], env=env)
    if args.runtime or args.scene is None:
        return _runtime(args)
    try:
        scene = load_scene(args.scene)
    except SceneError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    root = args.out or generated_root()
    stale = 0
    rigid = scene.rigid_bodies
    if rigid and "particles" in (args.formulation or ()):
        print(f"error: `--formulation` = 'particles': bodies {rigid} are rigid, frames T without particle "
              "coordinates, which only the floating formulation has", file=sys.stderr)
        return 2
    for formulation in args.formulation or (("floating",) if rigid else FORMULATIONS):
        name = args.scene if Path(args.scene).suffix == "" else str(args.scene)
        start = time.perf_counter()
        files = render_scene(scene, formulation, source=name,
                             command=f"flexbody derive {name} --formulation {formulation}")
        seconds = time.perf_counter() - start
        folder = root / model_dir_name(scene.name, formulation)
        stale += _write_or_check(files, folder, args.check, f"{formulation}, derived and rendered in {seconds:.1f} s")
    if stale:
        print("generated code is stale: regenerate with `flexbody derive SCENE` and commit it", file=sys.stderr)
    return 1 if stale else 0


def _write_or_check(files: dict[str, str], folder: Path, check: bool, how: str) -> bool:
    """Write ``files`` as ``folder``, or compare them with it; True if it is stale."""
    if not check:
        write_model(files, folder)
        print(f"wrote {folder} ({how})")
        return False
    problems = check_model(files, folder)
    print(f"{folder}: {'STALE' if problems else 'fresh'} ({how})")
    for problem in problems:
        print(problem)
    return bool(problems)


def _runtime(args: argparse.Namespace) -> int:
    """Render (or check) the model-independent files: element kernels and runtime."""
    from .kernelgen import render_kernels
    from .runtime import render_runtime

    root = args.out or generated_root()
    stale = 0
    for name, render in (("kernels", render_kernels), ("runtime", render_runtime)):
        start = time.perf_counter()
        files = render()
        seconds = time.perf_counter() - start
        stale += _write_or_check(files, root / name, args.check, f"rendered in {seconds:.1f} s")
    if stale:
        print("generated code is stale: regenerate with `flexbody derive --runtime` and commit it", file=sys.stderr)
    return 1 if stale else 0


if __name__ == "__main__":
    sys.exit(main())
