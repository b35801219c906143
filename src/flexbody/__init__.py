"""flexbody: flexible bodies as particles, springs and dampers, with exact impact and contact."""

from .scene import Scene, SceneError, load_scene

__version__ = "0.1.0"
__all__ = ["Scene", "SceneError", "load_scene", "__version__"]
