"""The repository's docs stand alone: no file points outside the repository (a user's clone has no
folder of specs beside it), the spec files the code once cited are cited through `docs/spec.md`, and
every section of `docs/spec.md` a file cites (`docs/spec.md` + `#` + its anchor) exists."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUTSIDE = ("../" + "shared", "shared" + "/spec", "/work/" + "shared")  # spelled apart: this file is scanned too
SPEC_FILES = re.compile(r"\b(?:task|baselines|dataset|vlfm|world|expert|architecture|platform)\.md\b")
CITED_DIRS = ("ovon", "tests", "benchmarks", "docs", "experiments", "README.md")
SKIP_DIRS = {".git", ".venv", "__pycache__", ".pytest_cache", ".ruff_cache", "node_modules", "data", "runs"}


def _repo_files() -> list[Path]:
    """Tracked and new (not ignored) files; without git, a walk that skips virtualenvs and outputs."""
    try:
        out = subprocess.run(
            ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
            cwd=ROOT,
            capture_output=True,
            check=True,
            timeout=60,
        ).stdout
        return [ROOT / p for p in out.decode().split("\0") if p and (ROOT / p).is_file()]
    except (OSError, subprocess.SubprocessError):
        return [p for p in ROOT.rglob("*") if p.is_file() and not SKIP_DIRS & set(p.relative_to(ROOT).parts)]


def _text(path: Path) -> str | None:
    try:
        data = path.read_bytes()
    except OSError:
        return None
    if b"\0" in data[:4096]:
        return None  # binary (meshes, images, checkpoints)
    return data.decode("utf-8", errors="replace")


def test_no_file_points_outside_the_repository() -> None:
    bad = []
    for path in _repo_files():
        text = _text(path)
        if text is None:
            continue
        for i, line in enumerate(text.splitlines(), 1):
            if any(s in line for s in OUTSIDE):
                bad.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()[:120]}")
    assert bad == [], "cite docs/spec.md or the paper (arXiv 2409.14296) instead:\n" + "\n".join(bad)


def test_spec_files_are_cited_through_docs_spec() -> None:
    bad = []
    for path in _repo_files():
        rel = path.relative_to(ROOT)
        if rel.parts[0] not in CITED_DIRS or path == Path(__file__).resolve():
            continue
        text = _text(path)
        for i, line in enumerate((text or "").splitlines(), 1):
            if SPEC_FILES.search(line):
                bad.append(f"{rel}:{i}: {line.strip()[:120]}")
    assert bad == [], "\n".join(bad)


def _anchors(markdown: str) -> set[str]:
    """GitHub's heading slugs plus explicit `<a id="...">` anchors."""
    out = set(re.findall(r'<a id="([\w-]+)"></a>', markdown))
    for line in markdown.splitlines():
        m = re.match(r"#+\s+(.*)", line)
        if m:
            title = re.sub(r"<[^>]+>", "", m.group(1)).strip().lower()
            out.add(re.sub(r"\s", "-", re.sub(r"[^\w\s-]", "", title)))
    return out


def test_every_cited_section_exists() -> None:
    anchors = _anchors((ROOT / "docs" / "spec.md").read_text(encoding="utf-8"))
    cite = re.compile(r"docs/spec\.md\)?#[\w-]+(?:(?:, | and )#[\w-]+)*")
    bad, seen = [], 0
    for path in _repo_files():
        text = _text(path)
        for m in cite.finditer(text or ""):
            for slug in re.findall(r"#([\w-]+)", m.group(0)):
                seen += 1
                if slug not in anchors:
                    bad.append(f"{path.relative_to(ROOT)}: #{slug}")
    assert seen > 20 and bad == [], bad


def test_the_anchor_rule_matches_github() -> None:
    assert _anchors('## Frontier choice\n### <a id="dagrl-od"></a>DAgRL+OD\n## Task: the rules\n') == {
        "frontier-choice",
        "dagrl-od",
        "dagrlod",
        "task-the-rules",
    }
