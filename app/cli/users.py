"""`wideprint users add|remove|list`: the operator's user tokens (docs/server.md
"Users and roles")."""

from __future__ import annotations

import sys
from pathlib import Path

from ..client import user_token_file
from .common import EXIT_FAILED, EXIT_OK, EXIT_USAGE
from .remote import _state_dir_option


def cmd_users(args) -> int:
    """`wideprint users add|remove|list`: straight on the state directory (who can write
    there is the operator)."""
    from ..server.auth import add_user, check_user_name, list_users, remove_user
    from ..server.config import default_state_dir, write_token_file
    state = Path(args.state_dir or default_state_dir())
    what = args.users_command
    if what == "list":
        for name in list_users(state):
            print(name)
        return EXIT_OK
    try:
        check_user_name(args.name)
    except ValueError as exc:
        print(f"wideprint users: {exc}", file=sys.stderr)
        return EXIT_USAGE
    if what == "remove":
        if not remove_user(state, args.name):
            print(f"wideprint users: user {args.name} has no token in {state}", file=sys.stderr)
            return EXIT_FAILED
        print(f"user {args.name}: token deleted (refused from the next request)", file=sys.stderr)
        return EXIT_OK
    if not state.is_dir():
        print(f"wideprint users: no state directory {state}", file=sys.stderr)
        return EXIT_USAGE
    try:
        path, token = add_user(state, args.name, replace=args.replace)
        if args.out:
            out = Path(args.out)
            write_token_file(out, token, replace=True)
    except FileExistsError:
        print(f"wideprint users: user {args.name} has a token already (--replace makes a new "
              f"one)", file=sys.stderr)
        return EXIT_FAILED
    except OSError as exc:
        print(f"wideprint users: {exc.filename or state}: {exc.strerror}", file=sys.stderr)
        return EXIT_FAILED
    if args.out:
        print(f"user {args.name}: token in {path} and {args.out} (0600); the user keeps it in "
              f"{user_token_file()} or names it in $WIDEPRINT_TOKEN_FILE", file=sys.stderr)
    else:
        print(f"user {args.name}: token made ({path}); the user keeps it in "
              f"{user_token_file()} (0600) or names it in $WIDEPRINT_TOKEN_FILE",
              file=sys.stderr)
        print(token)
    return EXIT_OK


def add_parser(sub) -> None:
    p = sub.add_parser("users", help="the operator's user tokens: a user acts on its own jobs "
                                     "only (docs/server.md \"Users and roles\")")
    usub = p.add_subparsers(dest="users_command", required=True)
    for name, help in (("add", "make a user's token (printed, or written to --out)"),
                       ("remove", "delete a user's token: refused from the next request"),
                       ("list", "the users with a token")):
        q = usub.add_parser(name, help=help)
        _state_dir_option(q)
        if name != "list":
            q.add_argument("name", metavar="NAME")
        if name == "add":
            q.add_argument("--out", metavar="FILE", help="write the token to FILE (0600) "
                           "instead of printing it; the user keeps it in "
                           "~/.config/wideprint/token")
            q.add_argument("--replace", action="store_true",
                           help="a user with a token gets a new one (the old one stops working)")
        q.set_defaults(func=cmd_users)
