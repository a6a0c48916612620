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
    from ovon.models.scorers import ScorerConfig, make_scorer

    assert type(make_scorer(ScorerConfig(kind="my_scorer_mod:S"))).__name__ == "S"


@pytest.mark.parametrize("factory", ["detector", "scorer"])
def test_factories_name_their_key(factory: str) -> None:
    if factory == "detector":
        from ovon.models.detectors import DetectorConfig, make_detector

        with pytest.raises(PluginError, match=r"^detector.kind = 'no_such_pkg_x:D': cannot import"):
            make_detector(DetectorConfig(kind="no_such_pkg_x:D"))
    else:
        from ovon.models.scorers import ScorerConfig, make_scorer

        with pytest.raises(PluginError, match=r"^value.scorer.kind = 'no_such_pkg_x:D': cannot import"):
            make_scorer(ScorerConfig(kind="no_such_pkg_x:D"))
