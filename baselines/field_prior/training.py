"""Train a field prior (``ipp-train prior``): supervised learning on simulator ground truth.

The prior (:mod:`ipp_toolkit.belief.field_prior`) predicts how likely each 2 m block is to be
interesting from a UAV's local map. Labels are free in simulation: the ground truth's share
of interesting cells per block. The states it learns from are those a planner that uses it
visits (DAgger-style rounds):

1. round 0: fly ``ig_spatial`` (the Gaussian prior) on training missions; record, at every
   step, the input planes of up to ``agents_per_step`` UAVs' local maps and the mission's
   labels; fly the same number of validation missions alike;
2. train the network on everything recorded so far (cross-entropy against the block shares,
   weighted by the share of each block inside the area), ``epochs`` passes;
3. round r > 0: fly ``ig_learned`` with the best prior so far, record, train again; with
   ``cleanup`` it flies ``ig_learned``'s default objective (the prior plus its clean-up of
   likely false positives in the last steps), otherwise the prior's objective alone.

Missions cycle over the team settings (``team_sizes`` x ``comm_ranges``) on the ``terrain``
(the mixture of every family by default), so 2-, 4- and 8-UAV maps are equally many.
Selection: ``best.pt`` is the network with the lowest cross-entropy on the validation states
recorded so far (re-scored when a round adds states). The Gaussian smoothing's cross-entropy
on the same states is printed beside it, as the reference to beat.

Files in ``--out``: ``config.json`` (the command, the settings and the sha256 of a raster
file the terrain reads, checked on ``--resume``), ``data/`` (the states of
every finished round), ``progress.csv`` (one row per epoch), ``last.pt`` (to ``--resume``
after an interruption: the network, optimiser, round and epoch) and ``best.pt`` (the prior,
flown as ``ig_learned=OUT/best.pt``, its record naming the command and validation score).
"""

from __future__ import annotations

import argparse
import csv
import itertools
import json
import math
import shlex
import sys
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np

from ipp_toolkit.belief.field_prior import (
    FieldPrior,
    PriorNetConfig,
    block_average,
    block_cells,
    block_labels,
    build_network,
    prior_inputs,
)
from ipp_toolkit.belief.interest import interest_smoother
from ipp_toolkit.config.field_types import check_integers, is_integer
from ipp_toolkit.config.files import config_to_dict
from ipp_toolkit.config.limits import check_mission
from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.config.settings import build_env_config, setting_line
from ipp_toolkit.io import CheckpointError, atomic_write, load_torch, save_torch, write_json
from ipp_toolkit.planning import Planner, planner_views
from ipp_toolkit.runs.cli_flags import comm_range_list, int_list, positive_float, positive_int
from ipp_toolkit.runs.cli_help import HelpFormatter, add_version
from ipp_toolkit.runs.progress import continue_hint, progress_bar, run_reporting
from ipp_toolkit.runs.result_store import check_raster_unchanged, raster_digest
from ipp_toolkit.runs.run_folder import LOCK_NAME, RECORD_NAME, claim
from ipp_toolkit.sim.driver import fly_missions, start_missions
from ipp_toolkit.world.seeding import planner_seed
from ipp_toolkit.world.terrain import check_raster_file

from ..heuristics.spatial_gain import SpatialGainPlanner
from .planner import LearnedPriorPlanner

__all__ = ["PriorTrainingConfig", "check_inputs", "collect_states", "main", "train_prior"]

TRAINING_FORMAT = "ipp-toolkit/field-prior-training"
PRIOR_COMMAND = "ipp-train prior"
PROGRESS_COLUMNS = ("round", "epoch", "train_bce", "validation_bce", "smoothing_bce", "states",
                    "seconds")
# The counts of PriorTrainingConfig that must be >= 1 (the config checks them; the command's
# flags refuse a bad one before that).
POSITIVE_FIELDS = ("rounds", "missions", "validation_missions", "agents_per_step", "epochs",
                   "batch_size", "width")


@dataclass(frozen=True)
class PriorTrainingConfig:
    """Every setting of a prior's training run (the mission config is separate).

    Attributes:
        rounds: data-collection rounds (round 0 flies ``ig_spatial``, later ones the prior).
        missions: training missions flown per round.
        validation_missions: validation missions flown per round.
        team_sizes, comm_ranges: the team settings missions cycle over.
        agents_per_step: UAVs whose maps are recorded per step (chosen at random).
        epochs: passes over the recorded states after each round.
        batch_size, learning_rate: Adam's minibatch and step size.
        width: the network's channels (:class:`PriorNetConfig`).
        seed: run seed (missions, agent choice, shuffling, initial weights).
        cleanup: rounds r > 0 fly ``ig_learned`` with its default clean-up, so the prior
            learns on the maps the deployed planner makes (False: the prior's objective
            alone, as the shipped prior was trained).
    """

    rounds: int = 3
    missions: int = 240
    validation_missions: int = 48
    team_sizes: tuple[int, ...] = (2, 4, 8)
    comm_ranges: tuple[float, ...] = (0.0, 25.0, math.inf)
    agents_per_step: int = 2
    epochs: int = 10
    batch_size: int = 64
    learning_rate: float = 2e-3
    width: int = 8
    seed: int = 0
    cleanup: bool = False

    def __post_init__(self) -> None:
        check_integers(self, dict.fromkeys(POSITIVE_FIELDS, 1),
                       "{name} must be a positive integer, got {value!r}", numpy=False)
        check_integers(self, {"seed": 0}, "{name} must be a non-negative integer, got {value!r}",
                       numpy=False)
        if not isinstance(self.cleanup, bool):
            raise ValueError(f"cleanup must be True or False, got {self.cleanup!r}")
        if not (math.isfinite(self.learning_rate) and self.learning_rate > 0):
            raise ValueError(f"learning_rate must be a positive number, "
                             f"got {self.learning_rate!r}")
        if not self.team_sizes or any(not is_integer(n, 1, numpy=False)
                                      for n in self.team_sizes):
            raise ValueError(f"team_sizes must be positive integers, got {self.team_sizes!r}")
        if not self.comm_ranges or any(not c >= 0 for c in self.comm_ranges):
            raise ValueError(f"comm_ranges must be non-negative metres, "
                             f"got {self.comm_ranges!r}")
        PriorNetConfig(self.width)

    def to_json(self) -> dict[str, Any]:
        """JSON-safe fields (inf ranges as the string ``"inf"``)."""
        values = asdict(self)
        values["team_sizes"] = list(self.team_sizes)
        values["comm_ranges"] = [c if math.isfinite(c) else "inf" for c in self.comm_ranges]
        return values


# -- Recording states ------------------------------------------------------------------------

def team_settings(config: PriorTrainingConfig) -> list[tuple[int, float]]:
    """(team size, range) of every setting, in the order missions cycle over them."""
    return list(itertools.product(config.team_sizes, config.comm_ranges))


def collect_states(env_config: EnvConfig, config: PriorTrainingConfig, planner: Planner,
                   namespace: str, first_mission: int, n_missions: int,
                   progress: bool = True) -> dict[str, np.ndarray]:
    """Fly missions with ``planner`` and record the prior's inputs and labels at every step.

    Mission ``m`` flies team setting ``m mod len(settings)``; at each step (and at the start)
    up to ``agents_per_step`` flying UAVs, drawn from the stream of (seed, m), give one state.

    Returns:
        ``inputs`` (S, 5, h, w) float16, ``mission`` (S,) int32 (an index into ``labels``),
        ``labels`` (M, h, w) float16 and ``smoothing`` (S, h, w) float16, the Gaussian
        prior of ``ig_spatial`` on the same blocks (the reference).
    """
    settings = team_settings(config)
    resolution = env_config.world.resolution
    smoother = interest_smoother(env_config.world.map_cells, resolution, 5.0)
    inputs: list[np.ndarray] = []
    smoothing: list[np.ndarray] = []
    owners: list[np.ndarray] = []
    labels: list[np.ndarray] = []
    bar = progress_bar(n_missions, f"prior: {namespace} states", "missions",
                       disable=not progress)
    for m in range(first_mission, first_mission + n_missions):
        agents, comm = settings[m % len(settings)]
        mission_config = env_config.replace(team={"n_agents": agents, "comm_range": comm})
        state, = start_missions(mission_config, config.seed, m, 1, namespace)
        planner.reset(mission_config, seed=planner_seed(config.seed, m, namespace))
        rng = np.random.default_rng([config.seed, m, 7])
        labels.append(block_labels(state.ground_truth, resolution).astype(np.float16))

        def record(views: list, state: Any = state, rng: np.random.Generator = rng) -> None:
            flying = np.flatnonzero(state.alive)
            chosen = rng.choice(flying, size=min(config.agents_per_step, len(flying)),
                                replace=False)
            prob = np.stack([views[k].local_prob for k in sorted(chosen)])
            inputs.append(prior_inputs(prob, resolution).astype(np.float16))
            # ig_spatial's Gaussian prior averaged onto the prior's blocks: the reference
            smooth = block_average(smoother(prob), block_cells(resolution, prob.shape[1]))
            smoothing.append(smooth.astype(np.float16))
            owners.append(np.full(len(prob), len(labels) - 1, dtype=np.int32))

        def policy(states: list) -> list[np.ndarray]:
            views = planner_views(states[0], planner)
            record(views)
            return [planner.act(views)]

        fly_missions([state], policy)
        record(planner_views(state, planner))
        bar.update(1)
    bar.close()
    return {"inputs": np.concatenate(inputs), "mission": np.concatenate(owners),
            "labels": np.stack(labels), "smoothing": np.concatenate(smoothing)}


def merge(parts: list[dict[str, np.ndarray]]) -> dict[str, np.ndarray]:
    """One data set of several rounds' recordings (mission indices renumbered)."""
    offset, owners = 0, []
    for part in parts:
        owners.append(part["mission"] + offset)
        offset += len(part["labels"])
    return {"inputs": np.concatenate([p["inputs"] for p in parts]),
            "mission": np.concatenate(owners),
            "labels": np.concatenate([p["labels"] for p in parts]),
            "smoothing": np.concatenate([p["smoothing"] for p in parts])}


# -- Learning --------------------------------------------------------------------------------

def weighted_bce(logits: Any, labels: Any, inside: Any) -> Any:
    """Mean cross-entropy (nats) of block logits against block shares, weighted by the share
    of each block inside the area (padding blocks count 0)."""
    from torch.nn import functional as F

    loss = F.binary_cross_entropy_with_logits(logits, labels, reduction="none")
    return (loss * inside).sum() / inside.sum()


def _batch(data: dict[str, np.ndarray], index: np.ndarray) -> tuple[Any, Any, Any]:
    import torch

    planes = torch.from_numpy(data["inputs"][index].astype(np.float32))
    labels = torch.from_numpy(data["labels"][data["mission"][index]].astype(np.float32))
    return planes, labels, planes[:, -1]


def evaluate_bce(network: Any, data: dict[str, np.ndarray], batch_size: int = 256
                 ) -> tuple[float, float]:
    """(network's, Gaussian smoothing's) weighted cross-entropy on ``data``."""
    import torch

    total = reference = weight = 0.0
    with torch.inference_mode():
        for start in range(0, len(data["mission"]), batch_size):
            index = np.arange(start, min(start + batch_size, len(data["mission"])))
            planes, labels, inside = _batch(data, index)
            logits = network(planes)
            smooth = torch.from_numpy(data["smoothing"][index].astype(np.float32))
            smooth_logits = torch.logit(smooth.clamp(1e-4, 1 - 1e-4))
            n = float(inside.sum())
            total += float(weighted_bce(logits, labels, inside)) * n
            reference += float(weighted_bce(smooth_logits, labels, inside)) * n
            weight += n
    return total / weight, reference / weight


def train_epoch(network: Any, optimiser: Any, data: dict[str, np.ndarray], batch_size: int,
                rng: np.random.Generator) -> float:
    """One shuffled pass of Adam over ``data``; returns the mean training cross-entropy."""
    network.train()
    order = rng.permutation(len(data["mission"]))
    total = 0.0
    for start in range(0, len(order), batch_size):
        planes, labels, inside = _batch(data, order[start:start + batch_size])
        loss = weighted_bce(network(planes), labels, inside)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        total += float(loss.detach()) * len(planes)
    network.eval()
    return total / len(order)


# -- The run ---------------------------------------------------------------------------------

def train_prior(config: PriorTrainingConfig, env_config: EnvConfig, out: str | Path,
                resume: bool = False, progress: bool = True, command: str = "ipp-train prior",
                announce: str | None = None) -> Path:
    """Run (or resume) a prior's training in ``out``; returns the path of ``best.pt``.

    Raises:
        ValueError: ``out`` holds another run, or a run while ``resume`` is False, or nothing
            to resume; a mission over a limit (:func:`check_inputs`); a raster file replaced
            since the run began (named with both sha256 digests).
        CheckpointError: a damaged ``last.pt``.
    """
    import torch

    torch.set_num_threads(1)
    out = Path(out)
    check_inputs(config, env_config)
    record = {"command": command, "training": config.to_json(),
              "env": config_to_dict(env_config)}
    digest = raster_digest(env_config)
    if digest is not None:
        record["raster_sha256"] = digest
    with claim(out, PRIOR_COMMAND) as folder:
        state = _open_run(out, record, resume, folder.found - {LOCK_NAME, RECORD_NAME})
        if announce:
            print(announce, file=sys.stderr)
        return _train(config, env_config, out, record, state, progress)


def check_inputs(config: PriorTrainingConfig, env_config: EnvConfig) -> None:
    """Refuse (ValueError naming the value) the missions of any team setting before a run's
    folder is claimed or anything written: a size over its limit by its estimate (at
    r_M = 1e-300 m the smoother's tables were built for ever), a raster file that cannot be
    read or is over a limit by its check (it was refused only at the first mission, leaving
    a folder no rerun would take)."""
    for agents, comm in team_settings(config):
        check_mission(env_config.replace(team={"n_agents": agents, "comm_range": comm}))
    check_raster_file(env_config.terrain, env_config.world)


def _train(config: PriorTrainingConfig, env_config: EnvConfig, out: Path,
           record: dict[str, Any], state: dict[str, Any] | None, progress: bool) -> Path:
    """The rounds of :func:`train_prior` from ``state`` (None: a new run) to the end."""
    import torch

    torch.manual_seed(config.seed)
    network = build_network(PriorNetConfig(config.width))
    optimiser = torch.optim.Adam(network.parameters(), lr=config.learning_rate)
    best_loss = math.inf
    if state is not None:
        network.load_state_dict(state["network"])
        optimiser.load_state_dict(state["optimiser"])
        best_loss = float(state["best_loss"])
    done_round, done_epoch = (int(state["round"]), int(state["epoch"])) if state else (0, 0)
    train_parts, validation_parts = _load_rounds(out, done_round)
    started = time.perf_counter()
    for round_ in range(done_round, config.rounds):
        if len(train_parts) <= round_:
            planner = _round_planner(out, round_, config.cleanup)
            for namespace, parts, count in (("train", train_parts, config.missions),
                                            ("validation", validation_parts,
                                             config.validation_missions)):
                part = collect_states(env_config, config, planner, namespace, round_ * count,
                                      count, progress)
                (out / "data").mkdir(exist_ok=True)
                np.savez(_data_path(out, namespace, round_, temporary=True), **part)
                _data_path(out, namespace, round_, temporary=True).replace(
                    _data_path(out, namespace, round_))
                parts.append(part)
        train_data, validation_data = merge(train_parts), merge(validation_parts)
        if done_epoch == 0 and (out / "best.pt").is_file():  # new states: score best again
            best_loss = evaluate_bce(FieldPrior.load(out / "best.pt").network,
                                     validation_data)[0]
        for epoch in range(done_epoch, config.epochs):
            rng = np.random.default_rng([config.seed, round_, epoch, 11])
            train_loss = train_epoch(network, optimiser, train_data, config.batch_size, rng)
            loss, reference = evaluate_bce(network, validation_data)
            if loss < best_loss:
                best_loss = loss
                FieldPrior(network, PriorNetConfig(config.width), {
                    **record, "round": round_, "epoch": epoch + 1,
                    "validation_bce": loss, "smoothing_bce": reference}).save(out / "best.pt")
            _append_progress(out, [round_, epoch + 1, train_loss, loss, reference,
                                   len(train_data["mission"]),
                                   time.perf_counter() - started])
            print(f"prior: round {round_} epoch {epoch + 1}/{config.epochs}: validation "
                  f"cross-entropy {loss:.4f} (Gaussian smoothing {reference:.4f}, best "
                  f"{best_loss:.4f})", file=sys.stderr)
            save_torch(out / "last.pt", {"network": network.state_dict(),
                                         "optimiser": optimiser.state_dict(),
                                         "round": round_, "epoch": epoch + 1,
                                         "best_loss": best_loss}, TRAINING_FORMAT)
        done_epoch = 0
        save_torch(out / "last.pt", {"network": network.state_dict(),
                                     "optimiser": optimiser.state_dict(),
                                     "round": round_ + 1, "epoch": 0,
                                     "best_loss": best_loss}, TRAINING_FORMAT)
    return out / "best.pt"


def _round_planner(out: Path, round_: int, cleanup: bool) -> Planner:
    """``ig_spatial`` in round 0, ``ig_learned`` with the best prior so far after it: its
    default objective with ``cleanup``, else the prior's objective alone."""
    if round_ == 0 or not (out / "best.pt").is_file():
        return SpatialGainPlanner()
    if cleanup:
        return LearnedPriorPlanner(out / "best.pt")
    return LearnedPriorPlanner(out / "best.pt", false_positive_weight=0.0)


def _data_path(out: Path, namespace: str, round_: int, temporary: bool = False) -> Path:
    name = f"{namespace}_round{round_}.npz"
    return out / "data" / (f".{name}.tmp.npz" if temporary else name)


def _load_rounds(out: Path, rounds: int) -> tuple[list[dict], list[dict]]:
    """The recorded states of every round a run has, up to the first missing one."""
    train: list[dict] = []
    validation: list[dict] = []
    for round_ in itertools.count():
        paths = [_data_path(out, "train", round_), _data_path(out, "validation", round_)]
        if not all(p.is_file() for p in paths):
            if round_ < rounds:
                raise CheckpointError(f"run {str(out)!r} lost its recorded states of round "
                                      f"{round_} ({paths[0].name}); start a new run")
            break
        for path, parts in zip(paths, (train, validation), strict=True):
            try:
                with np.load(path, allow_pickle=False) as data:
                    parts.append({key: data[key] for key in
                                  ("inputs", "mission", "labels", "smoothing")})
            except (OSError, ValueError, KeyError) as error:
                raise CheckpointError(f"recorded states {str(path)!r} are damaged "
                                      f"({error}); start a new run") from None
    return train, validation


#: What a prior's training writes before its first checkpoint (``last.pt``).
_BEFORE_FIRST_CHECKPOINT = frozenset({"config.json", "progress.csv", "data"})


def _stopped_before_checkpoint(out: Path, found: frozenset[str]) -> bool:
    """Whether ``out`` (holding ``found``) holds only a prior's training that stopped before
    its first checkpoint: nothing to resume and nothing trained, so a new run starts there
    (as the other trainers' do) instead of refusing both a new run and ``--resume``."""
    if "config.json" not in found or not found <= _BEFORE_FIRST_CHECKPOINT:
        return False
    try:
        stored = json.loads((out / "config.json").read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return False
    return isinstance(stored, dict) and stored.get("kind") == PRIOR_COMMAND


def _open_run(out: Path, record: dict[str, Any], resume: bool, found: frozenset[str]
              ) -> dict[str, Any] | None:
    """Check ``out`` (holding the files ``found``) and write its ``config.json``; the
    ``last.pt`` state when resuming."""
    config_path = out / "config.json"
    if resume:
        if _stopped_before_checkpoint(out, found):
            raise ValueError(f"nothing to resume: {str(out / 'last.pt')!r} does not exist (the "
                             "run stopped before its first checkpoint); drop --resume to start "
                             "it again")
        if not config_path.is_file() or not (out / "last.pt").is_file():
            raise ValueError(f"nothing to resume in {str(out)!r} (no config.json and last.pt "
                             "of a prior's training)")
        try:
            stored = json.loads(config_path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError) as err:
            raise ValueError(f"{str(config_path)!r} is unreadable ({err}); it should record "
                             "the prior's training settings") from None
        if not isinstance(stored, dict):
            raise ValueError(f"{str(config_path)!r} holds a JSON {type(stored).__name__}, not "
                             "the record of a prior's training; it cannot be resumed")
        if stored.get("kind") != PRIOR_COMMAND:
            raise ValueError(f"{str(out)!r} holds another command's run, not a prior's")
        # A run recorded before a setting existed ran it at its default.
        if isinstance(stored.get("training"), dict):
            stored["training"] = {**PriorTrainingConfig().to_json(), **stored["training"]}
        for key in ("training", "env"):
            if stored.get(key) != json.loads(json.dumps(record[key])):
                raise ValueError(f"--resume: the settings differ from the run in {str(out)!r} "
                                 f"(section {key!r}); resume with the run's own flags")
        check_raster_unchanged(stored.get("raster_sha256"), record.get("raster_sha256"),
                               record["env"]["terrain"]["raster"], f"run folder {str(out)!r}")
        return load_torch(out / "last.pt", TRAINING_FORMAT)
    if found and not _stopped_before_checkpoint(out, found):
        raise ValueError(f"--out {str(out)!r} exists and is not an empty folder; use --resume "
                         "to continue the run in it, or another folder")
    write_json(config_path, {"kind": PRIOR_COMMAND, **record})
    with open(out / "progress.csv", "w", newline="", encoding="utf-8") as handle:
        csv.writer(handle).writerow(PROGRESS_COLUMNS)
    return None


def _append_progress(out: Path, row: list[float]) -> None:
    path = out / "progress.csv"
    text = path.read_text(encoding="utf-8")
    line = ",".join(f"{v:.6g}" if isinstance(v, float) else str(v) for v in row) + "\n"
    atomic_write(path, lambda handle: handle.write((text + line).encode("utf-8")))


# -- Command line ----------------------------------------------------------------------------

FLAG_HELP = {
    "rounds": "data-collection rounds (round 0 flies ig_spatial, later ones ig_learned)",
    "missions": "training missions flown per round",
    "validation_missions": "validation missions flown per round",
    "agents_per_step": "UAVs whose local maps are recorded per step",
    "epochs": "passes over the recorded states after each round",
    "batch_size": "minibatch of states",
    "learning_rate": "Adam's step size",
    "width": "channels of the network's first level",
    "seed": "run seed (missions, recorded UAVs, shuffling, initial weights)",
}


def _flag_type(name: str) -> Callable[[str], Any]:
    """The value type of a config field's flag: a bad value (``--missions 0``) is refused by
    argparse with exit code 2, naming the flag, like the other commands' counts."""
    if name in POSITIVE_FIELDS:
        return positive_int(name)
    if name == "learning_rate":
        return positive_float
    return int


def _parser() -> argparse.ArgumentParser:
    defaults = PriorTrainingConfig()
    parser = argparse.ArgumentParser(
        prog="ipp-train prior",
        allow_abbrev=False,  # a prefix of another flag must not be taken for it
        description="Train a field prior (P(interesting | local map)) on simulator ground "
                    "truth, in DAgger-style rounds; fly it as ig_learned=OUT/best.pt.",
        formatter_class=HelpFormatter)
    add_version(parser)
    parser.add_argument("--out", required=True, help="run folder")
    parser.add_argument("--resume", action="store_true", help="continue the run in --out")
    for field in fields(PriorTrainingConfig):
        if field.name in FLAG_HELP:
            parser.add_argument(f"--{field.name.replace('_', '-')}", type=_flag_type(field.name),
                                default=field.default, help=FLAG_HELP[field.name])
    parser.add_argument("--team-sizes", type=int_list("--team-sizes"),
                        default=",".join(map(str, defaults.team_sizes)), metavar="N,N,...",
                        help="team sizes missions cycle over")
    parser.add_argument("--comm-ranges", type=comm_range_list("--comm-ranges"),
                        default="0,25,inf", metavar="D,D,...",
                        help="communication ranges (metres, inf) missions cycle over "
                             "(default: 0,25,inf)")
    parser.add_argument("--cleanup", action="store_true",
                        help="later rounds fly ig_learned with its clean-up of likely false "
                             "positives in the last steps (default: the prior's objective "
                             "alone)")
    parser.add_argument("--config", help="YAML mission config (world, terrain, sensor, ...; "
                        "default: none, the paper's mission)")
    parser.add_argument("--terrain", default=None, metavar="KIND",
                        help="terrain of the missions (default: mixture)")
    parser.add_argument("--resolution", type=positive_float, default=None,
                        help="map resolution in metres (default: 0.5)")
    parser.add_argument("--no-progress", action="store_true", help="no progress lines")
    return parser


def main(argv: list[str] | None = None) -> int:
    """``ipp-train prior [options]``; 0 on success, 2 on bad input, 130 when interrupted."""
    argv = list(sys.argv[1:] if argv is None else argv)
    args = _parser().parse_args(argv)

    def work() -> int:
        values = {f.name: getattr(args, f.name) for f in fields(PriorTrainingConfig)
                  if f.name not in ("team_sizes", "comm_ranges")}
        config = PriorTrainingConfig(
            **values, team_sizes=tuple(args.team_sizes), comm_ranges=tuple(args.comm_ranges))
        env_config = build_env_config(
            args.config, terrain=args.terrain, resolution=args.resolution,
            defaults={"world": {"resolution": 0.5}, "terrain": {"kind": "mixture"}})
        path = train_prior(config, env_config, args.out, resume=args.resume,
                           progress=not args.no_progress,
                           command=shlex.join(["ipp-train", "prior", *argv]),
                           announce=setting_line(env_config, args.config))
        print(f"saved {path}")
        return 0

    return run_reporting("ipp-train prior", work, continue_hint(
        args.out, "last.pt", f"continue with --resume --out {args.out}"))


if __name__ == "__main__":
    sys.exit(main())
