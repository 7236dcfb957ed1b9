"""USD Physics' own collision rules in a check: rigid bodies, joints, articulations.

A physics engine never tests two colliders of one rigid body against each other, nor (by default) two bodies
that a joint joins. A check of the same stage honours both, as excluded object pairs
(:mod:`~warp_ccd._src.usd.filters` turns them into the scene's ``exclude_pairs``, with
``UsdPhysics.FilteredPairsAPI`` and collision groups, all under ``usd_filters``). What the schema
(``pxr/usd/usdPhysics/schema.usda``) says, and what is done here:

* **Rigid bodies.** ``PhysicsRigidBodyAPI``: "All prims in the hierarchy below this prim should move rigidly
  along with the body, except when the descendant prim has its own UsdPhysicsRigidBodyAPI (marking a separate
  rigid body subtree which moves independently of the parent rigid body)". So a mesh belongs to its nearest
  rigid body at or above it, and meshes of one body are one object: never checked against each other. A
  body whose ``physics:rigidBodyEnabled`` is false is muted, as if it had no API ("Determines if this
  PhysicsRigidBodyAPI is enabled"; UsdPhysics' own parser, ``UsdPhysicsLoadStageFromPrimRange``, then gives its
  meshes to the enabled body above it, or to none). A rigid body inside a PointInstancer's prototype is one
  body per instance. A body's meshes are checked against every other body's, nested ones included.
* **Joints.** ``PhysicsJoint`` (any subtype): ``physics:collisionEnabled`` "Determines if the jointed subtrees
  should collide or not", false by default ("default behavior is to disable collision between jointed
  bodies"). So when it is false, the meshes of the body ``physics:body0`` names are never checked against those
  of the body ``physics:body1`` names. A target is resolved as UsdPhysics' parser resolves it: to the nearest
  enabled rigid body at or above the target prim (a target under a body names the body); a target under no
  body is a static collider, and names the meshes at or under it that belong to no body. A joint with an empty
  side joins a body to the world (the static frame): nothing to exclude; so does a target naming no prim of
  the stage (with a note). ``physics:jointEnabled`` false: the schema says only "Determines if the joint is
  enabled", and the overview gives enable flags as a way to mute an object without deleting it; read so, a
  disabled joint is absent, constrains nothing and filters nothing: its bodies are checked against each other.
  ``physics:excludeFromArticulation`` ("Determines if the joint can be included in an Articulation") changes
  how a joint is simulated, not whether its bodies collide: not read. A flag that changes over time (time
  samples of different values) cannot make a filter of the whole check: such a joint excludes nothing (a
  note); a ``rigidBodyEnabled`` that changes over time counts as enabled (a note).
* **Articulations.** ``PhysicsArticulationRootAPI`` "marks the subtree rooted here for inclusion in one or more
  reduced coordinate articulations"; the schema says nothing about collisions between the links, and
  UsdPhysics' parser gives an articulation only the ``physics:filteredPairs`` of its root prim. So links of an
  articulation follow the joints between them (``collisionEnabled``, as any joint); two links joined by no
  joint are checked against each other; a ``FilteredPairsAPI`` on the root prim excludes as on any prim.
  (PhysX also drops contacts between a link and its parent link whatever the joint says; that is PhysX's, not
  the schema's, and not done here.) Articulation roots are counted for the report.

Cost: the prims are those of the filters' one traversal; per object, numpy only. A body of ``m`` meshes
excludes ``m (m - 1) / 2`` object pairs and a joint ``m0 m1``, each an explicit key (the broad phase's
filters have no "one body" id: worlds pair within, groups and masks have 32 bits), counted against
:data:`~warp_ccd._src.usd.filters.MAX_EXCLUDED` before any is made: a body of more than about 10,000 meshes is
an error (with ``--no-usd-filters``, checked as separate meshes).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

PrimIndex = Any
"""A :class:`~warp_ccd._src.usd.filters.PrimIndex` (typed loosely here: filters imports this module)."""

__all__ = ["PhysicsPrims", "body_keys", "joint_keys", "object_bodies"]


def constant_bool(attr: Any) -> bool | None:
    """A bool attribute's value when it is the same at every time (its default or fallback, and every time
    sample), else None."""
    times = attr.GetTimeSamples()
    values = {bool(attr.Get(t)) for t in times} if times else {bool(attr.Get())}
    return values.pop() if len(values) == 1 else None


@dataclass
class PhysicsPrims:
    """The rigid bodies and joints of a stage, gathered during the filters' traversal.

    Attributes:
        bodies: prim paths of the enabled rigid bodies.
        joints: ``(joint path, body0 target or None, body1 target or None)`` of the joints whose
            ``collisionEnabled`` is false and that are enabled (the others exclude nothing).
        num_joints: every joint read.
        num_articulations: prims with ``PhysicsArticulationRootAPI``.
        notes: targets naming no prim, flags that change over time.
    """

    bodies: list[str] = field(default_factory=list)
    joints: list[tuple[str, str | None, str | None]] = field(default_factory=list)
    num_joints: int = 0
    num_articulations: int = 0
    notes: list[str] = field(default_factory=list)

    def add(self, prim: Any) -> None:
        """Reads ``prim`` when it is a rigid body, a joint or an articulation root.

        Raises:
            ValueError: naming the joint: a ``physics:body0`` or ``physics:body1`` with several targets, or
                one that is a property rather than a prim.
        """
        from pxr import UsdPhysics

        path = str(prim.GetPath())
        if prim.HasAPI(UsdPhysics.RigidBodyAPI):
            enabled = constant_bool(UsdPhysics.RigidBodyAPI(prim).GetRigidBodyEnabledAttr())
            if enabled is None:
                self.notes.append(f"rigid body {path}: physics:rigidBodyEnabled changes over time; read as enabled")
            if enabled is not False:
                self.bodies.append(path)
        if prim.HasAPI(UsdPhysics.ArticulationRootAPI):
            self.num_articulations += 1
        if not prim.IsA(UsdPhysics.Joint):
            return
        self.num_joints += 1
        joint = UsdPhysics.Joint(prim)
        targets = [self._target(prim, rel) for rel in (joint.GetBody0Rel(), joint.GetBody1Rel())]
        enabled = constant_bool(joint.GetJointEnabledAttr())
        collides = constant_bool(joint.GetCollisionEnabledAttr())
        if enabled is None or collides is None:
            which = "jointEnabled" if enabled is None else "collisionEnabled"
            self.notes.append(f"joint {path}: physics:{which} changes over time; its bodies are checked")
        elif enabled and not collides:
            self.joints.append((path, targets[0], targets[1]))

    def _target(self, prim: Any, rel: Any) -> str | None:
        """The prim path a joint's body relationship names, or None (the world)."""
        targets = rel.GetTargets() if rel else []
        name = f"joint {prim.GetPath()}: {rel.GetName() if rel else 'physics:body'}"
        if len(targets) > 1:
            raise ValueError(f"{name} has {len(targets)} targets ({', '.join(map(str, targets))}); a joint joins "
                             "one body on each side")
        if not targets:
            return None
        target = targets[0]
        if not target.IsPrimPath():
            raise ValueError(f"{name} targets {target}, which is not a prim")
        if not prim.GetStage().GetPrimAtPath(target).IsValid():
            self.notes.append(f"{name} target {target} is no prim of the stage; the joint is read as one to the "
                              "world")
            return None
        return str(target)


def object_bodies(index: PrimIndex, bodies: Sequence[str], instancer: np.ndarray | None = None,
                  instance: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Each object's rigid body.

    Args:
        index: the objects' :class:`~warp_ccd._src.usd.filters.PrimIndex`.
        bodies: prim paths of the enabled rigid bodies.
        instancer: ``(N,)`` int64 the ancestor id (in ``index``) of each object's PointInstancer, ``-1`` for
            objects that are no point instance; or None (none is).
        instance: ``(N,)`` int64 each point instance's index, with ``instancer``.

    Returns:
        ``(body, group)``: ``(N,)`` int64 the ancestor id of each object's body prim (its nearest enabled
        rigid body at or above it), ``-1`` for none; and ``(N,)`` int64 a group id per body, one per instance
        for a body inside a PointInstancer's prototype (``0 .. G - 1``), ``-1`` for none.
    """
    hit = np.zeros(len(index.ancestors), bool)
    ids = [index.ancestor_id(p) for p in bodies]
    hit[[k for k in ids if k is not None]] = True
    body = index.innermost(hit)
    split = np.full(index.num_objects, -1, np.int64)
    if instancer is not None:
        depth = index.depth
        inside = (body >= 0) & (instancer >= 0)
        inside[inside] = depth[body[inside]] > depth[instancer[inside]]  # the body lies in a prototype
        split[inside] = instance[inside]
    group = np.full(index.num_objects, -1, np.int64)
    has = body >= 0
    if has.any():
        _, group[has] = np.unique(np.stack([body[has], split[has]], axis=1), axis=0, return_inverse=True)
    return body, group


def _key(i: np.ndarray, j: np.ndarray) -> np.ndarray:
    return (np.minimum(i, j) << 32) | np.maximum(i, j)


def body_keys(group: np.ndarray, index: PrimIndex, body: np.ndarray, budget: list) -> np.ndarray:
    """Keys ``min << 32 | max`` of every pair of two objects of one body.

    Args:
        group: ``(N,)`` int64 body group of each object (:func:`object_bodies`), ``-1`` for none.
        index: the objects' prim index (for messages).
        body: ``(N,)`` int64 body prim of each object (an ancestor id, for messages).
        budget: ``[pairs left]`` of :data:`~warp_ccd._src.usd.filters.MAX_EXCLUDED`; lowered by the pairs made.

    Returns:
        ``(P,)`` int64 keys, ``P = sum m (m - 1) / 2`` over the bodies' mesh counts ``m``.

    Raises:
        ValueError: naming the body with the most meshes when ``P`` passes the budget.
    """
    obj = np.nonzero(group >= 0)[0]
    order = obj[np.argsort(group[obj], kind="stable")]
    g = group[order]
    after = np.searchsorted(g, g, side="right") - np.arange(len(g)) - 1  # objects of its body after each one
    total = int(after.sum())
    if total > budget[0]:
        sizes = np.bincount(g)
        big = order[np.argmax(g == np.argmax(sizes))]
        raise ValueError(f"rigid body {index.ancestors[body[big]]}: its {sizes.max()} meshes, one object for the "
                         f"check, make {total} excluded object pairs with the other bodies', more than the "
                         f"{budget[0]} left of the excluded pairs' limit; --no-usd-filters checks them as "
                         "separate meshes")
    budget[0] -= total
    first = np.repeat(np.arange(len(g)), after)
    second = first + 1 + np.arange(total) - np.repeat(np.cumsum(after) - after, after)
    return _key(order[first], order[second])


def joint_keys(joints: Sequence[tuple[str, str | None, str | None]], index: PrimIndex, body: np.ndarray,
               bodies: Sequence[str], budget: list) -> np.ndarray:
    """Keys ``min << 32 | max`` of the object pairs the joints exclude: every mesh of one side against every mesh
    of the other.

    Args:
        joints: ``(joint path, body0 target, body1 target)`` of the joints that exclude (targets: prim
            paths, None for the world).
        index: the objects' prim index.
        body: ``(N,)`` int64 body prim of each object (an ancestor id, ``-1`` for none; :func:`object_bodies`).
        bodies: prim paths of the enabled rigid bodies.
        budget: ``[pairs left]``; lowered by the pairs made.

    Returns:
        ``(P,)`` int64 keys (a pair may repeat), ``P = sum m0 m1`` over the joints' sides.

    Raises:
        ValueError: naming the joint with the most pairs when ``P`` passes the budget.
    """
    enabled = set(bodies)
    # Sides as (start, count) in one array of objects: the objects of each body, sorted by body, then
    # each static target's objects (meshes at or under it in no body).
    order = np.nonzero(body >= 0)[0]
    order = order[np.argsort(body[order], kind="stable")]
    sorted_body = body[order]
    parts, used = [order], len(order)
    static: dict[str, tuple[int, int]] = {}

    def side(target: str | None) -> tuple[int, int]:
        if target is None:
            return 0, 0
        path = target
        while path and path != "/":
            if path in enabled:  # the nearest enabled rigid body at or above the target
                k = index.ancestor_id(path)
                if k is None:
                    return 0, 0  # no checked mesh in it
                lo, hi = np.searchsorted(sorted_body, [k, k + 1])
                return int(lo), int(hi - lo)
            path = path.rsplit("/", 1)[0]
        if target not in static:
            nonlocal used
            mine = index.select(target)
            mine = mine[body[mine] < 0]
            static[target] = (used, len(mine))
            parts.append(mine)
            used += len(mine)
        return static[target]

    rows = [(*side(a), *side(b)) for _, a, b in joints]  # per joint prim: its two sides
    if not rows:
        return np.zeros(0, np.int64)
    r = np.asarray(rows, np.int64).reshape(-1, 4)
    members = np.concatenate(parts).astype(np.int64)
    a_start, a_count, b_start, b_count = r.T
    count = a_count * b_count * (a_start != b_start)  # a joint within one body: its pairs are the body's
    total = int(count.sum())
    if total > budget[0]:
        k = int(np.argmax(count))
        raise ValueError(f"joint {joints[k][0]}: its bodies' meshes ({a_count[k]} x {b_count[k]}), with the other "
                         f"joints', make {total} excluded object pairs, more than the {budget[0]} left of the "
                         "excluded pairs' limit; --no-usd-filters checks them")
    budget[0] -= total
    row = np.repeat(np.arange(len(count)), count)
    local = np.arange(total) - np.repeat(np.cumsum(count) - count, count)
    i = members[a_start[row] + local // b_count[row]]
    j = members[b_start[row] + local % b_count[row]]
    keep = i != j  # two static targets, one under the other, share meshes
    return _key(i[keep], j[keep])
