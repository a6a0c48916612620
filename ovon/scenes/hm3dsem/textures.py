"""Texture images inside scene files: PNG/JPEG through Pillow, Basis Universal (`.basis` payloads of
HM3D's `.basis.glb`, KTX2 of `KHR_texture_basisu` / ReplicaCAD) through `opengl_basisu`.

Why opengl_basisu: it wraps Basis Universal's own transcoder (both containers, ETC1S and UASTC) and
returns numpy arrays with numpy as its only dependency; it installs as a wheel and runs offline.
(Evaluated: `pyktx` needs a system libktx to build and reads KTX2 only; `alktx2` encodes and decodes
KTX2 but not `.basis`.) Decoding takes level 0 to RGBA8 and drops alpha.
"""

from __future__ import annotations

import io

import numpy as np

KTX2_MAGIC = b"\xabKTX 20\xbb\r\n\x1a\n"
BASIS_MAGIC = b"sB"
BASIS_MIMES = ("image/ktx2", "image/basis", "image/x-basis", "image/vnd-ms.basis")


class TextureError(ValueError):
    """A texture that cannot be decoded; the message says why (the loader falls back to flat colours)."""


def is_basis(data: bytes, mime: str = "") -> bool:
    return mime in BASIS_MIMES or data[:12] == KTX2_MAGIC or data[:2] == BASIS_MAGIC


def decode_basis(data: bytes) -> np.ndarray:
    """(H, W, 3) uint8 from a KTX2 (Basis payload) or `.basis` file."""
    try:
        import opengl_basisu
    except ImportError:
        raise TextureError(
            "Basis/KTX2 texture and the decoder `opengl_basisu` is not installed (pip install opengl_basisu)"
        ) from None
    try:
        tex = opengl_basisu.open(bytes(data))
        img = tex.transcode(opengl_basisu.Target.RGBA8)
    except Exception as e:  # the transcoder raises its own error types and RuntimeError
        raise TextureError(f"Basis/KTX2 texture could not be transcoded ({type(e).__name__}: {e})") from None
    arr = np.asarray(img.data, dtype=np.uint8)
    if arr.ndim != 3 or arr.shape[2] < 3:
        raise TextureError(f"Basis/KTX2 texture decoded to an unexpected shape {arr.shape}")
    if getattr(tex, "y_flipped", False):  # a .basis encoded bottom-up; glTF wants row 0 at the top
        arr = arr[::-1]
    return np.ascontiguousarray(arr[..., :3])


def decode_image(data: bytes, mime: str = "") -> np.ndarray:
    """(H, W, 3) uint8 from any supported image payload; TextureError when it cannot be read."""
    if is_basis(data, mime):
        return decode_basis(data)
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(io.BytesIO(bytes(data))) as im:
            return np.asarray(im.convert("RGB"), dtype=np.uint8).copy()
    except (OSError, ValueError, UnidentifiedImageError, Image.DecompressionBombError) as e:
        raise TextureError(f"undecodable texture ({mime or 'unknown type'}: {e})") from None
