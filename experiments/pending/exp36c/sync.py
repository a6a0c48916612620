"""Issue 36's run in progress, kept in the repository so that it survives a new machine (not part of ovon).

    python experiments/pending/exp36c/sync.py save     # run root -> experiments/pending/exp36c/cpu (then commit)
    python experiments/pending/exp36c/sync.py restore  # experiments/pending/exp36c/cpu -> run root

Saved: every cell's record and log, the episodes (with their goal cache, which records timings and so is
not byte-identical when regenerated: the cells' input fingerprints cover it), finished trainings' policy and
curves, an interrupted training's last checkpoint when it is small enough, evaluations' episodes and
summaries. Not saved: cells still running (stop the chain with stop.sh first), the scenes (restore
regenerates them byte-identical from their seed), locks, reports and finished trainings' checkpoints.
Restore on a new machine: `make install`, `git worktree add --detach /work/runs/wt36c 683b65f`,
`sync.py restore`, then `chain.sh` (two runners on the root; `stop.sh` stops them and saves).
"""

import json
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path("/work/runs/exp36c/cpu")
WORKTREE = Path("/work/runs/wt36c")  # the pinned commit, 683b65f
HERE = Path(__file__).resolve().parent / "cpu"
MAX_CHECKPOINT = 60 << 20  # bytes; DAgger's checkpoint holds its aggregated data (~150 MB)
SKIP_TOP = {"locks", "reports", ".file_hashes.json"}


def state(src: Path, kind: str, name: str) -> str:
    try:
        return json.loads((src / "cells" / f"{kind}-{name}.json").read_text())["state"]
    except (OSError, ValueError, KeyError):
        return "none"


def resumable(run: Path) -> bool:
    ckpt = run / "checkpoint.pt"
    return ckpt.is_file() and ckpt.stat().st_size <= MAX_CHECKPOINT


def keep(src: Path, rel: Path) -> bool:
    """A cell still running is left out (record and folder: it restarts); stop the chain with SIGINT first."""
    p = src / rel
    if rel.parts[0] in SKIP_TOP or ".old-" in str(rel) or p.name == ".lock":
        return False
    if rel.parts[0] == "data":  # the episodes as they are (their goal cache records timings); scenes regenerate
        return len(rel.parts) > 2 and rel.parts[1] == "episodes"
    if rel.parts[0] == "cells":
        kind, name = rel.stem.split("-", 1)
        return state(src, kind, name) != "running"
    if rel.parts[0] not in ("train", "eval") or len(rel.parts) < 3:
        return True
    st = state(src, rel.parts[0], rel.parts[1])
    if st == "running":
        return False
    if rel.parts[0] == "eval":
        return True
    if st == "done":
        return p.suffix != ".pt" or p.name == "policy.pt"  # others read its policy, not its checkpoints
    if not resumable(src / "train" / rel.parts[1]):
        return False  # it restarts from scratch (DAgger's checkpoint, with its data, is too large to keep)
    return p.suffix != ".pt" or p.name == "checkpoint.pt"  # it resumes from its last checkpoint


def wanted(src: Path) -> list[Path]:
    return [p.relative_to(src) for p in sorted(src.rglob("*")) if p.is_file() and keep(src, p.relative_to(src))]


def copy(src: Path, dst: Path) -> None:
    keep = set(wanted(src))
    for rel in keep:
        s, d = src / rel, dst / rel
        if d.is_file() and d.stat().st_size == s.stat().st_size and d.read_bytes() == s.read_bytes():
            continue
        d.parent.mkdir(parents=True, exist_ok=True)
        tmp = d.with_name(d.name + ".tmp")
        shutil.copy2(s, tmp)
        tmp.replace(d)
    if dst == HERE:
        for p in sorted(dst.rglob("*"), reverse=True):
            rel = p.relative_to(dst)
            if p.is_file() and rel not in keep:
                p.unlink()


def scenes() -> None:
    """The scenes regenerate byte-identical from their seed (checked); the episodes' goal cache does not,
    so the episodes are kept as files and only the data cell's `scenes generate` commands run again."""
    cmds = json.loads((ROOT / "cells" / "data-data.json").read_text())["commands"]
    for cmd in cmds:
        if cmd.startswith("ovon scenes generate"):
            argv = cmd.replace("$ROOT", str(ROOT.parent)).split()[1:]
            subprocess.run([sys.executable, "-m", "ovon.cli.main", *argv], check=True, cwd=WORKTREE)


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else ""
    if what == "save":
        copy(ROOT, HERE)
    elif what == "restore":
        copy(HERE, ROOT)
        scenes()
    else:
        sys.exit("usage: sync.py save|restore")
