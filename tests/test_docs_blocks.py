"""Every code block in docs/ runs as written (the slow test), and each block is either runnable or marked
with the reason it does not run (fast). The machinery and its documented departures (shrunk sizes, free
ports, `make -n`) are in tests/doc_blocks.py.

The pages run in the site's order (mkdocs.yml's nav) in one folder, so a page may find what an earlier
one made; each page is also written to run alone from an empty folder (its first blocks make its data,
and making it again is cheap). `pytest -m slow tests/test_docs_blocks.py -k train` runs one page.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest
import yaml

from tests.doc_blocks import RUNNABLE, SKIP, Ports, blocks, prepare_folder, run_block, shrink

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


def _nav_pages(nav) -> list[str]:
    out = []
    for item in nav:
        value = next(iter(item.values())) if isinstance(item, dict) else item
        if isinstance(value, list):
            out += _nav_pages(value)
        elif isinstance(value, str):
            out.append(value)
    return out


def pages() -> list[str]:
    """The docs/ pages in nav order (generated pages, which have no source in docs/, left out), then any
    page not in the nav."""
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"))
    ordered = [p for p in _nav_pages(config["nav"]) if (DOCS / p).is_file()]
    rest = sorted(str(p.relative_to(DOCS)) for p in DOCS.rglob("*.md") if str(p.relative_to(DOCS)) not in ordered)
    return ordered + rest


def test_every_block_runs_or_says_why_not():
    seen = 0
    for page in pages():
        text = (DOCS / page).read_text(encoding="utf-8")
        for b in blocks(text):
            seen += 1
            where = f"docs/{page}, block {seen}:\n{b.code}"
            if b.skip is None and not b.saved_as:
                assert b.lang in RUNNABLE, f"{where}\na {b.lang!r} block runs only with <!-- docs-test: skip (why) -->"
            if b.skip is None:
                assert "..." not in shrink(b.code, Ports()).replace('"..."', ""), f"placeholder in {where}"
        # a marker must sit right before a block: one anywhere else is a typo that skips nothing
        markers = sum(bool(SKIP.match(line)) for line in text.splitlines())
        assert markers == sum(b.skip is not None for b in blocks(text)), (
            f"docs/{page}: a skip marker not before a block"
        )
    assert seen > 30


def test_the_marker_is_read():
    text = "Intro.\n\n<!-- docs-test: skip (needs HM3D) -->\n```bash\novon evaluate\n```\n\n```bash\nls\n```\n"
    found = blocks(text)
    assert [b.skip for b in found] == ["needs HM3D", None]


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    cwd = tmp_path_factory.mktemp("docs")
    return cwd, prepare_folder(cwd), Ports()


@pytest.mark.slow
@pytest.mark.parametrize("page", pages())
def test_every_docs_block_runs_as_written(page, folder):
    cwd, env, ports = folder
    saved: dict[Path, str] = {}
    t0 = time.perf_counter()
    for i, b in enumerate(blocks((DOCS / page).read_text(encoding="utf-8")), 1):
        if b.skip is None:
            run_block(b, f"docs/{page} block {i}", cwd, env, timeout=1800, ports=ports, saved_files=saved)
    print(f"docs/{page}: {time.perf_counter() - t0:.0f} s")
