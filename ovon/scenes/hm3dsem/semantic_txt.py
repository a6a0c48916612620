"""HM3DSem `<id>.semantic.txt`: a first line `HM3D Semantic Annotations`, then one line per instance
`id,HEXCOLOR,"raw label",region_id`."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from ovon.scenes.hm3dsem.errors import SceneFileError, read_bytes

SEMANTIC_HEADER = "HM3D Semantic Annotations"
SEMANTIC_LINE_FORMAT = 'id,HEXCOLOR,"raw label",region_id'
_LINE_RE = re.compile(r'^\s*(\d+)\s*,\s*#?([0-9A-Fa-f]{6})\s*,\s*"(.*)"\s*,\s*(-?\d+)\s*$')


@dataclass
class SemanticEntry:
    id: int
    color: tuple[int, int, int]
    raw_label: str
    region_id: int


def _hex(c: tuple[int, int, int]) -> str:
    return "".join(f"{int(v):02X}" for v in c)


def format_semantic_txt(entries: list[SemanticEntry]) -> str:
    lines = [SEMANTIC_HEADER]
    for e in entries:
        label = e.raw_label.replace('"', "'").replace("\n", " ")
        lines.append(f'{e.id},{_hex(e.color)},"{label}",{e.region_id}')
    return "\n".join(lines) + "\n"


def parse_semantic_txt(path: Path) -> list[SemanticEntry]:
    """Parse an HM3DSem semantic.txt; a malformed line is an error naming the file and line."""
    data = read_bytes(path)
    if b"\x00" in data[:4096]:
        raise SceneFileError(path, "is binary, not an HM3DSem semantic.txt",
                             f"expected a first line '{SEMANTIC_HEADER}', then {SEMANTIC_LINE_FORMAT} per instance")
    text = data.decode("utf-8", errors="replace")
    entries: list[SemanticEntry] = []
    seen: dict[int, int] = {}
    for lineno, line in enumerate(text.splitlines(), start=1):
        if not line.strip():
            continue
        if lineno == 1 and line.strip().startswith("HM3D"):
            continue
        m = _LINE_RE.match(line)
        if m is None:
            raise SceneFileError(
                f"{path}:{lineno}", f"malformed line {line[:80]!r}",
                f'expected {SEMANTIC_LINE_FORMAT} e.g. 1,9A9CAA,"wall",0',
            )
        iid = int(m.group(1))
        if iid in seen:
            raise SceneFileError(f"{path}:{lineno}", f"instance id {iid} already defined on line {seen[iid]}")
        seen[iid] = lineno
        h = m.group(2)
        color = (int(h[0:2], 16), int(h[2:4], 16), int(h[4:6], 16))
        entries.append(SemanticEntry(iid, color, m.group(3), int(m.group(4))))
    return entries
