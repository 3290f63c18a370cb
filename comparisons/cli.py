"""mjed-verify: the command line of the verification suite.

    mjed-verify equivalence --material all --mesh cube-paper --json out.json

Each subcommand lives in its own module of :mod:`comparisons.commands`; this file only finds
them, parses, and turns :class:`common.options.InputError` into exit code 2.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import pkgutil
import signal
import sys
import threading
from types import ModuleType
from typing import Dict, List, Optional

from common.options import InputError, check_writable_destination
from common.result import EXIT_INPUT
from common.verdict import EXIT_POLICY
from comparisons import commands

__all__ = ["main", "build_parser", "command_modules"]


def command_modules() -> Dict[str, ModuleType]:
    """The subcommand modules, by name, in help order."""
    mods = [
        importlib.import_module(f"{commands.__name__}.{info.name}")
        for info in pkgutil.iter_modules(commands.__path__)
        if not info.name.startswith("_")
    ]
    mods = [m for m in mods if hasattr(m, "NAME") and hasattr(m, "run")]
    return {m.NAME: m for m in sorted(mods, key=lambda m: (getattr(m, "ORDER", 100), m.NAME))}


def build_parser(modules: Optional[Dict[str, ModuleType]] = None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="mjed-verify",
        description="Verify a NumPy MJED implementation force by force and stiffness by stiffness "
        "against a UFL Galerkin oracle.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, mod in (command_modules() if modules is None else modules).items():
        epilog = "\n".join(t for t in (getattr(mod, "EXAMPLES", ""), EXIT_POLICY) if t)
        p = sub.add_parser(
            name,
            help=mod.HELP,
            description=mod.HELP,
            epilog=epilog,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        mod.configure(p)
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    modules = command_modules()
    args = build_parser(modules).parse_args(argv)
    logging.disable(logging.INFO)  # FFCx's JIT logs every compilation at INFO
    previous = _sigterm_as_interrupt()
    try:
        for attr, is_dir in (("json", False), ("out", True)):
            if getattr(args, attr, None):
                check_writable_destination(getattr(args, attr), is_dir=is_dir)
        return int(modules[args.command].run(args))
    except InputError as exc:
        print(f"mjed-verify {args.command}: error: {exc}", file=sys.stderr)
        return EXIT_INPUT
    except KeyboardInterrupt:  # Ctrl-C or SIGTERM
        print(f"mjed-verify {args.command}: interrupted", file=sys.stderr)
        return 130
    finally:
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


def _sigterm_as_interrupt():
    """SIGTERM raises KeyboardInterrupt, as Ctrl-C does, so that every command cleans up the same
    way (an engine's process tree ended, a report's partial folder handled); returns the
    previous handler, or None off the main thread, where signals cannot be caught.
    """
    if threading.current_thread() is not threading.main_thread():
        return None

    def interrupt(signum, frame):
        raise KeyboardInterrupt()

    return signal.signal(signal.SIGTERM, interrupt)


if __name__ == "__main__":
    sys.exit(main())
