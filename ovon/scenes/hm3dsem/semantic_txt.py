"""HM3DSem `<id>.semantic.txt`: a first line `HM3D Semantic Annotations`, then one line per instance
`id,HEXCOLOR,"raw label",region_id`."""

from __future__ import annotations

import codecs
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

from ovon.scenes.hm3dsem.errors import SceneFileError, SceneLoadWarning, read_bytes

SEMANTIC_HEADER = "HM3D Semantic Annotations"
SEMANTIC_LINE_FORMAT = 'id,HEXCOLOR,"raw label",region_id'
_LINE_RE = re.compile(r'^\s*(\d+)\s*,\s*#?([0-9A-Fa-f]{6})\s*,\s*"(.*)"\s*,\s*(-?\d+)\s*$')
# Instance ids end up in int32 arrays (`Mesh.face_instance`, the semantic sensor), so an id (or a region
# id, kept next to them) beyond int32 cannot be represented: refused while parsing, where the file and
# line are known, instead of overflowing deep inside the mesh code.
INT32_MAX = 2**31 - 1
INT32_MIN = -(2**31)


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


def _decode(path: Path, data: bytes) -> str:
    """The file as text: UTF-8, with a leading byte order mark dropped (editors on Windows write one).

    Why a warning, not an error, for bytes that are not UTF-8: the file is still usable (every id and
    colour is ASCII); only the label holding them is affected, shown with U+FFFD where the bytes were.
    Such a label may no longer match the vocabulary, so the warning names the file and lines to re-save.
    """
    if data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        raise SceneFileError(
            path, "is UTF-16 text, not UTF-8", "fix: re-save it as UTF-8 (e.g. `iconv -f UTF-16 -t UTF-8`)"
        )
    if data.startswith(codecs.BOM_UTF8):
        data = data[len(codecs.BOM_UTF8) :]
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        pass
    lines: list[str] = []
    bad: list[int] = []
    for lineno, raw in enumerate(data.split(b"\n"), start=1):
        try:
            lines.append(raw.decode("utf-8"))
        except UnicodeDecodeError:
            lines.append(raw.decode("utf-8", errors="replace"))
            bad.append(lineno)
    more = f" and {len(bad) - 5} more" if len(bad) > 5 else ""
    warnings.warn(
        f"{path}: line(s) {', '.join(map(str, bad[:5]))}{more} hold bytes that are not UTF-8 (shown as U+FFFD in "
        "their labels, which may then miss the vocabulary); fix: re-save the file as UTF-8",
        SceneLoadWarning,
        stacklevel=2,  # one location: shown once however many callers parse the file
    )
    return "\n".join(lines)


def parse_semantic_txt(path: Path) -> list[SemanticEntry]:
    """Parse an HM3DSem semantic.txt; a malformed line is an error naming the file and line.

    Also errors, as each would give a silently wrong scene: an id or region id outside int32 (ids live in
    int32 arrays) and an id defined twice. A colour given to two instances is kept (habitat-sim reads such
    files): the loader gives its faces to the first (`shadowed_entries`) and says so.
    """
    data = read_bytes(path)
    if b"\x00" in data[:4096] and not data.startswith((codecs.BOM_UTF16_LE, codecs.BOM_UTF16_BE)):
        raise SceneFileError(
            path,
            "is binary, not an HM3DSem semantic.txt",
            f"expected a first line '{SEMANTIC_HEADER}', then {SEMANTIC_LINE_FORMAT} per instance",
        )
    text = _decode(path, data)
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
                f"{path}:{lineno}",
                f"malformed line {line[:80]!r}",
                f'expected {SEMANTIC_LINE_FORMAT} e.g. 1,9A9CAA,"wall",0',
            )
        iid, region = int(m.group(1)), int(m.group(4))
        if iid > INT32_MAX:
            raise SceneFileError(
                f"{path}:{lineno}",
                f"instance id {iid} is too large (ids must be 0..{INT32_MAX})",
                "fix: renumber the instances below 2**31 (the semantic mesh holds colours, not "
                "ids: it needs no change)",
            )
        if not INT32_MIN <= region <= INT32_MAX:
            raise SceneFileError(
                f"{path}:{lineno}",
                f"region id {region} is out of range ({INT32_MIN}..{INT32_MAX}; -1 means no region)",
                "fix: renumber the regions",
            )
        if iid in seen:
            raise SceneFileError(
                f"{path}:{lineno}",
                f"instance id {iid} already defined on line {seen[iid]}",
                "fix: give every instance its own id",
            )
        seen[iid] = lineno
        h = m.group(2)
        color = (int(h[0:2], 16), int(h[2:4], 16), int(h[4:6], 16))
        entries.append(SemanticEntry(iid, color, m.group(3), region))
    return entries


def shadowed_entries(entries: list[SemanticEntry]) -> tuple[dict[tuple[int, int, int], int], list[tuple]]:
    """(colour -> id, [(entry, id of the earlier entry with its colour)]): as habitat-sim's HM3D loader,
    the first line with a colour keeps it (its faces); a later line with the same colour gets no faces."""
    color_to_id: dict[tuple[int, int, int], int] = {}
    shadowed = []
    for e in entries:
        first = color_to_id.setdefault(e.color, e.id)
        if first != e.id:
            shadowed.append((e, first))
    return color_to_id, shadowed
