"""Worlds, collision groups and masks, excluded pairs (:mod:`warp_ccd._src.scene.filter`): the broad phase's
pairs equal numpy's brute force over every box pair with the filter's rule written out again here; a
frame of many worlds equals a Python loop of one scene per world; bad filters are named."""

import numpy as np
import pytest
import warp as wp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import warp_ccd as wc
from warp_ccd._src.broadphase.grid import sap_world_bits
from warp_ccd._src.broadphase.sap import BroadPhaseSAP, find_pairs
from warp_ccd._src.runtime.buffers import GrowableBuffer
from warp_ccd._src.scene.filter import WORLDS_MAX
from warp_ccd.scene import CollisionFilter, icosphere, shape


def brute_pairs(lo, hi, world=None, group=None, mask=None, exclude=()):
    """Every box pair that overlaps (closed boxes) and that the filter's rule lets through, sorted:
    the rule spelt out again, independent of the package's."""
    n = len(lo)
    a, b = np.triu_indices(n, 1)
    keep = ((lo[a] <= hi[b]) & (lo[b] <= hi[a])).all(axis=1)
    if world is not None:
        w = np.asarray(world)
        keep &= (w[a] == w[b]) | (w[a] == -1) | (w[b] == -1)
    if group is not None or mask is not None:
        g = np.full(n, 0xFFFFFFFF, np.uint64) if group is None else np.asarray(group, np.uint64)
        m = np.full(n, 0xFFFFFFFF, np.uint64) if mask is None else np.asarray(mask, np.uint64)
        keep &= ((g[a] & m[b]) != 0) & ((g[b] & m[a]) != 0)
    ex = {(min(p), max(p)) for p in exclude}
    if ex:
        keep &= np.array([(i, j) not in ex for i, j in zip(a, b)], bool)
    return np.stack([a[keep], b[keep]], axis=1).astype(np.int32)


def colocated_worlds(rng, num_worlds, per_world, spread=4.0, size=1.0):
    """Boxes of ``num_worlds`` worlds laid on top of each other (every world the same region)."""
    n = num_worlds * per_world
    centre = rng.uniform(0, spread, (n, 3))
    half = rng.uniform(0.1, size, (n, 3))
    world = np.repeat(np.arange(num_worlds), per_world)
    return (centre - half).astype(np.float32), (centre + half).astype(np.float32), world


@pytest.mark.parametrize("method", ["sap", "all_pairs"])
def test_worlds_on_top_of_each_other(device, rng, method):
    lo, hi, world = colocated_worlds(rng, 40, 12)
    world = world * 7 - 3  # any ids >= 0 (numbered by the filter), here not consecutive
    world[world == -3] = 1000
    world[::37] = -1  # some shared by every world
    got = wc.stages.broad_phase_pairs(lo, hi, method=method, device=device, world=world)
    assert np.array_equal(got, brute_pairs(lo, hi, world=world))


def brute_pairs_by_world(lo, hi, per_world):
    """The overlapping pairs within each world of ``per_world`` consecutive boxes (no world -1): every
    world's pairs at once, sorted."""
    a, b = np.triu_indices(per_world, 1)
    base = np.arange(0, len(lo), per_world)[:, None]
    a, b = (base + a).ravel(), (base + b).ravel()
    keep = ((lo[a] <= hi[b]) & (lo[b] <= hi[a])).all(axis=1)
    return np.stack([a[keep], b[keep]], axis=1).astype(np.int32)


@pytest.mark.parametrize("num_worlds", [1, 2, 3, 255, 4096])
def test_many_worlds_one_launch(device, rng, num_worlds):
    per = 5 if num_worlds > 255 else 20
    lo, hi, world = colocated_worlds(rng, num_worlds, per, spread=3.0)
    got = wc.stages.broad_phase_pairs(lo, hi, device=device, world=world)
    want = brute_pairs_by_world(lo, hi, per)
    if num_worlds <= 255:
        assert np.array_equal(want, brute_pairs(lo, hi, world=world))  # the two references agree
    assert np.array_equal(got, want)
    assert len(got) > 0


def test_groups_masks_and_excluded_pairs(device, rng):
    n = 300
    centre = rng.uniform(0, 6, (n, 3))
    lo, hi = (centre - 0.6).astype(np.float32), (centre + 0.6).astype(np.float32)
    group = rng.choice([1, 2, 4, 3, 0xFFFFFFFF, 0x80000000], n)
    mask = rng.choice([1, 2, 6, 0xFFFFFFFF, 0x80000001, 0], n)
    every = brute_pairs(lo, hi)
    exclude = every[rng.choice(len(every), len(every) // 3, replace=False)][:, ::-1]  # either order
    world = rng.integers(-1, 3, n)
    for kwargs in ({"group": group, "mask": mask}, {"exclude_pairs": exclude}, {"group": group},
                   {"world": world, "group": group, "mask": mask, "exclude_pairs": exclude}):
        got = wc.stages.broad_phase_pairs(lo, hi, device=device, **kwargs)
        want = brute_pairs(lo, hi, world=kwargs.get("world"), group=kwargs.get("group"), mask=kwargs.get("mask"),
                           exclude=[tuple(p) for p in kwargs.get("exclude_pairs", [])])
        assert np.array_equal(got, want), kwargs


def test_world_minus_one_big_and_small(device, rng):
    """World -1 boxes (a floor that spans every world, a small shared fixture) pair with each world's
    boxes once, and with each other once."""
    lo, hi, world = colocated_worlds(rng, 50, 8)
    floor_lo, floor_hi = np.array([[-10, -10, -1.0]], np.float32), np.array([[10, 10, 0.5]], np.float32)
    fix_lo, fix_hi = np.array([[1, 1, 1]], np.float32), np.array([[2, 2, 2]], np.float32)
    lo = np.concatenate([lo, floor_lo, fix_lo])
    hi = np.concatenate([hi, floor_hi, fix_hi])
    world = np.concatenate([world, [-1, -1]])
    got = wc.stages.broad_phase_pairs(lo, hi, device=device, world=world)
    assert np.array_equal(got, brute_pairs(lo, hi, world=world))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**31 - 1), worlds=st.integers(1, 40), per=st.integers(1, 12),
       shared=st.integers(0, 3), excluded=st.floats(0, 1))
def test_property_filters_equal_brute_force(seed, worlds, per, shared, excluded):
    rng = np.random.default_rng(seed)
    lo, hi, world = colocated_worlds(rng, worlds, per, spread=float(rng.uniform(0.5, 5)))
    world[rng.choice(len(world), min(shared, len(world)), replace=False)] = -1
    every = brute_pairs(lo, hi, world=world)
    exclude = every[rng.random(len(every)) < excluded]
    group = rng.integers(0, 8, len(lo))
    got = wc.stages.broad_phase_pairs(lo, hi, world=world, group=group, mask=7 - group // 2, exclude_pairs=exclude)
    want = brute_pairs(lo, hi, world=world, group=group, mask=7 - group // 2, exclude=[tuple(p) for p in exclude])
    assert np.array_equal(got, want)


def test_world_key_bits_fit():
    for n, w in [(10, 2), (81920, 4096), (10**6, 10**5), (2 * WORLDS_MAX, WORLDS_MAX)]:
        cell_limit, field_bits, q_bits = sap_world_bits(n, w)
        assert field_bits + q_bits <= 31 and q_bits >= 8
        assert w * (cell_limit - 1) <= (1 << field_bits) - 2  # the padding key's cell field is never reached
        assert cell_limit >= 2


def test_filter_in_the_frame_grows_and_replays(device, rng):
    """A broad phase frame with a filter, run twice on new boxes (graph replay on CUDA), grows its buffers."""
    lo, hi, world = colocated_worlds(rng, 30, 30, spread=2.0)
    f = CollisionFilter(len(lo), world=world, device=device)
    bp = BroadPhaseSAP(device=device)
    for _ in range(2):
        wlo, whi = wp.array(lo, dtype=wp.vec3, device=device), wp.array(hi, dtype=wp.vec3, device=device)
        pairs = np.sort(bp.find_pairs(wlo, whi, f).numpy().reshape(-1, 2), axis=1)
        pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]
        assert np.array_equal(pairs, brute_pairs(lo, hi, world=world))
        lo, hi = lo + 0.1, hi + 0.2
    buf = GrowableBuffer(wp.vec2i, 1, device, "pairs")
    count = find_pairs(bp, wp.array(lo, dtype=wp.vec3, device=device), wp.array(hi, dtype=wp.vec3, device=device),
                       buf, f)
    assert count == len(brute_pairs(lo, hi, world=world))


def _robot_worlds(num_worlds, seed=0):
    """Meshes and (N, 4, 4) transforms of ``num_worlds`` copies of a small cluttered scene, each copy
    jittered, all on top of each other, plus a floor in world -1."""
    rng = np.random.default_rng(seed)
    parts = [shape("cube"), icosphere(1), shape("octahedron")]
    meshes, transforms, world = [], [], []
    for w in range(num_worlds):
        for k in range(5):
            meshes.append(parts[k % 3])
            t = np.eye(4)
            t[:3, 3] = [0.8 * k, 0.0, 0.3] + rng.normal(0, 0.15, 3)
            transforms.append(t)
            world.append(w)
    floor = (np.array([[-5, -5, -0.5], [10, -5, -0.5], [10, 5, -0.5], [-5, 5, -0.5]], float),
             np.array([[0, 1, 2], [0, 2, 3]]))
    meshes.append(floor)
    transforms.append(np.eye(4))
    world.append(-1)
    return meshes, np.array(transforms), np.array(world)


def test_collide_worlds_equals_a_loop_over_worlds(device):
    meshes, transforms, world = _robot_worlds(12)
    res = wc.collide(meshes, transforms, device=device, world=world)
    want = []
    floor = len(meshes) - 1
    for w in range(12):
        idx = np.concatenate([np.flatnonzero(world == w), [floor]])
        sub = wc.collide([meshes[i] for i in idx], transforms[idx], device=device)
        want.extend(tuple(sorted((idx[a], idx[b]))) for a, b in sub.object_pairs)
    want = np.array(sorted(set(want)), np.int32).reshape(-1, 2)
    assert len(want) > 12  # parts touch each other and the floor
    assert np.array_equal(res.object_pairs, want)
    assert np.array_equal(res.pair_world, np.maximum(world[want[:, 0]], world[want[:, 1]]))
    every = wc.collide(meshes, transforms, device=device)
    assert len(every.object_pairs) > len(want)  # without worlds, the copies collide with each other
    assert np.array_equal(res.pair_world[res.pair_world >= 0], world[res.object_pairs[res.pair_world >= 0, 0]])


def test_pipeline_filters_every_frame(device):
    meshes, transforms, world = _robot_worlds(4)
    n = len(meshes)
    exclude = [(0, 1), (5, 6)]
    group = np.ones(n, np.int64)
    group[-1] = 2  # the floor
    mask = np.full(n, 3)
    mask[2] = 1  # object 2 ignores the floor
    scene = wc.Scene.from_meshes(meshes, transforms, device=device, world=world, exclude_pairs=exclude,
                                 group=group, mask=mask)
    pipe = wc.CollisionPipeline(scene)
    plain = wc.CollisionPipeline(wc.Scene.from_meshes(meshes, transforms, device=device))
    for step in range(3):
        t = transforms.copy()
        t[:-1, 2, 3] -= 0.1 * step
        scene.set_transforms(t)
        plain.scene.set_transforms(t)
        got = pipe.detect().object_pairs
        every = plain.detect().object_pairs
        keep = scene.collision_filter.allowed(every)
        assert np.array_equal(got, every[keep])
        assert not any(tuple(p) in {(0, 1), (5, 6), (2, n - 1)} for p in got.tolist())


def test_clearance_and_continuous_respect_filters(device):
    meshes, transforms, world = _robot_worlds(3)
    res = wc.collide(meshes, transforms, device=device, world=world, clearance=0.05)
    assert CollisionFilter(len(meshes), world=world).allowed(res.object_pairs).all()
    end = transforms.copy()
    end[:-1, 0, 3] += 0.5
    res = wc.collide(meshes, transforms, device=device, world=world, transforms_end=end)
    assert len(res.object_pairs) and CollisionFilter(len(meshes), world=world).allowed(res.object_pairs).all()


@pytest.mark.parametrize("kwargs, message", [
    ({"world": [0, -2, 1]}, "world: object 1 has world -2"),
    ({"world": [0, 1]}, r"world: expected \(3,\) values"),
    ({"world": [0.5, 1, 2]}, "world: expected integers"),
    ({"world": ["a", "b", "c"]}, "world: expected integers"),
    ({"group": [1, 2, 1 << 33]}, "group: object 2 has 8589934592, not a 32-bit mask"),
    ({"mask": [[1, 2, 3]]}, "mask: expected"),
    ({"exclude_pairs": [[0, 3]]}, r"exclude_pairs: row 0 \[0, 3\] names an object outside \[0, 3\)"),
    ({"exclude_pairs": [[1, 1]]}, "exclude_pairs: row 0 pairs object 1 with itself"),
    ({"exclude_pairs": [0, 1]}, r"exclude_pairs: expected \(E, 2\)"),
    ({"exclude_pairs": [[0.0, 1.0]]}, "exclude_pairs: expected integer"),
])
def test_bad_filters_are_named(kwargs, message):
    meshes = [shape("cube")] * 3
    with pytest.raises(ValueError, match=message):
        wc.Scene.from_meshes(meshes, **kwargs)
    with pytest.raises(ValueError, match=message):
        wc.collide(meshes, **kwargs)


def test_too_many_worlds():
    with pytest.raises(ValueError, match="distinct worlds"):
        CollisionFilter(WORLDS_MAX + 1, world=np.arange(WORLDS_MAX + 1))


def test_filter_defaults_and_views():
    f = CollisionFilter(4, world=[5, 5, -1, 9], exclude_pairs=np.array([[3, 0], [0, 3], [1, 2]]))
    assert f.num_worlds == 2 and f.num_global == 1 and f.active
    assert f.object_world_slot.tolist() == [0, 0, -1, 1]
    assert f.exclude_pairs.tolist() == [[0, 3], [1, 2]]
    assert f.allowed([[0, 1], [0, 2], [0, 3], [1, 3], [2, 3], [1, 2]]).tolist() == [True, True, False, False, True,
                                                                                   False]
    assert f.pair_world([[0, 1], [0, 2], [2, 3]]).tolist() == [5, 5, 9]
    assert not CollisionFilter(3).active
    assert CollisionFilter(3).object_group.tolist() == [0xFFFFFFFF] * 3


@pytest.mark.parametrize("kwargs, message", [
    ({"world": [2**63, 0]}, "world: object 0 has .*, out of range"),
    ({"group": np.full(2, 2**63, np.uint64)}, "group: object 0 has 9223372036854775808, out of range"),
    ({"world": np.full(2, 1e30)}, "world: object 0 has 1e[+]30, out of range"),
    ({"world": np.array([True, False])}, "world: expected integers, got bool"),
    ({"exclude_pairs": np.zeros((0, 3), int)}, r"exclude_pairs: expected \(E, 2\)"),
])
def test_out_of_range_filters_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        wc.Scene.from_meshes([shape("cube")] * 2, **kwargs)
    assert wc.Scene.from_meshes([shape("cube")] * 2, exclude_pairs=[]).collision_filter.exclude_pairs.shape == (0, 2)


def test_a_filter_of_another_size_is_refused(device, rng):
    lo = rng.uniform(0, 3, (50, 3)).astype(np.float32)
    with pytest.raises(ValueError, match="pair_filter: made for 10 objects, given 50 boxes"):
        BroadPhaseSAP(device=device).find_pairs(wp.array(lo, dtype=wp.vec3, device=device),
                                                wp.array(lo + 1, dtype=wp.vec3, device=device),
                                                CollisionFilter(10, world=np.arange(10), device=device))
