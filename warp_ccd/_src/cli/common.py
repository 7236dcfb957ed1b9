"""What the ``warp-ccd`` subcommands share: one-line argument errors, exit codes, device names.

:mod:`warp_ccd._src.cli.commands` (``demo``, ``check``) and the scaling benchmark (:mod:`warp_ccd._src.bench`,
``bench``) both import from here, and neither imports the other at module level.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
from collections.abc import Callable, Iterator
from dataclasses import fields
from typing import TYPE_CHECKING

from ..runtime.start import init_warp

if TYPE_CHECKING:
    from ..check.options import CheckOptions

__all__ = ["EXIT_ERROR", "EXIT_FINDINGS", "EXIT_INTERNAL", "EXIT_INTERRUPTED", "EXIT_OK", "EXIT_USAGE", "REPORT_STDOUT",
           "CliError", "OneLineParser", "QuietClosedStdout", "check_options_from", "flat_values", "init_warp",
           "pending_outputs", "quiet_warp", "refuse_overwriting", "require_usd", "resolve_device", "uncached_modules"]

EXIT_OK = 0
EXIT_ERROR = 1
EXIT_FINDINGS = EXIT_ERROR
"""``check``: something penetrates (or, with ``--count-touching``, touches)."""
EXIT_USAGE = 2
EXIT_INTERNAL = 3
"""An unexpected exception: a bug or the machine (out of memory), not the input."""
EXIT_INTERRUPTED = 130

class CliError(Exception):
    """A problem to report in one line, with the exit status to end with."""

    def __init__(self, message: str, status: int = EXIT_USAGE):
        super().__init__(message)
        self.status = status


class QuietClosedStdout(io.TextIOBase):
    """A command's standard output that ends quietly where its reader has gone.

    ``warp-ccd check a.usda | head -1`` (or ``| true``) closes the pipe before the summary is written;
    Python ignores SIGPIPE, so the next write raises BrokenPipeError. Here, as Python's documentation
    recommends (the ``signal`` module, "Note on SIGPIPE"), standard output is redirected to
    ``os.devnull`` at the first such error (so that no later write, nor the flush at exit, raises
    again) and the command goes on: its files are written and it ends with its verdict's status.

    Args:
        stream: the standard output to write to.
    """

    def __init__(self, stream):
        super().__init__()
        self.stream = stream
        self.reader_gone = False

    def _gone(self) -> None:
        self.reader_gone = True
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            try:
                os.dup2(devnull, self.stream.fileno())
            finally:
                os.close(devnull)
        except (OSError, ValueError, AttributeError, io.UnsupportedOperation):  # no descriptor (captured output)
            pass

    def write(self, text: str) -> int:
        if not self.reader_gone:
            try:
                return self.stream.write(text)
            except BrokenPipeError:
                self._gone()
        return len(text)

    def flush(self) -> None:
        if not self.reader_gone:
            try:
                self.stream.flush()
            except BrokenPipeError:
                self._gone()

    def writable(self) -> bool:
        return True

    def isatty(self) -> bool:
        return not self.reader_gone and self.stream.isatty()

    def fileno(self) -> int:
        return self.stream.fileno()

    @property
    def encoding(self):
        return getattr(self.stream, "encoding", "utf-8")


class OneLineParser(argparse.ArgumentParser):
    """argparse, but a usage error is one line on stderr (no usage dump) and exit status 2."""

    def error(self, message: str):
        raise CliError(f"{self.prog}: error: {message} (see --help)", EXIT_USAGE)

    def flags(self) -> dict[str, str]:
        """The flag each option is given as, by the name it is stored under (``{"min_depth": "--min-depth"}``)."""
        return {a.dest: a.option_strings[0] for a in self._actions if a.option_strings}


def quiet_warp() -> None:
    """Keeps Warp's start-up banner and module-load messages out of a command's output."""
    import warp as wp

    if hasattr(wp, "LOG_WARNING") and hasattr(wp.config, "log_level"):
        wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)
    wp.config.quiet = True


def uncached_modules(device, names) -> list[str] | None:
    """The Warp modules among ``names`` whose kernels for ``device`` are not in Warp's kernel cache.

    Warp compiles a module's kernels at its first launch on a device and keeps the binary in
    its kernel cache (``wp.config.kernel_cache_dir``), under a name that carries a hash of the
    module's code and options; this looks for that file as ``Module.load`` does.

    Args:
        device: a Warp device.
        names: Python module names whose Warp kernels will run (``"warp_ccd._src.narrowphase.discrete"``).

    Returns:
        The names to be compiled, or None when that cannot be told (kernel caching off, or a Warp
        without the methods used here).
    """
    import warp as wp

    try:
        from warp._src import context

        if not wp.config.cache_kernels or not wp.config.kernel_cache_dir:
            return None
        device = wp.get_device(device)
        out = []
        for name in names:
            module = context.user_modules.get(name)
            if module is None:
                continue
            default = None if device.is_cpu else module.options["block_dim"]  # as a launch resolves it
            block_dim = context._resolve_launch_block_dim(device, default)
            binary = os.path.join(wp.config.kernel_cache_dir, module.get_module_identifier(block_dim),
                                  module._get_compile_output_name(device, block_dim=block_dim))
            if not os.path.exists(binary):
                out.append(name)
        return out
    except Exception:  # Warp's internals differ: say nothing rather than something wrong
        return None


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


def flat_values(prims: list[list[str]] | None) -> list[str] | None:
    """``--prims`` (``--set-a``, ``--set-b``) values (lists, one per use of the option) as one list, or None."""
    return None if prims is None else [p for group in prims for p in group]


@contextlib.contextmanager
def pending_outputs(fail: Callable[[str], CliError]) -> Iterator[tuple[list, list]]:
    """Outputs written whole or not at all: the block appends :class:`~warp_ccd._src.output.PendingFile` s and, for
    each,
    a line naming it (``"  report : {}"``); when it ends they are all moved into place and the lines printed. On an
    error every one is discarded (a ValueError becomes ``fail``'s error: exit status 2)."""
    from ..output import commit_all

    pending: list = []
    lines: list = []
    try:
        yield pending, lines
        written = commit_all(pending)
    except BaseException as exc:
        for p in pending:
            if not p.done:
                p.discard()
        if isinstance(exc, ValueError):
            raise fail(str(exc)) from None
        raise
    for line, path in zip(lines, written):
        print(line.format(path))


def check_options_from(args: argparse.Namespace) -> CheckOptions:
    """``check``'s arguments as its one :class:`~warp_ccd._src.check.options.CheckOptions`: every option with a flag
    (stored under its name), with progress bars. The ignore-pairs files are read here, before any stage.

    Raises:
        ValueError: a bad option, named by the flag the user typed (``--min-depth must be ...``).
    """
    from ..check.options import CheckOptions

    values = {f.name: getattr(args, f.name) for f in fields(CheckOptions) if f.name in args.given_as}
    values.update(set_a=flat_values(args.set_a), set_b=flat_values(args.set_b), progress=True)
    return CheckOptions(**values, given_as=args.given_as)


def require_usd(fail: Callable[[str], CliError]) -> None:
    """Raises ``fail``'s error where usd-core is not installed."""
    try:
        import pxr  # noqa: F401
    except ImportError:
        raise fail("usd-core is not installed (pip install usd-core)") from None


REPORT_STDOUT = "-"
"""``--report -``: the JSON report on standard output."""


def refuse_overwriting(inputs: list[tuple[str, str]], outputs: list[tuple[str, str]]) -> None:
    """Raises ValueError when an output names the same file as an input (or an earlier output).

    Args:
        inputs: ``(what, path)`` of the files that must not be written.
        outputs: ``(option, path)`` of the destinations.
    """
    from ..output import same_file

    for flag, out in outputs:
        for what, path in inputs:
            if same_file(out, path):
                where = "" if os.path.realpath(path) == os.path.abspath(out) else f" ({os.path.realpath(path)})"
                raise ValueError(f"{flag} {out} is {what}{where}: it would be written over")
