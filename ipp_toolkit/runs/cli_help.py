"""What every command's ``--help`` and ``--version`` look like (one owner for all commands).

:class:`HelpFormatter` appends ``(default: X)`` to an option's help where X is a real
default: never for a default of None, False, an empty list or one the help already states,
so no command prints ``(default: None)``. :func:`add_version` adds ``--version``.
"""

from __future__ import annotations

import argparse

__all__ = ["HelpFormatter", "add_version", "version_line"]


class HelpFormatter(argparse.HelpFormatter):
    """argparse's formatter plus ``(default: X)`` on options whose default means something."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        default = action.default
        states_own = "(default" in text or "default:" in text  # the help says it already
        if (not action.option_strings or states_own
                or default is None or default is False or default is argparse.SUPPRESS
                or default == [] or isinstance(action, argparse._VersionAction)):
            return action.help
        return f"{text} (default: %(default)s)" if text else "(default: %(default)s)"


def version_line(prog: str) -> str:
    """``PROG VERSION`` of the installed toolkit."""
    from ipp_toolkit import __version__

    return f"{prog} {__version__}"


def add_version(parser: argparse.ArgumentParser) -> None:
    """Add ``--version`` (prints ``PROG VERSION`` and exits 0)."""
    parser.add_argument("--version", action="version", version=version_line(parser.prog))
