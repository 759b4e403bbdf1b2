"""The input side: sensor_msgs/Image <-> numpy for depth, NOCS and instance masks, without
cv_bridge, and header stamps <-> integer nanoseconds (how the node and tools key frames).

Reading honours ``step`` (row padding) and ``is_bigendian`` and never loops over pixels.
Building writes ``Image.data`` as ``array.array('B', arr.tobytes())``, the fast path of the
generated message class.

Conventions (REP-118 for depth): 32FC1/64FC1 depth in metres with NaN (or inf) invalid;
16UC1 depth in units of ``depth_scale`` metres (default millimetres) with 0 invalid. NOCS:
32FC3/64FC3 as is, rgb8/bgr8 as value/255 (bgr8 reversed to x,y,z), 16UC3 as value/65535.
Masks: mono8, 8UC1, mono16, 16UC1, 32SC1 with 0 = background (negative 32SC1 ids too).
"""
from __future__ import annotations

import array
import sys

import numpy as np
from builtin_interfaces.msg import Time
from sensor_msgs.msg import Image
from std_msgs.msg import Header

# encoding -> (numpy dtype without byte order, channels)
_LAYOUT = {
    "32FC1": ("f4", 1), "64FC1": ("f8", 1), "16UC1": ("u2", 1),
    "32FC3": ("f4", 3), "64FC3": ("f8", 3), "rgb8": ("u1", 3), "bgr8": ("u1", 3),
    "16UC3": ("u2", 3), "mono8": ("u1", 1), "8UC1": ("u1", 1), "mono16": ("u2", 1),
    "32SC1": ("i4", 1),
}
DEPTH_ENCODINGS = ("32FC1", "64FC1", "16UC1")
NOCS_ENCODINGS = ("32FC3", "64FC3", "rgb8", "bgr8", "16UC3")
MASK_ENCODINGS = ("mono8", "8UC1", "mono16", "16UC1", "32SC1")


class ImageFormatError(ValueError):
    """An Image whose encoding is unsupported for its role, or whose layout is inconsistent."""


def check_image(msg: Image, supported=None, role: str = "image") -> None:
    """Raise ImageFormatError unless ``msg`` can be read: an encoding among ``supported``, a
    size, a ``step`` that holds a row and data that hold ``step * height`` bytes. Reads the
    header only, so it is cheap enough for every message."""
    enc = msg.encoding
    allowed = tuple(supported) if supported is not None else tuple(_LAYOUT)
    if enc not in allowed or enc not in _LAYOUT:
        raise ImageFormatError(
            f"{role}: unsupported encoding {enc!r}; supported: {', '.join(allowed)}"
        )
    kind, ch = _LAYOUT[enc]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    row = w * ch * np.dtype(kind).itemsize
    if h == 0 or w == 0:
        raise ImageFormatError(f"{role}: empty image ({w}x{h}, encoding {enc})")
    if row > step:
        raise ImageFormatError(f"{role}: step {step} is shorter than width*channels*size = {row} "
                               f"({w} px, encoding {enc})")
    if len(msg.data) < step * h:
        raise ImageFormatError(f"{role}: data has {len(msg.data)} bytes, step*height needs "
                               f"{step * h} (encoding {enc}, {w}x{h})")


def image_to_array(msg: Image, supported=None, role: str = "image") -> np.ndarray:
    """View an Image's pixels as an (H,W) or (H,W,C) array in native byte order (a copy).

    ``supported`` restricts the accepted encodings; ``role`` names the input in errors."""
    check_image(msg, supported, role)
    kind, ch = _LAYOUT[msg.encoding]
    h, w, step = int(msg.height), int(msg.width), int(msg.step)
    dt = np.dtype(kind).newbyteorder(">" if msg.is_bigendian else "<")
    row = w * ch * dt.itemsize
    buf = np.frombuffer(msg.data, dtype=np.uint8)
    rows = buf[: step * h].reshape(h, step)[:, :row]
    arr = np.ascontiguousarray(rows).view(dt).reshape((h, w, ch) if ch > 1 else (h, w))
    return arr.astype(dt.newbyteorder("="), copy=True)


def depth_from_image(msg: Image, depth_scale: float = 0.001, role: str = "depth") -> np.ndarray:
    """(H,W) float32 depth in metres, NaN where invalid (16UC1 zero, non-finite float)."""
    arr = image_to_array(msg, DEPTH_ENCODINGS, role)
    if msg.encoding == "16UC1":
        out = arr.astype(np.float32) * np.float32(depth_scale)
        out[arr == 0] = np.nan
        return out
    out = arr.astype(np.float32, copy=False)
    out[~np.isfinite(out)] = np.nan
    return out


def nocs_from_image(msg: Image, role: str = "nocs") -> np.ndarray:
    """(H,W,3) float32 NOCS in [0,1] (all-zero pixels mean no prediction)."""
    arr = image_to_array(msg, NOCS_ENCODINGS, role)
    enc = msg.encoding
    if enc in ("rgb8", "bgr8"):
        out = arr.astype(np.float32) / np.float32(255.0)
        return out[..., ::-1].copy() if enc == "bgr8" else out
    if enc == "16UC3":
        return arr.astype(np.float32) / np.float32(65535.0)
    return arr.astype(np.float32, copy=False)


def to_fcop_convention(nocs: np.ndarray) -> np.ndarray:
    """NOCS of the NOCS dataset's convention (z flipped) in this package's: z = 1 - z on every
    pixel with a prediction (all-zero pixels stay all-zero: no prediction)."""
    out = np.array(nocs, dtype=np.float32, copy=True)
    valid = np.any(out != 0, axis=2)
    out[..., 2] = np.where(valid, 1.0 - out[..., 2], out[..., 2])
    return out


def mask_from_image(msg: Image, role: str = "mask") -> np.ndarray:
    """(H,W) integer instance ids in the encoding's own type (uint8, uint16 or int32),
    0 = background. Unsigned ids stay unsigned: the estimator then needs no pass to clip
    negative values."""
    return image_to_array(msg, MASK_ENCODINGS, role)


class ImageSizeMismatch(ImageFormatError):
    """The three images of one frame differ in size."""


def frame_from_images(depth_msg: Image, nocs_msg: Image, mask_msg: Image,
                      depth_scale: float = 0.001, nocs_convention: str = "fcop"):
    """One frame's (depth, nocs, mask) arrays from its three Images, the NOCS in this package's
    convention (``nocs_convention`` 'nocs_dataset': the NOCS dataset's, converted). Raises
    ImageFormatError for an image it cannot read, ImageSizeMismatch for sizes that differ."""
    depth = depth_from_image(depth_msg, depth_scale)
    nocs = nocs_from_image(nocs_msg)
    mask = mask_from_image(mask_msg)
    if not depth.shape == nocs.shape[:2] == mask.shape:
        raise ImageSizeMismatch(
            f"image sizes differ: depth {depth.shape[::-1]}, nocs {nocs.shape[1::-1]}, "
            f"mask {mask.shape[::-1]}")
    if nocs_convention == "nocs_dataset":
        nocs = to_fcop_convention(nocs)
    elif nocs_convention != "fcop":
        raise ValueError(f"nocs_convention must be 'fcop' or 'nocs_dataset', not "
                         f"{nocs_convention!r}")
    return depth, nocs, mask


def array_to_image(arr: np.ndarray, encoding: str, header=None) -> Image:
    """Build an Image from an array already in the encoding's dtype and channel count."""
    kind, ch = _LAYOUT[encoding]
    a = np.ascontiguousarray(arr, dtype=np.dtype(kind))
    if a.ndim != (3 if ch > 1 else 2) or (ch > 1 and a.shape[2] != ch):
        raise ImageFormatError(f"array of shape {a.shape} does not fit encoding {encoding}")
    msg = Image()
    if header is not None:
        msg.header = header
    msg.height, msg.width = int(a.shape[0]), int(a.shape[1])
    msg.encoding = encoding
    msg.is_bigendian = int(sys.byteorder == "big")
    msg.step = int(a.shape[1] * ch * a.dtype.itemsize)
    msg.data = array.array("B", a.tobytes())
    return msg


def depth_to_image(depth: np.ndarray, encoding: str = "32FC1", header=None,
                   depth_scale: float = 0.001) -> Image:
    """Depth in metres (NaN invalid) as 32FC1/64FC1, or 16UC1 in ``depth_scale`` units (0
    invalid)."""
    if encoding not in DEPTH_ENCODINGS:
        raise ImageFormatError(
            f"depth: unsupported encoding {encoding!r}; supported: {', '.join(DEPTH_ENCODINGS)}"
        )
    d = np.asarray(depth, dtype=np.float64)
    if encoding == "16UC1":
        units = np.where(np.isfinite(d) & (d > 0), np.round(d / depth_scale), 0)
        return array_to_image(np.clip(units, 0, 65535).astype(np.uint16), encoding, header)
    return array_to_image(np.where(np.isfinite(d), d, np.nan), encoding, header)


def nocs_to_image(nocs: np.ndarray, encoding: str = "32FC3", header=None) -> Image:
    """NOCS (H,W,3) in [0,1] as 32FC3/64FC3, rgb8/bgr8 (x255) or 16UC3 (x65535)."""
    if encoding not in NOCS_ENCODINGS:
        raise ImageFormatError(
            f"nocs: unsupported encoding {encoding!r}; supported: {', '.join(NOCS_ENCODINGS)}"
        )
    p = np.asarray(nocs, dtype=np.float64)
    if encoding in ("rgb8", "bgr8"):
        q = np.clip(np.round(p * 255.0), 0, 255).astype(np.uint8)
        return array_to_image(q[..., ::-1] if encoding == "bgr8" else q, encoding, header)
    if encoding == "16UC3":
        return array_to_image(np.clip(np.round(p * 65535.0), 0, 65535).astype(np.uint16),
                              encoding, header)
    return array_to_image(p, encoding, header)


def mask_to_image(mask: np.ndarray, encoding: str = "mono8", header=None) -> Image:
    """Instance ids as mono8/8UC1 (< 256), mono16/16UC1 (< 65536) or 32SC1."""
    if encoding not in MASK_ENCODINGS:
        raise ImageFormatError(
            f"mask: unsupported encoding {encoding!r}; supported: {', '.join(MASK_ENCODINGS)}"
        )
    m = np.asarray(mask)
    kind = _LAYOUT[encoding][0]
    info = np.iinfo(np.dtype(kind))
    if m.size and (m.min() < info.min or m.max() > info.max):
        raise ImageFormatError(f"mask: ids {m.min()}..{m.max()} do not fit encoding {encoding}")
    return array_to_image(m.astype(kind), encoding, header)


def time_to_ns(t) -> int:
    """A builtin_interfaces/Time (or anything with sec and nanosec) in integer nanoseconds."""
    return t.sec * 1_000_000_000 + t.nanosec


def time_from_ns(ns: int) -> Time:
    """builtin_interfaces/Time of integer nanoseconds."""
    sec, nanosec = divmod(int(ns), 1_000_000_000)
    return Time(sec=sec, nanosec=nanosec)


def stamp_ns(msg) -> int:
    """The header stamp of a message (anything with .header.stamp) in integer nanoseconds."""
    return time_to_ns(msg.header.stamp)


def header_from_ns(stamp_ns: int, frame_id: str = "") -> Header:
    """A std_msgs/Header stamped ``stamp_ns`` nanoseconds, in frame ``frame_id``."""
    return Header(stamp=time_from_ns(stamp_ns), frame_id=frame_id)
