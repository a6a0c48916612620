"""The documentation site builds with --strict, offline, and its reference pages come from the code.

The build needs the `docs` extra (`make docs` installs it); without it these tests skip. The built site
must not load anything from the network (fonts, scripts, styles, images): the build machine and many
readers have no internet, and a page that calls out is a privacy leak."""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
HOOKS = ROOT / "docs" / "_hooks" / "ovon_docs.py"

# a remote URL where a page loads something: src=, <link href=> (stylesheets, fonts, icons), CSS url(),
# @import, and any fonts.googleapis / cdn host in scripts
REMOTE_ASSET = re.compile(
    r"""(?:\bsrc\s*=\s*["']?\s*(?:https?:)?//)|(?:<link\b[^>]*\bhref\s*=\s*["']?\s*(?:https?:)?//)"""
    r"""|(?:url\(\s*["']?\s*(?:https?:)?//)|(?:@import\s+["']?(?:url\()?\s*["']?(?:https?:)?//)"""
    r"""|fonts\.googleapis|fonts\.gstatic|cdn\.jsdelivr|unpkg\.com|googletagmanager""",
    re.I,
)


def _theme_fallback(text: str, m: re.Match) -> bool:
    around = text[max(0, m.start() - 20) : m.end() + 60]
    return "unpkg.com/mermaid" in around or "unpkg.com/resize-observer-polyfill" in around


def test_no_page_draws_a_mermaid_diagram():
    """Material fetches mermaid from a CDN for a `mermaid` block: the pages have none."""
    for page in (ROOT / "docs").rglob("*.md"):
        assert "```mermaid" not in page.read_text(encoding="utf-8"), page


def _hooks():
    spec = importlib.util.spec_from_file_location("ovon_docs_hooks", HOOKS)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_cli_reference_has_every_command_and_option():
    import argparse

    hooks = _hooks()
    text = hooks.cli_reference()
    from ovon.cli.main import build_parser

    commands = hooks.cli_commands()
    assert {"ovon evaluate", "ovon train", "ovon dataset generate", "ovon experiment run", "ovon serve"} <= set(
        commands
    )
    for command in commands:
        assert f"`{command}`" in text, command
    evaluate = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)).choices["evaluate"]
    for action in evaluate._actions:
        for flag in action.option_strings if not isinstance(action, argparse._HelpAction) else ():
            assert flag in text, flag


def test_the_config_reference_has_every_key_with_its_domain():
    hooks = _hooks()
    keys = hooks.config_keys()
    assert {"sim.camera.width", "task.max_steps", "ppo.minibatches", "dagger.overlap"} <= set(keys["TrainConfig"])
    assert {"agent", "seeds", "remote.batch", "sim.camera.hfov_deg"} <= set(keys["EvalConfig"])
    assert "viewpoints.render_size" in keys["GenerationConfig"]
    text = hooks.config_reference()
    assert "`sim.camera.width`" in text and "an integer in [1, 4096]" in text
    for root, root_keys in keys.items():
        assert root_keys, root


def test_field_notes_come_from_the_comments():
    from ovon.config.sim import NavConfig

    notes = _hooks().field_notes(NavConfig)
    assert "separate floors" in notes["floor_separation"]  # an inline comment
    assert "navmesh" in notes["source"]  # the comment lines above the field


def _build(site: Path) -> subprocess.CompletedProcess:
    mkdocs = Path(sys.executable).parent / "mkdocs"
    if not mkdocs.exists() or importlib.util.find_spec("mkdocstrings") is None:
        pytest.skip("the docs tools are not installed (`make docs` installs the `docs` extra)")
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    return subprocess.run(
        [str(mkdocs), "build", "--strict", "--site-dir", str(site)],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    site = tmp_path_factory.mktemp("site")
    res = _build(site)
    assert res.returncode == 0, res.stderr[-5000:]
    return site


def test_the_site_builds_strict_and_loads_nothing_remote(site):
    bad = []
    for path in site.rglob("*"):
        if path.suffix not in (".html", ".css", ".js") or path.name.endswith(".map"):
            continue
        if path.parent.name == "javascripts" and path.name.startswith("bundle."):
            # the theme's bundle names two CDN fallbacks it loads only on demand: mermaid (for a mermaid
            # diagram, which the pages do not have: checked below) and a ResizeObserver polyfill (for
            # browsers without it); nothing else in it may point outside
            text = path.read_text(encoding="utf-8", errors="replace")
            others = [m.group(0) for m in REMOTE_ASSET.finditer(text) if not _theme_fallback(text, m)]
            bad += [f"{path.relative_to(site)}: {o}" for o in others]
            continue
        text = path.read_text(encoding="utf-8", errors="replace")
        for m in REMOTE_ASSET.finditer(text):
            bad.append(f"{path.relative_to(site)}: {text[max(0, m.start() - 60) : m.end() + 60]!r}")
    assert bad == [], "remote assets in the built site:\n" + "\n".join(bad[:20])


def test_the_site_has_every_report_and_its_figures(site):
    reports = sorted((ROOT / "experiments" / "results").glob("*/report.md"))
    assert reports
    for report in reports:
        name = report.parent.name
        page = site / "results" / name / "report.html"
        if not page.exists():
            page = site / "results" / name / "report" / "index.html"
        assert page.exists(), f"no page for experiments/results/{name}/report.md"
        for figure in re.findall(r"\]\((figures/[^)]+\.png)\)", report.read_text(encoding="utf-8")):
            assert (site / "results" / name / figure).exists(), f"{name}: {figure} is not in the site"
    assert (site / "benchmarks.html").exists() or (site / "benchmarks" / "index.html").exists()
