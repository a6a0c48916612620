"""Issue 36's run in progress, kept in the repository so that it survives a new machine (not part of ovon).

    python experiments/pending/exp36c/sync.py save     # run root -> experiments/pending/exp36c/cpu (then commit)
    python experiments/pending/exp36c/sync.py restore  # experiments/pending/exp36c/cpu -> run root

Saved: every cell's record and log, finished trainings' policy and curves, the interrupted training's last
checkpoint, evaluations' episodes and summaries. Not saved: the data (the chain regenerates it from its seed;
`episodes.sha256` checks it is byte-identical), locks, reports, caches and finished trainings' checkpoints.
The chain: `git worktree add --detach /work/runs/wt36c 683b65f`, then in it
`python -m ovon.cli.main experiment run NAME --scale cpu --root /work/runs/exp36c` for main, trajectories,
memory, noise, failures.
"""

import hashlib
import json
import shutil
import sys
from pathlib import Path

ROOT = Path("/work/runs/exp36c/cpu")
HERE = Path(__file__).resolve().parent / "cpu"
MAX_CHECKPOINT = 60 << 20  # bytes; DAgger's checkpoint holds its aggregated data (~150 MB)
SKIP_TOP = {"data", "locks", "reports", ".file_hashes.json"}


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
            if p.is_file() and rel not in keep and rel.name != "episodes.sha256":
                p.unlink()


def episodes_hashes(root: Path) -> str:
    eps = root / "data" / "episodes"
    files = sorted(eps.rglob("*.json.gz"))
    return "".join(f"{hashlib.sha256(p.read_bytes()).hexdigest()}  {p.relative_to(eps)}\n" for p in files)


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else ""
    if what == "save":
        copy(ROOT, HERE)
        (HERE / "episodes.sha256").write_text(episodes_hashes(ROOT))
    elif what == "restore":
        copy(HERE, ROOT)
        (ROOT / "episodes.sha256").unlink(missing_ok=True)
    elif what == "check":  # after the chain regenerated the data
        same = (HERE / "episodes.sha256").read_text() == episodes_hashes(ROOT)
        print("episodes identical" if same else "EPISODES DIFFER: the saved cells read other data")
        sys.exit(0 if same else 1)
    else:
        sys.exit("usage: sync.py save|restore|check")
