"""The README is the front page: at most 200 lines, and every command and code block in it runs.

Its blocks run where they are explained: each one appears verbatim in a page of docs/, whose blocks
tests/test_docs_blocks.py runs as written (tests/doc_blocks.py: the newcomer's environment, the shrunk
sizes). The Gymnasium example also runs here, fast.
"""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

from tests.doc_blocks import RUNNABLE, Ports, blocks, newcomer_env, shrink

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = ROOT / "docs"


def test_readme_is_a_front_page():
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= 200, "README.md is over 200 lines: move the detail into docs/"
    assert "2409.14296" in text
    assert not re.search(r"\b[0-9a-f]{7,40}\b(?<![0-9]{7})", re.sub(r"`[^`]*`|\([^)]*\)", "", text)), (
        "a commit hash in the README: results and measurements live in experiments/results and benchmarks/"
    )
    assert "load average" not in text


def test_readme_blocks_are_all_runnable_kinds():
    found = blocks(README.read_text(encoding="utf-8"))
    assert len(found) >= 4
    for b in found:
        assert b.lang in RUNNABLE, b.lang
        assert b.skip is None, "the README's blocks all run"
        assert "..." not in shrink(b.code, Ports()).replace('"..."', ""), f"placeholder in a README block:\n{b.code}"


def test_every_readme_block_runs_in_a_docs_page():
    """Each README block is one of a docs page's blocks (not a skipped one), so the docs test runs it."""
    page_blocks = {
        b.code for page in DOCS.rglob("*.md") for b in blocks(page.read_text(encoding="utf-8")) if not b.skip
    }
    missing = [b.code for b in blocks(README.read_text(encoding="utf-8")) if b.code not in page_blocks]
    assert missing == [], (
        "README blocks that no docs page runs (copy them into the page they belong to):\n" + "\n".join(missing)
    )


def test_readme_has_no_merge_leftovers():
    text = README.read_text(encoding="utf-8")
    assert not re.search(r"^(<<<<<<<|=======|>>>>>>>)( |$)", text, flags=re.M)


def test_readme_links_resolve():
    text = README.read_text(encoding="utf-8")
    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text):
        if not target.startswith("http"):
            assert (ROOT / target).exists(), f"README links to {target}, which does not exist"


def test_readme_python_env_example_runs(tmp_path):
    """The Gymnasium example (the Python block's paragraphs up to the evaluation) runs as written, fast."""
    code = next(b.code for b in blocks(README.read_text(encoding="utf-8")) if "gym.make" in b.code)
    paragraphs = code.split("\n\n")
    head = "\n\n".join(paragraphs[: next(i for i, p in enumerate(paragraphs) if "evaluate" in p)])
    assert "gym.make" in head
    script = tmp_path / "env_example.py"
    script.write_text(head)
    res = subprocess.run(
        ["python", str(script)], cwd=tmp_path, env=newcomer_env(tmp_path), capture_output=True, text=True, timeout=300
    )
    assert res.returncode == 0, res.stderr[-3000:]
