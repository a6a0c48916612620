"""`ovon perception pretrain`: the world-vl network on frames of the pretrain houses, read top to bottom.

1. Render (or reuse) labelled frames of `houses` + `calibration_houses` pretrain houses (frames.py).
2. Train with SigLIP's sigmoid loss against the frozen MiniLM embeddings of every vocabulary name: per
   cell (the cell's category and its synonyms are positives, every other name a negative; wall, floor and
   ceiling cells are negatives for all), per frame (names covering `global_min_share` of the frame are
   positives, names seen smaller are ignored), plus an objectness BCE per cell.
3. Calibrate on the calibration houses (never trained on): the frame score (the best of a few poolings of
   cell probabilities, by AP) and the detection threshold (best recall at precision >= `min_precision`).
4. Export `world_vl.safetensors` (weights + the calibration and config in its metadata).

The run folder is like `ovon train`'s: identity and lock, `checkpoint.pt` every `checkpoint_every` steps
(`--resume` continues exactly), `metrics.jsonl`, TensorBoard under `tb/`, `loss.png`.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from ovon.atomic import atomic_write_text, atomic_write_with
from ovon.config.base import to_dict
from ovon.parallel import progress_bar, run_jobs
from ovon.perception.calibrate import calibrate, frame_scores
from ovon.perception.config import PretrainConfig, lr_at
from ovon.perception.frames import HouseFrames
from ovon.runfolder import RunFolder

KIND = "perception-pretrain"
MAY_CHANGE = ("threads", "workers", "checkpoint_every")
WEIGHTS = "world_vl.safetensors"


def _render_job(job: tuple[int, int, int, str, str]) -> str:
    """Render one pretrain house's frames into its cache file (skipped when already there)."""
    from ovon.perception.frames import render_house
    from ovon.scenes.procedural import generate_house
    from ovon.scenes.procedural.config import HouseConfig
    from ovon.scenes.vocabulary import load_vocabulary

    house, n, seed, looks, path = job
    torch.set_num_threads(1)
    if not Path(path).exists():
        scene = generate_house(house, cfg=HouseConfig(looks=looks))
        render_house(scene, n, seed, load_vocabulary().names).save(Path(path))
    return path


def render_frames(cfg: PretrainConfig, out: Path, progress: bool = True) -> list[Path]:
    from ovon.scenes.procedural.seeds import house_seed

    (out / "frames").mkdir(parents=True, exist_ok=True)
    houses = [house_seed(0, "pretrain", i) for i in range(cfg.houses + cfg.calibration_houses)]
    tag = "" if cfg.looks == "category" else f"-{cfg.looks}"
    paths = [out / "frames" / f"{h}-{cfg.render_seed}-{cfg.frames_per_house}{tag}.npz" for h in houses]
    jobs = [
        (h, cfg.frames_per_house, cfg.render_seed, cfg.looks, str(p)) for h, p in zip(houses, paths) if not p.exists()
    ]
    with progress_bar("rendering pretrain frames", len(jobs), progress and bool(jobs)) as bar:
        for _ in run_jobs(_render_job, jobs, workers=cfg.workers):
            bar.advance()
    return paths


def text_table(names: list[str]) -> tuple[torch.Tensor, torch.Tensor]:
    """Unit MiniLM embeddings of the names (K, 384) and the synonym matrix (K, K) of their looks."""
    from ovon.models.encoders.text import MiniLMText
    from ovon.scenes.procedural.looks import look_key

    emb = F.normalize(MiniLMText().encode(names).float(), dim=-1)
    keys = [look_key(n) for n in names]
    syn = torch.tensor([[a == b for b in keys] for a in keys], dtype=torch.bool)
    return emb, syn


def _global_targets(frames: HouseFrames, n_names: int, min_share: float, syn: torch.Tensor):
    """(N, K) targets and mask: names covering >= min_share are positives (with their synonyms), names seen
    smaller are ignored, all others are negatives."""
    n = len(frames.rgb)
    pos = torch.zeros(n, n_names, dtype=torch.bool)
    seen = torch.zeros(n, n_names, dtype=torch.bool)
    for f, c, share in frames.inst[:, :3]:
        seen[int(f), int(c)] = True
        if share >= min_share:
            pos[int(f), int(c)] = True
    pos = (pos.float() @ syn.float()) > 0
    seen = (seen.float() @ syn.float()) > 0
    return pos, ~(seen & ~pos)


def train(cfg: PretrainConfig, out: str | Path, resume: bool = False, progress: bool = True) -> Path:
    from ovon.models.world.net import WorldVLNet
    from ovon.scenes.vocabulary import load_vocabulary

    out = Path(out)
    torch.set_num_threads(cfg.threads)
    folder = RunFolder.open(out, KIND, to_dict(cfg), {}, resume=resume, may_change=MAY_CHANGE)
    try:
        atomic_write_text(out / "config.json", json.dumps(to_dict(cfg), indent=1))
        paths = render_frames(cfg, out, progress)
        names = load_vocabulary().names
        text, syn = text_table(names)
        train_houses = [HouseFrames.load(p) for p in paths[: cfg.houses]]
        rgb = torch.from_numpy(np.concatenate([h.rgb for h in train_houses]))
        cells = torch.from_numpy(np.concatenate([h.cells for h in train_houses]).astype(np.int64))
        gpos, gmask = zip(*(_global_targets(h, len(names), cfg.global_min_share, syn) for h in train_houses))
        gpos, gmask = torch.cat(gpos), torch.cat(gmask)
        del train_houses

        torch.manual_seed(cfg.seed)
        net = WorldVLNet(cfg.net)
        opt = torch.optim.AdamW(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
        gen = torch.Generator().manual_seed(cfg.seed)
        step = 0
        ckpt = out / "checkpoint.pt"
        if resume and ckpt.exists():
            state = torch.load(ckpt, weights_only=False)
            net.load_state_dict(state["net"])
            opt.load_state_dict(state["opt"])
            gen.set_state(state["gen"])
            step = int(state["step"])
        from torch.utils.tensorboard import SummaryWriter

        tb = SummaryWriter(str(out / "tb"), purge_step=step)
        metrics = open(out / "metrics.jsonl", "a")
        net.train()
        t0 = time.time()
        with progress_bar("pretraining world-vl", cfg.steps - step, progress) as bar:
            while step < cfg.steps:
                for g in opt.param_groups:
                    g["lr"] = lr_at(cfg, step)
                idx = torch.randint(len(rgb), (cfg.batch,), generator=gen)
                x, lab = rgb[idx], cells[idx]
                if bool(torch.rand(1, generator=gen) < 0.5):  # horizontal flip (labels follow)
                    x, lab = x.flip(2), lab.flip(2)
                gain = 0.8 + 0.4 * torch.rand(cfg.batch, 1, 1, 1, generator=gen)
                x = (x.float() * gain).clamp(0, 255).to(torch.uint8)
                emb, obj, glob = net(x)
                # cells in the loss: object cells weighted 3x when drawing
                w = torch.where(lab >= 0, 3.0, 1.0).flatten(1)
                pick = torch.multinomial(w, min(cfg.cells_per_frame, w.shape[1]), replacement=False, generator=gen)
                e = emb.flatten(1, 2).gather(1, pick[..., None].expand(-1, -1, emb.shape[-1]))
                c = lab.flatten(1).gather(1, pick)
                target = torch.zeros(*c.shape, len(names))
                has = c >= 0
                target[has] = syn[c[has]].float()
                logits = net.logits(e, text)
                cell_loss = F.binary_cross_entropy_with_logits(logits, target, reduction="sum") / c.numel()
                obj_loss = F.binary_cross_entropy_with_logits(obj, (lab >= 0).float())
                gl = net.logits(glob, text)
                glob_loss = (
                    F.binary_cross_entropy_with_logits(
                        gl, gpos[idx].float(), weight=gmask[idx].float(), reduction="sum"
                    )
                    / cfg.batch
                )
                loss = cell_loss + cfg.obj_weight * obj_loss + cfg.global_weight * glob_loss
                opt.zero_grad(set_to_none=True)
                loss.backward()
                torch.nn.utils.clip_grad_norm_(net.parameters(), 5.0)
                opt.step()
                step += 1
                bar.advance()
                if step % 25 == 0 or step == cfg.steps:
                    row = {
                        "step": step, "loss": loss.item(), "cell": cell_loss.item(), "obj": obj_loss.item(),
                        "global": glob_loss.item(), "lr": lr_at(cfg, step - 1), "frames_per_s": 0.0,
                        "scale": net.logit_scale.exp().item(), "bias": net.logit_bias.item(),
                    }  # fmt: skip
                    row["frames_per_s"] = 25 * cfg.batch / max(time.time() - t0, 1e-9)
                    t0 = time.time()
                    metrics.write(json.dumps(row) + "\n")
                    metrics.flush()
                    for k, v in row.items():
                        if k != "step":
                            tb.add_scalar(f"pretrain/{k}", v, step)
                if step % cfg.checkpoint_every == 0 or step == cfg.steps:
                    state = {"net": net.state_dict(), "opt": opt.state_dict(), "gen": gen.get_state(), "step": step}
                    atomic_write_with(ckpt, lambda fh, s=state: torch.save(s, fh))
        tb.close()
        metrics.close()
        net.eval()
        calib_houses = [HouseFrames.load(p) for p in paths[cfg.houses :]]
        with torch.inference_mode():
            scores = [frame_scores(net, h, text) for h in calib_houses]
        cal = calibrate(calib_houses, scores, cfg.visible_share, cfg.min_precision)
        export(net, out / WEIGHTS, {"calibration": cal, "net": cfg.net.to_json(), "steps": step, "names": len(names)})
        atomic_write_text(out / "calibration.json", json.dumps(cal, indent=1))
        plot_losses(out)
        return out / WEIGHTS
    finally:
        folder.close()


def export(net, path: Path, meta: dict) -> None:
    """Weights as safetensors; `meta` (JSON) in the file's metadata, so one file is the whole model."""
    from safetensors.torch import save

    tensors = {k: v.detach().contiguous() for k, v in net.state_dict().items()}
    data = save(tensors, metadata={"ovon": json.dumps(meta)})
    atomic_write_with(path, lambda fh: fh.write(data))


def plot_losses(out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines() if line.strip()]
    if not rows:
        return
    fig, ax = plt.subplots(figsize=(6, 3.5))
    for k in ("loss", "cell", "obj", "global"):
        ax.plot([r["step"] for r in rows], [r[k] for r in rows], label=k)
    ax.set(xlabel="step", ylabel="loss", yscale="log", title="world-vl pretraining")
    ax.legend()
    fig.tight_layout()
    atomic_write_with(out / "loss.png", lambda fh: fig.savefig(fh, format="png", dpi=100))
    plt.close(fig)
