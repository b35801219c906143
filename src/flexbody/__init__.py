"""flexbody: flexible bodies as particles, springs and dampers, with exact impact and contact.

The public API::

    scene = flexbody.load_scene("thesis_ball")            # or a path to a TOML scene
    model = flexbody.load_model(scene, backend="c")        # generated equations, C or NumPy
    result = flexbody.simulate(scene)                      # impacts, contact, lift-off
    result.save("out/")                                    # result.npz + summary.json
"""

__version__ = "0.1.0"

from .driver import simulate  # noqa: E402
from .model import Model, load_model  # noqa: E402
from .result import SimulationResult, load_result  # noqa: E402
from .scene import Scene, SceneError, load_scene  # noqa: E402

__all__ = [
    "Model", "Scene", "SceneError", "SimulationResult", "__version__",
    "load_model", "load_result", "load_scene", "simulate",
]  # fmt: skip
