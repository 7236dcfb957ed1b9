"""A frame's inputs read where they lie: poses, transforms and world vertices from device arrays of
the caller's (torch, JAX, CuPy, Warp), checked by the kernel that copies them.

A scene's setters (:meth:`~warp_ccd._src.scene.scene.Scene.set_poses`, ``set_transforms``,
``set_world_vertices``) given an array already on the scene's device launch one kernel here: it reads
the caller's memory in place (any strides, float32 or float64), writes the scene's own array and checks
every row on the way. A bad row is not reported by a read to the host, which would stall the frame and
move data through it: the kernel records it in :attr:`InputCheck.fault` (on the device: the first row of
the worst problem), the collision pipeline's end-of-frame counter read brings it back with its counters
(the same kernel, two more values), and ``detect()`` raises ValueError naming the setter, the row and the
problem. A bad row is not written: the scene keeps that row's previous value, the rest of the call is
applied. The fault tells of the latest call of each kind: poses (``set_poses``, ``set_transforms``) and
world vertices (``set_world_vertices``) each have a word, emptied when such a call starts, so good inputs
after bad ones clear it.

The checks match the host's (:func:`~warp_ccd._src.scene.scene.transforms_to_poses`): finite numbers, unit
quaternions within ``1e-3``, rigid matrices (orthonormal within ``1e-4``, determinant +1, bottom row
``(0, 0, 0, 1)``), and coordinates the scene's precision resolves at its triangles' size
(:func:`~warp_ccd._src.geometry.precision.needed_precision`, as ``collide()`` refuses them): a limit computed on
the host when the scene is built (:func:`~warp_ccd._src.geometry.precision.coordinate_limit`), which a world
vertex's largest ``|coordinate|``, or a pose's largest ``|translation|`` plus its object's radius, must not pass
(a host array given to a setter is refused at once by the same rule). Poses are copied as given (bit for bit
where the precision is the scene's), as the host's are; a matrix's quaternion is normalised, as
``matrix_to_quat``'s are.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import warp as wp

from ..geometry.precision import FLOAT32_MAX, coordinate_limit
from ..runtime.aliases import DeviceLike

wp.set_module_options({"enable_backward": False, "fuse_fp": False})  # forward only; no FMA: the host's rounding

__all__ = ["FAULT_NONE", "InputCheck"]

FAULT_NONE = 0
"""The fault value of good input."""

_FAULT_BASE = wp.constant(wp.int64(1 << 40))
"""A fault is ``kind << 42 | source << 40 | (2**40 - 1 - row)``: the largest (``atomic_max``) is the worst
problem's first row."""

SOURCES = ("set_poses", "set_transforms", "set_world_vertices")
"""The setters a fault names (``source``: the index here)."""

_NOT_FINITE = wp.constant(wp.int64(5))
_NOT_RIGID = wp.constant(wp.int64(4))
_NOT_UNIT = wp.constant(wp.int64(3))
_BEYOND_ANY = wp.constant(wp.int64(2))
"""Beyond what float64 resolves at the scene's triangle size (or beyond float32's range)."""
_BEYOND_SCENE = wp.constant(wp.int64(1))
"""Beyond what the scene's float32 resolves at its triangle size, within float64's."""

_PROBLEMS = {5: "is not finite", 4: "is not a rigid transform (scale, shear, reflection or bottom row)",
             3: "has a quaternion that is not unit (within 1e-3)"}


@wp.func
def _fault(kind: wp.int64, source: int, row: int) -> wp.int64:
    return (kind * wp.int64(4) + wp.int64(source)) * _FAULT_BASE + (_FAULT_BASE - wp.int64(1) - wp.int64(row))


@wp.func
def _finite(x: wp.float64) -> bool:
    return wp.isfinite(x)


@wp.func
def _beyond(reach: wp.float64, limit: wp.float64, limit64: wp.float64) -> wp.int64:
    """The fault kind of a largest ``|coordinate|`` ``reach``: 0 within ``limit`` (the scene's precision's),
    else whether float64 (``limit64``) would resolve it."""
    if reach <= limit:
        return wp.int64(0)
    if reach <= limit64:
        return _BEYOND_SCENE
    return _BEYOND_ANY


@wp.func
def _radius(radius: wp.array[wp.float64], i: int) -> wp.float64:
    """Object ``i``'s radius, 0 where ``radius`` has none."""
    if i < radius.shape[0]:
        return radius[i]
    return wp.float64(0.0)


@wp.func
def _write_pose(v: Any, out: wp.array2d[Any], i: int, source: int, reach: wp.float64, limit: wp.float64,
                limit64: wp.float64, fault: wp.array[wp.int64]):
    """Pose ``v`` (7 float64) into row ``i`` of ``out`` in its precision, unless a value overflows it
    (a translation beyond float32 in a float32 scene) or the object then reaches beyond ``limit`` (its
    largest ``|translation|`` plus ``reach``, its radius): then nothing is written and the row is a fault."""
    far = wp.float64(0.0)
    for k in range(7):
        x = wp.float64(type(out[i, k])(v[k]))
        if not _finite(x):
            wp.atomic_max(fault, 0, _fault(_NOT_FINITE, source, i))
            return
        if k < 3:
            far = wp.max(far, wp.abs(x))
    kind = _beyond(far + reach, limit, limit64)
    if kind != wp.int64(0):
        wp.atomic_max(fault, 0, _fault(kind, source, i))
        return
    for k in range(7):
        o = out[i, k]
        out[i, k] = type(o)(v[k])


@wp.kernel
def _poses_from_rows_kernel(rows: wp.array2d[Any], out: wp.array2d[Any], source: int, radius: wp.array[wp.float64],
                            limit: wp.float64, limit64: wp.float64, fault: wp.array[wp.int64]):
    """Row ``i`` of ``(N, 7)`` poses ``(px, py, pz, qx, qy, qz, qw)`` into the scene's poses (viewed as
    ``(N, 7)`` scalars), as given; a bad row into ``fault``."""
    i = wp.tid()
    v = wp.vector(dtype=wp.float64, length=7)
    ok = bool(True)
    for k in range(7):
        v[k] = wp.float64(rows[i, k])
        if not _finite(v[k]):
            ok = False
    if not ok:
        wp.atomic_max(fault, 0, _fault(_NOT_FINITE, source, i))
        return
    norm = wp.sqrt(v[3] * v[3] + v[4] * v[4] + v[5] * v[5] + v[6] * v[6])
    if wp.abs(norm - wp.float64(1.0)) > wp.float64(1.0e-3):
        wp.atomic_max(fault, 0, _fault(_NOT_UNIT, source, i))
        return
    _write_pose(v, out, i, source, _radius(radius, i), limit, limit64, fault)


@wp.kernel
def _poses_from_matrices_kernel(m: wp.array3d[Any], out: wp.array2d[Any], source: int, radius: wp.array[wp.float64],
                                limit: wp.float64, limit64: wp.float64, fault: wp.array[wp.int64]):
    """Matrix ``i`` of ``(N, 4, 4)`` rigid transforms into the scene's poses (``(N, 7)`` scalars);
    a bad one into ``fault``."""
    i = wp.tid()
    a = wp.mat44d()
    ok = bool(True)
    for r in range(4):
        for c in range(4):
            a[r, c] = wp.float64(m[i, r, c])
            if not _finite(a[r, c]):
                ok = False
    if not ok:
        wp.atomic_max(fault, 0, _fault(_NOT_FINITE, source, i))
        return
    tol = wp.float64(1.0e-4)
    rot = wp.mat33d(a[0, 0], a[0, 1], a[0, 2], a[1, 0], a[1, 1], a[1, 2], a[2, 0], a[2, 1], a[2, 2])
    gram = wp.transpose(rot) * rot
    worst = wp.abs(a[3, 0]) + wp.float64(0.0)
    worst = wp.max(worst, wp.max(wp.abs(a[3, 1]), wp.abs(a[3, 2])))
    worst = wp.max(worst, wp.abs(a[3, 3] - wp.float64(1.0)))
    for r in range(3):
        for c in range(3):
            expect = wp.float64(0.0)
            if r == c:
                expect = wp.float64(1.0)
            worst = wp.max(worst, wp.abs(gram[r, c] - expect))
    if worst > tol or wp.determinant(rot) < wp.float64(0.0):
        wp.atomic_max(fault, 0, _fault(_NOT_RIGID, source, i))
        return
    q = wp.normalize(wp.quat_from_matrix(rot))
    v = wp.vector(a[0, 3], a[1, 3], a[2, 3], q[0], q[1], q[2], q[3])
    _write_pose(v, out, i, source, _radius(radius, i), limit, limit64, fault)


@wp.kernel
def _vertices_kernel(src: wp.array2d[Any], out: wp.array2d[Any], source: int, radius: wp.array[wp.float64],
                     limit: wp.float64, limit64: wp.float64, fault: wp.array[wp.int64]):
    """Vertex ``i`` of ``(V, 3)`` world vertices into the scene's (``(V, 3)`` scalars); a vertex not
    finite (or beyond float32, in a float32 scene), or with a coordinate beyond ``limit``, into ``fault``
    (``radius``: unused, the poses' argument)."""
    i = wp.tid()
    far = wp.float64(0.0)
    for k in range(3):
        x = wp.float64(type(out[i, k])(src[i, k]))
        if not _finite(x):
            wp.atomic_max(fault, 0, _fault(_NOT_FINITE, source, i))
            return
        far = wp.max(far, wp.abs(x))
    kind = _beyond(far, limit, limit64)
    if kind != wp.int64(0):
        wp.atomic_max(fault, 0, _fault(kind, source, i))
        return
    for k in range(3):
        o = out[i, k]
        out[i, k] = type(o)(src[i, k])


def _fault_value(kind: int, source: int, row: int) -> int:
    """The fault value the kernels write (:func:`_fault`), on the host."""
    base = 1 << 40
    return (kind * 4 + source) * base + (base - 1 - row)


class InputCheck:
    """The faults of a scene's device-side inputs, and the kernels that copy and check them.

    Args:
        device: the scene's device.
        precision: the scene's precision.
        size: the scene's typical triangle size
            (:func:`~warp_ccd._src.geometry.precision.triangle_size`; 0: only float32's range is checked).
        object_radius: ``(N,)`` each object's largest distance of a vertex from its origin, scaled (None:
            none, counted as 0).

    Attributes:
        fault: ``(2,)`` int64 on the device, one word for poses (``set_poses``, ``set_transforms``) and
            one for world vertices: 0, or the first bad row of the worst problem of the latest call of
            that kind, encoded (:meth:`message` decodes it).
        limit: the largest ``|coordinate|`` the scene's precision resolves at ``size``
            (:func:`~warp_ccd._src.geometry.precision.coordinate_limit`).
        limit64: float64's.
        object_radius, object_radius_np: ``(N,)`` float64 ``object_radius`` on the device and on the host.
    """

    POSES = 0
    VERTICES = 1

    def __init__(self, device: DeviceLike, *, precision: str = "float32", size: float = 0.0,
                 object_radius=None) -> None:
        self.device = wp.get_device(device)
        self.precision = precision
        self.size = float(size)
        self.limit = coordinate_limit(size, precision)
        self.limit64 = coordinate_limit(size, "float64")
        self.fault = wp.zeros(2, dtype=wp.int64, device=self.device)
        self._words = [self.fault[k : k + 1] for k in range(2)]
        self.object_radius_np = np.asarray([] if object_radius is None else object_radius, np.float64)
        self.object_radius = wp.array(self.object_radius_np, dtype=wp.float64, device=self.device)

    def _launch(self, kernel, src: wp.array, out: wp.array, source: str, word: int) -> None:
        fault = self._words[word]
        fault.zero_()  # this call's inputs replace the last ones of their kind: so does their fault
        if src.shape[0]:
            wp.launch(kernel, dim=src.shape[0], device=self.device,
                      inputs=[src, out, SOURCES.index(source), self.object_radius, wp.float64(self.limit),
                              wp.float64(self.limit64), fault])

    def poses(self, rows: wp.array, out: wp.array, source: str) -> None:
        """Enqueues the copy of ``(N, 7)`` ``rows`` into ``out`` (poses viewed as ``(N, 7)`` scalars).

        Args:
            rows: ``(N, 7)`` float32 or float64 on the device.
            out: the scene's poses as ``(N, 7)`` scalars.
            source: the setter's name (:data:`SOURCES`).
        """
        self._launch(_poses_from_rows_kernel, rows, out, source, self.POSES)

    def matrices(self, m: wp.array, out: wp.array, source: str) -> None:
        """Enqueues the conversion of ``(N, 4, 4)`` rigid transforms into ``out`` (``(N, 7)`` scalars).

        Args:
            m: ``(N, 4, 4)`` float32 or float64 on the device.
            out: the scene's poses as ``(N, 7)`` scalars.
            source: the setter's name (:data:`SOURCES`).
        """
        self._launch(_poses_from_matrices_kernel, m, out, source, self.POSES)

    def vertices(self, src: wp.array, out: wp.array, source: str) -> None:
        """Enqueues the copy of ``(V, 3)`` world vertices into ``out`` (``(V, 3)`` scalars).

        Args:
            src: ``(V, 3)`` float32 or float64 on the device.
            out: the scene's world vertices as ``(V, 3)`` scalars.
            source: the setter's name (:data:`SOURCES`).
        """
        self._launch(_vertices_kernel, src, out, source, self.VERTICES)

    def _beyond(self, kind: int, vertex: bool) -> str:
        """The problem of a vertex's coordinate (or a pose's object) beyond the limit of ``kind``
        (:data:`_BEYOND_SCENE`, :data:`_BEYOND_ANY`)."""
        what = "has a coordinate" if vertex else "places its object"
        if kind == _BEYOND_SCENE:
            return (f"{what} beyond {self.limit:.3g}, what float32 resolves at this scene's triangle size "
                    f"({self.size:.3g}): use precision='float64'")
        if self.limit64 >= FLOAT32_MAX:
            return f"{what} beyond float32's range ({FLOAT32_MAX:.3g}, which boxes use)"
        return (f"{what} beyond {self.limit64:.3g}, what float64 resolves at this scene's triangle size "
                f"({self.size:.3g}): move the scene nearer the origin")

    def message(self, value: int) -> str | None:
        """What a fault value says, or None for good input."""
        value = int(value)
        if value == FAULT_NONE:
            return None
        base = 1 << 40
        high, rest = divmod(value, base)
        kind, source = divmod(high, 4)
        row = base - 1 - rest
        name = SOURCES[source] if source < len(SOURCES) else "input"
        what = "vertex" if name == "set_world_vertices" else "row"
        far = kind in (_BEYOND_SCENE, _BEYOND_ANY)
        problem = self._beyond(kind, what == "vertex") if far else _PROBLEMS.get(kind, "is bad")
        return f"{name}: {what} {row} {problem}"

    def far_row(self, reach, source: str) -> str | None:
        """The message of the first row of host input whose largest ``|coordinate|`` ``reach`` passes the limit
        (the device's check, for arrays checked on the host), or None.

        Args:
            reach: ``(N,)`` float64: a vertex's largest ``|coordinate|``, or a pose's largest ``|translation|``
                plus its object's radius.
            source: the setter's name (:data:`SOURCES`).
        """
        far = np.flatnonzero(~(np.asarray(reach, np.float64) <= self.limit))
        if not len(far):
            return None
        row = int(far[0])
        kind = int(_BEYOND_SCENE if reach[row] <= self.limit64 else _BEYOND_ANY)
        return self.message(_fault_value(kind, SOURCES.index(source), row))

    def clear(self) -> None:
        """Forgets the faults (a memset on the device)."""
        self.fault.zero_()

    def check(self) -> None:
        """Waits for the device and raises the fault now (for a scene used without a pipeline, whose
        frame would read it with its counters).

        Raises:
            ValueError: naming the setter, the row and the problem.
        """
        self.raise_for(int(self.fault.numpy().max()))

    def raise_for(self, value: int) -> None:
        """Raises ValueError for a fault value read by the caller (and clears the faults); nothing for 0.

        Args:
            value: the largest of :attr:`fault`'s words, as read.

        Raises:
            ValueError: naming the setter, the row and the problem.
        """
        msg = self.message(value)
        if msg is not None:
            self.clear()
            raise ValueError(msg)
