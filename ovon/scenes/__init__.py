"""Scenes: the scene model, the vocabulary, procedural houses and HM3DSem folder I/O.

Only light modules are imported here; `ovon.scenes.procedural`, `.topdown` and `.inspect` are
imported where used (they pull in more).
"""

from ovon.scenes.hm3dsem import find_scene_files, list_scenes, load_scene, write_scene
from ovon.scenes.model import Mesh, ObjectInstance, Region, Scene

__all__ = [
    "Mesh",
    "ObjectInstance",
    "Region",
    "Scene",
    "find_scene_files",
    "list_scenes",
    "load_scene",
    "write_scene",
]
