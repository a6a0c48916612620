"""Which code each cell of a report ran with, and which entries rest on cells from other code.

Why: a report is one claim only when its numbers come from one version of the code. Every attempt of a
cell records `ovon 0.1.0 (commit[+dirty])` (`code_version`); the reference is the commit most
finished cells ran with, and a cell is *marked* when any of its attempts ran with another one, from a
tree with uncommitted changes, or with unrecorded code. A table entry is marked when its evaluation or
any cell it needs (its training, that training's init, the data) is.
"""

from __future__ import annotations

import re
import subprocess
from collections import Counter
from pathlib import Path
from typing import Any

from ovon.experiments.cells import Plan
from ovon.experiments.records import read_record
from ovon.experiments.status import Status

MARK = "†"
_CODE = re.compile(r"^(?P<version>.*?)(?: \((?P<commit>[0-9a-f]{4,40})(?P<dirty>\+dirty)?\))?$")


def code_version() -> str:
    """The ovon code a cell ran with: its version and, in a git checkout, the commit (+dirty)."""
    import ovon

    text = f"ovon {getattr(ovon, '__version__', '?')}"
    where = str(Path(ovon.__file__).resolve().parent)
    try:
        rev = subprocess.run(
            ["git", "-C", where, "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=10
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", where, "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=10,
        ).stdout.strip()
        # a new, untracked module in the package runs too (git's ignore rules keep caches out)
        dirty = (
            dirty
            or subprocess.run(
                ["git", "-C", where, "status", "--porcelain", "--untracked-files=all", "--", "."],
                capture_output=True,
                text=True,
                timeout=10,
            ).stdout.strip()
        )
    except (OSError, subprocess.SubprocessError):
        return text
    return f"{text} ({rev}{'+dirty' if dirty else ''})" if rev else text


def parse_code(text: str) -> dict[str, Any]:
    """`ovon 0.1.0 (abc1234+dirty)` -> {"version": "ovon 0.1.0", "commit": "abc1234", "dirty": True}
    (commit None outside a git checkout; "" text: nothing recorded)."""
    m = _CODE.match(text or "")
    assert m is not None  # the pattern matches any text
    return {"version": m["version"], "commit": m["commit"], "dirty": bool(m["dirty"]), "text": text or ""}


def _key(code: dict) -> str:
    """What two attempts must share to be the same code: the version and commit, dirty or not."""
    return f"{code['version']} ({code['commit']})" if code["commit"] else code["version"]


def attempt_codes(record: dict) -> list[str]:
    """The distinct code texts the cell's attempts ran with, oldest first (older records: the last only)."""
    codes = [c for h in record.get("history", []) for c in (h.get("code"), h.get("code_end")) if c]
    codes += [c for c in (record.get("code"), record.get("code_end")) if c]
    return list(dict.fromkeys(codes))


def cell_provenance(plan: Plan, statuses: dict[str, Status], report_code: str) -> dict[str, Any]:
    """{"report": code, "reference": key, "one_clean_commit": bool, "cells": {id: {...}}} for the cells
    that ran (the user's own dataset has no record and no code)."""
    cells: dict[str, dict] = {}
    for cid, cell in plan.cells.items():
        rec = read_record(plan, cell) if cell.run is not None else None
        if not rec or rec.get("state") == "unreadable":
            continue
        codes = [parse_code(c) for c in attempt_codes(rec)]
        cells[cid] = {
            "status": statuses[cid].state,
            "code": [c["text"] for c in codes],
            "commits": list(dict.fromkeys(c["commit"] or "?" for c in codes)),
            "dirty": any(c["dirty"] for c in codes),
            "keys": list(dict.fromkeys(_key(c) for c in codes)),
            "config_recorded": "config" in rec,
        }
    done = [c for c in cells.values() if c["status"] == "done"]
    votes = Counter(k for c in done for k in c["keys"])
    ours = _key(parse_code(report_code))
    # the most common code among finished cells; on a tie, the report's own code if it is one of them
    reference = max(votes, key=lambda k: (votes[k], k == ours)) if votes else ours
    for c in cells.values():
        reasons = []
        if not c["keys"]:
            reasons.append("code not recorded")
        elif c["keys"] != [reference]:
            reasons.append(
                f"other commit ({', '.join(c['commits'])})"
                if len(c["keys"]) == 1
                else f"attempts ran with {len(c['keys'])} commits ({', '.join(c['commits'])})"
            )
        if c["dirty"]:
            reasons.append("dirty tree")
        c["marked"], c["why"] = bool(reasons), "; ".join(reasons)
        del c["keys"]
    one_clean = bool(done) and all(not c["marked"] for c in done) and parse_code(reference)["commit"] is not None
    return {"report": report_code, "reference": reference, "one_clean_commit": one_clean, "cells": cells}


def marked_chain(plan: Plan, prov: dict, cid: str) -> bool:
    """Whether the cell `cid` or any cell it (transitively) needs is marked."""
    seen, todo = set(), [cid]
    while todo:
        c = todo.pop()
        if c in seen or c not in plan.cells:
            continue
        seen.add(c)
        if prov["cells"].get(c, {}).get("marked"):
            return True
        todo.extend(plan.cells[c].deps)
    return False


def headline(prov: dict) -> str:
    """The report's first provenance line."""
    cells = prov["cells"]
    done = [c for c in cells.values() if c["status"] == "done"]
    built = f"report built from {prov['report'] or 'unrecorded code'}"
    if not done:
        return f"Provenance: no cell has finished yet; {built}."
    if prov["one_clean_commit"]:
        return f"Provenance: every finished cell ran with {prov['reference']} from a clean tree; {built}."
    marked = [cid for cid, c in cells.items() if c["marked"]]
    versions = {k for c in done for k in c["code"]}
    return (
        f"Provenance: the cells ran with {len(versions)} code version(s); {len(marked)} cell(s) ran with "
        f"another commit than {prov['reference']} (that of most cells) or from a dirty tree: entries resting on "
        f'them are marked {MARK} (table "Provenance"); {built}.'
    )


def provenance_markdown(prov: dict) -> list[str]:
    """The per-cell table: what each attempt ran with, clean or dirty, and why it is marked."""
    lines = ["| cell | status | ran with | tree | resolved config | marked |", "|---|---|---|---|---|---|"]
    for cid, c in prov["cells"].items():
        commits = ", ".join(c["commits"]) or "not recorded"
        tree = "dirty" if c["dirty"] else ("clean" if "?" not in c["commits"] and c["commits"] else "unknown")
        config = "recorded" if c["config_recorded"] else "not recorded (run folder compared)"
        mark = f"{MARK} {c['why']}" if c["marked"] else ""
        lines.append(f"| {cid} | {c['status']} | {commits} | {tree} | {config} | {mark} |")
    return lines
