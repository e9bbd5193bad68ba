"""MkDocs hook: every command's ``--help``, rendered into the manual when the site is built.

A page marks the place with an HTML comment, ``<!-- help: ipp-train coma -->``; the hook
replaces it with the help that command prints, from the toolkit in this checkout, so the
reference of commands and flags cannot fall behind the code. On GitHub the comment stays
invisible and the page says to run the command with ``--help``.
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MARKER = re.compile(r"<!-- help: (ipp-[a-z]+(?: [a-z0-9]+)?) -->")
_HELP: dict[str, str] = {}


def command_help(command: str) -> str:
    """What ``COMMAND --help`` prints, at 100 columns."""
    if command not in _HELP:
        if str(ROOT) not in sys.path:
            sys.path.insert(0, str(ROOT))
        from reports import cli

        program, *sub = command.split()
        main = {"ipp-simulate": cli.simulate_main, "ipp-compare": cli.compare_main,
                "ipp-train": cli.train_main, "ipp-study": cli.study_main}[program]
        columns = os.environ.get("COLUMNS")
        os.environ["COLUMNS"] = "100"
        printed = io.StringIO()
        try:
            with contextlib.redirect_stdout(printed), contextlib.suppress(SystemExit):
                main([*sub, "--help"])
        finally:
            if columns is None:
                os.environ.pop("COLUMNS", None)
            else:
                os.environ["COLUMNS"] = columns
        text = printed.getvalue().rstrip()
        if not text.startswith("usage:"):
            raise RuntimeError(f"`{command} --help` printed no usage: {text[:200]!r}")
        _HELP[command] = text
    return _HELP[command]


def on_page_markdown(markdown: str, **kwargs: object) -> str:
    return MARKER.sub(lambda match: f"```text\n{command_help(match.group(1))}\n```", markdown)
