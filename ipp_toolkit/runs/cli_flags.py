"""The flags the commands share, one owner for their spelling and their values.

``ipp-compare``, ``ipp-study``, ``ipp-simulate`` (:mod:`reports.cli`) and the ``ipp-train``
trainers (:mod:`coma.cli`, :mod:`baselines.sb3.ppo_training` for ``ppo``, ``sb3`` and ``rllib``,
:mod:`baselines.field_prior.training`) parse some of the same flags. This module owns

* the value types of their flags: :func:`positive_int`, :func:`positive_float`,
  :func:`finite_float` and :func:`comm_range`, and the comma lists built on them,
  :func:`int_list` and :func:`comm_range_list` (``--team-sizes 2,4,8``, ``--comm-ranges
  0,25,inf``, ``--seeds 0,1,2``). argparse prints their message after ``argument --flag:`` and
  exits with code 2, so ``--agents 0`` reads the same in every command, and a list names its
  bad item in the same words as the single value would;
* the flags themselves where both command modules parse them: where the missions fly
  (:func:`add_compute_flags`: ``--workers``, ``--backend``, ``--address``), ``--set
  FIELD=VALUE`` (:func:`add_set_flag`), ``--no-progress`` (:func:`add_progress_flag`) and
  ``--force`` (:func:`add_force_flag`).

Each command keeps its own help text, since the same flag does a different job in each
(``--workers`` flies an evaluation's missions, or a training's updates).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from typing import Any

from ..config.settings import parse_comm
from .ray_backend import add_backend_flags

__all__ = ["positive_int", "positive_float", "finite_float", "comm_range", "int_list",
           "comm_range_list", "add_compute_flags", "add_set_flag", "add_progress_flag",
           "add_force_flag", "FORCE_HELP"]


def _integer(text: str, minimum: int) -> int:
    """``text`` as an integer >= ``minimum``; ArgumentTypeError saying so otherwise."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"must be an integer >= {minimum}, got {text!r}") from None
    if value < minimum:
        raise argparse.ArgumentTypeError(f"must be an integer >= {minimum}, got {text!r}")
    return value


def positive_int(flag: str) -> Callable[[str], int]:
    """The value type of an integer flag >= 1 (``flag`` names it in tracebacks)."""

    def parse(text: str) -> int:
        return _integer(text, 1)

    parse.__name__ = flag
    return parse


def positive_float(text: str) -> float:
    """The value type of a positive, finite number (a resolution, a size in metres)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return value


def finite_float(text: str) -> float:
    """The value type of any finite number (a raster threshold)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return value


def comm_range(text: str) -> float:
    """The value type of a communication range: metres >= 0, or ``inf``
    (:func:`~ipp_toolkit.config.settings.parse_comm`)."""
    return _comm_range(text, "--comm")


def _comm_range(text: str, flag: str) -> float:
    """:func:`~ipp_toolkit.config.settings.parse_comm` of ``text``, its ValueError (naming
    ``flag``) as argparse's ArgumentTypeError."""
    try:
        return parse_comm(text, flag)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def int_list(flag: str, minimum: int = 1) -> Callable[[str], list[int]]:
    """The value type of a comma list of integers >= ``minimum`` (``--team-sizes 2,4,8``;
    ``minimum=0`` for seeds and failure counts).

    Each item is read as :func:`positive_int` reads one value, so a bad item is refused in the
    same words, with the whole list after it: ``argument --team-sizes: must be an integer >= 1,
    got 'x' (in '2,x')``. Spaces around an item are allowed; an empty item is refused.
    """

    def parse(text: str) -> list[int]:
        return _items(text, lambda item: _integer(item, minimum))

    parse.__name__ = flag
    return parse


def comm_range_list(flag: str) -> Callable[[str], list[float]]:
    """The value type of a comma list of communication ranges (``--comm-ranges 0,25,inf``),
    each read as :func:`comm_range` reads one, naming ``flag`` in its message."""

    def parse(text: str) -> list[float]:
        return _items(text, lambda item: _comm_range(item, flag))

    parse.__name__ = flag
    return parse


def _items(text: str, parse_item: Callable[[str], Any]) -> list[Any]:
    """The items of a comma list, each read by ``parse_item``; a refusal names the item (in
    ``parse_item``'s words) and the list, so ``2,x,8`` points at ``x``."""
    items = [item.strip() for item in text.split(",")]
    if any(not item for item in items):
        raise argparse.ArgumentTypeError(
            f"{text!r} has an empty value; give values separated by commas, e.g. 2,4,8")
    values = []
    for item in items:
        try:
            values.append(parse_item(item))
        except argparse.ArgumentTypeError as err:
            if len(items) == 1:
                raise
            raise argparse.ArgumentTypeError(f"{err} (in {text!r})") from None
    return values


def add_compute_flags(parser: argparse.ArgumentParser, *, workers_help: str,
                      workers_type: Callable[[str], int], backend_help: str,
                      address_help: str, workers_default: int = 1,
                      workers_metavar: str | None = None) -> None:
    """``--workers``, then ``--backend local|ray`` and ``--address HOST:PORT``
    (:func:`~ipp_toolkit.runs.ray_backend.add_backend_flags`): where a command's missions fly.

    Args:
        parser: the command's parser.
        workers_help: what the workers do in this command.
        workers_type: the value type of ``--workers`` (an integer >= 1).
        backend_help, address_help: as :func:`~ipp_toolkit.runs.ray_backend.add_backend_flags`
            takes them.
        workers_default: the number of workers without the flag.
        workers_metavar: the value's name in the help (default: WORKERS).
    """
    parser.add_argument("--workers", type=workers_type, default=workers_default,
                        metavar=workers_metavar, help=workers_help)
    add_backend_flags(parser, backend_help, address_help)


def add_set_flag(parser: argparse.ArgumentParser, help: str) -> None:
    """``--set FIELD=VALUE`` (repeatable): a :class:`~coma.config.COMAConfig` field, its
    value read by ``coma.cli.coerce_value``."""
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help=help)


def add_progress_flag(parser: argparse.ArgumentParser, help: str | None) -> None:
    """``--no-progress``: no progress bar (``args.no_progress``)."""
    kwargs: dict[str, Any] = {} if help is None else {"help": help}
    parser.add_argument("--no-progress", action="store_true", **kwargs)


FORCE_HELP = ("write into --out even when it holds files the toolkit did not write (they may "
              "be overwritten); without it such a folder is refused")


def add_force_flag(parser: argparse.ArgumentParser) -> None:
    """``--force`` (``args.force``): accept an ``--out`` folder holding files of its own
    (:func:`ipp_toolkit.runs.run_folder.allow_foreign_files`)."""
    parser.add_argument("--force", action="store_true", default=False, help=FORCE_HELP)
