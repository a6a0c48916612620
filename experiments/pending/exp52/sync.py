"""Issue 52's re-run in progress, kept in the repository so that it survives a new machine (not part of ovon).

    python experiments/pending/exp52/sync.py save     # run root -> experiments/pending/exp52/cpu (then commit)
    python experiments/pending/exp52/sync.py restore  # experiments/pending/exp52/cpu -> run root

Saved: every cell's record and log, the episodes (their goal cache records timings, so a regeneration is not
byte-identical and every cell would read as changed), finished trainings' policy and curves, an interrupted
training's last checkpoint when it is small enough, evaluations' episodes and summaries, and the scenes'
sha256 list. Not saved: cells still running (stop the chain with stop.sh first), the scenes (restore
regenerates them from their seed and checks them against the list), locks, reports and finished trainings'
checkpoints. On a new machine: `bash experiments/pending/exp52/resume.sh` (install, worktree at PINNED,
restore, chain); `stop.sh` stops the runners and saves; `finish.sh` writes the reports once the chain is done.
"""

import hashlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

RUNS = Path("/work/runs")
ROOT = RUNS / "exp52" / "cpu"
WORKTREE = RUNS / "wt52"  # the pinned commit (PINNED)
HERE = Path(__file__).resolve().parent / "cpu"
SCENES_SHA = Path(__file__).resolve().parent / "scenes.sha256"
MAX_CHECKPOINT = 60 << 20  # bytes; DAgger's checkpoint holds its aggregated data (~150 MB): it restarts
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
    """A cell still running is left out (record and folder: it restarts); stop the chain with stop.sh first."""
    p = src / rel
    if rel.parts[0] in SKIP_TOP or ".old-" in str(rel) or p.name == ".lock" or p.suffix == ".tmp":
        return False
    if rel.parts[0] == "data":  # the episodes as they are; the scenes regenerate
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
        return False
    return p.suffix != ".pt" or p.name == "checkpoint.pt"  # it resumes from its last checkpoint


def wanted(src: Path) -> list[Path]:
    return [p.relative_to(src) for p in sorted(src.rglob("*")) if p.is_file() and keep(src, p.relative_to(src))]


def copy(src: Path, dst: Path) -> None:
    kept = set(wanted(src))
    for rel in kept:
        s, d = src / rel, dst / rel
        if d.is_file() and d.stat().st_size == s.stat().st_size and d.read_bytes() == s.read_bytes():
            continue
        d.parent.mkdir(parents=True, exist_ok=True)
        tmp = d.with_name(d.name + ".tmp")
        shutil.copy2(s, tmp)
        tmp.replace(d)
    if dst == HERE:
        for p in sorted(dst.rglob("*"), reverse=True):
            if p.is_file() and p.relative_to(dst) not in kept:
                p.unlink()


def scene_hashes() -> str:
    scenes = ROOT / "data" / "scenes"
    files = sorted(p for p in scenes.rglob("*") if p.is_file())
    return "".join(f"{hashlib.sha256(p.read_bytes()).hexdigest()}  {p.relative_to(scenes)}\n" for p in files)


def scenes() -> None:
    """Regenerate the scenes with the data cell's own commands, then check them byte for byte."""
    cmds = json.loads((ROOT / "cells" / "data-data.json").read_text())["commands"]
    for cmd in cmds:
        if cmd.startswith("ovon scenes generate"):
            argv = cmd.replace("$ROOT", str(ROOT.parent)).split()[1:]
            subprocess.run([sys.executable, "-m", "ovon.cli.main", *argv], check=True, cwd=WORKTREE)
    if SCENES_SHA.is_file() and scene_hashes() != SCENES_SHA.read_text():
        sys.exit(f"{ROOT / 'data' / 'scenes'}: regenerated scenes differ from {SCENES_SHA}; do not resume on them")


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else ""
    if what == "save":
        copy(ROOT, HERE)
        if (ROOT / "data" / "scenes").is_dir():
            SCENES_SHA.write_text(scene_hashes())
    elif what == "restore":
        copy(HERE, ROOT)
        scenes()
    else:
        sys.exit("usage: sync.py save|restore")
