"""The files of a COMA training run other than the networks: its progress log and its end.

This module owns ``progress.csv`` (one row per update, the columns :data:`CSV_COLUMNS`:
:func:`write_progress`, :func:`read_progress` for a resume, read by
:func:`ipp_toolkit.runs.progress_csv.read_progress_csv`), which configuration fields a
resumed run must share with its checkpoint (:func:`resume_fields`), the raster file's sha256
that ``config.json`` records and a resume checks (:func:`check_raster_record`), and
:class:`TrainResult`, what :func:`coma.learner.train` returns. The networks' files
(``last.pt``, ``best.pt``) are written by :mod:`coma.persistence`.
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ipp_toolkit.config.field_types import is_integer
from ipp_toolkit.io import CheckpointError, atomic_write
from ipp_toolkit.runs.progress_csv import read_progress_csv
from ipp_toolkit.runs.result_store import check_raster_unchanged

from .config import COMAConfig
from .persistence import load_policy

__all__ = ["CSV_COLUMNS", "TrainResult", "write_progress", "read_progress", "resume_fields",
           "saved_update", "check_counters", "check_raster_record"]


CSV_COLUMNS = ["update", "missions", "transitions", "eps", "return_mean", "final_entropy_mean",
               "critic_loss", "value_loss", "actor_loss", "advantage_std", "policy_entropy",
               "critic_grad_norm", "actor_grad_norm", "transitions_per_s", "wall_s",
               "eval_return", "eval_entropy_final", "eval_f1_final", "eval_gap_worst",
               "n_agents", "comm_range"]


@dataclass
class TrainResult:
    """Where a run left its files and how it ended.

    Attributes:
        out_dir: the run folder.
        best_policy: path of the policy with the lowest validation entropy (``best.pt``).
        last_checkpoint: path of the resumable training checkpoint (``last.pt``).
        updates: updates done in total.
        missions: training missions played in total.
        best_entropy: validation final entropy of the best policy.
        history: one dict per update (the CSV rows).
    """

    out_dir: Path
    best_policy: Path
    last_checkpoint: Path
    updates: int
    missions: int
    best_entropy: float
    history: list[dict[str, Any]] = field(default_factory=list)


def write_progress(path: Path, rows: list[dict[str, Any]]) -> None:
    """Write ``progress.csv`` (the columns :data:`CSV_COLUMNS`, None as empty), atomically."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=CSV_COLUMNS, extrasaction="ignore")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: ("" if row.get(k) is None else row.get(k)) for k in CSV_COLUMNS})
    data = buffer.getvalue().encode("utf-8")
    atomic_write(path, lambda handle: handle.write(data))


def resume_fields(config: COMAConfig) -> dict[str, Any]:
    """Fields that must match to resume a run (the total length may be extended)."""
    values = config.to_dict()
    values.pop("missions")
    return values


def check_counters(path: Path, progress: dict[str, Any], total_missions: int,
                   missions_per_update: int) -> None:
    """Refuse (CheckpointError naming the value) a checkpoint's update and mission counters
    that no run of this config reaches: not an integer, negative, more missions than
    ``total_missions``, or missions that are not ``update`` x ``missions_per_update``. Read
    as they are, 10^9 updates would build a history of 10^9 rows."""
    update, missions = progress["update"], progress["missions"]
    for name, value in (("update", update), ("missions", missions)):
        if not is_integer(value, 0, numpy=False):
            raise CheckpointError(f"checkpoint {str(path)!r} has {name} = {value!r}, not an "
                                  "integer >= 0: it is damaged; start a new folder")
    if missions > total_missions or missions != update * missions_per_update:
        raise CheckpointError(
            f"checkpoint {str(path)!r} has update = {update!r} and missions = {missions!r}, "
            f"which no run of {total_missions} missions ({missions_per_update} per update) "
            "reaches: it is damaged; start a new folder")


def read_progress(path: Path, up_to_update: int) -> list[dict[str, Any]]:
    """The rows of ``progress.csv`` for updates 1..``up_to_update`` (a resumed run's history).

    Rows after ``up_to_update`` are dropped: the file is written before the checkpoint, so a
    run stopped between the two writes left rows of updates the checkpoint does not hold.

    Raises:
        CheckpointError: the file is missing (at update > 0), unreadable, malformed, or does
            not hold one row per update up to ``up_to_update``; resuming would silently
            restart or garble the history.
    """
    if not path.exists():
        if up_to_update == 0:
            return []
        raise CheckpointError(f"{str(path)!r} is missing, but the checkpoint is at update "
                              f"{up_to_update}: resuming would lose the history; restore it "
                              "or start a new folder")
    try:
        history = read_progress_csv(path, CSV_COLUMNS)
    except (OSError, UnicodeDecodeError, csv.Error, ValueError) as err:
        raise CheckpointError(f"{str(path)!r} is damaged ({err}); restore it or start a new "
                              "folder") from None
    rows = [row for row in history if isinstance(row["update"], int)
            and row["update"] <= up_to_update]
    if [row["update"] for row in rows] != list(range(1, up_to_update + 1)):
        raise CheckpointError(f"{str(path)!r} does not hold one row per update 1..{up_to_update} "
                              "(the checkpoint's): it is truncated or damaged; restore it or "
                              "start a new folder")
    return rows


def saved_update(path: Path) -> str:
    """The update a training checkpoint holds, for messages: a number, "none yet" or
    "unreadable"."""
    if not path.exists():
        return "none yet"
    try:
        _, data = load_policy(path)
        return str(data["progress"]["update"])
    except (CheckpointError, KeyError):
        return "unreadable"


def check_raster_record(out: Path, digest: str | None, raster: str | None) -> None:
    """Refuse (CheckpointError naming the file and both digests) to resume the run in ``out``
    when its ``config.json`` recorded another sha256 of the raster file ``raster`` than the
    file's now, ``digest``: the missions would no longer be those the run trained on. A
    run without a raster file, or whose record is unreadable or predates the digest, is not
    checked (its checkpoint's own checks still apply)."""
    if digest is None:
        return
    try:
        record = json.loads((out / "config.json").read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return
    recorded = record.get("raster_sha256") if isinstance(record, dict) else None
    check_raster_unchanged(recorded, digest, raster, f"run folder {str(out)!r}",
                           CheckpointError)
