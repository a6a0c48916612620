"""The site reads at 1280 px: the extra stylesheet is registered and linked from every page, long code
lines wrap (not cut off under the copy button), wide tables scroll sideways, figures fit the column; and
the command-line reference renders as tables whose rows keep their four cells."""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
CSS = ROOT / "docs" / "assets" / "extra.css"


def _rules(css: str) -> dict[str, str]:
    """selector -> declarations (comments dropped)."""
    css = re.sub(r"/\*.*?\*/", "", css, flags=re.S)
    return {m.group(1).strip(): m.group(2) for m in re.finditer(r"([^{}]+)\{([^}]*)\}", css)}


class _Loader(yaml.SafeLoader):
    pass


_Loader.add_multi_constructor("tag:yaml.org,2002:python/", lambda loader, suffix, node: None)


def test_the_stylesheet_is_registered_and_has_the_rules():
    config = yaml.load((ROOT / "mkdocs.yml").read_text(), Loader=_Loader)  # noqa: S506 - a safe loader
    assert "assets/extra.css" in config.get("extra_css", [])
    rules = _rules(CSS.read_text())
    code = rules[".md-typeset pre > code"]
    assert "white-space: pre-wrap" in code and "overflow-wrap: anywhere" in code
    assert "overflow-x: auto" in rules[".md-typeset table:not([class])"]
    assert "overflow-x: auto" in rules[".md-typeset__table"]
    assert "max-width: 100%" in rules[".md-typeset img"] and "height: auto" in rules[".md-typeset img"]


def test_the_stylesheet_loads_nothing_remote():
    css = CSS.read_text()
    assert "url(" not in css and "@import" not in css


@pytest.mark.slow
def test_built_pages_link_the_stylesheet_and_render_the_cli_tables(tmp_path):
    mkdocs = Path(sys.executable).parent / "mkdocs"
    if not mkdocs.exists() or importlib.util.find_spec("mkdocstrings") is None:
        pytest.skip("the docs tools are not installed (`make docs` installs the `docs` extra)")
    site = tmp_path / "site"
    res = subprocess.run(
        [str(mkdocs), "build", "--strict", "--site-dir", str(site)],
        cwd=ROOT,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert res.returncode == 0, res.stderr[-3000:]
    assert (site / "assets" / "extra.css").read_text() == CSS.read_text()
    for page in ("index.html", "reference/cli/index.html", "tutorials/hm3d/index.html"):
        html = (site / page).read_text(encoding="utf-8")
        assert re.search(r'<link[^>]+href="(\.\./)*assets/extra\.css"', html), page
    cli = (site / "reference" / "cli" / "index.html").read_text(encoding="utf-8")
    assert "continue from &lt;out&gt;/checkpoint.pt exactly" in cli
    for row in re.findall(r"<tr>(.*?)</tr>", cli, flags=re.S):
        assert len(re.findall(r"<t[dh][ >]", row)) == 4, row[:300]
