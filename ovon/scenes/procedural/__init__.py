"""Seeded procedural houses (the embedded world's default scenes); see `house.py` for the algorithm."""

from .config import HouseConfig
from .house import generate_house, scene_tag

__all__ = ["HouseConfig", "generate_house", "scene_tag"]
