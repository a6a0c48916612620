"""`ovon dataset verify`: an inventory of a dataset download and of what in it is wrong.

The released HM3D-OVON download has traps that cost users days: macOS `._*` AppleDouble files beside
the shards, top-level split files that hold no episodes (the episodes are in `content/`), and folders
named after one split holding files named after another (`val_seen_synonyms/val_unseen_easy.json.gz`).
This check names each of them in one table, with scenes referenced but missing and episodes whose goals
or viewpoints are invalid. Only what evaluation cannot use is an error (exit status 1): a split with no
usable episode, a shard that does not parse, a scene that is not there. Everything ovon reads around (junk
files, name aliases, empty top-level files, invalid episodes it skips with a counted warning) is a note.
"""

from __future__ import annotations

import warnings
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from ovon.dataset.io import SHARD_SUFFIX, SPLIT_ALIASES, EpisodeDataset, read_shard
from ovon.dataset.records import DatasetError, resolve_scene_path
from ovon.dataset.validate import check_shard, dataset_splits

JUNK_NAMES = (".DS_Store", "Thumbs.db", "__MACOSX")


@dataclass(frozen=True)
class Finding:
    split: str  # "" for the whole dataset
    severity: str  # "ok" | "note" | "error"
    what: str
    detail: str


@dataclass
class Verification:
    root: Path
    findings: list[Finding] = field(default_factory=list)
    episodes: Counter = field(default_factory=Counter)  # usable episodes per split

    def add(self, split: str, severity: str, what: str, detail: str) -> None:
        self.findings.append(Finding(split, severity, what, detail))

    @property
    def ok(self) -> bool:
        return not any(f.severity == "error" for f in self.findings)

    def table(self) -> str:
        lines = [f"dataset {self.root}", "", "| split | status | what | detail |", "|---|---|---|---|"]
        lines += [f"| {f.split or '-'} | {f.severity} | {f.what} | {f.detail} |" for f in self.findings]
        total = sum(self.episodes.values())
        lines += ["", f"{total} usable episodes: " + ", ".join(f"{s} {n}" for s, n in sorted(self.episodes.items()))]
        return "\n".join(lines) + "\n"


def _junk(root: Path) -> list[Path]:
    return sorted(p for p in root.rglob("*") if p.name.startswith("._") or p.name in JUNK_NAMES)


def shell_only(ds: EpisodeDataset) -> str | None:
    """The released download's trap, as one line: a split whose only file is the top-level
    `<split>/<split>.json.gz` (the categories; the episodes are in `<split>/content/*.json.gz`, absent or
    empty here). None when the split has shards, or no top-level file either."""
    folder = ds.split_dir
    top = folder / f"{folder.name}{SHARD_SUFFIX}"
    if ds.scenes() or not top.is_file():
        return None
    where = "is missing" if not ds.content_dir.is_dir() else f"holds no *{SHARD_SUFFIX} file"
    return (
        f"split {folder.name} is shell-only: {folder.name}/{top.name} holds the split's categories, not its "
        f"episodes, and {folder.name}/content/ {where}; expected the episodes in "
        f"{folder.name}/content/<scene>{SHARD_SUFFIX}; fix: extract the release's {folder.name}/content/ folder "
        f"into {folder}"
    )


def _split(rep: Verification, split: str, scenes: Path | None) -> None:
    ds = EpisodeDataset(rep.root, split)
    folder = ds.split_dir
    trap = shell_only(ds)
    if trap is not None:
        rep.add(split, "error", "shell-only split (no content/ episodes)", trap)
    if folder.name != split:
        rep.add(split, "note", "split folder name", f"read from {folder.name}/ (the same split's other name)")
    tops = sorted(p.name for p in folder.glob(f"*{SHARD_SUFFIX}") if not p.name.startswith("._"))
    other = [n for n in tops if n != f"{folder.name}{SHARD_SUFFIX}"]
    if other:
        alias = {f"{a}{SHARD_SUFFIX}" for a in (split, SPLIT_ALIASES.get(split, ""))}
        kind = "names the split's other name" if set(other) <= alias else "names another split"
        rep.add(split, "note", "file name disagrees with folder", f"{folder.name}/{', '.join(other)} {kind}")
    try:
        shell_eps = len(ds.shell_episodes().episodes)
    except DatasetError as e:
        rep.add(split, "error", "top-level file unreadable", str(e))
        return
    shards = ds.scenes()
    if tops and not shell_eps and shards:
        rep.add(split, "note", "top-level file holds no episodes", f"the episodes are in {folder.name}/content/")
    if shell_eps:
        rep.add(split, "note", "episodes in the top-level file (not read)", f"{shell_eps}: evaluation reads content/")
    usable, skipped, missing = 0, Counter(), set()
    for scene in shards:
        try:
            shard = read_shard(ds.shard_path(scene))
        except (DatasetError, OSError) as e:
            rep.add(split, "error", "shard unreadable", str(e))
            continue
        chk = check_shard(shard)
        skipped.update(probs[0][0] for probs in chk.episodes.values())
        for kind, where, detail in chk.goals:
            rep.add(split, "note", f"invalid goal ({kind})", f"content/{scene}{SHARD_SUFFIX}: {where}: {detail}")
        good = [ep for i, ep in enumerate(shard.episodes) if not chk.bad(i)]
        if scenes is not None:
            for sid in sorted({str(ep.scene_id) for ep in good}):
                try:
                    resolve_scene_path(sid, scenes)
                except (FileNotFoundError, DatasetError):
                    missing.add(sid)
            good = [ep for ep in good if str(ep.scene_id) not in missing]
        usable += len(good)
    if skipped:
        reasons = ", ".join(f"{n} {k}" for k, n in sorted(skipped.items()))
        rep.add(split, "note", "invalid episodes (skipped when evaluating)", reasons)
    if missing:
        rep.add(split, "error", "scenes missing", f"{len(missing)} under {scenes}, e.g. {sorted(missing)[0]}")
    if not usable:
        rep.add(split, "error", "no usable episodes", f"{folder} holds none ovon can run")
    else:
        rep.add(split, "ok", "episodes", f"{usable} usable in {len(shards)} shard(s)")
    rep.episodes[split] = usable


def verify_dataset(root: str | Path, scenes: str | Path | None = None) -> Verification:
    rep = Verification(Path(root))
    splits = dataset_splits(rep.root)  # a missing root is one line (FileNotFoundError)
    junk = _junk(rep.root)
    if junk:
        shown = ", ".join(str(p.relative_to(rep.root)) for p in junk[:3])
        rep.add(
            "",
            "note",
            "junk files (ignored)",
            f"{len(junk)}, e.g. {shown}; delete them with `find . -name '._*' -delete`",
        )
    if not splits:
        rep.add(
            "", "error", "no splits", f"{rep.root} holds no split folder (expected e.g. val_seen/content/*.json.gz)"
        )
    loose = sorted(p.name for p in rep.root.glob(f"*{SHARD_SUFFIX}") if not p.name.startswith("._"))
    if loose:
        rep.add("", "note", "files outside split folders (not read)", ", ".join(loose))
    with warnings.catch_warnings():  # the readers' warnings (junk files) are findings here
        warnings.simplefilter("ignore")
        for split in splits:
            _split(rep, split, Path(scenes) if scenes else None)
    return rep
