"""Config validation at the edge: declared domains, one-line messages, one code path (issue 13, item 1)."""

from __future__ import annotations

import dataclasses
import typing

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from ovon.config.base import ConfigError, build, from_dict, merge, validate, violations
from ovon.config.dataset import GENERATION_PRESETS, GenerationConfig
from ovon.config.sim import CameraConfig, SimConfig
from ovon.config.task import TaskConfig
from ovon.dataset.splits import SplitConfig
from ovon.evaluate.config import EvalConfig
from ovon.models.config import ENCODER_PRESETS, POLICY_PRESETS, EncoderConfig, PolicyConfig
from ovon.train.config import TrainConfig

# The configs whose domains this session owns (train/expert configs declare theirs with the same helpers).
OWNED = (SimConfig, TaskConfig, GenerationConfig, EncoderConfig, PolicyConfig, EvalConfig, SplitConfig, TrainConfig)
# Fields whose type is their whole domain: any finite reward, a free-form kwargs mapping.
FREE = {
    "RewardConfig": {
        "dense_success",
        "dense_slack",
        "sparse_success",
        "sparse_slack",
        "sparse_collision",
        "dense_failed_stop",
        "dense_coverage",
    },
    "EvalConfig": {"agent_kwargs"},
    # paths that may not exist yet (written when absent)
    "BCConfig": {"shards"},
    "TrainConfig": {"text_cache"},
}


def _tree(cls):
    yield cls
    for f in dataclasses.fields(cls):
        tp = typing.get_type_hints(cls)[f.name]
        if dataclasses.is_dataclass(tp):
            yield from _tree(tp)


def test_every_owned_config_field_has_a_declared_domain():
    """bool, Literal and nested configs are closed by their type; every other field declares a domain."""
    missing = []
    for root in OWNED:
        for cls in _tree(root):
            hints = typing.get_type_hints(cls)
            for f in dataclasses.fields(cls):
                tp = hints[f.name]
                closed = tp is bool or typing.get_origin(tp) is typing.Literal or dataclasses.is_dataclass(tp)
                if not closed and f.metadata.get("domain") is None and f.name not in FREE.get(cls.__name__, ()):
                    missing.append(f"{cls.__name__}.{f.name}")
    assert not missing, f"fields without a declared domain: {missing}"


def test_presets_are_inside_their_domains():
    from ovon.train.config import PRESETS

    for make in PRESETS.values():
        validate(make())
    for make in GENERATION_PRESETS.values():
        validate(make())
    for p in [*POLICY_PRESETS.values(), *ENCODER_PRESETS.values()]:
        validate(p)
    assert violations(EvalConfig()) == [v for v in violations(EvalConfig()) if v.startswith(("--data", "--scenes"))]


ISSUE_CASES = [  # (config, --set override, key named in the message)
    (TaskConfig, "success_distance=-1", "success_distance"),
    (TaskConfig, "max_steps=0", "max_steps"),
    (TaskConfig, "max_steps=-5", "max_steps"),
    (TaskConfig, "max_steps=1e400", "max_steps"),
    (TaskConfig, "max_steps=abc", "max_steps"),
    (TaskConfig, "max_steps=2.5", "max_steps"),
    (SimConfig, "camera.width=0", "camera.width"),
    (SimConfig, "camera.hfov_deg=180", "camera.hfov_deg"),
    (SimConfig, "camera.hfov_deg=0", "camera.hfov_deg"),
    (SimConfig, "agent.forward_step=0", "agent.forward_step"),
    (SimConfig, "camera.min_depth=9", "camera.min_depth"),
    (SimConfig, "camera.backend=vulkan", "camera.backend"),
    (SimConfig, "noise.odometry=maybe", "noise.odometry"),
    (SimConfig, "nav.cell_size=.nan", "nav.cell_size"),
    (SimConfig, "camrea.width=3", "camrea"),
    (GenerationConfig, "episodes_per_val_split=-5", "episodes_per_val_split"),
    (GenerationConfig, "viewpoints.render_size=0", "viewpoints.render_size"),
    (GenerationConfig, "viewpoints.tilts_deg=[]", "viewpoints.tilts_deg"),
    (GenerationConfig, "starts.min_geodesic=50", "starts.min_geodesic"),
    (PolicyConfig, "heads=3", "heads"),
    (EncoderConfig, "oracle_depth_grid=[3, 0]", "oracle_depth_grid"),
]


@pytest.mark.parametrize("cls,override,key", ISSUE_CASES)
def test_out_of_domain_values_are_one_line_errors_naming_key_value_domain_fix(cls, override, key):
    with pytest.raises(ConfigError) as ei:
        build(cls, None, None, [override])
    msg = str(ei.value)
    assert "\n" not in msg and key in msg
    if "camrea" not in override:
        assert "expected" in msg and "fix:" in msg
        value = override.split("=", 1)[1]
        assert value.strip("[]").strip(".")[:3] in msg.replace("(", "[").replace(")", "]")


def test_validate_catches_configs_built_in_python():
    bad = SimConfig(camera=CameraConfig(width=0, hfov_deg=float("nan")))
    with pytest.raises(ConfigError, match=r"2 invalid config values: camera.width = 0.*camera.hfov_deg = nan"):
        validate(bad)
    with pytest.raises(ConfigError, match="an integer"):
        validate(TaskConfig(max_steps=2.5))  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match="sim.camera.width"):
        merge(SimConfig(), {"camera": {"width": -1}}, "sim")
    with pytest.raises(ConfigError, match="expected a mapping"):
        from_dict(SimConfig, {"camera": 3})


def test_unknown_key_suggests_the_close_one(tmp_path):
    with pytest.raises(ConfigError, match=r"sim\.camrea \(did you mean 'camera'\?\)"):
        build(EvalConfig, EvalConfig(), None, ["sim.camrea.width=3"])
    y = tmp_path / "c.yaml"
    y.write_text("viewpoints: {render_sise: 64}\n")
    with pytest.raises(ConfigError, match=r"config file .*c\.yaml: unknown config key\(s\) viewpoints\.render_sise"):
        build(GenerationConfig, None, y)
    y.write_text("- a\n- b\n")
    with pytest.raises(ConfigError, match="must hold a mapping"):
        build(GenerationConfig, None, y)
    y.write_text("a: [\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        build(GenerationConfig, None, y)
    with pytest.raises(ConfigError, match="does not exist"):
        build(GenerationConfig, None, tmp_path / "nope.yaml")


def test_override_syntax_errors_are_clear():
    for bad, what in (["novalue"], "key=value"), (["a..b=1"], "empty key part"), (["sim=1", "sim.x=2"], "both"):
        with pytest.raises(ConfigError, match=what):
            build(SimConfig, None, None, bad)


def test_flagged_fields_name_their_option():
    with pytest.raises(
        ConfigError,
        match=r"^--episodes = -1: expected an integer > 0, or leave it out; fix: pass "
        r"--episodes",
    ):
        from_dict(EvalConfig, {"episodes": -1, "data": ".", "scenes": "."})
    with pytest.raises(ConfigError, match=r"^--seeds = \(0, 0\): expected a non-empty list of distinct"):
        from_dict(EvalConfig, {"seeds": "0,0", "data": ".", "scenes": "."})


# -- fuzz: any override of any numeric field either builds a valid config or is a one-line ConfigError ----
def _leaf_keys(cls, prefix=""):
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        key = f"{prefix}{f.name}"
        if dataclasses.is_dataclass(tp):
            yield from _leaf_keys(tp, key + ".")
        else:
            yield key


KEYS = sorted(set(_leaf_keys(SimConfig, "sim.")) | set(_leaf_keys(TaskConfig, "task.")))
GEN_KEYS = sorted(_leaf_keys(GenerationConfig))
values = st.one_of(
    st.integers(-(10**6), 10**6).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(
        [
            "",
            "abc",
            "1e400",
            "-1e400",
            ".nan",
            "true",
            "[]",
            "[1, 2]",
            "{a: 1}",
            "null",
            "0",
            "-0",
            "1,2,3",
            "[[[[1]]]]",
        ]
    ),
    st.text(max_size=12),
)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(key=st.sampled_from(KEYS + GEN_KEYS), value=values)
def test_fuzz_overrides_give_a_valid_config_or_a_one_line_error(key, value):
    cls, k = (EvalConfig, key) if key.startswith(("sim.", "task.")) else (GenerationConfig, key)
    base = EvalConfig(data=".", scenes=".") if cls is EvalConfig else GenerationConfig()
    try:
        cfg = build(cls, base, None, [f"{k}={value}"])
    except ConfigError as e:
        assert "\n" not in str(e) and str(e)
        return
    validate(cfg)  # a config that was built is inside every domain
