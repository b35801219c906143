"""Rendering of the model-independent C runtime: ``generated/runtime/``.

The integrator (its Runge-Kutta tables read from SciPy), the phase machine's fixed point,
the assembled particles formulation and the pivots of Lemke's method are rendered once, not per model, and compiled
once per install into one library with the element kernels.  Their constants come from
:mod:`flexbody.constants`, the one source Python shares.
"""

from __future__ import annotations

import hashlib
import json

from flexbody.constants import C_DEFINES

from .codegen import environment, runge_kutta_tables
from .elements import DIMENSIONS

#: Rendered files of generated/runtime/: template -> file name.
FILES = {
    "fb_runtime.h.jinja": "fb_runtime.h",
    "work.h.jinja": "work.h",
    "integrator.c.jinja": "integrator.c",
    "phases.c.jinja": "phases.c",
    "assembly.c.jinja": "assembly.c",
    "narrowphase.c.jinja": "narrowphase.c",
    "held_rows.c.jinja": "held_rows.c",
    "lcp.c.jinja": "lcp.c",
}
COMMAND = "flexbody derive --runtime"


def render_runtime() -> dict[str, str]:
    """Render every file of ``generated/runtime/``; file name -> text (with manifest.json)."""
    env = environment()
    context = {"command": COMMAND, "rk": runge_kutta_tables(), "defines": C_DEFINES, "dimensions": DIMENSIONS}
    files = {out: env.get_template(t).render(template=t, **context) for t, out in FILES.items()}
    manifest = {
        "regenerate": COMMAND,
        "sha256": {name: hashlib.sha256(text.encode()).hexdigest() for name, text in sorted(files.items())},
    }
    files["manifest.json"] = json.dumps(manifest, indent=1) + "\n"
    return files
