"""What the ``warp-ccd`` subcommands share: one-line argument errors, exit codes, device names.

:mod:`warp_ccd.cli` (``demo``) and :mod:`warp_ccd.bench` (``bench``) both import from here, and
neither imports the other at module level.
"""

from __future__ import annotations

import argparse

__all__ = ["EXIT_ERROR", "EXIT_INTERRUPTED", "EXIT_OK", "EXIT_USAGE", "CliError", "OneLineParser", "quiet_warp",
           "resolve_device"]

EXIT_OK = 0
EXIT_ERROR = 1
EXIT_USAGE = 2
EXIT_INTERRUPTED = 130


class CliError(Exception):
    """A problem to report in one line, with the exit status to end with."""

    def __init__(self, message: str, status: int = EXIT_USAGE):
        super().__init__(message)
        self.status = status


class OneLineParser(argparse.ArgumentParser):
    """argparse, but a usage error is one line on stderr (no usage dump) and exit status 2."""

    def error(self, message: str):
        raise CliError(f"{self.prog}: error: {message} (see --help)", EXIT_USAGE)


def quiet_warp() -> None:
    """Keeps Warp's start-up banner and module-load messages out of a command's output."""
    import warp as wp

    if hasattr(wp, "LOG_WARNING") and hasattr(wp.config, "log_level"):
        wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)
    wp.config.quiet = True


def resolve_device(name: str | None):
    """A Warp device from a command-line name.

    Args:
        name: ``None`` (Warp's preferred device: ``cuda:0`` when there is one, else ``cpu``),
            ``"cuda"`` (``cuda:0``), or a device name Warp lists.

    Raises:
        ValueError: an unknown name; the message lists the devices available.
    """
    import warp as wp

    if name is None:
        return wp.get_preferred_device()
    if name == "cuda" and wp.is_cuda_available():
        name = "cuda:0"
    available = [str(d) for d in wp.get_devices()]
    if name not in available:
        raise ValueError(f"unknown device {name!r} (available: {', '.join(available)})")
    return wp.get_device(name)
