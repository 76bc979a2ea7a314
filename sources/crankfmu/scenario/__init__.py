"""Scene files: schema, loading and validation with errors that name file, key and what is allowed."""
from .scene import Component, Connection, InputSignal, Master, Scene, SceneError, load_scene

__all__ = ["Component", "Connection", "InputSignal", "Master", "Scene", "SceneError", "load_scene"]
