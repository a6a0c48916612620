"""Training logs: TensorBoard scalars, a `metrics.jsonl` training curve and a rich progress bar.

Why three: TensorBoard for looking, JSONL for scripts/reports (one line per logged update), the bar for
the person at the terminal. Only rank 0 logs; other ranks get a no-op logger. On `--resume`, lines
past the resumed update are dropped and TensorBoard purges events past it, so curves never fork; a line
that is not a JSON object (the torn last line a kill -9 leaves) is dropped with a warning, as the torn
lines of an evaluation's `episodes.jsonl` are.
"""

from __future__ import annotations

import json
import time
import warnings
from pathlib import Path
from typing import Any


class RunLogger:
    def __init__(
        self,
        out_dir: str | Path,
        total_updates: int,
        description: str,
        enabled: bool = True,
        progress: bool = True,
        start_update: int = 0,
        start_step: int = 0,
    ) -> None:
        self.enabled = enabled
        self.out_dir = Path(out_dir)
        self.writer = None
        self._bar = None
        self.t0 = time.perf_counter()
        if not enabled:
            return
        from torch.utils.tensorboard import SummaryWriter

        self.out_dir.mkdir(parents=True, exist_ok=True)
        self.jsonl = self.out_dir / "metrics.jsonl"
        if self.jsonl.exists():  # resume: drop the part of the curve that will be redone
            from ovon.atomic import atomic_write_text

            rows, torn = _parse(self.jsonl, warn=False)
            if torn:
                warnings.warn(
                    f"{self.jsonl}: dropped {len(torn)} line(s) that are not complete metrics rows "
                    f"(line {', '.join(map(str, torn[:5]))}: a write cut short by a kill); resuming at "
                    f"update {start_update}",
                    stacklevel=2,
                )
            keep = [ln for ln, r in rows if r.get("update", 0) <= start_update]
            atomic_write_text(self.jsonl, "".join(ln + "\n" for ln in keep))
        self.writer = SummaryWriter(str(self.out_dir / "tb"), purge_step=start_step if start_step else None)
        if progress:
            from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

            self._bar = Progress(
                "[bold]{task.description}",
                BarColumn(),
                MofNCompleteColumn(),
                TimeRemainingColumn(),
                TextColumn("{task.fields[info]}"),
            )
            self._bar.start()
            self._task = self._bar.add_task(description, total=total_updates, completed=start_update, info="")

    def log(self, update: int, step: int, metrics: dict[str, Any]) -> None:
        """One point of the curve: scalars under their names (e.g. `loss/policy`, `episode/success`)."""
        if not self.enabled:
            return
        row = {"update": update, "step": step, "time": round(time.perf_counter() - self.t0, 3)}
        for k, v in metrics.items():
            if v is None:
                continue
            row[k] = float(v)
            self.writer.add_scalar(k, float(v), step)
        with self.jsonl.open("a") as f:
            f.write(json.dumps(row) + "\n")
        if self._bar is not None:
            shown = {k: metrics[k] for k in ("loss", "episode/success", "steps_per_s") if metrics.get(k) is not None}
            info = " ".join(f"{k.split('/')[-1]}={v:.3g}" for k, v in shown.items())
            self._bar.update(self._task, completed=update, info=info)

    def text(self, tag: str, value: str) -> None:
        if self.enabled:
            self.writer.add_text(tag, value)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.stop()
            self._bar = None
        if self.writer is not None:
            self.writer.flush()
            self.writer.close()
            self.writer = None


def _parse(path: Path, warn: bool = True) -> tuple[list[tuple[str, dict[str, Any]]], list[int]]:
    """The (line, row) pairs of a metrics.jsonl and the numbers of the lines that are not JSON objects."""
    rows, torn = [], []
    for i, ln in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
        if not ln.strip():
            continue
        try:
            row = json.loads(ln)
        except (ValueError, RecursionError):
            row = None
        if isinstance(row, dict) and isinstance(row.get("update"), int):
            rows.append((ln, row))
        else:
            torn.append(i)
    if torn and warn:
        warnings.warn(
            f"{path}: skipped {len(torn)} line(s) that are not complete metrics rows (line "
            f"{', '.join(map(str, torn[:5]))})",
            stacklevel=3,
        )
    return rows, torn


def read_metrics(out_dir: str | Path) -> list[dict[str, Any]]:
    """The training curve written by `RunLogger` (a torn line skipped with a warning)."""
    path = Path(out_dir) / "metrics.jsonl"
    return [row for _, row in _parse(path)[0]] if path.exists() else []
