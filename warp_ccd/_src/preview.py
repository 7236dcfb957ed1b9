"""Preview images: a scene's frame ray-cast by a Warp kernel, colliding objects in colour.

All world triangles of the frame form one ``wp.Mesh`` (its points are the scene's world vertices,
its indices a flat global triangle list built once from the shapes and the object offsets); the
mesh's BVH is refit every frame. One thread per pixel casts a primary ray with
``wp.mesh_query_ray``; the hit triangle's owner object picks the colour (grey when free, red-orange
when colliding), shaded with Lambert's law under a key light and a fill light, plus ambient; rays
that miss get a vertical background gradient. The camera frames the scene's bounding sphere
automatically (fitted to the vertices of the first frame, with some room for the motion) and then
stays fixed, so an animation does not jitter. Cost per frame: one BVH refit (O(triangles)) and
``width * height`` ray queries (O(log triangles) each).

:func:`save_preview` writes one frame as PNG or an animation as GIF with Pillow (to a temporary
file renamed into place when complete).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np
import warp as wp

from .output import PendingFile, check_output_path
from .runtime.aliases import ArrayLike, DeviceLike, PathLike
from .runtime.checks import integer_option, number_option

if TYPE_CHECKING:
    from .pipeline.result import CollisionResult
    from .scene.scene import Scene

wp.set_module_options({"enable_backward": False})  # forward kernels only

__all__ = [
    "PREVIEW_EXTENSIONS",
    "PreviewRenderer",
    "mesh_triangle_indices",
    "prepare_preview",
    "render_frame",
    "save_preview",
    "validate_preview_path",
]

PREVIEW_EXTENSIONS = (".png", ".gif")
"""``.png``: one frame; ``.gif``: an animation."""


@wp.kernel
def _preview_render_kernel(
    mesh: wp.uint64,
    triangle_object: wp.array[wp.int32],
    object_colliding: wp.array[wp.int32],
    camera_origin: wp.vec3,
    camera_forward: wp.vec3,
    camera_right: wp.vec3,
    camera_up: wp.vec3,
    tan_half_fov: float,
    max_distance: float,
    color_free: wp.vec3,
    color_colliding: wp.vec3,
    background_top: wp.vec3,
    background_bottom: wp.vec3,
    width: int,
    height: int,
    # Outputs
    pixel: wp.array2d[wp.vec3],
):
    """One thread per pixel: primary ray, Lambert shading of the hit, gradient where it misses.

    ``pixel`` is ``(height, width)`` linear RGB in ``[0, 1]``, row 0 at the top.
    """
    y, x = wp.tid()
    aspect = float(width) / float(height)
    sx = (2.0 * (float(x) + 0.5) / float(width) - 1.0) * tan_half_fov * aspect
    sy = (1.0 - 2.0 * (float(y) + 0.5) / float(height)) * tan_half_fov
    direction = wp.normalize(camera_forward + sx * camera_right + sy * camera_up)

    fy = float(y) / float(height - 1 if height > 1 else 1)
    color = background_top * (1.0 - fy) + background_bottom * fy

    query = wp.mesh_query_ray(mesh, camera_origin, direction, max_distance)
    if query.result:
        obj = triangle_object[query.face]
        base = color_free
        if object_colliding[obj] != 0:
            base = color_colliding
        n = wp.normalize(query.normal)
        if wp.dot(n, direction) > 0.0:
            n = -n  # face the viewer (also for open meshes and inward-wound triangles)
        key = wp.normalize(camera_up * 0.8 - camera_right * 0.5 - camera_forward * 0.6)
        fill = wp.normalize(camera_right * 0.7 - camera_forward * 0.4 - camera_up * 0.2)
        shade = 0.28 + 0.62 * wp.max(wp.dot(n, key), 0.0) + 0.22 * wp.max(wp.dot(n, fill), 0.0)
        color = base * wp.min(shade, 1.1)
    pixel[y, x] = color


def _camera_axes(view_direction) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit ``forward``, ``right``, ``up`` of a camera looking along ``-view_direction``, +Y up."""
    view = np.asarray(view_direction, np.float64).reshape(3)
    norm = np.linalg.norm(view)
    if not np.isfinite(norm) or norm == 0.0:
        raise ValueError(f"view_direction must be a non-zero 3-vector, got {view_direction!r}")
    forward = -view / norm
    world_up = np.array([0.0, 1.0, 0.0]) if abs(forward[1]) < 0.99 else np.array([0.0, 0.0, 1.0])
    right = np.cross(forward, world_up)
    right /= np.linalg.norm(right)
    return forward, right, np.cross(right, forward)


def mesh_triangle_indices(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """Flat triangle list over all objects of a scene, into its concatenated world vertices.

    Args:
        scene: a :class:`~warp_ccd._src.scene.scene.Scene`.

    Returns:
        ``(indices (3 * T,) int32, triangle_object (T,) int32)``: vertex indices into
        ``scene.world_vertex`` (three per triangle) and the object owning each triangle.
    """
    n = scene.num_objects
    if n == 0:
        return np.zeros(0, np.int32), np.zeros(0, np.int32)
    shape_tri = [np.asarray(t, np.int64) for _, t in scene.shape_meshes]
    inst = np.asarray(scene.object_shape_np, np.int64)
    counts = np.array([len(shape_tri[s]) for s in inst], np.int64)
    # Local triangles of every object, gathered per object without a loop over objects.
    cat = np.concatenate(shape_tri)
    shape_start = np.concatenate([[0], np.cumsum([len(t) for t in shape_tri])])
    triangle_object = np.repeat(np.arange(n, dtype=np.int64), counts)
    first = np.concatenate([[0], np.cumsum(counts)])[:-1]
    local = np.arange(int(counts.sum()), dtype=np.int64) - np.repeat(first, counts)
    tri = cat[shape_start[inst][triangle_object] + local]
    tri = tri + np.asarray(scene.object_vertex_start_np, np.int64)[triangle_object][:, None]
    return tri.reshape(-1).astype(np.int32), triangle_object.astype(np.int32)


def validate_preview_path(path: PathLike) -> tuple[str, str]:
    """Checks that a preview image can be written at ``path``, without writing it.

    Returns:
        ``(absolute path, extension)``, the extension ``.png`` or ``.gif``.

    Raises:
        ValueError: another extension, a missing folder or one where no file can be created,
            or ``path`` is a folder or a read-only file.
    """
    return check_output_path(path, PREVIEW_EXTENSIONS, "preview")


class PreviewRenderer:
    """Renders frames of one scene from a fixed camera.

    The camera looks at the centre of the scene's bounding box from an elevated three-quarter
    view, as close as it can while every vertex of the first frame, pushed out from the centre by
    ``margin``, stays in the image.

    Args:
        scene: a :class:`~warp_ccd._src.scene.scene.Scene`; its world vertices are read at each :meth:`render`.
        width: image width in pixels.
        height: image height in pixels.
        fov: vertical field of view in degrees.
        view_direction: ``(3,)`` direction from the scene centre towards the camera.
        margin: room left around the first frame's vertices (1: tight), for the motion to come.
        device: Warp device of the ray casting (default: the scene's).
    """

    color_free = (0.66, 0.67, 0.70)
    color_colliding = (0.97, 0.30, 0.10)
    background_top = (0.93, 0.95, 0.98)
    background_bottom = (0.62, 0.67, 0.75)

    def __init__(self, scene: Scene, width: int = 640, height: int = 480, *, fov: float = 40.0,
                 view_direction: ArrayLike = (1.0, 0.75, 1.35), margin: float = 1.1,
                 device: DeviceLike = None) -> None:
        integer_option("width", width, low=1)
        integer_option("height", height, low=1)
        number_option("fov (degrees)", fov, low=1.0, high=170.0, high_open=True)
        self.scene = scene
        self.width = int(width)
        self.height = int(height)
        self.fov = float(fov)
        self.device = wp.get_device(device if device is not None else scene.device)
        indices, triangle_object = mesh_triangle_indices(scene)
        self.num_triangles = len(triangle_object)
        d = self.device
        self.triangle_object = wp.array(triangle_object, dtype=wp.int32, device=d)
        self._indices = wp.array(indices, dtype=wp.int32, device=d)
        same_device = scene.world_vertex.device == d
        points = scene.world_vertex32()
        self._points = points if same_device else wp.zeros_like(points, device=d)
        self._mesh = None
        self.pixel = wp.zeros((self.height, self.width), dtype=wp.vec3, device=d)
        self._colliding = wp.zeros(max(scene.num_objects, 1), dtype=wp.int32, device=d)

        forward, right, up = _camera_axes(view_direction)
        self.camera_forward, self.camera_right, self.camera_up = forward, right, up
        tan_half = float(np.tan(np.radians(self.fov) / 2.0))
        aspect = self.width / self.height
        wv = scene.world_vertex.numpy().astype(np.float64)
        if len(wv) == 0:
            wv = np.zeros((1, 3))
        centre = 0.5 * (wv.min(axis=0) + wv.max(axis=0))
        rel = wv - centre
        # Distance from the centre at which every vertex, pushed out by ``margin``, is in view.
        toward = rel @ -forward
        need = np.maximum(np.abs(rel @ right) / (tan_half * aspect), np.abs(rel @ up) / tan_half)
        distance = max(float(np.max(toward + float(margin) * need)), 1e-3)
        self.camera_origin = centre - forward * distance
        radius = float(np.sqrt(np.max(np.sum(rel**2, axis=1))))
        self.max_distance = distance + 2.0 * float(margin) * radius + 1.0

    def render(self, colliding: ArrayLike | CollisionResult | None = None) -> np.ndarray:
        """Ray-casts the scene's current world vertices.

        Args:
            colliding: ``(N,)`` bool flags (or a :class:`~warp_ccd._src.pipeline.pipeline.CollisionResult`);
                None: nothing collides.

        Returns:
            ``(height, width, 3)`` uint8 RGB image, row 0 at the top.
        """
        scene = self.scene
        n = scene.num_objects
        flags = getattr(colliding, "colliding", colliding)
        if flags is None:
            flags = np.zeros(n, bool)
        flags = np.asarray(flags)
        if flags.shape != (n,):
            raise ValueError(f"colliding: expected shape ({n},), got {flags.shape}")
        if n:
            self._colliding.assign(flags.astype(np.int32))
        d = self.device
        if self.num_triangles == 0:
            self.pixel.zero_()
            mesh_id = wp.uint64(0)
        else:
            points = scene.world_vertex32()
            if self._points is not points:
                wp.copy(self._points, points)
            if self._mesh is None:
                self._mesh = wp.Mesh(points=self._points, indices=self._indices)
            else:
                self._mesh.refit()
            mesh_id = self._mesh.id
        if self.num_triangles:
            wp.launch(
                _preview_render_kernel,
                dim=(self.height, self.width),
                inputs=[
                    mesh_id,
                    self.triangle_object,
                    self._colliding,
                    wp.vec3(*self.camera_origin),
                    wp.vec3(*self.camera_forward),
                    wp.vec3(*self.camera_right),
                    wp.vec3(*self.camera_up),
                    float(np.tan(np.radians(self.fov) / 2.0)),
                    self.max_distance,
                    wp.vec3(*self.color_free),
                    wp.vec3(*self.color_colliding),
                    wp.vec3(*self.background_top),
                    wp.vec3(*self.background_bottom),
                    self.width,
                    self.height,
                ],
                outputs=[self.pixel],
                device=d,
            )
            img = self.pixel.numpy()
        else:
            fy = np.linspace(0.0, 1.0, self.height)[:, None, None]
            top, bottom = np.array(self.background_top), np.array(self.background_bottom)
            img = np.broadcast_to(top * (1.0 - fy) + bottom * fy, (self.height, self.width, 3))
        return (np.clip(img, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def render_frame(scene: Scene, colliding: ArrayLike | CollisionResult | None = None, width: int = 640,
                 height: int = 480, device: DeviceLike = None) -> np.ndarray:
    """Renders the scene's current frame (a one-off :class:`PreviewRenderer`).

    Args:
        scene: a :class:`~warp_ccd._src.scene.scene.Scene`.
        colliding: ``(N,)`` bool flags or a :class:`~warp_ccd._src.pipeline.pipeline.CollisionResult`; None: none.
        width: image width in pixels.
        height: image height in pixels.
        device: Warp device of the ray casting (default: the scene's).

    Returns:
        ``(height, width, 3)`` uint8 RGB image.
    """
    return PreviewRenderer(scene, width, height, device=device).render(colliding)


def save_preview(frames: np.ndarray | Sequence[np.ndarray], path: PathLike, *, fps: float = 30.0) -> str:
    """Writes one frame as PNG or several as an animated GIF (looping), through a temporary file
    moved into place (:func:`prepare_preview`).

    Args:
        frames: one ``(H, W, 3)`` uint8 image, or a sequence of them (all the same size).
        path: ``.png`` (exactly one frame; of a sequence, the last) or ``.gif``.
        fps: GIF playback rate in frames per second (GIF delays are whole centiseconds, at least
            2, so at most 50 frames per second).

    Returns:
        The absolute path written.

    Raises:
        ValueError: a bad path (see :func:`validate_preview_path`), no frames, or bad images.
    """
    return prepare_preview(frames, path, fps=fps).commit()


def prepare_preview(frames: np.ndarray | Sequence[np.ndarray], path: PathLike, *,
                    fps: float = 30.0) -> PendingFile:
    """Writes the picture of :func:`save_preview` to a temporary file beside ``path``, not yet in place.

    Args:
        frames: one ``(H, W, 3)`` uint8 image, or a sequence of them (all the same size).
        path: ``.png`` (exactly one frame; of a sequence, the last) or ``.gif``.
        fps: GIF playback rate in frames per second (GIF delays are whole centiseconds, at least
            2, so at most 50 frames per second).

    Returns:
        The :class:`~warp_ccd._src.output.PendingFile`: :meth:`~warp_ccd._src.output.PendingFile.commit`
        moves it to ``path``, :meth:`~warp_ccd._src.output.PendingFile.discard` removes it.

    Raises:
        ValueError: as :func:`save_preview`.
    """
    from PIL import Image

    full, ext = validate_preview_path(path)
    if isinstance(frames, np.ndarray) and frames.ndim == 3:
        frames = [frames]
    frames = [np.asarray(f) for f in frames]
    if not frames:
        raise ValueError("save_preview: no frames")
    for f in frames:
        if f.ndim != 3 or f.shape[2] != 3 or f.dtype != np.uint8 or f.shape != frames[0].shape:
            raise ValueError(f"save_preview: frames must be (H, W, 3) uint8 of one size, got {f.shape} {f.dtype}")
    pending = PendingFile(full)
    try:
        if ext == ".png":
            Image.fromarray(frames[-1], "RGB").save(pending.temp_path, format="PNG")
        else:
            images = [
                Image.fromarray(f, "RGB").quantize(colors=255, method=Image.Quantize.MEDIANCUT,
                                                   dither=Image.Dither.NONE)
                for f in frames
            ]
            duration = 10 * max(int(round(100.0 / float(fps))), 2)  # ms, whole centiseconds
            images[0].save(pending.temp_path, format="GIF", save_all=True, append_images=images[1:],
                           duration=duration, loop=0, optimize=False)
    except BaseException:
        pending.discard()
        raise
    return pending
