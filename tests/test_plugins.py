"""`package.module:Name` plug-ins: one loader for agents, detectors, scorers and navigators."""

from __future__ import annotations

import sys

import pytest

from ovon.plugins import PluginError, load_class


def test_load_class_and_its_one_line_errors() -> None:
    import json

    assert load_class("json:JSONDecoder", "k", "f") is json.JSONDecoder
    with pytest.raises(PluginError, match=r"k = 'json:loads' is a function, not a class; fix: f"):
        load_class("json:loads", "k", "f")
    with pytest.raises(PluginError, match=r"cannot import module 'no_such_pkg_x'"):
        load_class("no_such_pkg_x:A", "k", "f")
    with pytest.raises(PluginError, match=r"has no attribute 'Nope'"):
        load_class("json:Nope", "k", "f")


def test_a_module_in_the_working_directory_loads(tmp_path, monkeypatch) -> None:
    (tmp_path / "my_scorer_mod.py").write_text("class S:\n    def __init__(self, cfg):\n        self.cfg = cfg\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])
    from ovon.models.config import ScorerConfig
    from ovon.models.scorers import make_scorer

    assert type(make_scorer(ScorerConfig(kind="my_scorer_mod:S"))).__name__ == "S"


@pytest.mark.parametrize("factory", ["detector", "scorer"])
def test_factories_name_their_key(factory: str) -> None:
    if factory == "detector":
        from ovon.models.config import DetectorConfig
        from ovon.models.detectors import make_detector

        with pytest.raises(PluginError, match=r"^detector.kind = 'no_such_pkg_x:D': cannot import"):
            make_detector(DetectorConfig(kind="no_such_pkg_x:D"))
    else:
        from ovon.models.config import ScorerConfig
        from ovon.models.scorers import make_scorer

        with pytest.raises(PluginError, match=r"^value.scorer.kind = 'no_such_pkg_x:D': cannot import"):
            make_scorer(ScorerConfig(kind="no_such_pkg_x:D"))


def test_one_dispatch_for_built_ins_and_plug_ins() -> None:
    """Agents, detectors, scorers and navigators pick their class the same way: a name in the built-in table
    (each entry loads), else `package.module:Class`, else one line naming the key and the valid names."""
    import inspect

    from ovon.agents import BUILTIN as AGENTS
    from ovon.agents.modular.navigation import NAVIGATORS
    from ovon.models.detectors import BUILTIN as DETECTORS
    from ovon.models.scorers import BUILTIN as SCORERS
    from ovon.plugins import load_named, load_object, lookup

    for table in (AGENTS, NAVIGATORS, DETECTORS, SCORERS):
        for name, spec in table.items():
            assert lookup(name, table) == spec and inspect.isclass(load_object(spec)), spec
    assert lookup("json:JSONDecoder", DETECTORS) == "json:JSONDecoder" and lookup("nope", DETECTORS) is None
    with pytest.raises(
        PluginError, match=r"^detector.kind = 'yolo' is unknown; use one of \['oracle', 'owlv2', 'world-owl'\]"
    ):
        load_named("yolo", DETECTORS, "detector.kind")


@pytest.mark.parametrize("factory", ["detector", "scorer", "navigator"])
def test_factories_refuse_an_unknown_name_in_one_line(factory: str) -> None:
    if factory == "detector":
        from ovon.models.config import DetectorConfig
        from ovon.models.detectors import make_detector

        with pytest.raises(
            PluginError, match=r"^detector.kind = 'nope' is unknown; use one of \['oracle', 'owlv2', 'world-owl'\]"
        ):
            make_detector(DetectorConfig(kind="nope"))
    elif factory == "scorer":
        from ovon.models.config import ScorerConfig
        from ovon.models.scorers import make_scorer

        with pytest.raises(PluginError, match=r"^value.scorer.kind = 'nope' is unknown; use one of \['oracle-vl'"):
            make_scorer(ScorerConfig(kind="nope"))
    else:
        from ovon.agents.modular.config import NavigatorConfig
        from ovon.agents.modular.navigation import make_navigator

        expected = r"^navigator.kind = 'nope' is unknown; use one of \['geometric', 'learned'\]"
        with pytest.raises(PluginError, match=expected):
            make_navigator(NavigatorConfig(kind="nope"), None, None)  # type: ignore[arg-type]
