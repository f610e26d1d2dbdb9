"""Turning messages into what a browser shows: JPEG frames, PNG maps, WAV audio, JSON.

These functions run in a worker thread (OpenCV and Pillow release the GIL while they encode),
never on the event loop that receives topics. OpenCV is used when installed, Pillow otherwise.
"""
from __future__ import annotations

import io
import math
import struct
from typing import Any

import numpy as np

from emos.geometry import planar_pose, yaw_of_quaternion
from emos.msgs.sensor import IMAGE_ENCODINGS

_cv2: Any = None
_pil: Any = None


def _backend() -> str:
    global _cv2, _pil
    if _cv2 is None and _pil is None:
        try:
            import cv2

            _cv2 = cv2
        except ImportError:
            try:
                from PIL import Image as PILImage

                _pil = PILImage
            except ImportError:
                raise ImportError("the web UI needs OpenCV or Pillow to encode images: pip install 'emos[ui]'") from None
    return "cv2" if _cv2 is not None else "pil"


def _downscale(rgb: np.ndarray, max_side: int) -> np.ndarray:
    h, w = rgb.shape[:2]
    factor = math.ceil(max(h, w) / max_side)
    return rgb[::factor, ::factor] if factor > 1 else rgb


def image_to_rgb(encoding: str, array: np.ndarray) -> np.ndarray:
    """A (h, w, 3) or (h, w) uint8 picture of any supported image encoding (depth is scaled)."""
    if encoding in ("rgb8", "8UC3"):
        return array
    if encoding == "bgr8":
        return array[:, :, ::-1]
    if encoding == "rgba8":
        return array[:, :, :3]
    if encoding == "bgra8":
        return array[:, :, 2::-1]
    if array.dtype == np.uint8:
        return array
    # Depth and other single-channel data: scale the finite values to 0..255, near is bright.
    data = array.astype(np.float32)
    finite = np.isfinite(data) & (data > 0)
    if not finite.any():
        return np.zeros(data.shape, np.uint8)
    lo, hi = float(data[finite].min()), float(data[finite].max())
    scaled = np.zeros(data.shape, np.float32)
    scaled[finite] = 255.0 - (data[finite] - lo) * (200.0 / max(hi - lo, 1e-9))
    return scaled.astype(np.uint8)


def encode_jpeg(picture: np.ndarray, quality: int) -> bytes:
    if _backend() == "cv2":
        bgr = picture[:, :, ::-1] if picture.ndim == 3 else picture
        ok, buf = _cv2.imencode(".jpg", np.ascontiguousarray(bgr), [_cv2.IMWRITE_JPEG_QUALITY, int(quality)])
        if not ok:
            raise ValueError(f"JPEG encoding failed for a {picture.shape} picture")
        return buf.tobytes()
    out = io.BytesIO()
    _pil.fromarray(np.ascontiguousarray(picture)).save(out, format="JPEG", quality=int(quality))
    return out.getvalue()


def encode_png(picture: np.ndarray) -> bytes:
    if _backend() == "cv2":
        bgr = picture[:, :, ::-1] if picture.ndim == 3 else picture
        ok, buf = _cv2.imencode(".png", np.ascontiguousarray(bgr), [_cv2.IMWRITE_PNG_COMPRESSION, 1])
        if not ok:
            raise ValueError(f"PNG encoding failed for a {picture.shape} picture")
        return buf.tobytes()
    out = io.BytesIO()
    _pil.fromarray(np.ascontiguousarray(picture)).save(out, format="PNG", compress_level=1)
    return out.getvalue()


def encode_image_msg(msg: Any, quality: int, max_side: int) -> tuple[bytes, str, int, int]:
    """(bytes, mime type, width, height) of an Image or CompressedImage message."""
    if type(msg).__name__ == "CompressedImage":
        fmt = (msg.format or "").lower()
        mime = "image/png" if "png" in fmt else "image/jpeg"
        return bytes(msg.data), mime, 0, 0
    if msg.encoding not in IMAGE_ENCODINGS:
        raise ValueError(f"image encoding {msg.encoding!r} cannot be shown; supported: {', '.join(IMAGE_ENCODINGS)}")
    picture = _downscale(image_to_rgb(msg.encoding, msg.to_numpy()), max_side)
    return encode_jpeg(picture, quality), "image/jpeg", int(msg.width), int(msg.height)


# Occupancy values: -1 unknown (grey), 0 free (white) .. 100 occupied (black).
_GRID_LUT = np.empty(256, np.uint8)
for _v in range(256):
    _s = _v - 256 if _v > 127 else _v
    _GRID_LUT[_v] = 128 if _s < 0 or _s > 100 else round(255 - _s * 2.55)


def encode_grid(msg: Any, overlay: bool = False) -> bytes:
    """A PNG of an OccupancyGrid, north up (row 0 of the picture is the map's top row).
    An overlay (a local map drawn over the global one) is transparent where free or unknown."""
    w, h = int(msg.info.width), int(msg.info.height)
    data = np.asarray(msg.data, dtype=np.int8)
    if w * h == 0 or data.size != w * h:
        raise ValueError(f"OccupancyGrid has {data.size} cells for {w}x{h}")
    grey = _GRID_LUT[data.view(np.uint8)].reshape(h, w)[::-1]
    if not overlay:
        return encode_png(grey)
    rgba = np.zeros((h, w, 4), np.uint8)
    cells = data.reshape(h, w)[::-1]
    occupied = cells > 0
    rgba[occupied] = (230, 60, 60, 0)
    rgba[occupied, 3] = np.clip(cells[occupied].astype(np.int32) * 2 + 55, 0, 255).astype(np.uint8)
    if _backend() == "cv2":
        ok, buf = _cv2.imencode(".png", np.ascontiguousarray(rgba[:, :, [2, 1, 0, 3]]))
        return buf.tobytes()
    out = io.BytesIO()
    _pil.fromarray(rgba, "RGBA").save(out, format="PNG", compress_level=1)
    return out.getvalue()


def encode_wav(msg: Any, sample_rate: int = 16000) -> bytes:
    """A WAV file of an Audio message (16-bit mono PCM, EmbodiedAgents' convention)."""
    pcm = bytes(msg.data)
    header = b"RIFF" + struct.pack("<I", 36 + len(pcm)) + b"WAVEfmt " + struct.pack(
        "<IHHIIHH", 16, 1, 1, sample_rate, sample_rate * 2, 2, 16) + b"data" + struct.pack("<I", len(pcm))
    return header + pcm


def yaw_of(q: Any) -> float:
    return yaw_of_quaternion(q.x, q.y, q.z, q.w)


def pose_of(msg: Any) -> dict[str, float] | None:
    """x, y, yaw of Odometry, PoseStamped, PoseWithCovarianceStamped, Pose or Pose2D; None for
    anything else."""
    try:
        x, y, yaw = planar_pose(msg)
    except TypeError:
        return None
    return {"x": x, "y": y, "yaw": yaw}


def path_points(msg: Any, max_points: int = 2000) -> list[list[float]]:
    poses = msg.poses
    step = max(1, math.ceil(len(poses) / max_points))
    return [[round(p.pose.position.x, 4), round(p.pose.position.y, 4)] for p in poses[::step]]


def summarize(msg: Any, max_items: int = 32) -> Any:
    """A JSON-friendly view of any message; long arrays and lists are cut, with their size noted
    (without converting a whole point cloud to a list first)."""
    import attrs

    if attrs.has(type(msg)):
        return {f.name: summarize(getattr(msg, f.name), max_items) for f in attrs.fields(type(msg))}
    if isinstance(msg, np.ndarray):
        flat = msg.reshape(-1)
        head = [summarize(v.item(), max_items) for v in flat[:max_items]]
        return head + [f"... {msg.size} items, shape {list(msg.shape)}"] if msg.size > max_items else head
    if isinstance(msg, (list, tuple)):
        head = [summarize(v, max_items) for v in msg[:max_items]]
        return head + [f"... {len(msg)} items"] if len(msg) > max_items else head
    if isinstance(msg, float) and not math.isfinite(msg):
        return str(msg)
    if isinstance(msg, (bytes, bytearray, memoryview)):
        return f"<{len(msg)} bytes>"
    return msg
