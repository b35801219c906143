"""flexbody: flexible bodies as particles, springs and dampers, with exact impact and contact.

The public API::

    scene = flexbody.load_scene("thesis_ball")            # or a path to a TOML scene
    model = flexbody.load_model(scene, backend="c")        # generated equations, C or NumPy
    result = flexbody.simulate(scene)                      # impacts, contact, lift-off
    result.save("out/")                                    # result.npz + summary.json

The names are imported on first use (PEP 562), so ``import flexbody`` and
``flexbody --help`` do not pay for NumPy, SciPy and matplotlib until they are needed.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

__version__ = "0.1.0"

#: Public name -> the module that defines it.
_LAZY = {
    "simulate": "driver",
    "Model": "model",
    "load_model": "model",
    "SimulationResult": "result",
    "load_result": "result",
    "Scene": "scene",
    "SceneError": "scene",
    "load_scene": "scene",
    "InputError": "errors",
}

__all__ = [
    "InputError", "Model", "Scene", "SceneError", "SimulationResult", "__version__",
    "load_model", "load_result", "load_scene", "simulate",
]  # fmt: skip

if TYPE_CHECKING:  # for type checkers and editors; at run time the names come from __getattr__
    from .driver import simulate
    from .errors import InputError
    from .model import Model, load_model
    from .result import SimulationResult, load_result
    from .scene import Scene, SceneError, load_scene


def __getattr__(name: str):
    if name in _LAZY:
        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value  # once imported, an ordinary attribute
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
