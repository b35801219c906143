"""Write rendered models to disk atomically, or compare them with what is on disk."""

from __future__ import annotations

import difflib
from pathlib import Path

from flexbody.paths import staged_folder
from flexbody.scene import Scene

from .codegen import render
from .mechanics import derive


def render_scene(scene: Scene, formulation: str, *, source: str, command: str) -> dict[str, str]:
    """Derive and render the model of ``scene`` in ``formulation``; file name -> text."""
    return render(derive(scene.topology(), formulation), source=source, command=command)


def write_model(files: dict[str, str], out_dir: Path) -> Path:
    """Write ``files`` into ``out_dir``, replacing it whole (never half-written): they go to
    a sibling temporary folder first, which is then renamed into place."""
    with staged_folder(out_dir) as staging:
        for name, text in files.items():
            (staging / name).write_text(text)
    return Path(out_dir)


def check_model(files: dict[str, str], out_dir: Path) -> list[str]:
    """Differences between freshly rendered ``files`` and ``out_dir``; empty when fresh.

    Returns
    -------
    list of str
        One entry per stale, missing or extra file, with a unified diff where useful.
    """
    out_dir = Path(out_dir)
    problems = []
    on_disk = {p.name for p in out_dir.iterdir() if p.is_file()} if out_dir.is_dir() else set()
    for name in sorted(set(files) | on_disk):
        path = out_dir / name
        if name not in files:
            problems.append(f"{path}: not produced by the generator (remove it)")
        elif not path.exists():
            problems.append(f"{path}: missing")
        elif path.read_text() != files[name]:
            diff = difflib.unified_diff(
                path.read_text().splitlines(), files[name].splitlines(), f"{path} (on disk)", f"{path} (fresh)", lineterm="", n=1
            )
            shown = list(diff)
            problems.append(f"{path}: stale\n" + "\n".join(shown[:40]) + ("\n..." if len(shown) > 40 else ""))
    return problems
