"""USD export: a scene's animation, with colliding objects in colour.

Stage layout (``defaultPrim`` is ``/World``)::

    /World                       Xform
      /World/Objects             PointInstancer (rigid scenes)
        /World/Objects/Prototypes          Scope
          /World/Objects/Prototypes/shape_0  Mesh, one per shape, in local coordinates
      /World/Segments            BasisCurves (optional): the intersection segments of each frame,
                                 two points each, points and counts time-sampled
      /World/Bounds              BasisCurves (optional): each object's AABB, 12 edges as 4 linear
                                 polylines (16 points per box), points time-sampled

A rigid scene is one ``UsdGeom.PointInstancer``: ``protoIndices`` (static), and ``positions``,
``orientations`` (``quath``), ``scales``, ``extent`` and the per-instance
``primvars:displayColor`` time-sampled at every frame. The colour primvar has ``vertex``
interpolation: on a PointInstancer, ``vertex`` (like ``varying``) assigns the ``i``-th element to
instance ``i`` (USD's PointInstancer schema, "Primvars on PointInstancer"), whereas ``constant``
and ``uniform`` would give every instance the whole array. Colours are sampled at every frame,
not only when they change, because readers interpolate between samples.

A deforming scene (``scene.deforming``) is one ``UsdGeom.Mesh`` per object under
``/World/Objects`` with time-sampled ``points``, ``extent`` and a ``constant`` displayColor.

One time code per frame: time code ``frame_index``, ``timeCodesPerSecond == framesPerSecond ==
fps``. The stage is built in memory and written when the writer closes: first to a hidden
temporary file in the destination folder, which is then renamed over the destination
(:class:`~warp_ccd._src.output.PendingFile`), so an interrupted run never leaves a partial file at
``path``. The destination is checked (extension, folder, a probe file) when the writer is
created, before any simulation runs.

Cost per frame of a rigid scene: a few O(N) numpy operations and five array copies into USD, no
Python loop over objects; the optional wireframes add one kernel (one thread per object) and a
copy of ``16 N`` points. A deforming scene costs a Python loop over its objects (one prim each).
``pxr`` is imported inside functions only, so the rest of the library works without usd-core.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import warp as wp

from ..geometry.box import vertex_bounds
from ..output import PendingFile, check_output_path
from ..runtime.aliases import ArrayLike, PathLike
from ..runtime.checks import integer_option, number_option

if TYPE_CHECKING:
    from ..pipeline.result import CollisionResult
    from ..scene.scene import Scene

wp.set_module_options({"enable_backward": False})  # forward kernels only

__all__ = [
    "COLOR_COLLIDING",
    "COLOR_FREE",
    "COLOR_SEGMENT",
    "STAGE_EXTENSIONS",
    "UsdAnimationWriter",
    "segment_points",
    "validate_stage_path",
]

STAGE_EXTENSIONS = (".usd", ".usdc", ".usda")
"""Accepted extensions: ``.usd`` and ``.usdc`` are written as binary crate files, ``.usda`` as text."""

COLOR_FREE = (0.62, 0.62, 0.62)
"""displayColor (linear RGB in [0, 1]) of an object that touches nothing."""

COLOR_SEGMENT = (1.0, 0.9, 0.1)
"""displayColor of the intersection segment markers."""

COLOR_COLLIDING = (0.95, 0.22, 0.08)
"""displayColor (linear RGB in [0, 1]) of an object whose surface intersects another's."""

COLOR_BOUNDS = (0.25, 0.55, 0.95)
"""displayColor of the AABB wireframes."""

# The 12 edges of a box as 4 polylines through its corners, numbered 4*x + 2*y + z (x, y, z in
# {0, 1}): the x = 0 square, one edge across, the x = 1 square (9 edges in 10 points), then the
# other three edges across (2 points each): 16 points per box instead of 24 for 12 segments.
_BOX_PATH = np.array([0, 1, 3, 2, 0, 4, 5, 7, 6, 4, 1, 5, 3, 7, 2, 6], dtype=np.int64)
_BOX_CURVE_COUNTS = np.array([10, 2, 2, 2], dtype=np.int32)


def validate_stage_path(path) -> tuple[str, str]:
    """Checks that a USD file can be written at ``path``, without writing it.

    Args:
        path: destination file (str or path-like); its extension picks the format.

    Returns:
        ``(absolute path, extension)``, the extension lower-case (one of :data:`STAGE_EXTENSIONS`).

    Raises:
        ValueError: the extension is not ``.usd``, ``.usdc`` or ``.usda``; the folder does not
            exist or no file can be created in it; ``path`` is a folder or a read-only file.
    """
    return check_output_path(path, STAGE_EXTENSIONS, "USD")


def segment_points(segments) -> np.ndarray:
    """End points of the finite ones of ``(M, 2, 3)`` intersection segments (coplanar contacts have
    none: NaN), as ``(2K, 3)`` float32 rows for a linear ``BasisCurves`` of two points a curve."""
    seg = np.asarray(segments, dtype=np.float64).reshape(-1, 2, 3)
    return np.ascontiguousarray(seg[np.isfinite(seg).all(axis=(1, 2))].astype(np.float32).reshape(-1, 3))


def _vec3f_array(a: np.ndarray):
    from pxr import Vt

    return Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(a, dtype=np.float32).reshape(-1, 3))


def _extent(lower: np.ndarray, upper: np.ndarray):
    from pxr import Vt

    return Vt.Vec3fArray.FromNumpy(np.stack([lower, upper]).astype(np.float32))


@wp.kernel
def _usd_box_polyline_kernel(
    world_vertex: wp.array[wp.vec3],
    object_vertex_start: wp.array[wp.int32],
    box_path_corner: wp.array[wp.int32],
    # Outputs
    bounds_lower: wp.array[wp.vec3],
    bounds_upper: wp.array[wp.vec3],
    box_point: wp.array[wp.vec3],
):
    """One thread per object: its AABB from its world vertices, and the 16 polyline points of the box.

    ``box_path_corner`` holds 16 corner numbers ``4*x + 2*y + z``; ``box_point`` has ``16 * N`` entries.
    """
    i = wp.tid()
    lo, hi = vertex_bounds(world_vertex, object_vertex_start[i], object_vertex_start[i + 1])
    bounds_lower[i] = lo
    bounds_upper[i] = hi
    for k in range(16):
        c = box_path_corner[k]
        x = lo[0]
        y = lo[1]
        z = lo[2]
        if (c >> 2) & 1 == 1:
            x = hi[0]
        if (c >> 1) & 1 == 1:
            y = hi[1]
        if c & 1 == 1:
            z = hi[2]
        box_point[16 * i + k] = wp.vec3(x, y, z)


class UsdAnimationWriter:
    """Writes the animation of a :class:`~warp_ccd._src.scene.scene.Scene` to a USD file, frame by frame.

    The destination is checked here, before any simulation runs; the file appears at ``path``
    only when :meth:`close` succeeds (use the writer as a context manager: on an exception the
    partial data is discarded and an existing file at ``path`` is left untouched).

    Example::

        with UsdAnimationWriter("collisions.usd", scene) as writer:
            for frame in range(120):
                scene.advance(1 / 60)
                writer.add_frame(frame, pipe.detect())

    Args:
        path: destination file; ``.usd`` / ``.usdc`` binary, ``.usda`` text.
        scene: the scene whose poses (or world vertices, when deforming) are recorded.
        fps: frames per second of the animation (time codes per second as well).
        aabb: also write each object's axis-aligned bounding box as a wireframe.
        segments: also write the intersection segments of each frame as line markers (the
            pipeline must be built with ``segments=True``).
        up_axis: ``"Y"`` or ``"Z"``, stage metadata for viewers.
        meters_per_unit: length of one scene unit in metres, stage metadata.

    Raises:
        ValueError: bad path (see :func:`validate_stage_path`) or bad option.
    """

    def __init__(self, path: PathLike, scene: Scene, *, fps: float = 60.0, aabb: bool = False, segments: bool = False,
                 up_axis: str = "Y", meters_per_unit: float = 1.0) -> None:
        self.path, self._ext = validate_stage_path(path)
        number_option("fps", fps, low=0.0, low_open=True)
        if up_axis not in ("Y", "Z"):
            raise ValueError(f"up_axis must be 'Y' or 'Z', got {up_axis!r}")
        number_option("meters_per_unit", meters_per_unit, low=0.0, low_open=True)
        for name in ("object_pose", "object_scale", "world_vertex", "shape_meshes"):
            if not hasattr(scene, name):
                raise TypeError(f"scene: expected a warp_ccd.Scene, got {type(scene).__name__}")
        from pxr import Usd  # here, not at close(): a missing usd-core fails before any simulation

        self._pending = PendingFile(self.path)

        self.scene = scene
        self.fps = float(fps)
        self.aabb = bool(aabb)
        self.segments = bool(segments)
        self.deforming = bool(getattr(scene, "deforming", False))
        self.num_objects = int(scene.num_objects)
        self.num_frames = 0
        self.closed = False
        self._first = None
        self._last = None
        self._palette = np.array([COLOR_FREE, COLOR_COLLIDING], dtype=np.float32)
        self._box_point = None

        self._object_shape = np.asarray(scene.object_shape_np, dtype=np.int32)
        self._vertex_start = np.asarray(scene.object_vertex_start_np, dtype=np.int64)
        # Bounding radius of each shape (local units), for a cheap conservative instancer extent.
        self._shape_radius = np.array(
            [float(np.linalg.norm(v, axis=1).max()) if len(v) else 0.0 for v, _ in scene.shape_meshes],
            dtype=np.float32,
        )

        self.stage = Usd.Stage.CreateInMemory(f"warp_ccd{self._ext}")
        self._build_stage(up_axis, meters_per_unit)

    # ------------------------------------------------------------------ stage layout
    def _build_stage(self, up_axis: str, meters_per_unit: float) -> None:
        from pxr import Gf, Sdf, UsdGeom, Vt

        stage = self.stage
        scene = self.scene
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y if up_axis == "Y" else UsdGeom.Tokens.z)
        UsdGeom.SetStageMetersPerUnit(stage, float(meters_per_unit))
        stage.SetTimeCodesPerSecond(self.fps)
        stage.SetFramesPerSecond(self.fps)
        stage.SetStartTimeCode(0.0)
        stage.SetEndTimeCode(0.0)
        world = UsdGeom.Xform.Define(stage, "/World")
        stage.SetDefaultPrim(world.GetPrim())
        stage.GetRootLayer().documentation = (
            f"warp_ccd collision animation: {self.num_objects} objects; "
            f"displayColor {COLOR_COLLIDING} while an object's surface intersects another's, "
            f"{COLOR_FREE} otherwise."
        )

        def define_mesh(path: str, vertices: np.ndarray, triangles: np.ndarray) -> UsdGeom.Mesh:
            mesh = UsdGeom.Mesh.Define(stage, path)
            mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
            mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
            mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(triangles), 3, np.int32)))
            indices = np.ascontiguousarray(triangles, np.int32).reshape(-1)
            mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(indices))
            if vertices is not None:
                mesh.CreatePointsAttr(_vec3f_array(vertices))
                mesh.CreateExtentAttr(_extent(vertices.min(axis=0), vertices.max(axis=0)))
            return mesh

        if self.deforming:
            UsdGeom.Xform.Define(stage, "/World/Objects")
            width = len(str(max(self.num_objects - 1, 0)))
            self._meshes = []
            self._mesh_colors = []
            for i in range(self.num_objects):
                tri = scene.shape_meshes[self._object_shape[i]][1]
                mesh = define_mesh(f"/World/Objects/object_{i:0{width}d}", None, tri)
                color = mesh.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant)
                self._meshes.append(mesh)
                self._mesh_colors.append(color)
        else:
            inst = UsdGeom.PointInstancer.Define(stage, "/World/Objects")
            UsdGeom.Scope.Define(stage, "/World/Objects/Prototypes")
            targets = []
            for k, (v, t) in enumerate(scene.shape_meshes):
                mesh = define_mesh(f"/World/Objects/Prototypes/shape_{k}", np.asarray(v, np.float32), t)
                targets.append(mesh.GetPath())
            inst.CreatePrototypesRel().SetTargets(targets)
            inst.CreateProtoIndicesAttr(Vt.IntArray.FromNumpy(self._object_shape))
            self._positions = inst.CreatePositionsAttr()
            self._orientations = inst.CreateOrientationsAttr()
            self._scales = inst.CreateScalesAttr()
            self._instancer_extent = inst.CreateExtentAttr()
            self._colors = UsdGeom.PrimvarsAPI(inst).CreatePrimvar(
                "displayColor", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.vertex
            )

        if self.aabb:
            curves = UsdGeom.BasisCurves.Define(stage, "/World/Bounds")
            curves.CreateTypeAttr(UsdGeom.Tokens.linear)
            counts = np.tile(_BOX_CURVE_COUNTS, self.num_objects)
            curves.CreateCurveVertexCountsAttr(Vt.IntArray.FromNumpy(counts))
            curves.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set(Vt.Vec3fArray([Gf.Vec3f(*COLOR_BOUNDS)]))
            self._bounds_points = curves.CreatePointsAttr()
            self._bounds_extent = curves.CreateExtentAttr()
            self._bounds_widths = curves.CreateWidthsAttr()
            curves.SetWidthsInterpolation(UsdGeom.Tokens.constant)

        if self.segments:
            marks = UsdGeom.BasisCurves.Define(stage, "/World/Segments")
            marks.CreateTypeAttr(UsdGeom.Tokens.linear)
            marks.CreateDisplayColorPrimvar(UsdGeom.Tokens.constant).Set(Vt.Vec3fArray([Gf.Vec3f(*COLOR_SEGMENT)]))
            self._segment_counts = marks.CreateCurveVertexCountsAttr()
            self._segment_points = marks.CreatePointsAttr()
            self._segment_extent = marks.CreateExtentAttr()
            radius = self._shape_radius[self._object_shape]
            widths = radius * self.scene.object_scale_np if self.num_objects else [1.0]
            marks.CreateWidthsAttr(Vt.FloatArray([max(float(np.median(widths)) * 0.03, 1e-6)]))
            marks.SetWidthsInterpolation(UsdGeom.Tokens.constant)

    # ------------------------------------------------------------------ frames
    def _colliding(self, result) -> np.ndarray:
        flags = getattr(result, "colliding", result)
        if flags is None:
            return np.zeros(self.num_objects, bool)
        flags = np.asarray(flags)
        if flags.shape != (self.num_objects,):
            raise ValueError(f"colliding: expected shape ({self.num_objects},), got {flags.shape}")
        return flags.astype(bool)

    def add_frame(self, frame_index: int, result: CollisionResult | ArrayLike | None = None) -> None:
        """Records the scene's current poses and the frame's collision flags at time code ``frame_index``.

        Args:
            frame_index: integer frame number (>= 0); time code ``frame_index`` (seconds:
                ``frame_index / fps``). Adding the same index again overwrites that frame.
            result: a :class:`~warp_ccd._src.pipeline.pipeline.CollisionResult` (its ``colliding``), an
                ``(N,)`` bool array, or None (nothing collides).

        Raises:
            ValueError: the writer is closed, a bad index, or flags of the wrong shape.
        """
        if self.closed:
            raise ValueError("add_frame: the writer is closed")
        integer_option("add_frame: frame_index", frame_index, low=0)
        from pxr import Sdf, Usd

        colliding = self._colliding(result)
        time = Usd.TimeCode(float(frame_index))
        colors = self._palette[colliding.view(np.uint8)]  # (N, 3): one colour per object
        with Sdf.ChangeBlock():
            if self.deforming:
                self._write_meshes(time, self.scene.world_vertex32().numpy(), colors)
            else:
                self._write_instancer(time, colors)
            if self.aabb:
                self._write_bounds(time)
            if self.segments:
                self._write_segments(time, result)
        self.num_frames += 1
        f = int(frame_index)
        self._first = f if self._first is None else min(self._first, f)
        self._last = f if self._last is None else max(self._last, f)

    def _write_instancer(self, time, colors: np.ndarray) -> None:
        from pxr import Vt

        pose = self.scene.object_pose.numpy().reshape(-1, 7)
        scale = self.scene.object_scale.numpy().astype(np.float32).reshape(-1)
        position = np.ascontiguousarray(pose[:, :3], dtype=np.float32)
        # wp.transform stores (x, y, z, w), the memory layout of GfQuath (imaginary, then real).
        orientation = np.ascontiguousarray(pose[:, 3:7], dtype=np.float16)
        self._positions.Set(Vt.Vec3fArray.FromNumpy(position), time)
        self._orientations.Set(Vt.QuathArray.FromNumpy(orientation), time)
        self._scales.Set(Vt.Vec3fArray.FromNumpy(np.repeat(scale[:, None], 3, axis=1)), time)
        self._colors.Set(Vt.Vec3fArray.FromNumpy(colors), time)
        if self.num_objects:
            reach = (self._shape_radius[self._object_shape] * scale)[:, None]
            self._instancer_extent.Set(_extent((position - reach).min(axis=0), (position + reach).max(axis=0)), time)

    def _write_meshes(self, time, world: np.ndarray, colors: np.ndarray) -> None:
        from pxr import Gf, Vt

        start = self._vertex_start
        for i, (mesh, color) in enumerate(zip(self._meshes, self._mesh_colors)):
            v = world[start[i] : start[i + 1]]
            mesh.GetPointsAttr().Set(_vec3f_array(v), time)
            mesh.GetExtentAttr().Set(_extent(v.min(axis=0), v.max(axis=0)), time)
            color.Set(Vt.Vec3fArray([Gf.Vec3f(*map(float, colors[i]))]), time)

    def _write_bounds(self, time) -> None:
        from pxr import Vt

        n = self.num_objects
        if n == 0:
            return
        scene = self.scene
        d = scene.world_vertex.device
        if self._box_point is None:
            self._box_corner = wp.array(_BOX_PATH.astype(np.int32), dtype=wp.int32, device=d)
            self._box_lower = wp.zeros(n, dtype=wp.vec3, device=d)
            self._box_upper = wp.zeros(n, dtype=wp.vec3, device=d)
            self._box_point = wp.zeros(16 * n, dtype=wp.vec3, device=d)
        wp.launch(
            _usd_box_polyline_kernel,
            dim=n,
            inputs=[scene.world_vertex32(), scene.object_vertex_start, self._box_corner],
            outputs=[self._box_lower, self._box_upper, self._box_point],
            device=d,
        )
        lower = self._box_lower.numpy()
        upper = self._box_upper.numpy()
        self._bounds_points.Set(Vt.Vec3fArray.FromNumpy(self._box_point.numpy()), time)
        self._bounds_extent.Set(_extent(lower.min(axis=0), upper.max(axis=0)), time)
        if not self._bounds_widths.HasAuthoredValue():
            # Line width: 1 % of the median box size of the first frame, constant over time.
            size = float(np.median(np.max(upper - lower, axis=1)))
            self._bounds_widths.Set(Vt.FloatArray([max(size * 0.01, 1e-6)]))

    def _write_segments(self, time, result) -> None:
        from pxr import Vt

        seg = getattr(result, "segments", None)
        if seg is None:
            raise ValueError("add_frame: segments=True needs results of a CollisionPipeline(..., segments=True)")
        points = segment_points(seg)
        self._segment_counts.Set(Vt.IntArray.FromNumpy(np.full(len(points) // 2, 2, np.int32)), time)
        self._segment_points.Set(Vt.Vec3fArray.FromNumpy(points), time)
        if len(points):
            self._segment_extent.Set(_extent(points.min(axis=0), points.max(axis=0)), time)
        else:
            self._segment_extent.Set(_extent(np.zeros(3), np.zeros(3)), time)

    # ------------------------------------------------------------------ closing
    def close(self) -> str:
        """Writes the stage to a temporary file beside ``path``, then renames it to ``path``.

        A writer that received no frame writes the scene's current state as a single frame 0.
        Closing twice does nothing.

        Returns:
            The absolute path of the written file.

        Raises:
            ValueError: the file could not be written (the temporary file is removed).
        """
        if self.closed:
            return self.path
        if self.num_frames == 0:
            self.add_frame(0, None)
        self.stage.SetStartTimeCode(float(self._first))
        self.stage.SetEndTimeCode(float(self._last))
        self.closed = True
        args = {"format": "usdc"} if self._ext == ".usd" else {}
        try:
            ok = self.stage.GetRootLayer().Export(self._pending.temp_path, args=args)
        except Exception as exc:  # pxr.Tf.ErrorException: disk full, I/O error, ...
            self._pending.discard()
            first_line = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise ValueError(f"cannot write {self.path}: {first_line}") from None
        if not ok:
            self._pending.discard()
            raise ValueError(f"cannot write {self.path}: USD export failed")
        self._pending.commit()
        self.stage = None
        return self.path

    def abort(self) -> None:
        """Discards the frames: nothing is written and an existing file at ``path`` stays as it was."""
        self.closed = True
        self.stage = None
        self._pending.discard()

    def __enter__(self) -> UsdAnimationWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()
