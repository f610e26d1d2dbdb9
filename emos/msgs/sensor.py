"""sensor_msgs (and the audio message EmbodiedAgents uses)."""
from __future__ import annotations

import math

import numpy as np

from emos.msgs import fields as F
from emos.msgs.registry import Message, message_type
from emos.msgs.std import Header

# encoding -> (numpy dtype, channels)
IMAGE_ENCODINGS: dict[str, tuple[str, int]] = {
    "rgb8": ("uint8", 3),
    "bgr8": ("uint8", 3),
    "rgba8": ("uint8", 4),
    "bgra8": ("uint8", 4),
    "mono8": ("uint8", 1),
    "8UC1": ("uint8", 1),
    "8UC3": ("uint8", 3),
    "mono16": ("uint16", 1),
    "16UC1": ("uint16", 1),
    "32FC1": ("float32", 1),
}


@message_type("sensor_msgs")
class Image(Message):
    header: Header = F.message(Header)
    height: int = F.integer(bits=32, signed=False)
    width: int = F.integer(bits=32, signed=False)
    encoding: str = F.string()
    is_bigendian: int = F.integer(bits=8, signed=False)
    step: int = F.integer(bits=32, signed=False)
    data: np.ndarray = F.bytes_array()

    @classmethod
    def from_numpy(cls, array: np.ndarray, encoding: str = "rgb8", header: Header | None = None) -> Image:
        """An image message whose ``data`` holds ``array``'s bytes (no copy if contiguous)."""
        if encoding not in IMAGE_ENCODINGS:
            raise ValueError(f"Image encoding {encoding!r} is not supported; use one of {', '.join(IMAGE_ENCODINGS)}")
        dtype, channels = IMAGE_ENCODINGS[encoding]
        arr = np.asarray(array)
        if arr.dtype != np.dtype(dtype):
            raise TypeError(f"Image encoding {encoding!r} needs dtype {dtype}, got {arr.dtype}")
        want_ndim = 2 if channels == 1 else 3
        if arr.ndim == 3 and channels == 1 and arr.shape[2] == 1:
            arr = arr[:, :, 0]
        if arr.ndim != want_ndim or (channels > 1 and arr.shape[2] != channels):
            raise ValueError(f"Image encoding {encoding!r} needs shape (h, w{f', {channels}' if channels > 1 else ''}), got {arr.shape}")
        arr = np.ascontiguousarray(arr)
        h, w = arr.shape[:2]
        return cls(
            header=header or Header(),
            height=h,
            width=w,
            encoding=encoding,
            step=w * channels * arr.dtype.itemsize,
            data=arr.reshape(-1).view(np.uint8),
        )

    def to_numpy(self) -> np.ndarray:
        """A (h, w[, c]) view of ``data`` in the encoding's dtype."""
        if self.encoding not in IMAGE_ENCODINGS:
            raise ValueError(f"Image encoding {self.encoding!r} is not supported")
        dtype, channels = IMAGE_ENCODINGS[self.encoding]
        itemsize = np.dtype(dtype).itemsize
        if self.step != self.width * channels * itemsize:
            rows = self.data.reshape(self.height, self.step)[:, : self.width * channels * itemsize]
            flat = np.ascontiguousarray(rows).view(dtype)
        else:
            flat = self.data.view(dtype)
        shape = (self.height, self.width) if channels == 1 else (self.height, self.width, channels)
        return flat.reshape(shape)


@message_type("sensor_msgs")
class CompressedImage(Message):
    header: Header = F.message(Header)
    format: str = F.string()
    data: np.ndarray = F.bytes_array()


@message_type("sensor_msgs")
class RegionOfInterest(Message):
    x_offset: int = F.integer(bits=32, signed=False)
    y_offset: int = F.integer(bits=32, signed=False)
    height: int = F.integer(bits=32, signed=False)
    width: int = F.integer(bits=32, signed=False)
    do_rectify: bool = F.boolean()


@message_type("sensor_msgs")
class CameraInfo(Message):
    header: Header = F.message(Header)
    height: int = F.integer(bits=32, signed=False)
    width: int = F.integer(bits=32, signed=False)
    distortion_model: str = F.string("plumb_bob")
    d: np.ndarray = F.array(dtype="float64")
    k: np.ndarray = F.array(dtype="float64", shape=(9,))
    r: np.ndarray = F.array(dtype="float64", shape=(9,))
    p: np.ndarray = F.array(dtype="float64", shape=(12,))
    binning_x: int = F.integer(bits=32, signed=False)
    binning_y: int = F.integer(bits=32, signed=False)
    roi: RegionOfInterest = F.message(RegionOfInterest)

    @classmethod
    def from_intrinsics(cls, width: int, height: int, fx: float, fy: float, cx: float, cy: float, header: Header | None = None) -> CameraInfo:
        k = np.array([fx, 0, cx, 0, fy, cy, 0, 0, 1], dtype=np.float64)
        p = np.array([fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], dtype=np.float64)
        return cls(header=header or Header(), width=width, height=height, k=k, r=np.eye(3).reshape(-1), p=p, d=np.zeros(5))

    @property
    def fx(self) -> float:
        return float(self.k[0])

    @property
    def fy(self) -> float:
        return float(self.k[4])

    @property
    def cx(self) -> float:
        return float(self.k[2])

    @property
    def cy(self) -> float:
        return float(self.k[5])


@message_type("sensor_msgs")
class LaserScan(Message):
    header: Header = F.message(Header)
    angle_min: float = F.float32()
    angle_max: float = F.float32()
    angle_increment: float = F.float32()
    time_increment: float = F.float32()
    scan_time: float = F.float32()
    range_min: float = F.float32()
    range_max: float = F.float32()
    ranges: np.ndarray = F.array(dtype="float32", ndim=1)
    intensities: np.ndarray = F.array(dtype="float32", ndim=1)

    def angles(self) -> np.ndarray:
        """The bearing of every beam, in the scan frame."""
        return self.angle_min + self.angle_increment * np.arange(len(self.ranges), dtype=np.float64)

    def valid_mask(self) -> np.ndarray:
        """Beams with a real return: finite and within [range_min, range_max]."""
        r = self.ranges
        with np.errstate(invalid="ignore"):
            mask: np.ndarray = np.isfinite(r) & (r >= self.range_min) & (r <= self.range_max)
        return mask


@message_type("sensor_msgs")
class PointField(Message):
    INT8, UINT8, INT16, UINT16, INT32, UINT32, FLOAT32, FLOAT64 = 1, 2, 3, 4, 5, 6, 7, 8
    name: str = F.string()
    offset: int = F.integer(bits=32, signed=False)
    datatype: int = F.integer(bits=8, signed=False)
    count: int = F.integer(bits=32, signed=False, default=1)


@message_type("sensor_msgs")
class PointCloud2(Message):
    header: Header = F.message(Header)
    height: int = F.integer(bits=32, signed=False)
    width: int = F.integer(bits=32, signed=False)
    fields: list[PointField] = F.message_list(PointField)
    is_bigendian: bool = F.boolean()
    point_step: int = F.integer(bits=32, signed=False)
    row_step: int = F.integer(bits=32, signed=False)
    data: np.ndarray = F.bytes_array()
    is_dense: bool = F.boolean()

    @classmethod
    def from_xyz(cls, points: np.ndarray, header: Header | None = None) -> PointCloud2:
        """An unorganised cloud of float32 x, y, z."""
        pts = np.ascontiguousarray(np.asarray(points, dtype=np.float32))
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise ValueError(f"PointCloud2.from_xyz expects an (N, 3) array, got shape {pts.shape}")
        fields = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, n in enumerate("xyz")]
        return cls(
            header=header or Header(), height=1, width=len(pts), fields=fields, point_step=12,
            row_step=12 * len(pts), data=pts.reshape(-1).view(np.uint8), is_dense=bool(np.isfinite(pts).all()),
        )

    def xyz(self) -> np.ndarray:
        """(N, 3) float32 x, y, z, whatever other fields the cloud carries."""
        offsets = {f.name: f.offset for f in self.fields}
        missing = [n for n in "xyz" if n not in offsets]
        if missing:
            raise ValueError(f"PointCloud2 has no field {missing[0]!r}")
        n = self.width * self.height
        raw = self.data.reshape(n, self.point_step) if n else self.data.reshape(0, max(self.point_step, 1))
        out = np.empty((n, 3), dtype=np.float32)
        for i, name in enumerate("xyz"):
            o = offsets[name]
            out[:, i] = np.ascontiguousarray(raw[:, o : o + 4]).view(np.float32)[:, 0]
        return out


@message_type("sensor_msgs")
class JointState(Message):
    header: Header = F.message(Header)
    name: list[str] = F.string_list()
    position: np.ndarray = F.array(dtype="float64", ndim=1)
    velocity: np.ndarray = F.array(dtype="float64", ndim=1)
    effort: np.ndarray = F.array(dtype="float64", ndim=1)


@message_type("sensor_msgs")
class BatteryState(Message):
    """A battery's state (sensor_msgs/msg/BatteryState); unmeasured values are NaN, as in ROS."""

    POWER_SUPPLY_STATUS_UNKNOWN, POWER_SUPPLY_STATUS_CHARGING, POWER_SUPPLY_STATUS_DISCHARGING = 0, 1, 2
    POWER_SUPPLY_STATUS_NOT_CHARGING, POWER_SUPPLY_STATUS_FULL = 3, 4
    POWER_SUPPLY_HEALTH_UNKNOWN, POWER_SUPPLY_HEALTH_GOOD = 0, 1
    POWER_SUPPLY_TECHNOLOGY_UNKNOWN, POWER_SUPPLY_TECHNOLOGY_NIMH, POWER_SUPPLY_TECHNOLOGY_LION = 0, 1, 2
    header: Header = F.message(Header)
    voltage: float = F.float32(math.nan)  # V
    temperature: float = F.float32(math.nan)  # deg C
    current: float = F.float32(math.nan)  # A, negative when discharging
    charge: float = F.float32(math.nan)  # Ah
    capacity: float = F.float32(math.nan)  # Ah
    design_capacity: float = F.float32(math.nan)  # Ah
    percentage: float = F.float32(math.nan)  # 0..1
    power_supply_status: int = F.integer(bits=8, signed=False)
    power_supply_health: int = F.integer(bits=8, signed=False)
    power_supply_technology: int = F.integer(bits=8, signed=False)
    present: bool = F.boolean()
    cell_voltage: np.ndarray = F.array(dtype="float32", ndim=1)
    cell_temperature: np.ndarray = F.array(dtype="float32", ndim=1)
    location: str = F.string()
    serial_number: str = F.string()


@message_type("audio_common_msgs", name="Audio")
class Audio(Message):
    """Raw audio bytes; EmbodiedAgents streams 16 kHz mono 16-bit PCM by convention."""

    data: np.ndarray = F.bytes_array()


def scan_from_ranges(ranges: np.ndarray, angle_min: float = -math.pi, angle_max: float = math.pi, range_min: float = 0.05, range_max: float = 30.0, header: Header | None = None) -> LaserScan:
    """A LaserScan evenly spread over [angle_min, angle_max]."""
    n = len(ranges)
    inc = (angle_max - angle_min) / max(n - 1, 1)
    return LaserScan(header=header or Header(), angle_min=angle_min, angle_max=angle_max, angle_increment=inc, range_min=range_min, range_max=range_max, ranges=ranges)
