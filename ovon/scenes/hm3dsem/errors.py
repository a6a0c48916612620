"""Errors and warnings of scene loading: one line that names the file and what is wrong in it.

Why a module of its own: every reader (glTF, PLY/OBJ, semantic.txt, sidecar, textures) reports through
the same two classes, so the command line prints one line instead of a traceback from deep inside
numpy or struct ("buffer is smaller than requested size" says nothing about which file is broken).
"""

from __future__ import annotations

from pathlib import Path

LFS_MAGIC = b"version https://git-lfs.github.com/spec/"


class SceneLoadWarning(UserWarning):
    """Something in a scene folder was read approximately or skipped; the message says what."""


class SceneFileError(ValueError):
    """A scene file cannot be used. A ValueError, so `ovon` prints it as one line and exits 2."""

    def __init__(self, path: str | Path, problem: str, fix: str = "") -> None:
        self.path = Path(path)
        self.problem = problem
        super().__init__(f"{path}: {problem}" + (f"; {fix}" if fix else ""))


def lfs_pointer_error(path: str | Path, head: bytes) -> SceneFileError | None:
    """The error for a Git LFS pointer file (a ~130-byte text stub left by a clone without LFS)."""
    if not head.startswith(LFS_MAGIC):
        return None
    size = ""
    for line in head.decode("utf-8", "replace").splitlines():
        if line.startswith("size "):
            size = f" of {int(line[5:]):,} bytes" if line[5:].strip().isdigit() else ""
    return SceneFileError(
        path,
        f"is a Git LFS pointer file, not the file itself (the real file{size} was never downloaded)",
        "fetch it with `git lfs install && git lfs pull` inside that repository "
        "(or `git lfs pull --include <path>`), then retry",
    )


def read_bytes(path: str | Path) -> bytes:
    """File contents, refusing Git LFS pointers with instructions."""
    data = Path(path).read_bytes()
    err = lfs_pointer_error(path, data[:200])
    if err is not None:
        raise err
    return data
