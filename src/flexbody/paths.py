"""Where generated models and compiled libraries live.

* ``generated/`` at the project root holds the committed models of the bundled scenes
  (``generated/<scene>_<formulation>/``); ``FLEXBODY_GENERATED`` overrides it.
* The cache (``FLEXBODY_CACHE``, default ``~/.cache/flexbody``) holds models derived on
  demand (``models/<digest>/``) and compiled C libraries (``lib/<sha256>.so``).
"""

from __future__ import annotations

import os
from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parents[2]


def generated_root() -> Path:
    """The committed ``generated/`` folder (it may not exist in a non-editable install)."""
    return Path(os.environ.get("FLEXBODY_GENERATED", PROJECT_ROOT / "generated"))


def cache_root() -> Path:
    """The cache folder for on-demand models and compiled libraries."""
    default = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "flexbody"
    return Path(os.environ.get("FLEXBODY_CACHE", default))


def model_dir_name(scene_name: str, formulation: str) -> str:
    return f"{scene_name}_{formulation}"
