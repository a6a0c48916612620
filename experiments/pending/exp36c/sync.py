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
import shutil
import sys
from pathlib import Path

ROOT = Path("/work/runs/exp36c/cpu")
HERE = Path(__file__).resolve().parent / "cpu"
SKIP_TOP = {"data", "locks", "reports", ".file_hashes.json"}


def wanted(src: Path) -> list[Path]:
    out = []
    for p in sorted(src.rglob("*")):
        rel = p.relative_to(src)
        if not p.is_file() or rel.parts[0] in SKIP_TOP or ".old-" in str(rel) or p.name == ".lock":
            continue
        if rel.parts[0] == "train":
            run = src / rel.parts[0] / rel.parts[1]
            finished = (run / "policy.pt").is_file()
            if finished and p.name != "policy.pt" and p.suffix == ".pt":
                continue  # checkpoints of a finished training: its policy is what others read
            if not finished and p.suffix == ".pt" and p.name != "checkpoint.pt":
                continue  # older checkpoints of an interrupted one: the last is enough to resume
        out.append(rel)
    return out


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
