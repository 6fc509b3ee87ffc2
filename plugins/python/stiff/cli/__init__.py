"""The `stiff` command line. Each subcommand is a module with `register(subparsers)`; user
errors print one clear line and exit with code 2, never a traceback."""
from __future__ import annotations

import argparse
import importlib
import sys

from ..errors import StiffError

# Subcommand modules, in the order `stiff --help` lists them.
COMMANDS = ["demo", "examples", "robot", "simulate", "identify", "predict", "effects", "import_"]
OPTIONAL_COMMANDS = ["plan", "diagnose", "compensate", "filter", "fmu", "study"]


class UserError(Exception):
    """A mistake of the user (bad option, missing file): one line, exit code 2."""


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__
    from ..api import library_version

    p = argparse.ArgumentParser(
        prog="stiff",
        description="Joint stiffness identification, diagnosis and deflection compensation "
        "for industrial robots. SI units inside; files carry their units.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        epilog="Start with `stiff demo`; every subcommand has --help with a worked example.",
    )
    p.add_argument("--version", action="version",
                   version=f"stiff {__version__} (libstiff_c {library_version()})")
    sub = p.add_subparsers(dest="command", metavar="<command>")
    for name in COMMANDS + OPTIONAL_COMMANDS:
        try:
            mod = importlib.import_module(f".{name}", __name__)
        except ModuleNotFoundError as e:
            if e.name and e.name.endswith(f"cli.{name}") and name in OPTIONAL_COMMANDS:
                continue
            raise
        mod.register(sub)
    return p


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "command", None):
        parser.print_help()
        return 2
    try:
        return int(args.func(args) or 0)
    except (UserError, StiffError, FileNotFoundError, PermissionError, IsADirectoryError, ValueError) as e:
        msg = str(e)
        if isinstance(e, (FileNotFoundError, PermissionError, IsADirectoryError)) and e.filename:
            msg = f"{e.filename}: {e.strerror}"
        print(f"stiff {args.command}: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"stiff {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0


if __name__ == "__main__":
    sys.exit(main())
