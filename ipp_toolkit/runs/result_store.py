"""The files of an evaluation folder: identity, per-mission shards, trajectories, results.csv.

``ipp_toolkit.runs.evaluation`` runs missions; this module owns how their results are stored and
read back, so a folder can be resumed, checked against the configuration that made it and
grown with more planners. Layout (written atomically, file by file)::

    out_dir/
        config.json                          identity: config, seed, namespace (+ version)
        shards/<label>/planner.json          the planner spec behind the label
        shards/<label>/mission_00007.json    the rows (+ trajectory) of one mission
        results.csv                          every row of the requested missions, of the
                                             requested planners and of every planner stored
                                             before with all of those missions
        trajectories/<label>_mission0.npz    recorded missions (ground truth, final map, path)
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import math
import warnings
import zipfile
import zlib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..config.field_types import is_real
from ..config.files import config_from_dict, config_to_dict
from ..config.limits import check_limit
from ..config.schema import EnvConfig
from ..config.settings import safe_name
from ..config.terrain_checks import drawn_kinds
from ..io import atomic_write, check_regular_file, write_json

if TYPE_CHECKING:
    from ..planning.specs import PlannerSpec

__all__ = ["RESULT_COLUMNS", "EvaluationError", "folder_identity", "read_identity", "check_folder",
           "check_label", "check_finite_row", "check_raster_unchanged", "raster_digest", "run_key",
           "shard_checksum", "shard_path", "trajectory_path", "stored_planners", "read_shard",
           "read_stored_missions", "write_shard", "write_trajectory", "read_trajectory",
           "write_results_csv", "read_results_csv"]

RESULT_COLUMNS = ("planner", "agents", "comm", "terrain", "seed", "mission", "step",
                  "entropy", "f1", "rmse", "reward", "plan_ms")
"""Columns of a result row: identity (planner label, team size, communication range in metres,
terrain, run seed, mission index, step s = 0..B), the global map's metrics after step s, the
team reward of step s and the planner's wall-clock time for step s in milliseconds (both NaN
at s = 0)."""

_INT_COLUMNS = frozenset({"agents", "seed", "mission", "step"})
_FLOAT_COLUMNS = frozenset({"comm", "entropy", "f1", "rmse", "reward", "plan_ms"})
_MISSING = object()
_FORMAT = 1  # version of the shard and config.json layout


class EvaluationError(ValueError):
    """An evaluation folder cannot be used: it holds results of another configuration or of
    another planner under the same label, or a file in it is malformed."""


def folder_identity(config: EnvConfig, seed: int, namespace: str) -> dict[str, Any]:
    """What ``config.json`` records of a run: layout version, config, seed, namespace, version."""
    from .. import __version__

    # Through JSON so that it compares equal to what is read back from config.json.
    identity = json.loads(json.dumps({"format": _FORMAT, "config": config_to_dict(config),
                                      "seed": int(seed), "namespace": namespace,
                                      "version": __version__}))
    digest = raster_digest(config)
    if digest is not None:
        identity["raster_sha256"] = digest
    return identity


def raster_digest(config: EnvConfig) -> str | None:
    """The sha256 of the raster file the terrain reads (``raster``, or a ``mixture`` with
    it), so that a folder refuses missions of another content under the same file name;
    None when no raster file is read. ValueError naming a file that cannot be read."""
    terrain = config.terrain
    if "raster" not in drawn_kinds(terrain) or not isinstance(terrain.raster, str):
        return None
    digest = hashlib.sha256()
    try:
        check_regular_file(terrain.raster, "terrain.raster")
        with open(terrain.raster, "rb") as file:
            for block in iter(lambda: file.read(1 << 20), b""):
                digest.update(block)
    except OSError as err:  # bad input, as the terrain's own read reports it
        raise ValueError(f"cannot read raster file {terrain.raster!r}: "
                         f"{err.strerror or err}") from None
    return digest.hexdigest()


def check_raster_unchanged(recorded: Any, current: str | None, raster: Any, where: str,
                           error: type[ValueError] = ValueError) -> None:
    """Refuse (``error`` naming the file and both digests) to go on with a run or folder
    ``where`` that recorded the sha256 ``recorded`` of its raster file ``raster`` when the
    file's is now ``current`` (:func:`raster_digest`): the file was replaced since, and the
    missions it makes are not those the run began on. Nothing to compare (no raster file, or
    a record written before digests were) passes."""
    if recorded is None or current is None or recorded == current:
        return
    raise error(f"{where} was made with another content of the raster file "
                f"{raster!r} (sha256 {str(recorded)[:64]}, the file's is now "
                f"{current}): the file was replaced since; use the file it was made with, or "
                "another folder")


def _flat_differences(old: Any, new: Any, prefix: str) -> list[str]:
    if isinstance(old, dict) and isinstance(new, dict):
        keys = sorted(set(old) | set(new))
        return [d for k in keys
                for d in _flat_differences(old.get(k), new.get(k), f"{prefix}.{k}" if prefix
                                           else str(k))]
    return [] if old == new else [prefix]


def read_identity(folder: Path) -> dict[str, Any]:
    """The stored ``config.json`` of ``folder`` (EvaluationError when missing or malformed)."""
    path = folder / "config.json"
    try:
        stored = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise EvaluationError(f"{str(folder)!r} holds no evaluation: {str(path)!r} is "
                              "missing") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise EvaluationError(f"cannot read {str(path)!r}: {err}") from None
    if not isinstance(stored, dict) or not {"config", "seed", "namespace"} <= set(stored):
        raise EvaluationError(f"{str(path)!r} is not an evaluation identity: it needs the "
                              "keys 'config', 'seed' and 'namespace'")
    return stored


def run_key(identity: Mapping[str, Any]) -> str:
    """A digest of what a folder's missions depend on (config, seed, namespace), stored in
    every shard so that a shard of another run is recognised when it is read.

    Only the config fields that differ from the defaults count: a field added in a later
    version, with a default that keeps the old behaviour, leaves the key of a folder as it was.
    """
    defaults = config_to_dict(EnvConfig())
    config = identity.get("config")
    if isinstance(config, dict):
        config = {section: {k: v for k, v in values.items()
                            if defaults.get(section, {}).get(k, _MISSING) != v}
                  if isinstance(values, dict) else values
                  for section, values in json.loads(json.dumps(config)).items()}
    data = json.dumps({"config": config, "seed": identity.get("seed"),
                       "namespace": identity.get("namespace")}, sort_keys=True)
    return hashlib.sha256(data.encode("utf-8")).hexdigest()[:16]


def check_folder(folder: Path, identity: dict[str, Any],
                 specs: Sequence[PlannerSpec]) -> bool:
    """Check that ``folder`` may take these results; returns whether config.json exists."""
    if folder.exists() and not folder.is_dir():
        raise EvaluationError(f"out_dir {str(folder)!r} exists and is not a folder")
    if not (folder / "config.json").exists():
        if (folder / "shards").exists():
            raise EvaluationError(f"out_dir {str(folder)!r} holds shards/ but no config.json: "
                                  "cannot tell which configuration they belong to")
        return False
    stored = read_identity(folder)
    # A folder written before a config field existed stored no value for it; the field's
    # default keeps the old behaviour, so compare the stored config with its defaults filled.
    try:
        stored["config"] = json.loads(json.dumps(config_to_dict(
            config_from_dict(stored["config"]))))
    except (ValueError, TypeError):
        pass  # not a valid config now: compared as stored, and reported as different
    differing = []
    for key in ("config", "seed", "namespace"):
        differing += _flat_differences(stored.get(key), identity[key], key)
    if differing:
        raise EvaluationError(
            f"out_dir {str(folder)!r} holds results of another configuration (differing: "
            f"{', '.join(differing)}); use another folder or the same configuration")
    _check_raster(folder, stored, identity)
    if stored.get("version") != identity["version"]:
        warnings.warn(f"{str(folder)!r} was written by ipp-toolkit {stored.get('version')}, "
                      f"this is {identity['version']}: stored missions are reused",
                      stacklevel=3)
    for spec in specs:
        path = folder / "shards" / safe_name(spec.effective_label) / "planner.json"
        if not path.exists():
            continue
        try:
            stored_spec = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
            raise EvaluationError(f"cannot read {str(path)!r}: {err}") from None
        if stored_spec != spec.to_dict():
            raise EvaluationError(
                f"out_dir {str(folder)!r} holds missions of planner label "
                f"{spec.effective_label!r} made with {stored_spec!r}, not {spec.to_dict()!r}; "
                "give this planner another label or use another folder")
    return True


def _check_raster(folder: Path, stored: Mapping[str, Any], identity: Mapping[str, Any]) -> None:
    """Refuse a folder made with another content of the same raster file (a folder written
    before the digest was recorded is not checked)."""
    check_raster_unchanged(stored.get("raster_sha256"), identity.get("raster_sha256"),
                           identity["config"]["terrain"]["raster"], f"out_dir {str(folder)!r}",
                           EvaluationError)


_MAX_LABEL_BYTES = 120  # of the file-name stem; trajectories add "_mission<k>.png"


def check_label(label: str) -> None:
    """Refuse a label that cannot name its files: not UTF-8 (undecodable bytes from the
    command line), or longer than a file name may be."""
    try:
        label.encode("utf-8")
    except UnicodeEncodeError:
        raise ValueError(f"planner label {label!r} is not valid UTF-8 text") from None
    if len(safe_name(label).encode("utf-8")) > _MAX_LABEL_BYTES:
        raise ValueError(f"planner label {label[:40]!r}... is {len(label)} characters long; "
                         f"labels name files, keep them to {_MAX_LABEL_BYTES}")


def shard_path(folder: Path, label: str, mission: int) -> Path:
    """Where the rows of one mission of one planner label are stored."""
    return folder / "shards" / safe_name(label) / f"mission_{mission:05d}.json"


def trajectory_path(folder: Path, label: str, mission: int) -> Path:
    """Where the recorded trajectory of one mission of one planner label is stored."""
    return folder / "trajectories" / f"{safe_name(label)}_mission{mission}.npz"


def _check_rows(rows: Any, label: str, mission: int, budget: int,
                seed: int) -> list[dict[str, Any]]:
    if not isinstance(rows, list) or len(rows) != budget + 1:
        raise ValueError(f"expected {budget + 1} rows")
    for step, row in enumerate(rows):
        if not isinstance(row, dict) or tuple(row) != RESULT_COLUMNS:
            raise ValueError(f"row {step} does not have the columns {RESULT_COLUMNS}")
        if row["planner"] != label or row["mission"] != mission or row["step"] != step:
            raise ValueError(f"row {step} belongs to another planner, mission or step")
        if row["seed"] != seed:
            raise ValueError(f"row {step} is of seed {row['seed']!r}, the folder's is {seed}")
        check_finite_row(row, f"row {step}")
    return rows


def check_finite_row(row: Mapping[str, Any], where: str) -> None:
    """ValueError naming ``where`` when a metric of ``row`` is not a finite number: its
    entropy, F1 or RMSE, or (after step 0, where both are NaN) its reward or planning time.
    A NaN would flow into every mean of the tables without a word."""
    columns = ("entropy", "f1", "rmse") + (("reward", "plan_ms") if row["step"] else ())
    for column in columns:
        value = row[column]
        if not is_real(value) or not math.isfinite(value):
            raise ValueError(f"{where} has {column} = {value!r}, not a finite number")


def stored_planners(folder: Path, exclude: Sequence[str], missions: int, budget: int,
                    identity: Mapping[str, Any]) -> dict[str, list[dict[str, Any]]]:
    """Rows of the planners stored in ``folder`` (other than ``exclude``) that hold every one
    of missions 0..missions-1, by label in folder order; incomplete ones are left out."""
    stored: dict[str, list[dict[str, Any]]] = {}
    shards = folder / "shards"
    if not shards.is_dir():
        return stored
    for spec_path in sorted(shards.glob("*/planner.json")):
        try:
            label = str(json.loads(spec_path.read_text(encoding="utf-8"))["label"])
        except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError):
            continue
        if label in exclude:
            continue
        try:
            stored[label] = [row for mission in range(missions) for row in read_shard(
                shard_path(folder, label, mission), label, mission, budget, identity)]
        except (OSError, UnicodeDecodeError, ValueError, KeyError):
            continue  # missing or damaged missions: not a complete planner of this run
    return stored


def read_shard(path: Path, label: str, mission: int, budget: int,
               identity: Mapping[str, Any]) -> list[dict[str, Any]]:
    """The checked rows of a shard (ValueError when it is not that mission's of the run
    ``identity`` (the folder's ``config.json``), or malformed)."""
    shard = json.loads(path.read_text(encoding="utf-8"))
    if not isinstance(shard, dict) or shard.get("format") != _FORMAT:
        raise ValueError("not a shard of this format")
    if shard.get("label") != label or shard.get("mission") != mission:
        raise ValueError("the shard belongs to another planner or mission")
    # Shards written before the run key existed are checked by the seed of their rows.
    if "run" in shard and shard["run"] != run_key(identity):
        raise ValueError("the shard belongs to another run (config, seed or namespace) than "
                         "the folder's config.json")
    rows = _check_rows(shard.get("rows"), label, mission, budget, identity["seed"])
    # Shards written before the checksum existed carry none.
    if "checksum" in shard and shard["checksum"] != shard_checksum(shard):
        raise ValueError("its checksum does not match its content (edited since it was "
                         "written)")
    return rows


def read_stored_missions(folder: Path, labels: Sequence[str], missions: int,
                         record: frozenset[int], budget: int, identity: Mapping[str, Any]
                         ) -> tuple[dict[tuple[str, int], list[dict[str, Any]]],
                                    dict[tuple[str, int], dict[str, Any]]]:
    """The missions 0..missions-1 of ``labels`` stored in ``folder`` (of the run
    ``identity``): their rows and, for the ``record`` missions, their trajectories, by
    ``(label, mission)``. A corrupt shard or an unreadable trajectory is warned about and left
    out (the mission flies again), as is a recorded mission stored without its trajectory."""
    done: dict[tuple[str, int], list[dict[str, Any]]] = {}
    trajectories: dict[tuple[str, int], dict[str, Any]] = {}
    for label in labels:
        for mission in range(missions):
            path = shard_path(folder, label, mission)
            if not path.exists():
                continue
            try:
                rows = read_shard(path, label, mission, budget, identity)
            except (OSError, UnicodeDecodeError, ValueError, KeyError) as err:
                # stacklevel 3: the warning points at evaluate (evaluation.py), two calls up.
                warnings.warn(f"shard {str(path)!r} is corrupt or of another run ({err}); "
                              f"flying mission {mission} of planner {label!r} again",
                              stacklevel=3)
                continue
            if mission in record:
                npz = trajectory_path(folder, label, mission)
                try:
                    trajectories[(label, mission)] = read_trajectory(npz)
                except FileNotFoundError:
                    continue  # stored without its trajectory: fly it again to record it
                except (OSError, ValueError, EOFError) as err:
                    warnings.warn(f"trajectory {str(npz)!r} is unreadable ({err}); flying "
                                  f"mission {mission} of planner {label!r} again",
                                  stacklevel=3)
                    continue
            done[(label, mission)] = rows
    return done, trajectories


def shard_checksum(shard: Mapping[str, Any]) -> str:
    """The sha256 of a shard's content (its run key included, its checksum left out), stored
    in it so that a shard edited by hand is recognised when it is read."""
    content = {key: value for key, value in shard.items() if key != "checksum"}
    return hashlib.sha256(json.dumps(content, sort_keys=True).encode("utf-8")).hexdigest()


def write_shard(folder: Path, spec: PlannerSpec, mission: int, result: dict[str, Any],
                identity: Mapping[str, Any]) -> None:
    """Store the rows (and the path) of one flown mission of the run ``identity`` (the
    folder's ``config.json``), atomically."""
    trajectory = result["trajectory"]
    shard = {
        "format": _FORMAT,
        "run": run_key(identity),
        "label": spec.effective_label,
        "planner": spec.name,
        "options": spec.options,
        "mission": mission,
        "rows": result["rows"],
        "trajectory": None if trajectory is None else {
            "positions": np.asarray(trajectory["positions"]).tolist(),
            "footprints": np.asarray(trajectory["footprints"]).tolist(),
        },
    }
    shard["checksum"] = shard_checksum(shard)
    write_json(shard_path(folder, spec.effective_label, mission), shard)


def write_trajectory(path: Path, trajectory: Mapping[str, Any]) -> None:
    """Store a recorded mission as a compressed npz, atomically."""
    arrays = {
        "ground_truth": np.asarray(trajectory["ground_truth"], dtype=bool),
        "final_prob": np.asarray(trajectory["final_prob"], dtype=np.float16),
        "positions": np.asarray(trajectory["positions"], dtype=np.float64),
        "footprints": np.asarray(trajectory["footprints"], dtype=np.int64),
        "area_size": np.float64(trajectory["area_size"]),
        "resolution": np.float64(trajectory["resolution"]),
    }
    atomic_write(path, lambda handle: np.savez_compressed(handle, **arrays))


def read_trajectory(path: Path) -> dict[str, Any]:
    """A recorded mission back from its npz.

    Raises:
        FileNotFoundError: no such file.
        ValueError: the file is not a regular file, is corrupt (truncated, not a zip, a
            damaged member), lacks arrays, or has a member over the ``zip_member_bytes``
            limit (checked before it is inflated).
    """
    check_regular_file(path, "trajectory")
    try:
        loaded = np.load(path, allow_pickle=False)
        if not isinstance(loaded, np.lib.npyio.NpzFile):
            raise ValueError("not an npz archive")
        with loaded as data:
            for info in data.zip.infolist():  # before any member is inflated
                check_limit("zip_member_bytes", info.file_size,
                            f"member {info.filename!r} of {str(path)!r}", estimate=False)
            missing = {"ground_truth", "final_prob", "positions", "footprints", "area_size",
                       "resolution"} - set(data.files)
            if missing:
                raise ValueError(f"missing arrays {sorted(missing)}")
            return {
                "ground_truth": data["ground_truth"].astype(bool),
                "final_prob": data["final_prob"],
                "positions": data["positions"],
                "footprints": data["footprints"],
                "area_size": float(data["area_size"]),
                "resolution": float(data["resolution"]),
            }
    except (zipfile.BadZipFile, zlib.error, EOFError, KeyError) as err:
        # numpy and zipfile raise these for a truncated or damaged archive
        raise ValueError(f"corrupt npz file ({type(err).__name__}: {err})") from None


def _format_cell(value: Any) -> str:
    if isinstance(value, bool):
        return str(int(value))
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating):
        value = float(value)
        if math.isnan(value):
            return ""
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    return str(value)


def write_results_csv(path: Path, rows: Sequence[Mapping[str, Any]]) -> None:
    """Write ``results.csv`` (the columns :data:`RESULT_COLUMNS`), atomically."""
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(RESULT_COLUMNS)
    for row in rows:
        writer.writerow([_format_cell(row[column]) for column in RESULT_COLUMNS])
    data = text.getvalue().encode("utf-8")
    atomic_write(path, lambda handle: handle.write(data))


def _parse_cell(column: str, text: str) -> Any:
    if column in _INT_COLUMNS:
        return int(text)
    if column in _FLOAT_COLUMNS:
        return math.nan if text == "" else float(text)
    return text


def read_results_csv(path: Path) -> list[dict[str, Any]]:
    """Read ``results.csv`` back, typed (EvaluationError naming the file on a bad one)."""
    try:
        handle = open(path, encoding="utf-8", newline="")
    except FileNotFoundError:
        raise EvaluationError(f"{str(path)!r} is missing") from None
    except OSError as err:
        raise EvaluationError(f"cannot read {str(path)!r}: {err.strerror}") from None
    rows = []
    with handle:
        reader = csv.reader(handle)
        try:
            header = next(reader, None)
            if header is None or tuple(header) != RESULT_COLUMNS:
                raise EvaluationError(f"{str(path)!r} is malformed: its header is {header}, "
                                      f"expected {list(RESULT_COLUMNS)}")
            for cells in reader:
                if len(cells) != len(RESULT_COLUMNS):
                    raise EvaluationError(f"{str(path)!r} is malformed: line {reader.line_num} "
                                          f"has {len(cells)} cells, expected "
                                          f"{len(RESULT_COLUMNS)}")
                try:
                    rows.append({c: _parse_cell(c, t) for c, t in zip(RESULT_COLUMNS, cells,
                                                                      strict=True)})
                except ValueError as err:
                    raise EvaluationError(f"{str(path)!r} is malformed: line "
                                          f"{reader.line_num}: {err}") from None
        except (csv.Error, UnicodeDecodeError) as err:
            raise EvaluationError(f"{str(path)!r} is malformed: {err}") from None
    return rows


