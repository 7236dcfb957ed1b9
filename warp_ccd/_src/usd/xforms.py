"""World transforms of animated prims read in bulk: the xform ops' time samples read at once and composed in numpy.

:func:`read_world_poses` gives the world transform of each given prim at every time code asked for, as
poses and scales (:mod:`~warp_ccd._src.usd.poses`), without one ``UsdGeom.XformCache`` lookup per prim and
time code where USD's own computation can be reproduced:

* **The animated ancestor.** Walking up from the prim (itself included) to the first prim that resets
  the transform stack, exactly one prim ``A`` must have a local transform that may vary over time
  (``TransformMightBeTimeVarying``). The world matrix is then ``rel @ local_A(t) @ parent_A`` (row
  vectors): ``rel`` the static transforms between the prim and ``A`` and ``parent_A`` the world
  transform of ``A``'s parent (identity when ``A`` resets the stack), both looked up once, at the first
  time code. Prims without an animated ancestor keep their first matrix; prims with two fall back.
* **The op stack.** ``A``'s ``xformOpOrder`` is read as USD reads it (ops after the last
  ``!resetXformStack!``; adjacent op / inverse-op pairs of one attribute skipped), every op of a type and
  value type USD knows: translate, scale (and their single-axis forms), rotateX/Y/Z, the six three-axis
  rotations, orient and transform, in double, float or half precision, inverse ops included. Each op's
  matrix is built as ``UsdGeomXformOp::GetOpTransform`` builds it (a rotation through ``GfRotation``:
  axis and angle, then its quaternion), and the ops are composed in USD's order.
* **Values.** A static op (``ValueMightBeTimeVarying`` False) is read once. A time-sampled op must
  resolve to time samples alone (``GetResolveInfo``: value clips, splines and values composed with
  weaker opinions fall back): the samples are those of the strongest spec holding them, its layer
  offset (sublayers, references) mapping stage time to layer time. Values are those USD 26 resolves:
  the samples bracketing each time code in layer time, mixed with a weight from their stage times
  (``Usd_Interpolate``), held or linear (component-wise in the value's own precision, rounded as
  ``GfLerp`` rounds; quaternions by ``GfSlerp``, for ``quatf`` with its float arithmetic and the C
  library's ``sinf``); before the first and after the last sample the end value is held. Half values
  that would need interpolating, value blocks, values of an unexpected type (every sample is checked:
  USD holds rather than interpolates between samples of two types), inverse single-axis scales (which
  USD 26.11 negates) and inverse matrix ops whose linear part is ill-conditioned (condition number above
  1e3, where ``GfMatrix4d::GetInverse`` and numpy's inverse part) fall back. Two limits: scalar samples
  written as two precisions through ``Sdf`` (a double and a float) look alike from Python and are
  interpolated; and the static matrices between an object and its animated ancestor are multiplied
  together before the animated one, so where their translations cancel (1e7 and -1e7) the rounding
  differs from USD's by about 1e-9 of the matrix.
* **Reads.** Per attribute, the whole dictionary of time samples (``Sdf`` spec ``GetInfo``) when the
  time codes asked for are at least :data:`WHOLE_READ_SHARE` of its samples, else the samples the
  time codes need one by one (``QueryTimeSample``; ``GetBracketingTimeSamplesForPath`` for a time code
  between samples): a range of frames costs in proportion to the range.

Everything else (PointInstancers aside, which the import reads on its own) falls back to
``XformCache`` per prim and time code. Prims with the same op stack are composed together, a batch
of about :data:`BATCH` prim-time codes at a time, one numpy pass per matrix entry.

Cost: per animated prim a few dozen ``pxr`` calls (its ops, their resolve info and spec); per sample
one read with its dictionary (most of the time: the ``Gf`` values made for Python; a sample read alone
costs about three times as much); the numpy composition and poses less than the reads. An
``XformCache`` lookup (the fallback) costs an order of magnitude more than a sample read in bulk (the
measurements: ``docs/site/architecture/usd.md``). The garbage collector is paused while reading (:func:`paused_gc`).
:data:`FAST_XFORMS` turns the bulk path off (every lookup through ``XformCache``), for comparison.
"""

from __future__ import annotations

import gc
import sys
from collections import defaultdict
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .poses import (
    SINGULAR_DETERMINANT,
    affine_poses,
    baked_linear,
    compose_ops,
    finite_matrix_poses,
    lerp_samples,
    mul3,
    op_transform,
    sample_brackets,
)

if TYPE_CHECKING:
    from pxr import Usd

__all__ = ["BATCH", "FAST_XFORMS", "WHOLE_READ_SHARE", "WorldPoses", "XformInfo", "paused_gc", "read_world_matrices",
           "read_world_poses", "world_transform", "xform_fault"]

FAST_XFORMS = True
"""Whether :func:`read_world_poses` composes the transforms it can reproduce in numpy (False: every
transform through ``UsdGeom.XformCache``, one lookup per prim and time code)."""

WHOLE_READ_SHARE = 0.4
"""An attribute's whole dictionary of time samples is read when the time codes asked for are at least
this share of its samples (a sample of the dictionary costs about 0.4 of one read alone)."""

BATCH = 16_384
"""Prim-time codes composed at once: the numpy passes' arrays stay small (128 KB), cached and reused
(larger ones are mapped and unmapped each time, which measured slower: ``docs/site/architecture/usd.md``)."""

_RESET = "!resetXformStack!"
_INVERT = "!invert!"
_KINDS = {"translate": "vec", "scale": "vec", "orient": "quat", "transform": "matrix",
          **{f"{op}{a}": "scalar" for op in ("translate", "scale", "rotate") for a in "XYZ"},
          **{f"rotate{o}": "vec" for o in ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")}}
_VALUE_TYPES = {"vec": ("double3", "float3", "half3"), "scalar": ("double", "float", "half"),
                "quat": ("quatd", "quatf", "quath"), "matrix": ("matrix4d",)}


@contextmanager
def paused_gc() -> Iterator[None]:
    """Python's cyclic garbage collector paused for the block (where it was running). ``pxr`` values
    (``Gf`` vectors, ``Usd`` prims) are tracked objects: with millions of them alive, collections
    triggered by their allocation scan them over and over, tripling the cost of a bulk read."""
    running = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if running:
            gc.enable()


@dataclass
class WorldPoses:
    """What :func:`read_world_poses` gives back, for ``P`` prims and ``F`` time codes."""

    first: np.ndarray  # (P, 4, 4) world matrices at the first time code
    poses: np.ndarray  # (F, P, 7) float64 poses relative to baked_linear(first)
    scale: np.ndarray  # (F, P) float64 uniform scales
    ok: np.ndarray  # (P,) bool: a similarity relative to the baked part at every time code
    finite: np.ndarray  # (F, P) bool: the world transform is finite
    fast: np.ndarray  # (P,) bool: read in bulk (False: through XformCache)
    matrices: np.ndarray | None = None  # (F, P, 4, 4) world matrices, where asked for


def xform_fault(prim: Usd.Prim, time: float, singular: bool = False) -> str | None:
    """What makes a prim's world transform unusable at a time code, naming the prim and attribute:
    the first xform op of the prim or of an ancestor (up to one that resets the transform stack)
    whose value USD cannot make a matrix of (a wrong type: ``xformOp:translate`` authored as a
    string) or whose matrix is not finite, or, with ``singular``, whose linear part is singular (a
    zero scale); None when every op is fine."""
    from pxr import Tf, Usd, UsdGeom

    code = Usd.TimeCode(time)
    p = prim
    while p and p.IsValid() and not p.IsPseudoRoot():
        xformable = UsdGeom.Xformable(p)
        if xformable:
            for op in xformable.GetOrderedXformOps():
                try:
                    m = np.asarray(op.GetOpTransform(code), np.float64)
                except Tf.ErrorException:
                    return (f"prim {p.GetPath()}: {op.GetName()} at time {time:g} is {op.Get(code)!r} "
                            f"({op.GetTypeName()}), of which USD makes no transform")
                if not np.isfinite(m).all():
                    return f"prim {p.GetPath()}: {op.GetName()} at time {time:g} is not finite ({op.Get(code)})"
                if singular and not abs(np.linalg.det(m[:3, :3])) > SINGULAR_DETERMINANT:
                    return (f"prim {p.GetPath()}: {op.GetName()} at time {time:g} is {op.Get(code)}: a zero scale "
                            "collapses the mesh")
            if xformable.GetResetXformStack():
                break
        p = p.GetParent()
    return None


def world_transform(cache, prim: Usd.Prim, time: float) -> np.ndarray:
    """``(4, 4)`` world matrix (row vectors) of ``prim`` from a ``UsdGeom.XformCache`` at ``time``.

    Raises:
        ValueError: naming the prim, attribute and time (:func:`xform_fault`) where USD cannot
            compute it (it raises its own error for an op of the wrong value type).
    """
    from pxr import Tf

    try:
        return np.asarray(cache.GetLocalToWorldTransform(prim), np.float64)
    except Tf.ErrorException as exc:
        fault = xform_fault(prim, time)
        if fault is None:
            text = [line.strip() for line in str(exc).splitlines() if line.strip()]
            fault = (f"prim {prim.GetPath()}: its transform cannot be computed at time {time:g} "
                     f"({text[-1] if text else 'USD error'})")
        raise ValueError(fault) from None


def _order_tokens(text: str, count: int) -> tuple | None:
    """``(resets, ((attribute name, inverse), ...))`` of an ``xformOpOrder`` as ``str()`` spells it
    (``[a, b, c]``): the ops after the last ``!resetXformStack!``; None where the text does not split
    into ``count`` tokens."""
    tokens = text[1:-1].split(", ") if len(text) > 2 else []
    if len(tokens) != count or text[:1] != "[" or text[-1:] != "]":
        return None
    resets = _RESET in tokens
    if resets:
        tokens = tokens[len(tokens) - tokens[::-1].index(_RESET):]
    return resets, tuple((t[len(_INVERT):], True) if t.startswith(_INVERT) else (t, False) for t in tokens)


class XformInfo:
    """Per prim, cached by path: its xform ops, whether it resets the transform stack, whether its
    local transform may vary over time (one set of ``pxr`` calls per prim, however many objects share it).

    Args:
        stage: the ``Usd.Stage``.
    """

    def __init__(self, stage: Usd.Stage) -> None:
        self.stage = stage
        self._info: dict[str, tuple] = {}
        self._xformable: dict[str, bool] = {}
        self._orders: dict[str, tuple | None] = {}
        self._seeded: dict[str, bool] = {}

    def get(self, prim: Usd.Prim | None, path: str | None = None) -> tuple:
        """``(ops, resets, varying)`` of ``prim`` (or of the prim at ``path``, asked for only when not known
        yet): its xform ops after the last ``!resetXformStack!`` (an
        empty tuple for a prim that is not Xformable), each ``(attribute name, inverse, attribute,
        ValueMightBeTimeVarying)``; whether it resets the stack; whether any op may vary over time
        (``UsdGeom.Xformable.TransformMightBeTimeVarying``: an op whose attribute does not exist counts
        as static, as USD skips it)."""
        key = str(prim.GetPath()) if path is None else path
        got = self._info.get(key)
        if got is not None:
            return got
        if prim is None:
            prim = self.stage.GetPrimAtPath(key)
        xformable = self._seeded.pop(key, None)
        if xformable is None:
            xformable = self.xformable(prim.GetTypeName(), prim)
        ops, resets, varying = (), False, False
        order = prim.GetAttribute("xformOpOrder").Get() if xformable else None
        if order:
            text = str(order)  # one call, where iterating the token array costs one per token
            tokens = self._orders.get(text, False)
            if tokens is False:
                tokens = self._orders[text] = _order_tokens(text, len(order))
            if tokens is not None:
                resets, names = tokens
                ops = tuple((name, inverse, prim.GetAttribute(name)) for name, inverse in names)
                ops = tuple((name, inverse, attr, attr.ValueMightBeTimeVarying()) for name, inverse, attr in ops)
                varying = any(op[3] for op in ops)
            else:  # tokens that str() does not spell unambiguously: as USD reads them
                from pxr import UsdGeom

                tokens = tuple(order)
                resets = _RESET in tokens
                varying = UsdGeom.Xformable(prim).TransformMightBeTimeVarying()
                ops = None
        got = self._info[key] = (ops, resets, varying)
        return got

    def xformable(self, type_name: str, prim: Usd.Prim) -> bool:
        """Whether prims of a type name are ``UsdGeom.Xformable`` (``prim`` one of them; asked once per type)."""
        got = self._xformable.get(type_name)
        if got is None:
            from pxr import UsdGeom

            got = self._xformable[type_name] = bool(prim.IsA(UsdGeom.Xformable))
        return got

    def seed(self, key: str, names: list, xformable: bool) -> None:
        """Notes a prim by its authored property names (``Usd.Prim.GetAuthoredPropertyNames``) and whether it
        is Xformable: one without ``xformOpOrder`` has no ops, and asks nothing more."""
        if key not in self._info:
            if xformable and "xformOpOrder" in names:
                self._seeded[key] = True
            else:
                self._info[key] = ((), False, False)

    def varies(self, prim: Usd.Prim, stop: Usd.Prim | None = None, key: str | None = None) -> bool:
        """Whether the transform of ``prim`` (its path ``key``, if known) relative to ``stop`` (or the
        world) may change over time: some prim from ``prim`` up to ``stop`` (excluded) has a local
        transform that may vary. Walks up by path: a prim already known is not asked for."""
        key = str(prim.GetPath()) if key is None else key
        end = None if stop is None else str(stop.GetPath())
        p = prim
        while key != end:
            if self.get(p, key)[2]:
                return True
            cut = key.rfind("/")
            if cut <= 0:
                return False
            key, p = key[:cut], None
        return False


# ---------------------------------------------------------------------- the reader
_CODES = {"double3": "d", "float3": "f", "half3": "h", "double": "d", "float": "f", "half": "h",
          "quatd": "d", "quatf": "f", "quath": "h", "matrix4d": "d"}


def _gf_types() -> tuple[dict, dict]:
    """``(Vt array class, Gf value class)`` per value type name."""
    from pxr import Gf, Vt

    arrays = {"double3": Vt.Vec3dArray, "float3": Vt.Vec3fArray, "half3": Vt.Vec3hArray, "double": Vt.DoubleArray,
              "float": Vt.FloatArray, "half": Vt.HalfArray, "quatd": Vt.QuatdArray, "quatf": Vt.QuatfArray,
              "quath": Vt.QuathArray, "matrix4d": Vt.Matrix4dArray}
    values = {"double3": Gf.Vec3d, "float3": Gf.Vec3f, "half3": Gf.Vec3h, "double": float, "float": float,
              "half": float, "quatd": Gf.Quatd, "quatf": Gf.Quatf, "quath": Gf.Quath, "matrix4d": Gf.Matrix4d}
    return arrays, values


class _TypeNames(dict):
    """``Sdf.ValueTypeName`` -> its name, asked once per type."""

    def __missing__(self, key) -> str:
        self[key] = str(key)
        return self[key]


def _as_array(arrays: dict, type_name: str, values: list) -> np.ndarray:
    """``(n, k)`` values of one value type in their own precision (quaternions ``(i, j, k, real)``)."""
    out = np.asarray(arrays[type_name](values))
    return out.reshape(len(values), -1)


def _affine(m: np.ndarray):
    """``(linear 3x3, translation)`` of an affine ``(4, 4)`` matrix, or None when it is not affine."""
    if not (m[:, 3] == (0.0, 0.0, 0.0, 1.0)).all():
        return None
    return m[:3, :3], m[3, :3]


class _Reader:
    """One read of many prims' world transforms (see the module docstring)."""

    def __init__(self, stage, times: np.ndarray, info: XformInfo) -> None:
        from pxr import Usd, UsdGeom

        self.stage, self.times, self.info = stage, times, info
        self.code0 = Usd.TimeCode(float(times[0]))
        self.cache0 = UsdGeom.XformCache(self.code0)
        self.held = stage.GetInterpolationType() == Usd.InterpolationTypeHeld
        self.time_samples = Usd.ResolveInfoSourceTimeSamples
        self.arrays, self.values = _gf_types()
        self._static_types = {cls: name for name, cls in self.values.items() if name not in ("float", "half")}
        self._type_names: dict = _TypeNames()
        self._op_types: dict[str, str | None] = {}
        self._parents: dict[str, object] = {}
        self._layer_times: dict[tuple, tuple] = {}
        self._brackets: dict[tuple, tuple] = {}

    # -------------------------------------------------------------- per prim
    def chain(self, prim, key: str):
        """``(animated prim, its path, rel)`` for an object prim (its path ``key``), ``rel`` the static
        ``(4, 4)`` transform between them or None where no op lies between; ``("static", None, None)``
        without an animated prim; None where the bulk read cannot reproduce it (two animated prims, a
        projective ``rel``). Walks up by path: prims already known are not asked for."""
        p, anim, between = prim, None, False
        info = self.info
        while True:
            ops, resets, varying = info.get(p, key)
            if varying:
                if anim is not None:
                    return None
                anim = (p, key)
            elif (ops is None or ops) and anim is None:
                between = True
            cut = key.rfind("/")
            if resets or cut <= 0:
                break
            key, p = key[:cut], None
        if anim is None:
            return "static", None, None
        a = anim[0] if anim[0] is not None else self.stage.GetPrimAtPath(anim[1])
        rel = None
        if between:
            rel = np.array(self.cache0.ComputeRelativeTransform(prim, a)[0], np.float64)
            if _affine(rel) is None:
                return None
        return a, anim[1], rel

    def parent(self, prim, key: str):
        """The affine world transform of ``prim``'s parent at the first time code, ``"identity"``
        (no parent transform, or ``prim`` resets the stack), or None (projective)."""
        cut = key.rfind("/")
        if self.info.get(prim, key)[1] or cut <= 0:
            return "identity"
        parent = key[:cut]
        got = self._parents.get(parent, False)
        if got is False:
            m = np.array(self.cache0.GetParentToWorldTransform(prim), np.float64)
            got = self._parents[parent] = "identity" if (m == np.eye(4)).all() else _affine(m)
        return got

    def plan(self, prim, key: str):
        """``(signature, static values, sources)`` of an animated prim's op stack, or None where the
        bulk read cannot reproduce it. ``signature``: per op in composition order (last op first),
        ``(op type, inverse, kind, value type name, time-varying)``; ``sources``: per time-varying op,
        ``(spec, mapping)``: the spec holding its samples and its layer offset, ``(inverse scale, inverse
        offset, scale, offset)`` (stage time = layer time * scale + offset)."""
        ops = self.info.get(prim, key)[0]
        if not ops:
            return None
        kept, i = [], len(ops) - 1
        while i >= 0:  # USD skips an op next to its own inverse, walking from the last op
            if i > 0 and ops[i][0] == ops[i - 1][0] and ops[i][1] != ops[i - 1][1]:
                i -= 2
                continue
            kept.append(ops[i])
            i -= 1
        signature, static, sources = [], [], []
        for name, inverse, attr, varying in kept:
            op_type = self._op_types.get(name, False)
            if op_type is False:
                parts = name.split(":")
                op_type = self._op_types[name] = parts[1] if len(parts) > 1 and parts[0] == "xformOp" \
                    and parts[1] in _KINDS else None
            if op_type is None or inverse and op_type in ("scaleX", "scaleY", "scaleZ"):
                return None  # (USD 26.11 negates an inverse single-axis scale: left to it)
            kind = _KINDS[op_type]
            if varying:
                resolved = attr.GetResolveInfo()
                if resolved.GetSource() != self.time_samples or resolved.HasNextWeakerInfo():
                    return None
                stack = attr.GetPropertyStackWithLayerOffsets()
                found = stack[0] if len(stack) == 1 else next(
                    ((spec, off) for spec, off in stack if spec.HasInfo("timeSamples")), None)
                if found is None:
                    return None
                type_name = self._type_names[found[0].typeName]
                off = found[1]
                if off.IsIdentity():
                    mapping = (1.0, 0.0, 1.0, 0.0)
                elif off.scale > 0:
                    inv = off.GetInverse()
                    mapping = (float(inv.scale), float(inv.offset), float(off.scale), float(off.offset))
                else:
                    return None
                sources.append((found[0], mapping))
            else:
                value = attr.Get(self.code0)
                type_name = self._static_types.get(type(value))  # a scalar's precision does not matter here
                static.append(value)
            if type_name not in _VALUE_TYPES[kind]:
                return None
            signature.append((op_type, inverse, kind, type_name, varying))
        return tuple(signature), static, sources

    # -------------------------------------------------------------- samples
    def layer_times(self, mapping: tuple) -> tuple[np.ndarray, list]:
        """Layer times of the time codes asked for under a layer offset (``t * inverse scale + inverse
        offset``, as ``SdfLayerOffset`` computes it), and the distinct ones sorted, as floats."""
        got = self._layer_times.get(mapping[:2])
        if got is None:
            lt = self.times if mapping[:2] == (1.0, 0.0) else self.times * mapping[0] + mapping[1]
            got = self._layer_times[mapping[:2]] = (lt, np.unique(lt).tolist())
        return got

    def samples(self, spec, mapping: tuple, type_name: str) -> tuple[tuple, list | None]:
        """``(sample times, values)`` of a spec's time samples that the time codes asked for need: all of
        them (one dictionary read), or those the time codes fall on or between, read one by one (a time
        code on a sample is one read, as USD's bracketing gives that sample alone). The values are None
        where the first is of another type than ``type_name``'s."""
        _, distinct = self.layer_times(mapping)
        if len(distinct) >= WHOLE_READ_SHARE * spec.GetNumTimeSamples():
            d = spec.GetInfo("timeSamples")
            keys, values = tuple(d), list(d.values())
        else:
            layer, path = spec.layer, spec.path
            got: dict[float, object] = {}
            query = layer.QueryTimeSample
            for t in distinct:
                if t in got:
                    continue
                value = query(path, t)
                if value is not None:
                    got[t] = value
                    continue
                _, lo, hi = layer.GetBracketingTimeSamplesForPath(path, t)
                for k in (lo, hi):
                    if k not in got:
                        got[k] = query(path, k)
            keys = tuple(sorted(got))
            values = [got[k] for k in keys]
        # Every sample of the expected type: USD interpolates only between samples of one type (it holds the
        # lower one otherwise), which a crate file written through Sdf can mix.
        want = self.values[type_name]
        return keys, values if values and all(type(v) is want for v in values) else None

    def evaluate(self, slot: tuple, sources: list, bad: np.ndarray) -> np.ndarray:
        """``(A, F, k)`` float64 values of one time-varying op of ``A`` prims at every time code, from
        their ``(spec, mapping)``; sets ``bad`` where one cannot be reproduced (a value block or a value
        of another type, half values to interpolate, a ``quatf`` slerp without ``sinf``)."""
        _, _, kind, type_name, _ = slot
        code = _CODES[type_name]
        read = [(*self.samples(spec, mapping, type_name), mapping) for spec, mapping in sources]
        groups: dict[tuple, list] = defaultdict(list)
        for a, (keys, values, mapping) in enumerate(read):
            if values is None:
                bad[a] = True
            else:
                groups[(keys, mapping)].append(a)
        out = np.zeros((len(sources), len(self.times), 16 if kind == "matrix" else 4 if kind == "quat" else 3))
        for (keys, mapping), members in groups.items():
            try:  # one Vt array for all (a value block or a value of another type: refused)
                v = _as_array(self.arrays, type_name, [x for a in members for x in read[a][1]])
            except TypeError:  # one by one, to find those at fault
                parts = []
                for a in members:
                    try:
                        parts.append(_as_array(self.arrays, type_name, read[a][1]))
                    except TypeError:
                        bad[a] = True
                members = [a for a in members if not bad[a]]
                if not members:
                    continue
                v = np.concatenate(parts)
            v = v.reshape(len(members), len(keys), -1)  # (members, samples, k)
            bracket = self._brackets.get((keys, mapping))
            if bracket is None:
                lt, _ = self.layer_times(mapping)
                bracket = self._brackets[(keys, mapping)] = sample_brackets(np.array(keys), lt, self.times, mapping[2:],
                                                                           self.held)
            lo, hi, alpha, lerp = bracket
            got = v[:, lo]
            if lerp.any():
                mixed = None if code == "h" else lerp_samples(kind, code, v[:, lo], v[:, hi], alpha)
                if mixed is None:  # half arithmetic is not reproduced; nor a quatf slerp without sinf
                    bad[members] = True
                    continue
                got = np.where(lerp[:, None], mixed, got)
            out[members, :, :got.shape[-1]] = got
        return out

    # -------------------------------------------------------------- composition
    def locals_(self, signature: tuple, entries: list, bad: np.ndarray):
        """Local transforms of ``A`` animated prims of one op signature at every time code:
        ``(linear 3x3, translation)`` entry by entry (arrays ``(A, F)`` or ``(A, 1)``; None for identity
        or zero); sets ``bad`` where a prim cannot be reproduced. ``entries``: ``(static values,
        sources)`` per prim."""
        ops, s, v = [], 0, 0
        for slot in signature:
            op_type, inverse, kind, type_name, varying = slot
            if varying:
                vals = self.evaluate(slot, [e[1][v] for e in entries], bad)
                v += 1
            else:
                vals = _as_array(self.arrays, type_name, [e[0][s] for e in entries]).astype(np.float64)[:, None]
                s += 1
            if kind == "matrix":
                m = vals.reshape(*vals.shape[:2], 4, 4)
                proj = ~(m[..., :, 3] == (0.0, 0.0, 0.0, 1.0)).all(axis=(1, 2))
                if inverse:  # USD's GfMatrix4d::GetInverse differs from numpy's where the inverse is ill-conditioned
                    lin = m[..., :3, :3]
                    proj |= (np.abs(np.linalg.det(lin)) < 1e-9).any(axis=1)
                    proj |= ~(np.linalg.cond(np.where(proj[:, None, None, None], np.eye(3), lin)) <= 1e3).all(axis=1)
                bad |= proj
                vals = np.where(proj[:, None, None], np.eye(4).ravel(), vals)
            ops.append(op_transform(op_type, inverse, vals))
        return compose_ops(ops)

    def batch(self, signature: tuple, group: list, bad: np.ndarray):
        """World transforms of the objects of ``A`` animated prims of one signature: ``(linear 3x3,
        translation)`` entry by entry, arrays ``(A, F)`` (one row per animated prim), after the parents'
        world transforms. ``group``: ``(key, prim, static values, sources, parent)`` per prim."""
        with np.errstate(all="ignore"):
            lin, t = self.locals_(signature, [(g[2], g[3]) for g in group], bad)
            shape = (len(group), len(self.times))
            eye = [[np.ones(1) if i == j else np.zeros(1) for j in range(3)] for i in range(3)]
            lin = [[np.broadcast_to(x, shape) for x in row] for row in (eye if lin is None else lin)]
            t = [np.broadcast_to(x, shape) for x in ([np.zeros(1)] * 3 if t is None else t)]
            parents = [g[4] for g in group]  # "identity" or (linear, translation)
            if not all(isinstance(p, str) for p in parents):
                pl = np.array([np.eye(3) if isinstance(p, str) else p[0] for p in parents])[:, None]
                pt = np.array([np.zeros(3) if isinstance(p, str) else p[1] for p in parents])[:, None]
                pl = [[pl[..., i, j] for j in range(3)] for i in range(3)]
                t = [t[0] * pl[0][j] + t[1] * pl[1][j] + t[2] * pl[2][j] + pt[..., j] for j in range(3)]
                lin = mul3(lin, pl)
        return lin, t


def _objects_world(lin, t, rows: np.ndarray, rel: np.ndarray | None):
    """The world transforms of objects from their animated prims' (``rows`` into the ``(A, F)`` arrays),
    times their static ``rel`` ``(B, 4, 4)`` (None: identity for all)."""
    if rows.size != len(lin[0][0]) or not np.array_equal(rows, np.arange(rows.size)):
        lin = [[x[rows] for x in row] for row in lin]
        t = [x[rows] for x in t]
    if rel is not None:
        rl = [[rel[:, i, j][:, None] for j in range(3)] for i in range(3)]
        t = [rel[:, 3, 0][:, None] * lin[0][j] + rel[:, 3, 1][:, None] * lin[1][j]
             + rel[:, 3, 2][:, None] * lin[2][j] + t[j] for j in range(3)]
        lin = mul3(rl, lin)
    return lin, t


def read_world_poses(stage: Usd.Stage, prims: list, times: np.ndarray, *, paths: list[str] | None = None,
                     info: XformInfo | None = None, progress: bool = False) -> WorldPoses:
    """World transforms of prims at every time code, as poses relative to the linear parts baked into
    their shapes (:func:`~warp_ccd._src.usd.poses.baked_linear` of the first matrices): in bulk where the
    op stacks allow it (see the module docstring), through ``UsdGeom.XformCache`` for the rest.

    Args:
        stage: the ``Usd.Stage``.
        prims: ``P`` prims (not PointInstancer instances).
        times: ``(F,)`` float64 time codes; the first is where ``first`` is read.
        paths: the prims' paths, if known.
        info: the per-prim :class:`XformInfo` of ``stage`` to share (one of its own by default).
        progress: show a progress bar on stderr.

    Returns:
        The :class:`WorldPoses`.
    """
    with paused_gc():
        return _read(stage, prims, np.asarray(times, np.float64), info or XformInfo(stage), progress, paths)


def read_world_matrices(stage: Usd.Stage, prims: list, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The world matrices :func:`read_world_poses` reads, as matrices: what the bulk read composes is
    compared with ``UsdGeom.XformCache`` through this.

    Args:
        stage: the ``Usd.Stage``.
        prims: ``P`` prims.
        times: ``(F,)`` float64 time codes.

    Returns:
        ``(matrices (F, P, 4, 4) float64 (row vectors), fast (P,) bool: read in bulk)``.
    """
    with paused_gc():
        out = _read(stage, prims, np.asarray(times, np.float64), XformInfo(stage), False, matrices=True)
    return out.matrices, out.fast


def _read(stage, prims: list, times: np.ndarray, info: XformInfo, progress: bool, paths: list | None = None,
          matrices: bool = False) -> WorldPoses:
    """:func:`read_world_poses` (and the world matrices, where asked for), the collector paused."""
    from pxr import Usd, UsdGeom
    from tqdm import tqdm

    num, frames = len(prims), len(times)
    reader = _Reader(stage, times, info)
    out = WorldPoses(np.empty((num, 4, 4)), np.empty((frames, num, 7)), np.empty((frames, num)),
                     np.ones(num, bool), np.ones((frames, num), bool), np.zeros(num, bool),
                     np.zeros((frames, num, 4, 4)) if matrices else None)
    bar = tqdm(total=num, desc="reading transforms", unit="prim", leave=False, disable=not progress or None,
               file=sys.stderr)
    static, slow = [], []
    groups: dict[tuple, dict] = defaultdict(dict)  # signature -> animated prim key -> (entry, [(row, rel)])
    plans: dict[str, object] = {}
    for row, prim in enumerate(prims):
        chain = reader.chain(prim, str(prim.GetPath()) if paths is None else paths[row]) if FAST_XFORMS else None
        if chain is None:
            slow.append(row)
            continue
        anim, key, rel = chain
        if anim == "static":
            static.append(row)
            continue
        plan = plans.get(key, False)
        if plan is False:
            parent = reader.parent(anim, key)
            plan = reader.plan(anim, key) if parent is not None else None
            plans[key] = plan = None if plan is None else (plan, parent, anim)
        if plan is None:
            slow.append(row)
            continue
        (signature, values, sources), parent, anim = plan
        entry = groups[signature].get(key)
        if entry is None:
            entry = groups[signature][key] = ((key, anim, values, sources, parent), [])
        entry[1].append((row, rel))
    batch = max(1, BATCH // frames)
    for signature, members in groups.items():
        members = list(members.values())
        for start in range(0, len(members), batch):
            part = members[start:start + batch]
            bad = np.zeros(len(part), bool)
            lin, t = reader.batch(signature, [m[0] for m in part], bad)
            a = np.array([k for k, m in enumerate(part) if not bad[k] for _ in m[1]], np.int64)
            rows = np.array([r for k, m in enumerate(part) if not bad[k] for r, _ in m[1]], np.int64)
            slow += [r for k, m in enumerate(part) if bad[k] for r, _ in m[1]]
            if rows.size:
                rels = [rel for k, m in enumerate(part) if not bad[k] for _, rel in m[1]]
                rel = None if all(r is None for r in rels) else np.array([np.eye(4) if r is None else r for r in rels])
                _fill(out, rows, *_objects_world(lin, t, a, rel))
            bar.update(len(rows))
    if static:
        rows = np.array(static, np.int64)
        first = np.array([world_transform(reader.cache0, prims[r], times[0]) for r in static], np.float64)
        out.first[rows] = first.reshape(-1, 4, 4)
        finite, poses, scale, ok = finite_matrix_poses(out.first[rows], baked_linear(out.first[rows])[0])
        out.poses[:, rows], out.scale[:, rows], out.ok[rows], out.finite[:, rows] = poses, scale, ok, finite
        if matrices:
            out.matrices[:, rows] = out.first[rows]
        bar.update(len(rows))
    if slow:
        rows = np.array(sorted(slow), np.int64)
        chosen = [prims[r] for r in rows.tolist()]
        bake = None
        for f, t in enumerate(times.tolist()):
            cache = reader.cache0 if f == 0 else UsdGeom.XformCache(Usd.TimeCode(t))
            m = np.array([world_transform(cache, p, t) for p in chosen], np.float64).reshape(-1, 4, 4)
            if f == 0:
                out.first[rows] = m
                bake = baked_linear(m)[0]
            out.finite[f, rows], out.poses[f, rows], out.scale[f, rows], ok = finite_matrix_poses(m, bake)
            out.ok[rows] &= ok
            if matrices:
                out.matrices[f, rows] = m
            bar.update(len(rows) / frames)
    bar.close()
    out.fast[:] = True
    out.fast[np.array(sorted(slow), np.int64)] = False
    return out


def _fill(out: WorldPoses, rows: np.ndarray, lin, t) -> None:
    """Writes the first matrices, poses, scales and flags of objects ``rows`` from their world transforms
    (entry by entry, arrays ``(B, F)``) into ``out``."""
    with np.errstate(all="ignore"):
        first = np.zeros((rows.size, 4, 4))
        for i in range(3):
            for j in range(3):
                first[:, i, j] = lin[i][j][:, 0]
            first[:, 3, i] = t[i][:, 0]
        first[:, 3, 3] = 1.0
        bake, _ = baked_linear(first)
        baked = ~(bake == np.eye(3)).all(axis=(1, 2))
        inverse = None
        if baked.any():
            binv = np.tile(np.eye(3), (rows.size, 1, 1))
            binv[baked] = np.linalg.inv(bake[baked])
            inverse = [[binv[:, i, j][:, None] for j in range(3)] for i in range(3)]
        poses, scale, ok = affine_poses(lin, t, inverse)
        # Finite where the scale (from the sum of the squares of the linear part) and the translation are.
        finite = np.isfinite(scale) & np.isfinite(t[0] + t[1] + t[2])
    out.first[rows] = first
    if out.matrices is not None:
        for i in range(3):
            for j in range(3):
                out.matrices[:, rows, i, j] = lin[i][j].T
            out.matrices[:, rows, 3, i] = t[i].T
        out.matrices[:, rows, 3, 3] = 1.0
    out.poses[:, rows] = poses.transpose(1, 0, 2)
    out.scale[:, rows] = scale.T
    out.ok[rows] = ok.all(axis=1)
    out.finite[:, rows] = finite.T
