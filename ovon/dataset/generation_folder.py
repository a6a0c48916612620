"""The run folder of `ovon dataset generate`: identity, resume check and lock at the generation entry.

Why: a re-run into the same `--out` resumes (finished shards are kept), so it must be the same
generation: another seed, episode count or scene set would mix two datasets in one folder. The check is
a decorator on `ovon.dataset.generate.generate`, so the CLI and Python callers get it alike, and the
generator's own code stays about generation.
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ovon.config.base import ConfigError, to_dict, validate
from ovon.dataset.records import DatasetError
from ovon.runfolder import RunFolder, file_sha256, listing_sha256, path_identity


class EmptyGenerationError(DatasetError):
    """A generation that yields no episode at all (e.g. no scene has a navigable floor): it removes the files
    it created, so a corrected re-run into the same folder starts afresh."""


KIND = "dataset"
# Which splits a session generates, and how fast, may change between sessions of one dataset folder.
MAY_CHANGE = ("splits", "workers", "executor")


def open_generation_folder(
    scenes_dir: str | Path,
    out: str | Path,
    cfg: Any,
    splits: tuple[str, ...],
    category_split_path: str | Path | None = None,
    workers: int = 1,
    executor: str = "process",
) -> RunFolder:
    """Validate the generation's inputs and open (create or resume) its output folder, locked."""
    validate(cfg)
    if category_split_path is not None and not Path(category_split_path).is_file():
        raise ConfigError(
            f"--categories {str(category_split_path)!r} = {category_split_path}: expected an existing "
            "file; fix: pass a categories.json written by `ovon dataset splits`, or leave --categories "
            "out to split the scenes' categories"
        )
    if not Path(scenes_dir).is_dir():
        raise ConfigError(
            f"--scenes {str(scenes_dir)!r}: expected an existing folder holding train/ and val/; fix: "
            "make one with `ovon scenes generate`"
        )
    listing = listing_sha256(scenes_dir, exclude=[out])
    inputs: dict[str, Any] = {"scenes": {"path": path_identity(scenes_dir), "listing": listing}}
    if category_split_path is not None:
        inputs["categories"] = file_sha256(category_split_path)
    config = {"generation": to_dict(cfg), "splits": list(splits), "workers": workers, "executor": executor}
    return RunFolder.open(out, KIND, config, inputs, may_change=MAY_CHANGE, markers=("generation_config.json",))


def generation_run_folder(generate: Callable) -> Callable:
    """Decorator for the generation entry point: the whole call runs inside its locked, checked folder."""
    sig = inspect.signature(generate)

    @functools.wraps(generate)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        bound = sig.bind(*args, **kwargs)
        bound.apply_defaults()
        a = bound.arguments
        with open_generation_folder(
            a["scenes_dir"],
            a["out"],
            a["cfg"],
            tuple(a["splits"]),
            a.get("category_split_path"),
            a.get("workers", 1),
            a.get("executor", "process"),
        ):
            return generate(*bound.args, **bound.kwargs)

    return wrapper
