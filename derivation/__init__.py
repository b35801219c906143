"""Build-time derivation of flexbody models (SymPy + jinja2); the runtime never imports this.

``python -m derivation SCENE`` (or ``flexbody derive SCENE``) derives the equations of
motion of a scene's topology by Kane's method and renders them into ``generated/``.
"""

from .codegen import render
from .mechanics import SymbolicModel, derive
from .writer import check_model, write_model

__all__ = ["SymbolicModel", "check_model", "derive", "render", "write_model"]
