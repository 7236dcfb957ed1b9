"""One verdict on every device: the triangle tests give bit-identical answers on CPU and CUDA.

On 10^5 near-degenerate pairs (:mod:`awkward_pairs`) in float32 and float64, each device's
verdicts (both tests) and Möller's segments must equal those recorded on the CPU
(``tests/data/narrow_phase_verdicts.npz``), so the check runs on a GPU machine whose Warp has no
CPU device too; where CPU and CUDA both exist they are also compared live, and a whole scene's
triangle pairs with them. The recorded verdicts are themselves judged by the float64 reference
(:func:`oracles.closed_triangle_distance`) away from the tolerance band, so that agreeing devices
agree on right answers.

Whole scenes (:mod:`scene_results`) are held to their recorded results the same way: triangle
pairs, segments, flags and containment pairs, bit for bit, with four option sets of the pipeline.
"""

import numpy as np
import pytest

import warp_ccd as wc
from warp_ccd._src.geometry.triangle import TOLERANCE

import awkward_pairs
import scene_results
from conftest import ALL_DEVICES, HOST_DEVICES
from oracles import touching_band

CUDA = [d for d in ALL_DEVICES if d.startswith("cuda")]


@pytest.fixture(scope="module")
def reference():
    return awkward_pairs.read_reference()


def same_inputs(precision, reference):
    if awkward_pairs.inputs_digest(precision) != reference[f"{precision}_inputs_sha256"]:
        pytest.fail("this machine builds other awkward pairs than those the verdicts were recorded for "
                    "(numpy's random stream changed?): record them anew with python tests/awkward_pairs.py --write")


@pytest.mark.parametrize("precision", awkward_pairs.PRECISIONS)
def test_recorded_verdicts_are_right(precision, reference):
    """Away from the band, both tests' recorded verdicts agree with the float64 reference: pairs
    within eps / 4 (less the height of a triangle taken as degenerate) touch, pairs 4 eps apart do not."""
    same_inputs(precision, reference)
    ta, tb = (t.astype(np.float64) for t in awkward_pairs.awkward_pairs(precision))
    must_hit, must_miss = touching_band(ta, tb, TOLERANCE, degenerate_slack=True)
    assert must_hit.mean() > 0.3 and must_miss.mean() > 0.2
    for method in awkward_pairs.METHODS:
        got = reference[f"{precision}_{method}"]
        missed, false = np.nonzero(must_hit & ~got)[0], np.nonzero(must_miss & got)[0]
        assert not len(missed), f"{method} {precision}: {len(missed)} touching pairs missed, e.g. {missed[:8]}"
        assert not len(false), f"{method} {precision}: {len(false)} pairs apart reported, e.g. {false[:8]}"


@pytest.mark.parametrize("precision", awkward_pairs.PRECISIONS)
def test_verdicts_match_the_recorded_ones(device, precision, reference):
    same_inputs(precision, reference)
    got = awkward_pairs.verdicts(precision, device)
    for method in awkward_pairs.METHODS:
        want = reference[f"{precision}_{method}"]
        differ = np.nonzero(got[method] != want)[0]
        assert not len(differ), (f"{method} {precision} on {device}: {len(differ)} of {len(want)} verdicts differ "
                                 f"from the CPU's, e.g. pairs {differ[:8].tolist()}")
        assert 0.1 < want.mean() < 0.9  # both answers are well represented
    assert got["segment_sha256"] == reference[f"{precision}_segment_sha256"], f"segments differ on {device}"
    swapped = awkward_pairs.verdicts(precision, device, swap=True)  # the pair's order changes nothing
    for method in awkward_pairs.METHODS:
        assert np.array_equal(swapped[method], got[method]), f"{method} {precision}: not symmetric on {device}"


@pytest.mark.skipif(not (CUDA and HOST_DEVICES), reason="needs the CPU and a CUDA device")
@pytest.mark.parametrize("precision", awkward_pairs.PRECISIONS)
def test_cpu_and_cuda_agree_live(precision):
    cpu = awkward_pairs.verdicts(precision, HOST_DEVICES[0])
    for device in CUDA:
        gpu = awkward_pairs.verdicts(precision, device)
        for method in awkward_pairs.METHODS:
            assert np.array_equal(cpu[method], gpu[method]), f"{method} {precision}: cpu and {device} differ"
        assert cpu["segment_sha256"] == gpu["segment_sha256"]


@pytest.mark.skipif(not (CUDA and HOST_DEVICES), reason="needs the CPU and a CUDA device")
def test_scene_from_poses_agrees_across_devices():
    """World vertices from the same poses are the same bits, so a crowded scene's pairs are too."""
    from test_robustness import crowded_cubes

    meshes, transforms = crowded_cubes(n=200, seed=4)
    transforms[:, :3, 3] *= 20.0
    results = []
    for device in [HOST_DEVICES[0], *CUDA]:
        scene = wc.Scene.from_meshes(meshes, transforms, device=device)
        results.append((scene.world_vertex.numpy(), wc.CollisionPipeline(scene).detect().triangle_pairs))
    for vertices, pairs in results[1:]:
        assert np.array_equal(vertices, results[0][0])
        assert np.array_equal(pairs, results[0][1])
    assert len(results[0][1]) > 0


@pytest.fixture(scope="module")
def recorded_scenes():
    return scene_results.read_reference()


def _canonical(a: np.ndarray) -> bytes:
    """The array's bytes, every NaN written alike."""
    a = np.ascontiguousarray(a)
    if np.issubdtype(a.dtype, np.floating):
        a = np.where(np.isnan(a), np.nan, a).astype(a.dtype)
    return a.tobytes()


@pytest.mark.parametrize("precision", scene_results.PRECISIONS)
def test_scene_results_match_the_recorded_ones(device, precision, recorded_scenes):
    got = scene_results.results(precision, device)
    want = {k: v for k, v in recorded_scenes.items() if k.startswith(f"{precision}/")}
    assert sorted(got) == sorted(want)
    differ = [k for k in want if got[k].shape != want[k].shape or got[k].dtype != want[k].dtype
              or _canonical(got[k]) != _canonical(want[k])]
    assert not differ, f"on {device}, results differ from the recorded ones: {differ}"
    assert sum(len(v) for k, v in want.items() if k.endswith("/triangle_pairs")) > 0
    assert sum(len(v) for k, v in want.items() if k.endswith("/containment_pairs")) > 0
