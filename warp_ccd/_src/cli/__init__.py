"""The ``warp-ccd`` command: ``demo``, ``check``, ``bench`` (:mod:`~warp_ccd._src.cli.commands`), and what they share
(:mod:`~warp_ccd._src.cli.common`)."""

from .commands import main

__all__ = ["main"]
