"""The ``psyop`` command.

Each sub-command lives in its own module in this package and exposes
``register(subparsers)``, which adds a parser and sets ``func`` on it. Modules are
discovered by name, so adding a command touches no shared file.

Start-up stays short: ``psyop COMMAND ...`` imports only that command's module, and a
command module imports its heavy dependencies (pandas, pydantic, OpenGL) inside the
function that runs it, so ``psyop --help`` and ``psyop validate`` import only what they use
(benchmarks/bench_cli_startup.py; tests/test_cli_startup.py).
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import re
import sys
from collections.abc import Sequence

from psyop import __version__
from psyop.errors import UserError


def command_names() -> list[str]:
    """The sub-commands: one module each in this package (names only, nothing imported)."""
    return sorted(info.name for info in pkgutil.iter_modules(__path__) if not info.name.startswith("_"))


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """The ``psyop`` parser with every sub-command, or only ``only`` (what ``main`` runs)."""
    parser = argparse.ArgumentParser(
        prog="psyop",
        description="Gaze-contingent VR psychophysics: protocols, sessions, rendering, analysis.",
    )
    parser.add_argument("--version", action="version", version=f"psyop {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in command_names():
        if only is not None and name != only:
            continue
        module = importlib.import_module(f"{__name__}.{name}")
        module.register(subparsers)
    return parser


#: A value list that starts with a minus sign (``-12,0``): argparse would take it for an option.
_NEGATIVE_LIST = re.compile(r"^-\d[\d.]*(,[-+]?[\d.]+)+$")


def attach_negative_lists(argv: Sequence[str]) -> list[str]:
    """``--gaze-deg -12,0`` -> ``--gaze-deg=-12,0``, so a comma list of numbers may start with a minus.

    Examples
    --------
    >>> attach_negative_lists(["render", "p.yaml", "--gaze-deg", "-12,0", "--out", "x.png"])
    ['render', 'p.yaml', '--gaze-deg=-12,0', '--out', 'x.png']
    """
    out: list[str] = []
    for arg in argv:
        if out and out[-1].startswith("--") and "=" not in out[-1] and _NEGATIVE_LIST.match(arg):
            out[-1] = f"{out[-1]}={arg}"
        else:
            out.append(arg)
    return out


def closed_pipe_exit() -> int:
    """The reader of stdout went away (``psyop show P | head -1``): end quietly, as ``cat`` does.

    Python's documented recipe (library/signal.html, "Note on SIGPIPE"): point stdout at devnull so
    that the interpreter's final flush at exit does not raise a second BrokenPipeError, and exit with
    128 + SIGPIPE (141), the status a shell reports for other tools killed by the closed pipe.
    """
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):  # stdout is no file descriptor (a test's StringIO): nothing to flush
        pass
    return 141


def main(argv: Sequence[str] | None = None) -> int:
    argv = attach_negative_lists(sys.argv[1:] if argv is None else argv)
    first = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(first if first in command_names() else None)
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 0
    try:
        code = int(args.func(args) or 0)
        sys.stdout.flush()  # a closed pipe shows here, inside the handler, not in the interpreter's exit
        return code
    except BrokenPipeError:
        return closed_pipe_exit()
    except UserError as error:
        print(f"psyop {args.command}: error: {error}", file=sys.stderr)
        return error.exit_code
    except KeyboardInterrupt:
        # Exit status 130 (128 + SIGINT). A Ctrl-C that lands while scipy/pandas are still being
        # imported can end the process by SIGINT itself after this return (CPython 3.11 keeps a flag
        # set by an extension's nested code run; reproduced without psyop): a shell reports 130
        # either way, and nothing has been recorded by then.
        print(f"psyop {args.command}: interrupted", file=sys.stderr)
        return 130
    except OSError as exc:  # disk full, I/O error, permissions: one line naming the file and the fix
        from psyop.atomic import io_error

        io_problem = io_error(exc)
        print(f"psyop {args.command}: error: {io_problem}", file=sys.stderr)
        return io_problem.exit_code


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
