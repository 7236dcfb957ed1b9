"""Arrays from anywhere: numpy, Warp, and any DLPack or ``__cuda_array_interface__`` object
(torch, JAX, CuPy, Numba), taken in place when they already live on the device that needs them.

Two doors:

* :func:`host_array` for set-up that validates on the host (meshes, ids, filters): a numpy view when
  the data is on the host already, one copy down from a device otherwise.
* :func:`device_view` for what a frame reads (poses, transforms, world vertices): a ``wp.array`` over
  the caller's own memory when it is on the wanted device (no copy, no host round trip), else one copy
  to that device. Such input is validated by a kernel on the device (the scenes' setters), never by a
  read to the host.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from .aliases import ArrayLike, DeviceLike
from .start import init_warp

__all__ = ["ArrayLike", "DeviceLike", "device_view", "host_array", "is_device_array", "packed_arrays", "packed_upload"]



def _foreign(x: ArrayLike) -> wp.array | None:
    """A ``wp.array`` over the memory of a DLPack or ``__cuda_array_interface__`` object (no copy), or
    None for anything else (numpy arrays and sequences included)."""
    if isinstance(x, wp.array):
        return x
    if isinstance(x, np.ndarray):
        return None
    if hasattr(x, "__dlpack__") or hasattr(x, "__cuda_array_interface__"):
        init_warp()  # DLPack's device lookup needs Warp's runtime (a no-op once it is up)
    if hasattr(x, "__dlpack__") and hasattr(x, "__dlpack_device__"):
        try:
            return wp.from_dlpack(x)
        except Exception as exc:  # an unsupported dtype, a device Warp does not know
            raise ValueError(f"cannot read this {type(x).__name__} through DLPack ({exc})") from None
    if hasattr(x, "__cuda_array_interface__"):
        try:
            return _from_cuda_interface(x)
        except Exception as exc:
            raise ValueError(f"cannot read this {type(x).__name__} through __cuda_array_interface__ ({exc})") from None
    return None


def _from_cuda_interface(x: Any) -> wp.array:
    """A ``wp.array`` over the CUDA memory an ``__cuda_array_interface__`` (version 2 or 3) describes,
    holding a reference to ``x`` (no copy)."""
    desc = x.__cuda_array_interface__
    if desc.get("mask") is not None:
        raise ValueError("masked arrays are not supported")
    dtype = wp.dtype_from_numpy(np.dtype(desc["typestr"]))
    shape = tuple(int(n) for n in desc["shape"])
    strides = desc.get("strides")
    if strides is None:
        strides = [wp.types.type_size_in_bytes(dtype) * int(np.prod(shape[k + 1:])) for k in range(len(shape))]
    a = wp.array(ptr=int(desc["data"][0]), dtype=dtype, shape=shape, strides=tuple(int(s) for s in strides),
                 device="cuda")
    a._ref = x  # keeps the producer's memory alive as long as the view
    return a


def is_device_array(x: ArrayLike) -> bool:
    """Whether ``x`` is a ``wp.array`` or a DLPack / ``__cuda_array_interface__`` object (not numpy)."""
    return isinstance(x, wp.array) or (not isinstance(x, np.ndarray) and (
        hasattr(x, "__dlpack__") or hasattr(x, "__cuda_array_interface__")))


def host_array(x: ArrayLike, name: str) -> np.ndarray:
    """``x`` as a numpy array (a view where it is on the host, one copy down from a device).

    Args:
        x: an :data:`ArrayLike` (or a scalar).
        name: the argument's name, for errors.

    Raises:
        ValueError: ``x`` is not an array of numbers.
    """
    try:
        w = _foreign(x)
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None
    if w is not None:
        return w.numpy()  # vectors (wp.vec3, ...) with their components as the last axis
    try:
        return np.asarray(x)
    except Exception as exc:
        raise ValueError(f"{name}: not an array ({type(exc).__name__}: {exc})") from None


_SCALARS = {wp.float32: np.float32, wp.float64: np.float64}


def device_view(x: ArrayLike, name: str, device: DeviceLike, *,
                scalar_types: tuple[type, ...] = (wp.float32, wp.float64)) -> wp.array:
    """``x`` as a ``wp.array`` of scalars on ``device``: the caller's memory itself when it is there
    (a view, any strides), else one copy to it.

    Vector-typed Warp arrays (``wp.vec3``, ``wp.transform``) are viewed as their scalars with one more
    axis (``(N,)`` ``wp.vec3`` as ``(N, 3)``), so kernels read every layout the same way.

    Args:
        x: an :data:`ArrayLike`.
        name: the argument's name, for errors.
        device: the Warp device that will read it.
        scalar_types: the Warp scalar types accepted in place; other real types are converted (a copy).

    Returns:
        A ``wp.array`` whose dtype is one of ``scalar_types``, on ``device``.

    Raises:
        ValueError: ``x`` is not an array of real numbers.
    """
    d = wp.get_device(device)
    try:
        w = _foreign(x)
    except ValueError as exc:
        raise ValueError(f"{name}: {exc}") from None
    if w is None:
        arr = host_array(x, name)
        if arr.dtype.kind not in "fiu" or arr.dtype == np.float16:
            raise ValueError(f"{name}: expected real numbers, got {arr.dtype}")
        target = arr.dtype if arr.dtype in (np.float32, np.float64) and \
            wp.dtype_from_numpy(arr.dtype) in scalar_types else np.dtype(_SCALARS[scalar_types[-1]])
        return wp.array(np.ascontiguousarray(arr, dtype=target), device=d)
    scalar = getattr(w.dtype, "_wp_scalar_type_", None)
    if scalar is not None:  # vectors, matrices, transforms: their scalars, one more axis
        if not w.is_contiguous:
            w = wp.clone(w)
        w = w.view(scalar)
    if w.dtype not in scalar_types:
        if w.dtype not in (wp.float16, wp.float32, wp.float64, wp.int8, wp.int16, wp.int32, wp.int64, wp.uint8,
                           wp.uint16, wp.uint32, wp.uint64):
            raise ValueError(f"{name}: expected real numbers, got {wp.types.type_repr(w.dtype)}")
        host = w.numpy().astype(_SCALARS[scalar_types[-1]])
        return wp.array(host, device=d)
    if w.device != d:
        return wp.clone(w, device=d)
    return w


def packed_upload(arrays: list, device: DeviceLike) -> list:
    """Integer host arrays to int32 device arrays with one copy.

    Args:
        arrays: 1D integer numpy arrays (any lengths, any integer dtype; values must fit int32).
        device: Warp device.

    Returns:
        One ``(len(a),)`` int32 device array per input, views of a single upload (:func:`packed_arrays`;
        an empty input gets an empty array of its own).
    """
    return packed_arrays([(a, wp.int32) for a in arrays], device, alone=2**62)  # the big ones in the block too


PACK_ALIGN = 64
"""Byte alignment of each array in a :func:`packed_arrays` block."""


def packed_arrays(items: list, device: DeviceLike, alone: int = 1 << 20) -> list:
    """Host arrays to device arrays of their Warp types with one copy for all the small ones.

    Args:
        items: ``(host array, Warp dtype)`` pairs; each host array holds the dtype's scalars
            (``(n, 3)`` float32 for ``wp.vec3``, ``(n,)`` int32 for ``wp.int32``; other scalar types
            are converted as ``wp.array(host, dtype)`` would).
        device: Warp device.
        alone: arrays of at least this many bytes get an upload of their own (copying them into the
            block would cost more than the upload it saves).

    Returns:
        One ``(n,)`` device array per item, in order: the small ones views of a single upload,
        each aligned to :data:`PACK_ALIGN` bytes and keeping the block alive.
    """
    out: list = [None] * len(items)
    parts, layout, offset = [], [], 0
    for i, (host, dtype) in enumerate(items):
        scalar, length = getattr(dtype, "_wp_scalar_type_", dtype), getattr(dtype, "_length_", 1)
        flat = np.ascontiguousarray(host, dtype=wp.dtype_to_numpy(scalar)).reshape(-1)
        if flat.nbytes >= alone or not flat.nbytes:
            out[i] = wp.array(flat.reshape(-1, length) if length > 1 else flat, dtype=dtype, device=device)
            continue
        pad = -offset % PACK_ALIGN
        if pad:
            parts.append(np.zeros(pad, np.uint8))
        offset += pad
        parts.append(flat.view(np.uint8))
        layout.append((i, offset, flat.size // length, dtype))
        offset += flat.nbytes
    if layout:
        block = wp.array(np.concatenate(parts), dtype=wp.uint8, device=device)
        for i, start, count, dtype in layout:
            view = wp.array(ptr=block.ptr + start, dtype=dtype, shape=(count,), device=block.device)
            view._ref = block  # keeps the block alive as long as the view
            out[i] = view
    return out
