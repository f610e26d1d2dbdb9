"""Map image files: PGM (P5 binary / P2 ASCII) in numpy, PNG and others through Pillow.

Images come back as ``(pixels, maxval, alpha)``: a 2D array of grey levels in image row order
(row 0 = top of the picture), the value that means white, and the alpha channel (or ``None``).
Colour images are handled the way ROS map_server does: the caller averages the colour channels
(see ``map_yaml``), so ``read_image`` returns the channels untouched as ``(H, W, C)``.
"""
from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from emos.errors import EmosError

__all__ = ["MapImageError", "read_pgm", "write_pgm", "read_image"]


class MapImageError(EmosError, ValueError):
    """A map image that cannot be read (missing, truncated, unsupported format)."""


def _header_tokens(buf: bytes, count: int) -> tuple[list[bytes], int]:
    """Read ``count`` whitespace-separated header tokens, skipping ``#`` comments."""
    tokens: list[bytes] = []
    pos = 0
    while len(tokens) < count:
        # Comments may appear anywhere between header tokens.
        while True:
            m_ws = re.match(rb"\s*", buf[pos:])
            pos += m_ws.end() if m_ws else 0
            if buf[pos:pos + 1] == b"#":
                nl = buf.find(b"\n", pos)
                pos = len(buf) if nl < 0 else nl + 1
            else:
                break
        m = re.match(rb"[^\s#]+", buf[pos:])
        if not m:
            raise MapImageError("PGM header is truncated")
        tokens.append(m.group(0))
        pos += m.end()
    return tokens, pos


def read_pgm(path: str | os.PathLike) -> tuple[np.ndarray, int]:
    """Read a P5 (binary) or P2 (ASCII) PGM file -> (pixels (H, W) int array, maxval)."""
    p = Path(path)
    try:
        buf = p.read_bytes()
    except OSError as exc:
        raise MapImageError(f"cannot read map image {p}: {exc.strerror or exc}") from exc
    magic = buf[:2]
    if magic not in (b"P5", b"P2"):
        raise MapImageError(f"{p}: not a PGM file (magic {magic!r}, expected b'P5' or b'P2')")
    try:
        (w_tok, h_tok, max_tok), pos = _header_tokens(buf[2:], 3)
        width, height, maxval = int(w_tok), int(h_tok), int(max_tok)
    except (MapImageError, ValueError) as exc:
        raise MapImageError(f"{p}: malformed PGM header ({exc})") from exc
    pos += 2
    if width <= 0 or height <= 0 or not (0 < maxval < 65536):
        raise MapImageError(f"{p}: bad PGM size/maxval {width}x{height} max {maxval}")
    if magic == b"P5":
        # Exactly one whitespace byte separates the header from the raster.
        pos += 1
        dtype = np.dtype(np.uint8) if maxval < 256 else np.dtype(">u2")
        need = width * height * dtype.itemsize
        raster = buf[pos:pos + need]
        if len(raster) < need:
            raise MapImageError(f"{p}: truncated PGM raster ({len(raster)} of {need} bytes)")
        pixels = np.frombuffer(raster, dtype=dtype).reshape(height, width).astype(np.int64)
    else:
        body = re.sub(rb"#[^\n]*", b"", buf[pos:])
        try:
            values = np.array(body.split(), dtype=np.int64)
        except ValueError as exc:
            raise MapImageError(f"{p}: non-numeric value in P2 raster") from exc
        if values.size < width * height:
            raise MapImageError(f"{p}: truncated P2 raster ({values.size} of {width * height} values)")
        pixels = values[: width * height].reshape(height, width)
    if pixels.size and int(pixels.max()) > maxval:
        raise MapImageError(f"{p}: pixel value {int(pixels.max())} exceeds maxval {maxval}")
    return pixels, maxval


def write_pgm(path: str | os.PathLike, pixels: np.ndarray, comment: str | None = None) -> None:
    """Write an 8-bit binary (P5) PGM; ``pixels`` is (H, W) with values 0..255, row 0 at the top."""
    px = np.asarray(pixels)
    if px.ndim != 2:
        raise ValueError(f"write_pgm: expected a 2D array, got shape {px.shape}")
    if px.size and (px.min() < 0 or px.max() > 255):
        raise ValueError("write_pgm: pixel values must be in 0..255")
    header = b"P5\n"
    if comment:
        header += b"# " + comment.replace("\n", " ").encode() + b"\n"
    header += f"{px.shape[1]} {px.shape[0]}\n255\n".encode()
    Path(path).write_bytes(header + px.astype(np.uint8).tobytes())


def read_image(path: str | os.PathLike) -> tuple[np.ndarray, int, np.ndarray | None]:
    """Read any map image -> (channels, maxval, alpha).

    ``channels`` is (H, W) for grey images or (H, W, 3) for colour; ``alpha`` is (H, W) or None.
    PGM files are read natively; everything else needs Pillow (``pip install 'emos[sim]'``).
    """
    p = Path(path)
    if not p.is_file():
        raise MapImageError(f"map image not found: {p}")
    with open(p, "rb") as fh:
        magic = fh.read(2)
    if magic in (b"P5", b"P2"):
        pixels, maxval = read_pgm(p)
        return pixels, maxval, None
    try:
        from PIL import Image, UnidentifiedImageError
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise ImportError(
            f"reading {p.suffix or 'non-PGM'} map images needs Pillow: pip install 'emos[sim]'"
        ) from exc
    try:
        with Image.open(p) as opened:
            opened.load()
            img: Image.Image = opened  # convert() below returns a plain Image, not an ImageFile
            mode = img.mode
            if mode in ("1", "L", "P", "I", "I;16", "RGB", "RGBA", "LA", "PA"):
                pass
            else:
                img = img.convert("RGBA" if "A" in mode else "RGB")
                mode = img.mode
            if mode == "P":
                img = img.convert("RGBA" if "transparency" in img.info else "RGB")
                mode = img.mode
            if mode == "PA":
                img = img.convert("RGBA")
                mode = img.mode
            arr = np.asarray(img)
    except (UnidentifiedImageError, OSError) as exc:
        raise MapImageError(f"cannot decode map image {p}: {exc}") from exc
    if mode == "1":
        return arr.astype(np.int64) * 255, 255, None
    if mode in ("I", "I;16"):
        return arr.astype(np.int64), 65535, None
    if mode == "L":
        return arr.astype(np.int64), 255, None
    if mode == "LA":
        return arr[..., 0].astype(np.int64), 255, arr[..., 1].astype(np.int64)
    if mode == "RGB":
        return arr.astype(np.int64), 255, None
    # RGBA
    return arr[..., :3].astype(np.int64), 255, arr[..., 3].astype(np.int64)
