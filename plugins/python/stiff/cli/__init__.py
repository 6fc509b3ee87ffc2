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


class Terminated(BaseException):
    """SIGTERM: stop like Ctrl-C (outputs discarded, workers stopped), exit code 143."""


class _Failed(Exception):
    def __init__(self, code: int):
        self.code = code


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
    import signal

    from .. import _outputs

    def on_sigterm(signum, frame):
        raise Terminated()

    try:
        previous = signal.signal(signal.SIGTERM, on_sigterm)
    except ValueError:  # not the main thread: leave signals to the host
        previous = None
    t = None
    try:
        # Outputs are committed only when the whole command has succeeded.
        with _outputs.transaction() as t:
            code = int(args.func(args) or 0)
            if code != 0:
                raise _Failed(code)
        return code
    except _Failed as e:
        return e.code
    except BrokenPipeError:
        return 0
    except (UserError, StiffError, OSError, ValueError) as e:
        msg = str(e)
        if isinstance(e, OSError) and not isinstance(e, StiffError) and e.filename:
            msg = f"{e.filename}: {e.strerror}"
        if t is not None:
            msg = t.public(msg)
        print(f"stiff {args.command}: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"stiff {args.command}: interrupted", file=sys.stderr)
        return 130
    except Terminated:
        print(f"stiff {args.command}: terminated", file=sys.stderr)
        return 143
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
