"""ovon: HM3D-OVON open-vocabulary object-goal navigation without the upstream stack."""

__version__ = "0.1.0"


def _register_envs() -> None:
    """`gymnasium.make("ovon/ObjectNav-v0", ...)`; the entry point is imported only when made."""
    try:
        import gymnasium as gym
    except ImportError:  # pragma: no cover
        return
    if "ovon/ObjectNav-v0" not in gym.registry:
        gym.register(id="ovon/ObjectNav-v0", entry_point="ovon.env:make_objectnav")


_register_envs()
