"""The near-degenerate triangle pairs (:mod:`warp_ccd.bench.awkward_pairs`) and their recorded verdicts.

:data:`REFERENCE` (``tests/data/narrow_phase_verdicts.npz``) holds, per precision, the SHA-256 of the
pairs' inputs, the verdicts of both triangle tests (bit-packed) and a SHA-256 of Möller's segments, as
computed on the CPU. A device whose verdicts differ rounds differently (see the narrow phase's
``fuse_fp``). To record them anew after a deliberate change of the tests' semantics:

    python tests/awkward_pairs.py --write
"""

from __future__ import annotations

import argparse
import os

import numpy as np

from warp_ccd.bench.awkward_pairs import (
    METHODS,
    NUM_PAIRS,
    OFFSETS,
    PRECISIONS,
    SCALES,
    SEED,
    SMALL,
    awkward_pairs,
    inputs_digest,
    verdicts,
)

__all__ = ["METHODS", "NUM_PAIRS", "OFFSETS", "PRECISIONS", "REFERENCE", "SCALES", "SEED", "SMALL", "awkward_pairs",
           "inputs_digest", "read_reference", "verdicts", "write_reference"]

REFERENCE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "narrow_phase_verdicts.npz")


def write_reference(device="cpu") -> None:
    """Records the inputs' digests and ``device``'s verdicts in :data:`REFERENCE`."""
    data = {}
    for precision in PRECISIONS:
        got = verdicts(precision, device)
        data[f"{precision}_inputs_sha256"] = np.array(inputs_digest(precision))
        data[f"{precision}_segment_sha256"] = np.array(got["segment_sha256"])
        for method in METHODS:
            data[f"{precision}_{method}"] = np.packbits(got[method])
    os.makedirs(os.path.dirname(REFERENCE), exist_ok=True)
    np.savez_compressed(REFERENCE, **data)


def read_reference() -> dict:
    """The recorded digests (str) and verdicts (``(n,)`` bool)."""
    with np.load(REFERENCE) as f:
        return {k: (str(v) if v.dtype.kind == "U" else np.unpackbits(v)[:NUM_PAIRS].astype(bool)) for k, v in f.items()}


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write", action="store_true", help=f"record the CPU's verdicts in {REFERENCE}")
    args = parser.parse_args()
    if args.write:
        import warp as wp

        wp.config.quiet = True
        write_reference("cpu")
        print(f"written: {REFERENCE}")
    for precision in PRECISIONS:
        print(precision, inputs_digest(precision))
