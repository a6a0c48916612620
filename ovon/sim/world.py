"""A loaded world = scene + navigability + renderer, built once per scene and reused across episodes."""

from __future__ import annotations

from dataclasses import dataclass

from ovon.config.sim import SimConfig
from ovon.scenes.model import Scene


def load_scene_any(scene: str | Scene, up: str | None = None) -> Scene:
    """A `Scene`, a path to a scene (HM3DSem folder or any of its files, or a bare .glb/.gltf/.ply/.obj),
    or `procedural:<seed>`. `up` overrides the up axis of a scan or bare mesh (see `load_scene`)."""
    if isinstance(scene, Scene):
        return scene
    if scene.startswith("procedural:"):
        from ovon.scenes.procedural import generate_house

        try:
            seed = int(scene.split(":", 1)[1])
        except ValueError:
            raise ValueError(f"bad procedural scene id {scene!r}: expected procedural:<integer seed>") from None
        return generate_house(seed)
    from ovon.scenes.hm3dsem import load_scene

    return load_scene(scene, up=up)


@dataclass
class World:
    scene: Scene
    nav: object  # ovon.sim.navgrid.SceneNav
    renderer: object  # ovon.sim.types.Renderer
    key: str

    def close(self) -> None:
        self.renderer.close()


def build_world(scene: str | Scene, cfg: SimConfig) -> World:
    from ovon.sim.navgrid import build_navigation
    from ovon.sim.render import make_renderer

    s = load_scene_any(scene)
    nav = build_navigation(s, cfg.agent, cfg.nav)
    renderer = make_renderer(s, cfg.camera)
    key = scene if isinstance(scene, str) else s.scene_id
    return World(s, nav, renderer, key)
