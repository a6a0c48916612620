"""A loaded world = scene + navigability + renderer, built once per scene and reused across episodes."""

from __future__ import annotations

from collections import OrderedDict
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
        if seed < 0:  # as `ovon scenes generate --seed` refuses: house seeds are non-negative
            raise ValueError(f"bad procedural scene id {scene!r}: the seed must be >= 0; fix: e.g. procedural:0")
        return generate_house(seed)
    from ovon.scenes.hm3dsem import load_scene

    return load_scene(scene, up=up)


@dataclass(eq=False)
class World:
    scene: Scene
    nav: object  # ovon.sim.navgrid.SceneNav
    renderer: object  # ovon.sim.types.Renderer
    key: str
    _share: tuple | None = None  # key in the per-process table of `acquire_world`

    def close(self) -> None:
        """Release this world (the last holder of a shared world closes its renderer)."""
        if self._share is not None:
            entry = _SHARED.get(self._share)
            if entry is not None:
                entry[1] -= 1
                if entry[1] > 0:
                    return
                # unused now: keep it for a while (envs that sample scenes come back to them)
                _IDLE[self._share] = entry
                _IDLE.move_to_end(self._share)
                del _SHARED[self._share]
                while len(_IDLE) > KEEP_IDLE_WORLDS:
                    _, (old, _) = _IDLE.popitem(last=False)
                    old._share = None
                    old.renderer.close()
                return
        self.renderer.close()


# Envs hosted by one process (the vector env puts several in each worker) share a world per scene and
# sim config: the scene, its navigability and the renderer's GPU buffers are loaded once. Rendering is
# synchronous, so envs of one process never use the renderer at the same time.
_SHARED: dict[tuple, list] = {}
_IDLE: OrderedDict[tuple, list] = OrderedDict()  # released worlds kept for reuse, least recent first
KEEP_IDLE_WORLDS = 8  # per process; a procedural house costs a few tens of MB


def acquire_world(scene: str | Scene, cfg: SimConfig) -> World:
    """A world shared by every env of this process with the same scene and sim config; `close()` it
    when done (reference counted)."""
    key = (scene if isinstance(scene, str) else ("scene-object", id(scene)), repr(cfg))
    entry = _SHARED.get(key)
    if entry is None and key in _IDLE:
        entry = _SHARED[key] = _IDLE.pop(key)
    if entry is None:
        world = build_world(scene, cfg)
        world._share = key
        entry = _SHARED[key] = [world, 0]
    entry[1] += 1
    return entry[0]


def build_world(scene: str | Scene, cfg: SimConfig) -> World:
    from ovon.sim.navgrid import build_navigation
    from ovon.sim.render import make_renderer

    s = load_scene_any(scene)
    nav = build_navigation(s, cfg.agent, cfg.nav)
    renderer = make_renderer(s, cfg.camera)
    key = scene if isinstance(scene, str) else s.scene_id
    return World(s, nav, renderer, key)
