"""`wideprint` command line (README "Command line"; contract in docs/cli.md).

One module a command (or a family of subcommands: `media`, `spot`, `printer`, `cups`, ...),
each with its `cmd_*` function and its `add_parser(sub)`; app/cli/parser.py puts them
together, common.py holds the option blocks and checks several share, remote.py what the
print server's clients share.  The console entry point is `wideprint.app.cli:main`;
`python -m wideprint.app.cli` runs the same (__main__.py)."""

from __future__ import annotations

import argparse

from .common import EXIT_DEVICE, EXIT_JOB_FAILED, EXIT_OK, EXIT_USAGE
from .process import (_QUICK_START, _collector_off, _collector_on, _give_back_big_buffers,
                      _one_blas_thread)

__all__ = ["EXIT_DEVICE", "EXIT_JOB_FAILED", "EXIT_OK", "EXIT_USAGE", "build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    """The whole parser; its command modules imported here, not at `import wideprint.app.cli`,
    so main() has the garbage collector off while they load (app/cli/process.py)."""
    from .parser import build_parser as build
    return build()


def main(argv: list[str] | None = None) -> int:
    _one_blas_thread()
    if argv is None:                # the `wideprint` command itself
        _collector_off()
    ap = build_parser()
    args = ap.parse_args(argv)
    if args.command not in _QUICK_START:
        _collector_on()
    if getattr(args, "threads", None) is not None:      # before the RIP makes its pools
        import os
        os.environ["WIDEPRINT_THREADS"] = str(args.threads)    # and for child processes
        from ...rip.parallel import set_workers
        try:
            set_workers(args.threads)
        except ValueError as exc:
            ap.error(str(exc))
    _give_back_big_buffers()
    if argv is None and args.command == "serve":     # the server's own process
        from ..server import heap
        heap.enable()
    import logging                  # here: `--help` and usage errors never need it
    logging.basicConfig(level=logging.DEBUG if args.verbose else logging.WARNING,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    # libvips reports decoding trouble as warnings too; our ImageError says it better
    logging.getLogger("pyvips").setLevel(logging.DEBUG if args.verbose else logging.ERROR)
    return args.func(args)
