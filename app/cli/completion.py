"""`wideprint completion SHELL`: the shell completion script, made from the parser."""

from __future__ import annotations

import argparse
import functools

from .common import EXIT_OK


def cmd_completion(root: argparse.ArgumentParser, args) -> int:
    """The completion script, generated from this very parser (`root`, the `wideprint`
    command's, given by app/cli/parser.py) by shtab."""
    import shtab
    try:
        print(shtab.complete(root, shell=args.shell))
    except BrokenPipeError:        # `| head`: the reader has what it wanted
        pass
    return EXIT_OK


def add_parser(sub, root: argparse.ArgumentParser) -> None:
    p = sub.add_parser("completion", help="print a shell completion script (bash, zsh, tcsh)",
                       description="Shell completion for wideprint, e.g. "
                       "`wideprint completion bash > /etc/bash_completion.d/wideprint` or "
                       "`source <(wideprint completion bash)`.")
    p.add_argument("shell", choices=("bash", "zsh", "tcsh"))
    p.set_defaults(func=functools.partial(cmd_completion, root))
