"""ovon: HM3D-OVON open-vocabulary object-goal navigation without the upstream stack."""

__version__ = "0.1.0"


def _register_envs() -> None:
    try:
        from ovon.sim.registration import register_envs
    except ImportError:  # pragma: no cover - only while the simulator is absent
        return
    register_envs()


_register_envs()
