"""Where generated models and compiled libraries live.

* ``generated/`` at the project root holds the committed models of the bundled scenes
  (``generated/<scene>_<formulation>/``); ``FLEXBODY_GENERATED`` overrides it.
* The cache (``FLEXBODY_CACHE``, default ``~/.cache/flexbody``) holds models derived on
  demand (``models/<digest>/``) and compiled C libraries (``lib/<sha256>.so``).
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parents[2]


def generated_root() -> Path:
    """The committed ``generated/`` folder: the checkout's, or the installed data package
    ``flexbody_generated`` (a non-editable install); ``FLEXBODY_GENERATED`` overrides both."""
    if "FLEXBODY_GENERATED" in os.environ:
        return Path(os.environ["FLEXBODY_GENERATED"])
    local = PROJECT_ROOT / "generated"
    if local.is_dir():
        return local
    spec = importlib.util.find_spec("flexbody_generated")
    if spec is not None and spec.submodule_search_locations:
        return Path(next(iter(spec.submodule_search_locations)))
    return local


def cache_root() -> Path:
    """The cache folder for on-demand models and compiled libraries."""
    default = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "flexbody"
    return Path(os.environ.get("FLEXBODY_CACHE", default))


def model_dir_name(scene_name: str, formulation: str) -> str:
    return f"{scene_name}_{formulation}"
