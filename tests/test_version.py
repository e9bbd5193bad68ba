"""The version has one source, ``ipp_toolkit.__version__``: the package metadata reads it and
every command prints it."""

from __future__ import annotations

import configparser
from importlib import metadata
from pathlib import Path

import pytest
from setuptools.config.expand import read_attr

import ipp_toolkit

ROOT = Path(__file__).resolve().parents[1]
DISTRIBUTION = "ipp-marl-toolkit"


def _installed_version() -> str:
    try:
        return metadata.version(DISTRIBUTION)
    except metadata.PackageNotFoundError:
        pytest.skip(f"{DISTRIBUTION} is not installed (pip install -e .)")


def test_setup_cfg_reads_the_version_from_the_package():
    config = configparser.ConfigParser()
    config.read(ROOT / "setup.cfg", encoding="utf-8")
    assert config["metadata"]["version"].strip() == "attr: ipp_toolkit.__version__"
    # What setuptools does with that line: it reads the literal from the source, unimported.
    assert read_attr("ipp_toolkit.__version__", root_dir=ROOT) == ipp_toolkit.__version__


def test_every_command_prints_the_installed_version(capsys):
    version = _installed_version()
    assert version == ipp_toolkit.__version__, (
        "the installed metadata is of another version: install the checkout again "
        "(pip install -e .)")
    scripts = [entry for entry in metadata.distribution(DISTRIBUTION).entry_points
               if entry.group == "console_scripts"]
    assert {entry.name for entry in scripts} >= {"ipp-compare", "ipp-simulate", "ipp-train",
                                                 "ipp-study"}
    for entry in scripts:
        with pytest.raises(SystemExit) as exit_:
            code = entry.load()(["--version"])
            raise SystemExit(code)  # a command that returns instead of exiting
        assert exit_.value.code in (0, None), entry.name
        printed = capsys.readouterr().out.split()
        assert printed[-1] == version, f"{entry.name} --version printed {printed}"
