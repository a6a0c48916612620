"""Goal / category text embeddings of a run: computed once, cached in the run folder, shipped to the
env workers (as a table) and into `policy.pt`, so acting never embeds text again."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ovon.models.config import EncoderConfig
from ovon.task.episode import EpisodeSpec


def needed_texts(specs: Iterable[EpisodeSpec]) -> list[str]:
    """Goal texts of the episodes + every vocabulary category (what oracle perception may show)."""
    from ovon.scenes.vocabulary import load_vocabulary

    out = dict.fromkeys(load_vocabulary().names)
    for s in specs:
        for c in s.goal_categories:
            out.setdefault(c)
    return list(out)


def _key(cfg: EncoderConfig) -> dict:
    return {"text": cfg.text, "siglip_model": cfg.siglip_model, "siglip_normalize": cfg.siglip_normalize}


def text_table(cfg: EncoderConfig, texts: Sequence[str], cache_path: str | Path, write: bool = True) -> dict:
    """{text: float32 embedding} for `texts`, read from / added to the `.pt` cache at `cache_path`.

    The cache key is the text encoder's config: a cache written by another encoder is ignored."""
    from ovon.train.checkpoint import atomic_torch_save

    key = _key(cfg)
    path = Path(cache_path)
    table: dict[str, torch.Tensor] = {}
    if path.is_file():
        data = _read_cache(path, warn=write)
        if data is None and not write:
            raise ValueError(f"text cache {path} is unreadable; fix: delete it (rank 0 rebuilds it)")
        if data is not None and (data.get("key") == key or data.get("key") is None):
            table = dict(data["table"])
    missing = [t for t in dict.fromkeys(texts) if t not in table]
    if missing:
        from ovon.models.encoders import make_text_encoder

        emb = make_text_encoder(cfg).encode(missing)
        table.update({t: e.clone() for t, e in zip(missing, emb)})
        if write:
            atomic_torch_save({"key": key, "table": table}, path)
    return table


def _read_cache(path: Path, warn: bool = True) -> dict | None:
    """The cache's dict, or None (with a warning) when it is torn or not a text cache: it only holds
    embeddings that the text encoder recomputes, so it is rebuilt instead of stopping the run."""
    import warnings

    from ovon.models.policy import load_weights_file

    try:
        data = load_weights_file(path)  # quiet: torch's own pickle-protocol warning would precede ours
    except Exception as e:  # noqa: BLE001 - torch raises many types for a torn file
        data, why = None, type(e).__name__
    else:
        ok = isinstance(data, dict) and isinstance(data.get("table"), dict)
        why = "" if ok else f"holds a {type(data).__name__} without a table"
        data = data if ok else None
    if data is None and warn:
        warnings.warn(f"text cache {path} is unreadable ({why}); its embeddings are recomputed", stacklevel=3)
    return data


def write_text_table(path: str | Path, table: dict[str, Any], cfg: EncoderConfig | None = None) -> Path:
    """Write a table in `text_table`'s format (e.g. a hand-made one for tests); key None matches any."""
    from ovon.train.checkpoint import atomic_torch_save

    tab = {k: torch.as_tensor(np.asarray(v, dtype=np.float32)) for k, v in table.items()}
    return atomic_torch_save({"key": None if cfg is None else _key(cfg), "table": tab}, path)
