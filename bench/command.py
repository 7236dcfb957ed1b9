"""The lab's command-line set-up, written once.

Every benchmark of the lab (``bench/``; the scaling benchmark, ``warp-ccd bench``, has its own one-line
errors and exit statuses) starts the same way:

* :func:`bench_parser`: the parser with ``--device`` (its default and help are the benchmark's).
* :func:`add_run_options`: ``--frames``, ``--warmup`` and ``--seed`` where the benchmark has them
  (their defaults and help are the benchmark's), then :func:`add_out_option`: ``--out``, the JSON
  file of the results (default: none).
* :func:`parse_options`: the arguments parsed, Warp quietened and the device resolved; a bad device
  or JSON destination is a usage error before anything is measured.
* :func:`start`: that, and the result document ``{**environment(device), "config": vars(args),
  "rows": []}`` (see :func:`~warp_ccd._src.bench.report.environment`), which the benchmark fills;
  :func:`add_row` shows a row as it comes and records it; :func:`write_result` writes the document
  where ``--out`` says (those with a default destination put it under :data:`RESULTS`).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from warp_ccd._src.bench.report import JSON_EXTENSIONS, environment, write_json
from warp_ccd._src.cli.common import quiet_warp, resolve_device
from warp_ccd._src.output import check_output_path

__all__ = ["RESULTS", "add_out_option", "add_row", "add_run_options", "bench_parser", "parse_options", "start",
           "write_result"]

RESULTS = Path("bench", "results")
"""Where the benchmarks that write results by default put them: ``bench/results`` under the working
directory (the repository root, where ``bench/run_cuda.sh`` runs them)."""


def bench_parser(description: str | None, *, device: str | None = None, device_help: str | None = None,
                 **options) -> argparse.ArgumentParser:
    """A benchmark's parser with its ``--device`` option, the first.

    Args:
        description: the ``--help`` text above the options.
        device: ``--device``'s default (``None``: Warp's preferred device, see
            :func:`~warp_ccd._src.cli.common.resolve_device`).
        device_help: ``--device``'s help (``None``: none).
        **options: passed on to :class:`argparse.ArgumentParser` (``formatter_class``, ...).
    """
    parser = argparse.ArgumentParser(description=description, **options)
    parser.add_argument("--device", default=device, help=device_help)
    return parser


def add_out_option(parser: argparse.ArgumentParser, help_text: str | None = None) -> None:
    """Adds ``--out``, the JSON file of the results (default: none), with ``help_text`` as its help
    (``None``: none)."""
    parser.add_argument("--out", default=None, help=help_text)


def add_run_options(parser: argparse.ArgumentParser, *, frames: int | None = None, warmup: int | None = None,
                    seed: int | None = None, out: bool = True, frames_help: str | None = None,
                    warmup_help: str | None = None, seed_help: str | None = None,
                    out_help: str | None = None) -> None:
    """Adds the integer options ``--frames``, ``--warmup`` and ``--seed`` in that order, each where
    its default is given, then ``--out`` (see :func:`add_out_option`).

    Args:
        parser: the benchmark's parser (from :func:`bench_parser`).
        frames: ``--frames``'s default, timed frames (``None``: no such option).
        warmup: ``--warmup``'s default, untimed frames before them (``None``: no such option).
        seed: ``--seed``'s default (``None``: no such option).
        out: whether to add ``--out`` here (``False``: the benchmark adds it after options of its own).
        frames_help, warmup_help, seed_help, out_help: the options' help (``None``: none).
    """
    for name, default, text in (("--frames", frames, frames_help), ("--warmup", warmup, warmup_help),
                                ("--seed", seed, seed_help)):
        if default is not None:
            parser.add_argument(name, type=int, default=default, help=text)
    if out:
        add_out_option(parser, out_help)


def parse_options(parser: argparse.ArgumentParser, argv: list[str] | None = None, *,
                  out: str = "out") -> tuple[argparse.Namespace, object]:
    """Parses a benchmark's arguments, quietens Warp and resolves ``--device``.

    Args:
        parser: the benchmark's parser (from :func:`bench_parser`).
        argv: arguments without the program name (default: ``sys.argv[1:]``).
        out: the attribute of the arguments naming the JSON file of the results; where it is set, the
            file must be one that can be written (checked now, not after the measurements).

    Returns:
        ``(args, device)``: the parsed arguments and the Warp device.

    Raises:
        SystemExit: a usage error (status 2, the message on stderr): the arguments, an unknown
            device, or a JSON destination that cannot be written.
    """
    args = parser.parse_args(argv)
    quiet_warp()
    try:
        device = resolve_device(args.device)
        if getattr(args, out, None):
            check_output_path(getattr(args, out), JSON_EXTENSIONS, "JSON")
    except ValueError as exc:
        parser.error(str(exc))
    return args, device


def start(parser: argparse.ArgumentParser, argv: list[str] | None = None) -> tuple[argparse.Namespace, object, dict]:
    """:func:`parse_options`, and the result document the benchmark fills.

    Returns:
        ``(args, device, document)``; ``document`` is ``{**environment(device), "config": vars(args),
        "rows": []}``: where it was measured (see :func:`~warp_ccd._src.bench.report.environment`), the
        options (the arguments' own dictionary: a value set on ``args`` later is recorded too) and an
        empty list of rows.
    """
    args, device = parse_options(parser, argv)
    return args, device, {**environment(device), "config": vars(args), "rows": []}


def add_row(document: dict, row: dict) -> None:
    """Prints ``row`` (as a dict, one line, at once) and appends it to ``document["rows"]``."""
    print(row, flush=True)
    document["rows"].append(row)


def write_result(path: str | None, document: dict) -> None:
    """Writes ``document`` to ``path`` (see :func:`~warp_ccd._src.bench.report.write_json`); nothing
    when ``path`` is ``None`` or empty (no ``--out``)."""
    if path:
        write_json(path, document)
