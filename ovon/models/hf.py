"""One loader for the frozen Hugging Face models (SigLIP, OWLv2): local files only, loaded once per
(model, device) and shared by every user in the process, moved to the device, in eval mode, frozen.

Why local only: no machine of this project can download weights, and without `local_files_only` a
missing model costs ~24 s of network retries before failing; here it is one `ModelNotAvailableError`
line at once, written by the caller (which model, how to get it, what to use instead).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from ovon.models.encoders.base import ModelNotAvailableError

_LOCK = threading.Lock()
_LOADED: dict[tuple[str, str, str], tuple[Any, Any, Any]] = {}


def load_pretrained(
    kind: str,
    name_or_path: str,
    device: str,
    classes: Callable[[], tuple[Any, Any, Any]],
    missing: Callable[[Exception], str],
) -> tuple[Any, Any, Any]:
    """(model, image processor, tokenizer) of `name_or_path` (a hub name in the local cache, or a
    `save_pretrained` folder). `classes()` returns the three transformers classes (imported only when a
    model is loaded); `missing(err)` is the one-line message when the files are not there."""
    key = (kind, str(name_or_path), device)
    with _LOCK:
        if key in _LOADED:
            return _LOADED[key]
        model_cls, processor_cls, tokenizer_cls = classes()
        try:
            model = model_cls.from_pretrained(str(name_or_path), local_files_only=True)
            processor = processor_cls.from_pretrained(str(name_or_path), local_files_only=True)
            tokenizer = tokenizer_cls.from_pretrained(str(name_or_path), local_files_only=True)
        except (OSError, ValueError) as e:
            raise ModelNotAvailableError(missing(e)) from None
        model = model.to(device).eval()
        for p in model.parameters():
            p.requires_grad_(False)
        _LOADED[key] = (model, processor, tokenizer)
        return _LOADED[key]
