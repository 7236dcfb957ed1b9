"""Warp's start, once, for every entry point: without the no-CUDA-driver notice on a machine without a GPU.

Warp's native library prints :data:`DRIVER_NOTICE` to the process's stderr when it initialises on a
machine without a CUDA driver, and Warp has no option to leave it out. warp_ccd starts Warp through
:func:`init_warp` wherever it first needs Warp's runtime (a :class:`~warp_ccd._src.scene.scene.Scene`,
the standalone queries, arrays read through DLPack, the command, the Ray actor), so a CPU machine
sees no such line; every other line Warp writes meanwhile (its banner, a real CUDA error on a GPU
machine) is passed on. Warp started by the caller first is left as it is.
"""

from __future__ import annotations

import os
import sys
import tempfile

__all__ = ["DRIVER_NOTICE", "init_warp"]

DRIVER_NOTICE = "Warp CUDA warning: Could not find or load the NVIDIA CUDA driver"
"""The start of the line Warp's native library prints on initialisation when there is no CUDA
driver (a machine without a GPU): its device list says as much, so warp_ccd leaves the line out."""


def init_warp() -> None:
    """Initialises Warp, without its no-CUDA-driver notice on stderr.

    Warp's native library prints :data:`DRIVER_NOTICE` to the process's stderr on
    initialisation on a machine without a CUDA driver. Here stderr (file descriptor 2) goes to a
    temporary file while Warp initialises, and every other line written meanwhile is passed on.
    Nothing happens when Warp is initialised already.
    """
    import warp as wp
    from warp._src import context

    if getattr(context, "runtime", None) is not None:  # started already: nothing to do, no descriptor moved
        return
    sys.stderr.flush()
    try:
        saved = os.dup(2)
    except OSError:  # no stderr to redirect
        wp.init()
        return
    try:
        with tempfile.TemporaryFile() as held:
            os.dup2(held.fileno(), 2)
            try:
                wp.init()
            finally:
                sys.stderr.flush()
                os.dup2(saved, 2)
            held.seek(0)
            text = held.read().decode(errors="replace")
    finally:
        os.close(saved)
    rest = [line for line in text.splitlines(keepends=True) if not line.startswith(DRIVER_NOTICE)]
    if rest:
        sys.stderr.write("".join(rest))
        sys.stderr.flush()
