"""Which object pairs may collide at all: worlds, collision groups and masks, excluded pairs.

Three filters, each optional, all applied in the broad phase (an excluded pair never reaches the mid
phase, so it costs one test of a few integers):

* **Worlds** (``world``, one id per object): objects of different worlds never pair; world ``-1``
  pairs with every world (newton's convention), for a ground or a fixture that thousands of
  simulated environments share. Ids are any integers ``>= -1``; the broad phase numbers the worlds
  it finds ``0 .. W - 1`` (:attr:`CollisionFilter.object_world_slot`) and sorts and sweeps all of them
  in one launch: a world's slot is the high part of every sort key of its objects
  (:class:`~warp_ccd._src.broadphase.sap.BroadPhaseSAP`), so worlds that overlap in space cost no more
  than worlds set side by side. Objects of world ``-1`` are tested against every box
  (its list of big boxes): ``O(N)`` each, so keep them few.
* **Groups and masks** (``group``, ``mask``: 32-bit masks per object): a pair collides when
  ``group[a] & mask[b]`` and ``group[b] & mask[a]`` are both non-zero (Bullet's and PhysX's rule).
  Defaults: every bit set in both, so every pair collides.
* **Excluded pairs** (``exclude_pairs``, ``(E, 2)`` object indices, in either order): the pairs meant
  to touch (a robot's adjacent links, a part and its fastener). Kept on the device as sorted 64-bit
  keys ``min << 32 | max``; each candidate pair is looked up by binary search, ``O(log E)``.

Kernels call :func:`pair_allowed` with the :class:`PairFilter` struct that
:attr:`CollisionFilter.device_filter` holds; a scene without filters has none (``Scene.collision_filter``
is None) and the broad phase passes an inactive struct whose test is one branch.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from ..runtime.aliases import ArrayLike, DeviceLike
from ..runtime.arrays import host_array

wp.set_module_options({"enable_backward": False})  # forward kernels only

__all__ = ["ALL_GROUPS", "WORLDS_MAX", "CollisionFilter", "PairFilter", "pair_allowed"]

ALL_GROUPS = 0xFFFFFFFF
"""Default group and mask of an object: every bit set (it collides with every object)."""

WORLDS_MAX = 1 << 20
"""Most distinct worlds of one scene (1,048,576): a world's slot takes the high bits (21 at most) of the
broad phase's 31-bit sort keys, beside at least 2 bits of grid cells and 8 of sweep order."""


@wp.struct
class PairFilter:
    """The filters on the device (see module docs); ``use_world``, ``use_groups`` and
    ``num_exclude`` say which are on (an inactive filter's arrays hold one unused entry)."""

    object_world: wp.array[wp.int32]
    """``(N,)`` world slot of each object, ``-1`` for the objects that pair with every world."""
    object_group: wp.array[wp.int32]
    """``(N,)`` collision group bits (a uint32 read as int32)."""
    object_mask: wp.array[wp.int32]
    """``(N,)`` collision mask bits."""
    exclude_key: wp.array[wp.int64]
    """``(E,)`` sorted keys ``min << 32 | max`` of the excluded pairs."""
    num_exclude: int
    use_world: int
    use_groups: int


@wp.func
def pair_allowed(f: PairFilter, a: int, b: int) -> bool:
    """Whether objects ``a`` and ``b`` (``a != b``) may collide under filter ``f``."""
    if f.use_world != 0:
        wa = f.object_world[a]
        wb = f.object_world[b]
        if wa != wb and wa >= 0 and wb >= 0:
            return False
    if f.use_groups != 0:
        if (f.object_group[a] & f.object_mask[b]) == 0 or (f.object_group[b] & f.object_mask[a]) == 0:
            return False
    if f.num_exclude > 0:
        key = (wp.int64(wp.min(a, b)) << wp.int64(32)) | wp.int64(wp.max(a, b))
        lo = int(0)
        hi = f.num_exclude
        while lo < hi:
            mid = (lo + hi) // 2
            if f.exclude_key[mid] < key:
                lo = mid + 1
            else:
                hi = mid
        if lo < f.num_exclude:
            if f.exclude_key[lo] == key:
                return False
    return True


def _integer_ids(values, name: str, n: int) -> np.ndarray:
    """``values`` as an ``(n,)`` int64 array of integers, or ValueError naming ``name``."""
    arr = host_array(values, name)
    if arr.ndim == 0:
        arr = np.broadcast_to(arr, (n,))
    if arr.shape != (n,):
        raise ValueError(f"{name}: expected ({n},) values, one per object, got shape {arr.shape}")
    if arr.size and arr.dtype.kind not in "iu":
        if arr.dtype.kind == "f" and np.isfinite(arr).all() and (arr == np.round(arr)).all():
            pass
        else:
            raise ValueError(f"{name}: expected integers, got {arr.dtype}")
    if arr.size and arr.dtype.kind in "uf" and np.abs(arr).max() > 2**62:
        bad = int(np.argmax(np.abs(arr) > 2**62))
        raise ValueError(f"{name}: object {bad} has {arr[bad]}, out of range")
    return arr.astype(np.int64)


def _bits(values, name: str, n: int) -> np.ndarray:
    """32-bit masks as int32 (their bits), or ValueError."""
    arr = _integer_ids(values, name, n)
    if arr.size and (arr.min() < -(1 << 31) or arr.max() > ALL_GROUPS):
        bad = int(np.argmax((arr < -(1 << 31)) | (arr > ALL_GROUPS)))
        raise ValueError(f"{name}: object {bad} has {arr[bad]}, not a 32-bit mask")
    return (arr & ALL_GROUPS).astype(np.uint32).view(np.int32)


def _pairs(values, n: int) -> np.ndarray:
    """Excluded pairs as sorted unique int64 keys ``min << 32 | max``, or ValueError."""
    arr = host_array(values, "exclude_pairs")
    if arr.shape == (0,) or arr.shape == (0, 2):
        return np.zeros(0, np.int64)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"exclude_pairs: expected (E, 2) object indices, got shape {arr.shape}")
    if arr.dtype.kind not in "iu":
        raise ValueError(f"exclude_pairs: expected integer object indices, got {arr.dtype}")
    arr = arr.astype(np.int64)
    bad = ((arr < 0) | (arr >= n)).any(axis=1)
    if bad.any():
        i = int(np.argmax(bad))
        raise ValueError(f"exclude_pairs: row {i} {arr[i].tolist()} names an object outside [0, {n})")
    same = arr[:, 0] == arr[:, 1]
    if same.any():
        i = int(np.argmax(same))
        raise ValueError(f"exclude_pairs: row {i} pairs object {arr[i, 0]} with itself")
    return np.unique((arr.min(axis=1) << 32) | arr.max(axis=1))


class CollisionFilter:
    """Worlds, groups and masks, excluded pairs of ``N`` objects (see module docs), validated on the
    host once and held on one device.

    Args:
        num_objects: ``N``.
        world: ``(N,)`` integer world id of each object (``>= -1``; ``-1``: pairs with every world), or
            None (one world).
        group: ``(N,)`` 32-bit collision group bits of each object, or None (every bit set).
        mask: ``(N,)`` 32-bit collision mask bits of each object (the groups it collides with), or None
            (every bit set).
        exclude_pairs: ``(E, 2)`` object indices of pairs that never collide, or None.
        device: Warp device.

    Attributes:
        object_world: ``(N,)`` int64 world ids as given (zeros without worlds).
        object_world_slot: ``(N,)`` int32 world slots ``0 .. W - 1`` (ids in increasing order),
            ``-1`` for world ``-1``.
        world_ids: ``(W,)`` int64 the world id of each slot.
        num_worlds: ``W`` (1 without worlds).
        object_group, object_mask: ``(N,)`` uint32.
        exclude_pairs: ``(E, 2)`` int32 the excluded pairs, ``a < b``, rows sorted, unique.
        device_filter: the :class:`PairFilter` kernels take.

    Raises:
        ValueError: naming the argument and the first bad object or row.
    """

    def __init__(self, num_objects: int, *, world: ArrayLike | None = None, group: ArrayLike | None = None,
                 mask: ArrayLike | None = None, exclude_pairs: ArrayLike | None = None,
                 device: DeviceLike = None) -> None:
        n = int(num_objects)
        if n < 0:
            raise ValueError(f"num_objects must be >= 0, got {num_objects!r}")
        d = wp.get_device(device)
        self.device = d
        self.num_objects = n
        self.use_world = world is not None
        self.use_groups = group is not None or mask is not None
        if self.use_world:
            ids = _integer_ids(world, "world", n)
            if ids.size and ids.min() < -1:
                bad = int(np.argmin(ids))
                raise ValueError(f"world: object {bad} has world {ids[bad]}; ids are >= 0, or -1 for every world")
            self.world_ids, slot = np.unique(ids[ids >= 0], return_inverse=True)
            if len(self.world_ids) > WORLDS_MAX:
                raise ValueError(f"world: {len(self.world_ids)} distinct worlds, at most {WORLDS_MAX}")
            self.object_world = ids
            self.object_world_slot = np.full(n, -1, np.int32)
            self.object_world_slot[ids >= 0] = slot.reshape(-1)
        else:
            self.world_ids = np.zeros(1, np.int64)
            self.object_world = np.zeros(n, np.int64)
            self.object_world_slot = np.zeros(n, np.int32)
        self.num_worlds = max(1, len(self.world_ids))
        group_bits = _bits(ALL_GROUPS if group is None else group, "group", n)
        mask_bits = _bits(ALL_GROUPS if mask is None else mask, "mask", n)
        self.object_group = group_bits.view(np.uint32)
        self.object_mask = mask_bits.view(np.uint32)
        keys = np.zeros(0, np.int64) if exclude_pairs is None else _pairs(exclude_pairs, n)
        self.exclude_pairs = np.stack([keys >> 32, keys & 0xFFFFFFFF], axis=1).astype(np.int32).reshape(-1, 2)

        def dev(a: np.ndarray, dtype) -> wp.array:
            return wp.array(a if a.size else np.zeros(1, a.dtype), dtype=dtype, device=d)

        f = PairFilter()
        f.object_world = dev(self.object_world_slot, wp.int32)
        f.object_group = dev(group_bits, wp.int32)
        f.object_mask = dev(mask_bits, wp.int32)
        f.exclude_key = dev(keys, wp.int64)
        f.num_exclude = len(keys)
        f.use_world = int(self.use_world)
        f.use_groups = int(self.use_groups)
        self.device_filter = f

    @property
    def active(self) -> bool:
        """Whether any filter is on (else every pair of overlapping boxes goes on)."""
        return self.use_world or self.use_groups or len(self.exclude_pairs) > 0

    @property
    def num_global(self) -> int:
        """Objects of world ``-1``."""
        return int((self.object_world < 0).sum()) if self.use_world else 0

    def allowed(self, pairs: np.ndarray) -> np.ndarray:
        """The host's :func:`pair_allowed`, vectorised (for references and reports).

        Args:
            pairs: ``(K, 2)`` object indices.

        Returns:
            ``(K,)`` bool.
        """
        p = np.asarray(pairs, np.int64).reshape(-1, 2)
        a, b = p[:, 0], p[:, 1]
        ok = np.ones(len(p), bool)
        if self.use_world:
            wa, wb = self.object_world_slot[a], self.object_world_slot[b]
            ok &= (wa == wb) | (wa < 0) | (wb < 0)
        if self.use_groups:
            g, m = self.object_group, self.object_mask
            ok &= ((g[a] & m[b]) != 0) & ((g[b] & m[a]) != 0)
        if len(self.exclude_pairs):
            keys = (np.minimum(a, b) << 32) | np.maximum(a, b)
            ex = (self.exclude_pairs[:, 0].astype(np.int64) << 32) | self.exclude_pairs[:, 1]
            ok &= ~np.isin(keys, ex)
        return ok

    def pair_world(self, pairs: np.ndarray) -> np.ndarray:
        """The world id of each object pair: its objects' (the non-global one's, when one is in world
        ``-1``; ``-1`` when both are).

        Args:
            pairs: ``(K, 2)`` object indices of allowed pairs.

        Returns:
            ``(K,)`` int64 world ids.
        """
        p = np.asarray(pairs, np.int64).reshape(-1, 2)
        return np.maximum(self.object_world[p[:, 0]], self.object_world[p[:, 1]])


def inactive_filter(device: DeviceLike) -> PairFilter:
    """A :class:`PairFilter` that lets every pair through (for scenes without filters), one per device."""
    d = wp.get_device(device)
    cached = _INACTIVE.get(d.alias)
    if cached is None:
        cached = CollisionFilter(0, device=d).device_filter
        _INACTIVE[d.alias] = cached
    return cached


_INACTIVE: dict = {}
