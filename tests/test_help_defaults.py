"""Every command's --help names the default of every option that has one, and building the
parsers imports no torch (--help answers at once; benchmarks/help_time.py times it)."""

from __future__ import annotations

import argparse
import configparser
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from reports.cli import TRAINERS, command_parsers

ROOT = Path(__file__).resolve().parents[1]

#: A default stated as such: "(default: X)" from the formatter, or the help's own words.
_DEFAULT = re.compile(r"\bdefault\b")


def _console_scripts() -> list[str]:
    config = configparser.ConfigParser()
    config.read(ROOT / "setup.cfg")
    lines = config["options.entry_points"]["console_scripts"].strip().splitlines()
    return [line.split("=")[0].strip() for line in lines]


def _has_default(action: argparse.Action) -> bool:
    """Whether ``action`` takes a value that has a default: not --help or --version, not a
    positional or required one, not an on/off flag (off unless given), not a repeatable one
    that starts empty."""
    if action.help == argparse.SUPPRESS or not action.option_strings or action.required:
        return False
    if isinstance(action, argparse._HelpAction | argparse._VersionAction):
        return False
    if action.nargs == 0 and not isinstance(action, argparse.BooleanOptionalAction):
        return False
    return not (isinstance(action, argparse._AppendAction) and not action.default)


def test_every_console_script_and_trainer_has_its_parser():
    commands = set(command_parsers())
    for script in _console_scripts():
        if script == "ipp-train":  # ipp-train dispatches to its trainers, each with a parser
            assert {f"ipp-train {name}" for name in TRAINERS} <= commands
        else:
            assert script in commands


@pytest.mark.parametrize("command", sorted(command_parsers()))
def test_every_option_with_a_default_names_it_in_help(command):
    parser = command_parsers()[command]()
    formatter = parser._get_formatter()
    missing = []
    for action in parser._actions:
        if not _has_default(action):
            continue
        # What --help prints for the option: argparse prints nothing for an option without
        # help text, not even the formatter's "(default: X)".
        text = formatter._expand_help(action) if action.help else ""
        if not _DEFAULT.search(text):
            missing.append(action.option_strings[0])
    assert not missing, f"{command} --help names no default for {missing}"


def test_coma_help_names_the_presets_defaults():
    text = " ".join(command_parsers()["ipp-train coma"]().format_help().split())
    for flag in ("--missions", "--seed", "--width", "--variant", "--comm"):
        help_text = text.split(f" {flag} ", 1)[1].split(" --", 1)[0]
        assert "default" in help_text, flag
    assert "default: the preset's: cpu 20000, paper 75000, scratch 20000" in text


def test_building_every_parser_imports_no_torch():
    # A fresh interpreter: this one has imported torch through other tests. Building and
    # printing every parser (what --help does) must not import torch, SB3 or Ray, each
    # seconds of import before the help appears.
    code = ("import json, sys\n"
            "from reports.cli import command_parsers\n"
            "for build in command_parsers().values():\n"
            "    build().format_help()\n"
            "print(json.dumps(sorted(m for m in ('torch', 'stable_baselines3', 'sb3_contrib',"
            " 'ray', 'matplotlib') if m in sys.modules)))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT, timeout=120, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads(done.stdout.strip().splitlines()[-1]) == []
