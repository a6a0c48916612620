"""Seeded procedural houses (the embedded world's default scenes); see `house.py` for the algorithm."""

from .house import generate_house, scene_tag
from .layout import HouseConfig

__all__ = ["HouseConfig", "generate_house", "scene_tag"]
