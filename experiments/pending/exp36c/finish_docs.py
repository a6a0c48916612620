"""Issue 36's finish, the docs part (idempotent; run after finish.sh): the site's nav lists the kept
oracle-perception reports, and the two pages that describe experiments/results/ say what the -oracle
folders and the released weights are."""

from pathlib import Path

TOP = Path(__file__).resolve().parents[3]
NAMES = ("main", "trajectories", "memory", "noise", "failures")


def edit(path: Path, old: str, new: str) -> None:
    text = path.read_text(encoding="utf-8")
    if new in text:
        return
    if old not in text:
        raise SystemExit(f"{path}: {old[:60]!r} not found; edit it by hand")
    path.write_text(text.replace(old, new, 1), encoding="utf-8")


def main() -> None:
    nav = "".join(f"      - {n} (oracle perception): results/{n}-oracle/report.md\n" for n in NAMES)
    edit(
        TOP / "mkdocs.yml",
        "      - pointnav: results/pointnav/report.md\n",
        nav + "      - pointnav: results/pointnav/report.md\n",
    )
    oracle = (
        "Each `results/<name>-oracle/` folder is the same experiment run earlier with oracle perception (every\n"
        "agent read the simulator's semantic frame), kept with its weights as the upper bound of the\n"
        "learned-perception run in `results/<name>/`; the headline's findings table shows both verdicts.\n\n"
    )
    edit(TOP / "experiments" / "README.md", "## Producing a result folder", oracle + "## Producing a result folder")
    edit(
        TOP / "experiments" / "README.md",
        "`dagrl.pt` and `results/pointnav/pointnav.pt`; under 5 MB each)",
        "`dagrl.pt`, `dagger-seed1.pt`, `dagrl-seed1.pt`; `results/memory/*-lstm.pt`, `results/trajectories/*-sp.pt`\n"
        "and `results/pointnav/pointnav.pt`; under 5 MB each)",
    )
    edit(
        TOP / "docs" / "results" / "index.md",
        "Every report:",
        "The same experiments with oracle perception, run before ovon had learned perception, are kept as\n"
        "`<name>-oracle` reports: the upper bound the learned rows are read against.\n\nEvery report:",
    )


if __name__ == "__main__":
    main()
