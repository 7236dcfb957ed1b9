"""The composed motion of random scenes: an inclined ellipse with spin.

Each object's pose at time ``t`` (seconds) is a composition of translations and rotations, each
with its own angular velocity:

    position(t)    = centre + tilt * (a cos(w t + phi), b sin(w t + phi), 0)
    orientation(t) = quat(spin_axis, s t + psi) * base

The orbit (semi-axes ``a``, ``b`` in scene units, angular velocity ``w`` in rad/s) lies in a plane
inclined by the rotation ``tilt``; the object spins about its own ``spin_axis`` at ``s`` rad/s.
One kernel computes the poses of all objects; cost O(N), no host work. The time can live on the
device (a float64 array of one element, plus a step added in the kernel), so that a frame that
advances the time can be captured in a CUDA graph and replayed.
"""


from typing import Any

import numpy as np
import warp as wp

from ..geometry.precision import precision_overloads, precision_types
from ..runtime.aliases import ArrayLike, DeviceLike

wp.set_module_options({"enable_backward": False})  # forward kernels only

__all__ = ["EllipseMotion", "advance_time"]


@wp.kernel
def _time_step_kernel(time_step: wp.float64, time_now: wp.array[wp.float64]):
    """One thread: ``time_now[0] += time_step`` (float64, the same sum as the host's)."""
    time_now[0] = time_now[0] + time_step


@wp.kernel
def _motion_pose_kernel(
    time_now: wp.array[wp.float64],
    time_step: wp.float64,
    scalar: Any,
    motion_centre: wp.array[Any],
    motion_axes: wp.array[wp.vec2],
    motion_orbit: wp.array[wp.vec2],
    motion_tilt: wp.array[wp.quat],
    motion_spin_axis: wp.array[wp.vec3],
    motion_spin: wp.array[wp.vec2],
    motion_base: wp.array[wp.quat],
    # Outputs
    object_pose: wp.array[Any],
):
    """One thread per object: pose at ``time_now[0] + time_step`` (added in float64, as the host
    adds), computed in the type of ``scalar`` (float32 or float64; its value is unused) like the
    centres and the poses written."""
    i = wp.tid()
    time = type(scalar)(time_now[0] + time_step)
    axes = motion_axes[i]
    orbit = motion_orbit[i]
    theta = type(time)(orbit[0]) * time + type(time)(orbit[1])
    local = type(motion_centre[i])(type(time)(axes[0]) * wp.cos(theta), type(time)(axes[1]) * wp.sin(theta),
                                   type(time)(0.0))
    pos = motion_centre[i] + wp.quat_rotate(wp.quaternion(motion_tilt[i], dtype=type(time)), local)
    spin = motion_spin[i]
    angle = type(time)(spin[0]) * time + type(time)(spin[1])
    spin_axis = type(local)(motion_spin_axis[i])
    rot = wp.quat_from_axis_angle(spin_axis, angle) * wp.quaternion(motion_base[i], dtype=type(time))
    object_pose[i] = wp.transformation(pos, wp.normalize(rot), dtype=type(time))


_MOTION_POSE = precision_overloads(_motion_pose_kernel, lambda s, v, q, t: {
    "scalar": s, "motion_centre": wp.array[v], "object_pose": wp.array[t]})


def _random_quat(rng: np.random.Generator, n: int) -> np.ndarray:
    """Uniformly distributed unit quaternions, (n, 4) as (x, y, z, w)."""
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _random_unit(rng: np.random.Generator, n: int) -> np.ndarray:
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


class EllipseMotion:
    """Parameters of the composed motion of ``N`` objects, as device arrays.

    Args:
        centre: ``(N, 3)`` ellipse centres (scene units).
        axes: ``(N, 2)`` semi-axes ``a, b`` (scene units).
        orbit: ``(N, 2)`` orbit angular velocity (rad/s) and phase (rad).
        tilt: ``(N, 4)`` quaternions ``(x, y, z, w)`` of the orbit plane.
        spin_axis: ``(N, 3)`` unit spin axes.
        spin: ``(N, 2)`` spin rate (rad/s) and phase (rad).
        base: ``(N, 4)`` base orientation quaternions.
        device: Warp device of the arrays.
        precision: ``"float32"`` or ``"float64"``: type of the centres and of the poses written.
    """

    def __init__(self, centre: ArrayLike, axes: ArrayLike, orbit: ArrayLike, tilt: ArrayLike, spin_axis: ArrayLike,
                 spin: ArrayLike, base: ArrayLike, device: DeviceLike = None, precision: str = "float32") -> None:
        self.scalar_type, vec, _, _ = precision_types(precision)
        self.device = wp.get_device(device)
        self.num_objects = len(centre)
        self.precision = precision
        d = self.device
        self.motion_centre = wp.array(np.asarray(centre, np.float64), dtype=vec, device=d)
        self.motion_axes = wp.array(np.asarray(axes, np.float32), dtype=wp.vec2, device=d)
        self.motion_orbit = wp.array(np.asarray(orbit, np.float32), dtype=wp.vec2, device=d)
        self.motion_tilt = wp.array(np.asarray(tilt, np.float32), dtype=wp.quat, device=d)
        self.motion_spin_axis = wp.array(np.asarray(spin_axis, np.float32), dtype=wp.vec3, device=d)
        self.motion_spin = wp.array(np.asarray(spin, np.float32), dtype=wp.vec2, device=d)
        self.motion_base = wp.array(np.asarray(base, np.float32), dtype=wp.quat, device=d)

    @classmethod
    def random(
        cls,
        rng: np.random.Generator,
        centre: np.ndarray,
        radius: np.ndarray,
        *,
        orbit_scale: float = 2.0,
        device: DeviceLike = None,
        precision: str = "float32",
    ) -> "EllipseMotion":
        """Random ellipses around given centres.

        Args:
            rng: numpy random generator.
            centre: ``(N, 3)`` ellipse centres.
            radius: ``(N,)`` object radii; semi-axes are ``U(0.5, 1) * orbit_scale * radius``,
                so objects travel a few of their own sizes and the density stays constant.
            orbit_scale: semi-axis scale relative to the object radius.
            device: Warp device.
            precision: ``"float32"`` or ``"float64"``.
        """
        n = len(centre)
        axes = rng.uniform(0.5, 1.0, size=(n, 2)) * orbit_scale * np.asarray(radius)[:, None]
        orbit = np.stack([rng.uniform(0.5, 2.0, n) * rng.choice([-1.0, 1.0], n), rng.uniform(0, 2 * np.pi, n)], 1)
        spin = np.stack([rng.uniform(0.5, 3.0, n) * rng.choice([-1.0, 1.0], n), rng.uniform(0, 2 * np.pi, n)], 1)
        return cls(
            centre, axes, orbit, _random_quat(rng, n), _random_unit(rng, n), spin, _random_quat(rng, n), device=device,
            precision=precision,
        )

    def launch(self, time: float | wp.array, object_pose: wp.array, step: float = 0.0) -> None:
        """Writes the poses of all objects at ``time + step`` (seconds) into ``object_pose`` ``(N,)``.

        Args:
            time: a number, or a ``wp.array`` of one float64 on this device (read by the kernel:
                the launch can be captured in a CUDA graph and replayed as the time changes).
            object_pose: ``(N,)`` poses to write.
            step: seconds added to ``time`` (in float64) before the poses are computed.
        """
        if not isinstance(time, wp.array):
            if getattr(self, "_time", None) is None:
                self._time = wp.zeros(1, dtype=wp.float64, device=self.device)
            self._time.fill_(float(time))
            time = self._time
        wp.launch(
            _MOTION_POSE[self.precision],
            dim=self.num_objects,
            inputs=[
                time,
                wp.float64(step),
                self.scalar_type(0.0),
                self.motion_centre,
                self.motion_axes,
                self.motion_orbit,
                self.motion_tilt,
                self.motion_spin_axis,
                self.motion_spin,
                self.motion_base,
            ],
            outputs=[object_pose],
            device=self.device,
        )


def advance_time(time_now: wp.array, step: float) -> None:
    """Adds ``step`` seconds to the device time ``time_now`` (one float64; capturable)."""
    wp.launch(_time_step_kernel, dim=1, inputs=[wp.float64(step)], outputs=[time_now], device=time_now.device)
