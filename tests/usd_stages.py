"""USD stages for the tests, built with ``pxr``, and their world meshes computed independently.

:func:`mixed_stage` holds one of everything ``scene_from_usd`` reads: rigid prims moved by
time-sampled transforms under nested (scaled) parents, a non-uniform scale, a deforming mesh,
a PointInstancer with two prototypes, instanceable references of one prototype, polygons of 4 to
8 sides with a hole, a resting box that only touches the floor, and prims that must be skipped
(a guide, an invisible one). :func:`world_polygon_meshes` computes every object's world
triangles at a time code with plain per-prim loops and USD's own transforms, for the oracles.
"""

from __future__ import annotations

import numpy as np


def prism(sides: int, radius: float = 1.0, height: float = 1.0):
    """A closed prism: two ``sides``-gons and ``sides`` quads. Returns ``(points (2s, 3), counts, indices)``."""
    a = 2 * np.pi * np.arange(sides) / sides
    ring = np.stack([radius * np.cos(a), np.zeros(sides), radius * np.sin(a)], axis=1)
    points = np.concatenate([ring, ring + [0, height, 0]])
    counts = [sides, sides] + [4] * sides
    indices = list(range(sides - 1, -1, -1)) + list(range(sides, 2 * sides))
    for i in range(sides):
        j = (i + 1) % sides
        indices += [i, j, sides + j, sides + i]
    return points, counts, indices


def grid(n: int, size: float):
    """A flat ``n x n`` quad grid in the y = 0 plane, centred. Returns ``(points, counts, indices)``."""
    x = np.linspace(-size / 2, size / 2, n + 1)
    gx, gz = np.meshgrid(x, x, indexing="ij")
    points = np.stack([gx.ravel(), np.zeros(gx.size), gz.ravel()], axis=1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    quads = np.stack([idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]], axis=-1).reshape(-1, 4)
    return points, [4] * len(quads), quads.ravel().tolist()


def define_mesh(stage, path: str, points, counts, indices, holes=None):
    from pxr import UsdGeom, Vt

    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.asarray(points, np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray([int(c) for c in counts]))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray([int(i) for i in indices]))
    if holes is not None:
        mesh.CreateHoleIndicesAttr(Vt.IntArray(list(holes)))
    return mesh


def mixed_stage(path=None, num_frames: int = 24):
    """The stage described in the module docstring, time codes ``0 .. num_frames - 1``.

    Returns:
        The ``Usd.Stage`` (saved to ``path`` when given).
    """
    from pxr import Gf, Sdf, Usd, UsdGeom, Vt

    stage = Usd.Stage.CreateNew(str(path)) if path is not None else Usd.Stage.CreateInMemory()
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(num_frames - 1)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    frames = range(num_frames)

    define_mesh(stage, "/World/Floor", *grid(6, 12.0))
    box = define_mesh(stage, "/World/Resting", *prism(4, radius=0.7, height=1.0))  # on the floor: touches only
    UsdGeom.Xformable(box).AddTranslateOp().Set(Gf.Vec3d(-4.0, 0.0, -4.0))

    # Two rigid movers under a scaled, rotated parent: an octagonal prism sweeping along x through
    # a hexagonal prism spinning in place.
    movers = UsdGeom.Xform.Define(stage, "/World/Movers")
    movers.AddTranslateOp().Set(Gf.Vec3d(0.0, 2.0, 0.0))
    movers.AddRotateYOp().Set(30.0)
    movers.AddScaleOp().Set(Gf.Vec3f(1.5, 1.5, 1.5))
    a = UsdGeom.Xform.Define(stage, "/World/Movers/A")
    ta = a.AddTranslateOp()
    ra = a.AddOrientOp()
    for f in frames:
        ta.Set(Gf.Vec3d(-3.0 + 6.0 * f / max(num_frames - 1, 1), 0.1, 0.05), f)
        q = Gf.Rotation(Gf.Vec3d(0.3, 1.0, 0.2), 10.0 * f).GetQuat()
        ra.Set(Gf.Quatf(q), f)
    define_mesh(stage, "/World/Movers/A/Geom", *prism(8, radius=0.5, height=0.8))
    b = UsdGeom.Xform.Define(stage, "/World/Movers/B")
    rb = b.AddRotateXYZOp()
    for f in frames:
        rb.Set(Gf.Vec3f(5.0 * f, 12.0 * f, 0.0), f)
    define_mesh(stage, "/World/Movers/B/Geom", *prism(6, radius=0.6, height=0.7), holes=[2])

    # A non-uniform scale (baked into a shape of its own), crossing the floor.
    stretched = define_mesh(stage, "/World/Stretched", *prism(5, radius=0.5, height=1.0))
    st = UsdGeom.Xformable(stretched)
    tr = st.AddTranslateOp()
    for f in frames:
        tr.Set(Gf.Vec3d(4.0, -0.6 + 0.05 * f, 4.0), f)
    st.AddScaleOp().Set(Gf.Vec3f(2.0, 1.0, 0.5))

    # A deforming mesh: a heptagonal prism whose top breathes, near the instancer's row.
    blob_points, blob_counts, blob_indices = prism(7, radius=0.6, height=0.8)
    blob = define_mesh(stage, "/World/Blob", blob_points, blob_counts, blob_indices)
    UsdGeom.Xformable(blob).AddTranslateOp().Set(Gf.Vec3d(0.0, 0.5, 4.0))
    pts = blob.GetPointsAttr()
    for f in frames:
        p = blob_points.copy()
        p[7:, 0] *= 1.0 + 1.2 * f / max(num_frames - 1, 1)
        pts.Set(Vt.Vec3fArray.FromNumpy(p.astype(np.float32)), f)

    # A PointInstancer: six instances of two prototypes in a row along x, sliding towards the blob.
    inst = UsdGeom.PointInstancer.Define(stage, "/World/Inst")
    UsdGeom.Scope.Define(stage, "/World/Inst/Protos")
    cube = UsdGeom.Xform.Define(stage, "/World/Inst/Protos/Cube")
    cube.AddScaleOp().Set(Gf.Vec3f(0.5, 0.5, 0.5))  # the prototype root's own transform counts
    define_mesh(stage, "/World/Inst/Protos/Cube/Geom", *prism(4, radius=1.0, height=1.0))
    define_mesh(stage, "/World/Inst/Protos/Tet", [[0, 0, 0], [0.8, 0, 0], [0, 0.8, 0], [0, 0, 0.8]],
                [3, 3, 3, 3], [0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3])
    inst.CreatePrototypesRel().SetTargets([Sdf.Path("/World/Inst/Protos/Cube"), Sdf.Path("/World/Inst/Protos/Tet")])
    inst.CreateProtoIndicesAttr(Vt.IntArray([0, 1, 0, 1, 0, 1]))
    pos = inst.CreatePositionsAttr()
    orient = inst.CreateOrientationsAttr()
    orient.Set(Vt.QuathArray([Gf.Quath(1, 0, 0, 0)] * 6))
    for f in frames:
        x = -3.0 + 1.2 * np.arange(6)
        z = 5.5 - 1.5 * f / max(num_frames - 1, 1) + 0.0 * x
        pos.Set(Vt.Vec3fArray.FromNumpy(np.stack([x, np.full(6, 0.6), z], axis=1).astype(np.float32)), f)

    # Instanceable references of one prototype (two prisms apart): two spinning copies that overlap each other.
    proto = UsdGeom.Xform.Define(stage, "/Prototypes/Pair")
    stage.GetPrimAtPath("/Prototypes").SetSpecifier(Sdf.SpecifierClass)
    define_mesh(stage, "/Prototypes/Pair/Left", *prism(4, radius=0.4, height=0.6))
    left = UsdGeom.Xformable(stage.GetPrimAtPath("/Prototypes/Pair/Left"))
    left.AddTranslateOp().Set(Gf.Vec3d(-1.0, 0.0, 0.0))
    define_mesh(stage, "/Prototypes/Pair/Right", *prism(5, radius=0.4, height=0.6))
    del proto
    for name, x in (("RefA", -5.0), ("RefB", -4.5)):
        ref = UsdGeom.Xform.Define(stage, f"/World/{name}")
        ref.GetPrim().GetReferences().AddInternalReference("/Prototypes/Pair")
        ref.GetPrim().SetInstanceable(True)
        ref.AddTranslateOp().Set(Gf.Vec3d(x, 3.0, 2.0))
        spin = ref.AddRotateYOp()
        for f in frames:
            spin.Set(7.0 * f * (1 if name == "RefA" else -1), f)

    # Skipped: a guide and an invisible mesh, both right through the floor.
    guide = define_mesh(stage, "/World/Guide", *prism(4, radius=1.0, height=2.0))
    guide.CreatePurposeAttr(UsdGeom.Tokens.guide)
    UsdGeom.Xformable(guide).AddTranslateOp().Set(Gf.Vec3d(2.0, -1.0, -2.0))
    hidden = define_mesh(stage, "/World/Hidden", *prism(4, radius=1.0, height=2.0))
    hidden.CreateVisibilityAttr(UsdGeom.Tokens.invisible)
    UsdGeom.Xformable(hidden).AddTranslateOp().Set(Gf.Vec3d(-2.0, -1.0, 2.0))
    if path is not None:
        stage.GetRootLayer().Save()
    return stage


def fan(counts, indices, holes=()):
    """Fan triangles of USD polygons and the face of each, plain loops (as the USD import is
    documented to fan: ``n - 2`` triangles a face from its first vertex, faces in ``holes`` left out).

    Returns:
        ``(triangles (m, 3) int32, faces (m,) int32)``.
    """
    tris, faces, k = [], [], 0
    for f, c in enumerate(counts):
        poly = list(indices[k:k + c])
        k += c
        if f in holes:
            continue
        for j in range(1, c - 1):
            tris.append((poly[0], poly[j], poly[j + 1]))
            faces.append(f)
    return np.array(tris, np.int32).reshape(-1, 3), np.array(faces, np.int32)


def world_polygon_meshes(stage, time) -> dict:
    """Every object's world triangles at ``time``, computed prim by prim with plain loops.

    Returns:
        ``{object path: (world vertices (n, 3) float64, triangles (m, 3) int32, USD face of each triangle)}``,
        named as :class:`warp_ccd._src.usd.importer.UsdMeshImport` names its objects. Guides, invisible
        prims and a PointInstancer's prototypes (drawn through the instancer only) are left out.
    """
    from pxr import Usd, UsdGeom

    code = Usd.TimeCode(time)
    cache = UsdGeom.XformCache(code)
    out = {}

    def read(prim, m):
        """Points, triangles wound so that their normals point out of the object (the other way
        round for a leftHanded mesh or under a mirroring world matrix ``m``), faces."""
        mesh = UsdGeom.Mesh(prim)
        points = np.asarray(mesh.GetPointsAttr().Get(code), np.float64)
        holes = set(mesh.GetHoleIndicesAttr().Get(code) or [])
        tri, face = fan(list(mesh.GetFaceVertexCountsAttr().Get(code)),
                        list(mesh.GetFaceVertexIndicesAttr().Get(code)), holes)
        left = mesh.GetOrientationAttr().Get(code) == UsdGeom.Tokens.leftHanded
        if left != (np.linalg.det(m[:3, :3]) < 0):
            tri = np.ascontiguousarray(tri[:, ::-1])
        return points, tri, face

    it = iter(Usd.PrimRange(stage.GetPseudoRoot(), Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)))
    for prim in it:
        if prim.IsA(UsdGeom.Imageable):
            img = UsdGeom.Imageable(prim)
            if img.ComputePurpose() in ("guide", "proxy") or img.ComputeVisibility(code) == UsdGeom.Tokens.invisible:
                it.PruneChildren()
                continue
        if prim.IsA(UsdGeom.PointInstancer):
            it.PruneChildren()
            inst = UsdGeom.PointInstancer(prim)
            xf = inst.ComputeInstanceTransformsAtTime(code, code)
            world = np.asarray(cache.GetLocalToWorldTransform(prim))
            protos = inst.GetPrototypesRel().GetTargets()
            for i, p_idx in enumerate(inst.GetProtoIndicesAttr().Get(code)):
                root = stage.GetPrimAtPath(protos[p_idx])
                for p in Usd.PrimRange(root):
                    if p.IsA(UsdGeom.Mesh):
                        rel = np.asarray(cache.ComputeRelativeTransform(p, root)[0])
                        m = rel @ np.asarray(xf[i]) @ world
                        points, tri, face = read(p, m)
                        name = f"{prim.GetPath()}[{i}]{str(p.GetPath())[len(str(root.GetParent().GetPath())):]}"
                        out[name] = (points @ m[:3, :3] + m[3, :3], tri, face)
            continue
        if prim.IsA(UsdGeom.Mesh):
            m = np.asarray(cache.GetLocalToWorldTransform(prim))
            points, tri, face = read(prim, m)
            out[str(prim.GetPath())] = (points @ m[:3, :3] + m[3, :3], tri, face)
    return out


DUPLICATE_CASES = ("exact", "reordered", "offset", "half_turn", "quarter_turn")
"""The copies :func:`duplicate_stage` builds: the same mesh (``exact``); its fanned triangles shuffled, each
one's vertices rotated and the vertices renumbered (``reordered``); moved by 1e-3 of its bounding-box
diagonal (``offset``); turned half a turn about its axis, where its triangles land on the original's
(``half_turn``); turned a quarter turn, which fills the same box with other triangles (``quarter_turn``)."""


def duplicate_stage(case: str = "exact", path=None, seed: int = 0):
    """A box-like prism ``/World/Part`` (at ``(1, 2, 3)``) and ``/World/Copy/Part``, a copy of it under an
    ``Xform`` that carries the translation instead (another hierarchy, the same world matrix), made as
    :data:`DUPLICATE_CASES` says; a floor ``/World/Floor`` far below. Time codes 0 to 2: the copy sits
    on the original at 0 and 1 and is lifted by 0.5 at 2 (then it penetrates the original).

    Returns:
        ``(stage, diagonal)``: the ``Usd.Stage`` (saved to ``path`` when given) and the prism's
        bounding-box diagonal.
    """
    from pxr import Gf, Usd, UsdGeom

    stage = Usd.Stage.CreateNew(str(path)) if path is not None else Usd.Stage.CreateInMemory()
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(2)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    points, counts, indices = prism(4, radius=0.7, height=1.0)
    diagonal = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    define_mesh(stage, "/World/Floor", *grid(2, 12.0))
    UsdGeom.Xformable(stage.GetPrimAtPath("/World/Floor")).AddTranslateOp().Set(Gf.Vec3d(0.0, -5.0, 0.0))
    part = define_mesh(stage, "/World/Part", points, counts, indices)
    UsdGeom.Xformable(part).AddTranslateOp().Set(Gf.Vec3d(1.0, 2.0, 3.0))
    holder = UsdGeom.Xform.Define(stage, "/World/Copy")
    move = holder.AddTranslateOp()
    for tc, lift in ((0, 0.0), (1, 0.0), (2, 0.5)):
        move.Set(Gf.Vec3d(1.0, 2.0 + lift, 3.0), tc)
    if case == "reordered":
        rng = np.random.default_rng(seed)
        tri, _ = fan(counts, indices)
        tri = tri[rng.permutation(len(tri))]
        tri = np.array([np.roll(t, int(r)) for t, r in zip(tri, rng.integers(0, 3, len(tri)))])  # same winding
        new_of_old = rng.permutation(len(points))
        copy = np.empty_like(points)
        copy[new_of_old] = points
        define_mesh(stage, "/World/Copy/Part", copy, [3] * len(tri), new_of_old[tri].ravel().tolist())
    else:
        copy = define_mesh(stage, "/World/Copy/Part", points, counts, indices)
        xf = UsdGeom.Xformable(copy)
        if case == "offset":
            xf.AddTranslateOp().Set(Gf.Vec3d(*(1e-3 * diagonal * np.array([0.6, 0.0, 0.8]))))
        elif case in ("half_turn", "quarter_turn"):
            xf.AddRotateYOp().Set(180.0 if case == "half_turn" else 90.0)
        elif case != "exact":
            raise ValueError(f"unknown case {case!r} (one of {', '.join(DUPLICATE_CASES)})")
    if path is not None:
        stage.GetRootLayer().Save()
    return stage, diagonal


def boxes_stage(path=None, boxes: dict | None = None, filtered_pairs: dict | None = None,
                collision_groups: dict | None = None, filtered_groups: dict | None = None):
    """Box-like prisms (``prism(4)``, radius 0.7, height 1) for the filter tests, time codes 0 and 1, static.

    Args:
        path: where to save the stage (None: in memory).
        boxes: ``{mesh path: (x, y, z) translation}``; the parents of a mesh path are made ``Xform``s. Default:
            ``/World/A/Geom`` at the origin and ``/World/B/Geom`` 0.5 along x (they penetrate).
        filtered_pairs: ``{prim path: [target paths]}``: ``UsdPhysics.FilteredPairsAPI`` applied to the prim
            with those ``physics:filteredPairs`` targets.
        collision_groups: ``{group path: [member paths]}``: ``UsdPhysics.CollisionGroup`` prims whose
            ``collectionAPI:colliders`` includes the members.
        filtered_groups: ``{group path: [group paths]}``: the groups' ``physics:filteredGroups``.

    Returns:
        The ``Usd.Stage`` (saved to ``path`` when given).
    """
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics

    stage = Usd.Stage.CreateNew(str(path)) if path is not None else Usd.Stage.CreateInMemory()
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(1)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    boxes = {"/World/A/Geom": (0.0, 0.0, 0.0), "/World/B/Geom": (0.5, 0.0, 0.0)} if boxes is None else boxes
    points, counts, indices = prism(4, radius=0.7, height=1.0)
    for mesh_path, offset in boxes.items():
        parent = Sdf.Path(mesh_path).GetParentPath()
        while parent != Sdf.Path.absoluteRootPath and not stage.GetPrimAtPath(parent).IsValid():
            UsdGeom.Xform.Define(stage, parent)
            parent = parent.GetParentPath()
        mesh = define_mesh(stage, mesh_path, points, counts, indices)
        UsdGeom.Xformable(mesh).AddTranslateOp().Set(Gf.Vec3d(*offset))
    for prim_path, targets in (filtered_pairs or {}).items():
        api = UsdPhysics.FilteredPairsAPI.Apply(stage.GetPrimAtPath(prim_path))
        api.CreateFilteredPairsRel().SetTargets([Sdf.Path(t) for t in targets])
    for group_path, members in (collision_groups or {}).items():
        group = UsdPhysics.CollisionGroup.Define(stage, group_path)
        group.GetCollidersCollectionAPI().CreateIncludesRel().SetTargets([Sdf.Path(m) for m in members])
    for group_path, others in (filtered_groups or {}).items():
        UsdPhysics.CollisionGroup(stage.GetPrimAtPath(group_path)).CreateFilteredGroupsRel().SetTargets(
            [Sdf.Path(o) for o in others])
    if path is not None:
        stage.GetRootLayer().Save()
    return stage


def env_boxes(num_envs: int = 2, ground: bool = True) -> dict:
    """:func:`boxes_stage`'s ``boxes`` for worlds: ``/World/envs/env<k>/P`` and ``/Q`` in every environment, at the
    same places in each (the environments lie on top of each other; ``P`` and ``Q`` penetrate), and with
    ``ground`` a ``/World/Ground/Geom`` through all of them."""
    boxes = {}
    for k in range(num_envs):
        boxes[f"/World/envs/env{k}/P"] = (0.0, 0.0, 0.0)
        boxes[f"/World/envs/env{k}/Q"] = (0.5, 0.0, 0.0)
    if ground:
        boxes["/World/Ground/Geom"] = (0.25, -0.5, 0.0)
    return boxes


def far_flight_stage(path=None, num_frames: int = 12, flight: int = 3, far: float = 1e6):
    """Three box-like prisms (``prism(4)``, radius 0.7, height 1, triangles of size about 1.4), time codes
    ``0 .. num_frames - 1``, whose coordinates need float64 in the last ``flight`` time codes only: ``/World/A``
    stays at the origin; ``/World/B`` and ``/World/C`` start through it from either side and slide apart by 0.1 a
    time code, then fly ``far`` away together (B at ``(far, far, -far)``, C 0.5 from it along x: they penetrate
    each other there). ``far = 1e6`` is beyond float32 at that triangle size, well within float64
    (:func:`~warp_ccd._src.geometry.precision.needed_precision`: float32 up to about ``8.4e3`` times the size).

    Returns:
        The ``Usd.Stage`` (saved to ``path`` when given).
    """
    from pxr import Gf, Usd, UsdGeom

    stage = Usd.Stage.CreateNew(str(path)) if path is not None else Usd.Stage.CreateInMemory()
    stage.SetStartTimeCode(0)
    stage.SetEndTimeCode(num_frames - 1)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/World").GetPrim())
    points, counts, indices = prism(4, radius=0.7, height=1.0)
    define_mesh(stage, "/World/A", points, counts, indices)
    for name, side, dx in (("B", 1.0, 0.0), ("C", -1.0, 0.5)):
        move = UsdGeom.Xformable(define_mesh(stage, f"/World/{name}", points, counts, indices)).AddTranslateOp()
        for f in range(num_frames):
            if f < num_frames - flight:
                move.Set(Gf.Vec3d(side * (0.3 + 0.1 * f), 0.0, 0.1 * side), f)
            else:
                move.Set(Gf.Vec3d(far + dx + 0.01 * f, far + 0.1 * dx, -far), f)
    if path is not None:
        stage.GetRootLayer().Save()
    return stage


def blinking_stage(path=None):
    """:func:`boxes_stage`'s two penetrating boxes ``/World/A/Geom`` and ``/World/B/Geom``, time codes 0 to 3,
    ``/World/B`` invisible at 0 and 1 and visible (``inherited``) from 2 on. The import reads visibility at the
    first time code it reads: a check of 0..3 leaves B out at every time code, one of 2..3 checks it.

    Returns:
        The ``Usd.Stage`` (saved to ``path`` when given).
    """
    from pxr import UsdGeom

    stage = boxes_stage(path)
    stage.SetEndTimeCode(3)
    visibility = UsdGeom.Imageable(stage.GetPrimAtPath("/World/B")).CreateVisibilityAttr()
    visibility.Set(UsdGeom.Tokens.invisible, 0)
    visibility.Set(UsdGeom.Tokens.inherited, 2)
    if path is not None:
        stage.GetRootLayer().Save()
    return stage
