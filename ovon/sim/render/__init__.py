"""Renderers for RGB, z-depth and instance ids: GL (moderngl/EGL) and embree, which agree per pixel.

`make_renderer(scene, camera)` picks the backend from `camera.backend` unless `backend` is given;
"auto" tries GL and falls back to embree (with a warning) when no EGL context can be created.
"""

from __future__ import annotations

import logging

from ovon.config.sim import CameraConfig
from ovon.scenes.model import Scene
from ovon.sim.types import Renderer

log = logging.getLogger(__name__)

BACKENDS = ("auto", "gl", "embree")


def make_renderer(scene: Scene, camera: CameraConfig, backend: str | None = None) -> Renderer:
    """Build a renderer for `scene`; geometry is uploaded / the BVH is built once here."""
    backend = backend or camera.backend
    if backend not in BACKENDS:
        raise ValueError(f"unknown render backend {backend!r}; expected one of {BACKENDS}")
    if backend in ("auto", "gl"):
        try:
            from ovon.sim.render.gl import GLRenderer

            return GLRenderer(scene, camera)
        except Exception as exc:  # EGL missing, no GL driver, ...
            if backend == "gl":
                raise
            log.warning("GL renderer unavailable (%s: %s); falling back to embree", type(exc).__name__, exc)
    from ovon.sim.render.embree import EmbreeRenderer

    return EmbreeRenderer(scene, camera)


def gl_available() -> bool:
    """True when a headless EGL context can be created in this process."""
    try:
        from ovon.sim.render.gl import gl_context

        gl_context()
        return True
    except Exception:
        return False


__all__ = ["BACKENDS", "Renderer", "gl_available", "make_renderer"]
