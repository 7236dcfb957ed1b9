"""The ``warp-ccd`` command: ``demo``, ``check``, ``bench`` (:mod:`~warp_ccd.cli.commands`), and what they share
(:mod:`~warp_ccd.cli.common`)."""

from .commands import main

__all__ = ["main"]
