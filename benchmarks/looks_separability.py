"""What the world's looks add: the same world-vl recipe trained on houses dressed as before issue 37
(`looks=family`: siblings of a shape family differ only in colour and size) and as now (`looks=category`),
then measured on the calibration houses of the pretrain split (never trained on).

Per looks: average precision and recall at the calibrated threshold (precision >= 0.5) for goals covering 5%
of the frame, at name level (strict: the name's own instances) and at synonym-group level; and top-1 naming
accuracy (of the house's names, is the best-scoring one the largest visible object's name / group).

    python benchmarks/looks_separability.py                # about 15 minutes on 2 cores
    python benchmarks/looks_separability.py --quick        # a few minutes, for a smoke test
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from ovon.atomic import write_json
from ovon.models.world import load_world_vl
from ovon.perception.calibrate import average_precision, frame_labels, frame_scores, pr_at
from ovon.perception.config import PRESETS
from ovon.perception.frames import HouseFrames
from ovon.perception.pretrain import WEIGHTS, render_frames, text_table, train
from ovon.scenes.procedural.looks import look_key
from ovon.scenes.vocabulary import load_vocabulary


def naming_accuracy(net, houses: list[HouseFrames], text: torch.Tensor, groups: np.ndarray) -> tuple[float, float]:
    """Top-1 over the house's names of the global embedding, for frames whose largest object covers 5%."""
    right = right_group = total = 0
    for h in houses:
        cats = torch.as_tensor(h.house_cats, dtype=torch.long)
        with torch.inference_mode():
            _, _, glob = net.features(torch.from_numpy(h.rgb))
            best = cats[(glob @ text[cats].T).argmax(dim=1)].numpy()
        for f in range(len(h.rgb)):
            rows = h.inst[(h.inst[:, 0] == f) & (h.inst[:, 2] >= 0.05)]
            if len(rows) == 0:
                continue
            truth = int(rows[np.argmax(rows[:, 2]), 1])
            total += 1
            right += int(best[f] == truth)
            right_group += int(groups[best[f]] == groups[truth])
    return right / max(1, total), right_group / max(1, total)


def measure(out: Path, names: list[str], n_train: int) -> dict:
    model = load_world_vl(out / WEIGHTS)
    net = model.net
    text, _ = text_table(names)
    keys = [look_key(n) for n in names]
    groups = np.array([keys.index(k) for k in keys])
    paths = sorted((out / "frames").glob("*.npz"))
    houses = [HouseFrames.load(p) for p in paths[n_train:]]
    with torch.inference_mode():
        scores = np.concatenate([frame_scores(net, h, text)[model.pooling].ravel() for h in houses])
    row = {"pooling": model.pooling, "threshold": model.threshold}
    for level, g in (("name", None), ("group", groups)):
        labels = np.concatenate([frame_labels(h, 0.05, g).ravel() for h in houses])
        p, r = pr_at(scores, labels, model.threshold)
        row[level] = {"ap": average_precision(scores, labels), "precision": p, "recall": r,
                      "positives": int(labels.sum())}  # fmt: skip
    row["naming_top1"], row["naming_top1_group"] = naming_accuracy(net, houses, text, groups)
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="4 houses, 40 steps: a smoke test, the numbers mean little")
    ap.add_argument("--work", default=str(Path(tempfile.gettempdir()) / "ovon-looks-separability"))
    ap.add_argument("--out", default=str(Path(tempfile.gettempdir()) / "looks_separability.json"))
    ap.add_argument("--threads", type=int, default=2, help="torch threads for training")
    args = ap.parse_args()
    base = dataclasses.replace(
        PRESETS["cpu"],
        houses=16,
        calibration_houses=4,
        frames_per_house=240,
        steps=800,
        checkpoint_every=400,
        threads=args.threads,
    )
    if args.quick:
        base = dataclasses.replace(base, houses=4, calibration_houses=1, frames_per_house=60, steps=40)
    names = load_vocabulary().names
    results: dict = {"config": dataclasses.asdict(base) | {"net": base.net.to_json()}, "looks": {}}
    for looks in ("family", "category"):
        cfg = dataclasses.replace(base, looks=looks)
        out = Path(args.work) / looks
        t0 = time.perf_counter()
        render_frames(cfg, out, progress=False)  # cached: a re-run trains on the same frames
        if not (out / WEIGHTS).exists():
            train(cfg, out, resume=(out / "run_identity.json").exists(), progress=True)
        results["looks"][looks] = measure(out, names, cfg.houses) | {"seconds": time.perf_counter() - t0}
    fam, cat = results["looks"]["family"], results["looks"]["category"]
    print(
        f"{'looks':10} {'name AP':>8} {'name P/R':>12} {'group AP':>9} {'group P/R':>12} {'top-1':>6} {'top-1 grp':>9}"
    )
    for looks, r in results["looks"].items():
        n, g = r["name"], r["group"]
        print(
            f"{looks:10} {n['ap']:8.3f} {n['precision']:6.2f}/{n['recall']:4.2f} {g['ap']:9.3f} "
            f"{g['precision']:6.2f}/{g['recall']:4.2f} {r['naming_top1']:6.3f} {r['naming_top1_group']:9.3f}"
        )
    results["ratio_name_ap"] = cat["name"]["ap"] / max(fam["name"]["ap"], 1e-9)
    results["ratio_group_ap"] = cat["group"]["ap"] / max(fam["group"]["ap"], 1e-9)
    print(f"name-level AP x{results['ratio_name_ap']:.2f}, group-level AP x{results['ratio_group_ap']:.2f} with looks")
    write_json(args.out, results)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
