"""Console scripts of the toolkit.

``ipp-simulate``: fly one mission of the shared simulator with random valid actions, print
the metrics after every step and write the per-step metrics (CSV) and the final frame (PNG).

``ipp-compare``: evaluate planners on the test missions of one configuration, print the
Markdown table (Table I style, with a paired column per reference planner: ``ig`` and
``ig_spatial`` by default) and the planning time per step, and write the tables, the figures
and the raw results (see :func:`compare_main`).

``ipp-train coma|ppo|sb3``: train a learned planner (see :func:`train_main`); ``sb3 --algo
ALGO`` trains any supported SB3 algorithm (``ppo`` is its PPO case).
"""

from __future__ import annotations

import argparse
import csv
import gc
import hashlib
import io
import json
import math
import os
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.config.settings import (
    build_env_config,
    comm_label,
    named_terrain_kinds,
    safe_name,
    setting_line,
)
from ipp_toolkit.env import IPPEnv
from ipp_toolkit.io import atomic_write
from ipp_toolkit.runs.cli_flags import (
    FORCE_HELP,
    add_compute_flags,
    add_force_flag,
    add_progress_flag,
    comm_range,
    finite_float,
    positive_float,
    positive_int,
)
from ipp_toolkit.runs.cli_help import HelpFormatter, add_version, version_line
from ipp_toolkit.runs.progress import sigterm_as_interrupt
from ipp_toolkit.runs.ray_backend import RayUnavailableError, check_backend_flags
from ipp_toolkit.runs.run_folder import allow_foreign_files, check_out_path, claim

from .compare import DEFAULT_PLANNERS, interrupted


def _simulate_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ipp-simulate",
        allow_abbrev=False,  # a prefix of another flag must not be taken for it
        description="Fly one mission with random valid actions and report its metrics. The "
                    "reward column is the team reward of each step, alpha (H_t - H_t+1) / H_t "
                    "+ beta, where H is the weighted entropy of the global map (cells believed "
                    "interesting weigh 1, the others 0) and beta a time penalty (alpha 22, "
                    "beta -0.5 by default): a step that cuts H by less than -beta / alpha "
                    "(2.3 %) is rewarded below 0 even while the entropy falls. The entropy "
                    "column is the mean entropy over the truly interesting cells.",
        formatter_class=HelpFormatter,
    )
    add_version(parser)
    parser.add_argument("--config", type=Path,
                        help="YAML config (default: none, the paper's configuration)")
    parser.add_argument("--agents", type=positive_int("agents"),
                        help="team size (overrides the config; default: the config's, else 4)")
    parser.add_argument("--comm", type=comm_range,
                        help="communication range in metres or 'inf' (overrides the config; "
                             "default: the config's, else 25)")
    parser.add_argument("--resolution", type=positive_float,
                        help="map resolution r_M in metres (default: the config's, else 0.1)")
    parser.add_argument("--seed", type=int, default=0, metavar="SEED", help="run seed")
    parser.add_argument("--mission", type=int, default=0, help="mission index within the run")
    parser.add_argument("--out", default="results/simulate",
                        help="folder for metrics.csv and final.png")
    add_force_flag(parser)
    return parser


def simulate_main(argv: list[str] | None = None) -> int:
    """Entry point of ``ipp-simulate``; returns the exit code (2 for bad input)."""
    parser = _simulate_parser()
    args = parser.parse_args(argv)
    try:
        args.out = check_out_path(args.out)  # before Path("") turns into the current folder
        targets = (args.out / "final.png", args.out / "metrics.csv")
        config = build_env_config(args.config, agents=args.agents, comm=args.comm,
                                  resolution=args.resolution)
        for target in targets:
            if target.exists() and not target.is_file():
                raise ValueError(f"{str(target)!r} exists and is not a file; it would be "
                                 "written after the mission")
        env = IPPEnv(config, render_mode="rgb_array", namespace="test", observation="dict")
        observations, infos = env.reset(seed=args.seed, options={"mission": args.mission})
        with allow_foreign_files(args.force), claim(args.out, "ipp-simulate"):
            # Held from the mission to the files: a run writing the folder is not mixed in.
            return _simulate(env, observations, infos, args.seed, targets)
    except ValueError as err:
        print(f"ipp-simulate: error: {err}", file=sys.stderr)
        return 2
    except OSError as err:
        print(f"ipp-simulate: error: cannot write into {str(args.out)!r}: {err.strerror}",
              file=sys.stderr)
        return 2


def reward_lines(config: EnvConfig) -> list[str]:
    """What ``ipp-simulate``'s columns are, with ``config``'s reward weights: a random
    flight's rewards are mostly negative while its entropy falls, which needs saying."""
    reward = config.reward
    sign = "-" if reward.beta < 0 else "+"
    lines = [f"reward = {reward.alpha:g} (H_t - H_t+1) / H_t {sign} {abs(reward.beta):g} per step: "
             "H is the weighted entropy of the global map",
             f"  (cells believed interesting, p > 0.5, weigh {reward.weight_interesting:g}, the "
             f"others {reward.weight_uninteresting:g})"]
    if reward.beta < 0:
        lines[-1] += f", {reward.beta:g} a time penalty, so a step"
        lines.append(f"  that cuts H by less than {-reward.beta / reward.alpha:.1%} is "
                     "rewarded below 0 even while the entropy falls")
    lines.append("entropy: mean entropy in bits over the truly interesting cells (1 at the "
                 "prior)")
    return lines


def _simulate(env: IPPEnv, observations: dict, infos: dict, seed: int,
              targets: tuple[Path, Path]) -> int:
    """Fly ``env``'s mission with random valid actions, print and write its metrics."""
    rng = np.random.default_rng(seed)
    metric_keys = ("entropy", "f1", "rmse")
    first = next(iter(infos.values()))
    rows = [{"step": 0, "reward": "", **{key: first[key] for key in metric_keys}}]
    config = env.config
    print(f"{config.team.n_agents} UAVs, D = {config.team.comm_range:g} m, "
          f"{config.world.map_cells}^2 map, budget {config.team.budget} steps")
    print("\n".join(reward_lines(config)))
    print(f"{'step':>4} {'reward':>8} {'entropy':>8} {'f1':>6} {'rmse':>6}")
    print(f"{0:>4} {'':>8} {rows[0]['entropy']:8.3f} {rows[0]['f1']:6.3f} {rows[0]['rmse']:6.3f}")
    while env.agents:
        actions = {agent: int(rng.choice(np.flatnonzero(observations[agent]["action_mask"])))
                   for agent in env.agents}
        # The team's reward is any flying UAV's: a failed one (kept or gone) gets none.
        flying = [agent for agent in env.agents
                  if env.mission.alive[env.possible_agents.index(agent)]]
        observations, rewards, _, _, infos = env.step(actions)
        metrics = {key: next(iter(infos.values()))[key] for key in metric_keys}
        reward = rewards[flying[0]] if flying else 0.0
        rows.append({"step": env.mission.step, "reward": reward, **metrics})
        print(f"{env.mission.step:>4} {reward:8.3f} {metrics['entropy']:8.3f} "
              f"{metrics['f1']:6.3f} {metrics['rmse']:6.3f}")
    from ipp_toolkit.sim.rendering import save_png

    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=["step", "reward", "entropy", "f1", "rmse"],
                            lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    data = text.getvalue().encode("utf-8")
    save_png(env.render(), targets[0])
    atomic_write(targets[1], lambda handle: handle.write(data))
    print(f"wrote {targets[1]} and {targets[0]}")
    return 0


def default_compare_out(env_config: EnvConfig, seed: int, namespace: str,
                        planners: str) -> str:
    """``ipp-compare``'s folder when ``--out`` is not given.

    ``results/compare-aN-dD`` for the paper's configuration of N UAVs at range D (seed 0,
    planners without weight files of their own): rerunning it reuses the stored missions, and
    other planners flown into it join them. Any other run key (config, seed, the weight files
    named in ``--planners``) adds the settings that differ and a short hash of the key, e.g.
    ``results/compare-a4-d25-r0.5-b20-1a2b3c4d``: a folder refuses missions of another
    configuration, so two configurations must never share a default one.
    """
    team = env_config.team
    stem = "validate" if namespace == "validation" else "compare"
    name = f"results/{stem}-a{team.n_agents}-d{comm_label(team.comm_range)}"
    reference = build_env_config(None, agents=team.n_agents, comm=team.comm_range)
    key = _run_key(env_config, seed, namespace, planners)
    if key == _run_key(reference, 0, namespace, "default"):
        return name
    digest = hashlib.sha256(json.dumps(key, sort_keys=True).encode("utf-8")).hexdigest()
    return "-".join([name, *_differing_settings(env_config, reference, seed), digest[:8]])


def _run_key(env_config: EnvConfig, seed: int, namespace: str, planners: str) -> dict:
    """What decides whether a folder may take a run's missions (the folder's identity but
    the toolkit's version, whose change only warns), with each planner that names options
    (a weight file: its sha256 too, so retrained weights get their own folder)."""
    from ipp_toolkit.runs.result_store import folder_identity

    from .compare import _requested_specs

    identity = folder_identity(env_config, seed, namespace)
    identity.pop("version", None)
    weights = {}
    for spec in _requested_specs(planners):
        if spec.options:
            files = {key: _file_sha256(Path(value)) for key, value in spec.options.items()
                     if isinstance(value, str) and Path(value).is_file()}
            weights[spec.effective_label] = {"name": spec.name, "options": spec.options,
                                             "files": files}
    return {"run": identity, "planners": weights}


def _file_sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with path.open("rb") as file:
        for block in iter(lambda: file.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _differing_settings(env_config: EnvConfig, reference: EnvConfig, seed: int) -> list[str]:
    """The flag-level settings of ``env_config`` that differ from ``reference`` (the paper's
    configuration of the team) and a seed other than 0, as words of a folder name."""
    parts = []
    terrain = env_config.terrain
    if (terrain.kind, terrain.raster) != (reference.terrain.kind, reference.terrain.raster):
        raster = terrain.kind == "raster" and isinstance(terrain.raster, str)
        parts.append(safe_name(Path(terrain.raster).stem) if raster else terrain.kind)
    world, base = env_config.world, reference.world
    for prefix, mine, theirs in (("r", world.resolution, base.resolution),
                                 ("b", env_config.team.budget, reference.team.budget),
                                 ("area", world.area_size, base.area_size),
                                 ("g", world.grid_spacing, base.grid_spacing)):
        if mine != theirs:
            parts.append(f"{prefix}{mine:g}")
    if seed != 0:
        parts.append(f"seed{seed}")
    return parts


def _add_world_flags(parser: argparse.ArgumentParser) -> None:
    """``ipp-compare``'s flags of the mission's world and length (each over the config's)."""
    parser.add_argument("--resolution", type=positive_float, default=None,
                        metavar="METRES",
                        help="map resolution r_M in metres (default: the config's, else 0.1)")
    parser.add_argument("--budget", type=positive_int("budget"), default=None, metavar="STEPS",
                        help="number of steps B (default: the config's, else 15)")
    parser.add_argument("--area-size", type=positive_float, default=None, metavar="METRES",
                        help="side of the square area in metres (default: the config's, else 50)")
    parser.add_argument("--grid-spacing", type=positive_float, default=None, metavar="METRES",
                        help="distance between waypoints in metres (default: the config's, else "
                             "5); the altitudes stay 5/10/15 m, fixed starts snap to the nearest "
                             "waypoints")


def _compare_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ipp-compare",
        allow_abbrev=False,  # a prefix of another flag must not be taken for it
        description="Evaluate planners on the same test missions of one configuration; print "
                    "the table (mean ± std of entropy and F1 at 33/67/100 % of the budget, "
                    "best in bold) and the planning time per step; write summary.md/.csv/.tex, "
                    "curves.png/.pdf, trajectories/<planner>_mission0.png/.pdf and the raw "
                    "results (results.csv, config.json, shards/) to --out.",
        formatter_class=HelpFormatter,
    )
    add_version(parser)
    parser.add_argument("--agents", type=positive_int("agents"), default=None, metavar="N",
                        help="team size N (default: the --config file's, else 4; teams "
                             "without fixed starts start at random cells)")
    parser.add_argument("--comm", type=comm_range, default=None, metavar="METRES|inf",
                        help="communication range D in metres, or 'inf' (default: the "
                             "--config file's, else 25)")
    parser.add_argument("--planners", default="default", metavar="LIST",
                        help="comma-separated planners: registered names (ig, coverage, "
                             "random, ...) or NAME=CHECKPOINT items: coma=PATH, "
                             "coma=shipped:NAME, ppo=PATH, ppo=shipped:NAME, sb3=PATH "
                             "(an ipp-train sb3/ppo policy.pt or an SB3 model.zip), "
                             "rllib=RUN, torchrl=PATH, ig_learned=PATH; each with an "
                             "optional LABEL: prefix (mine:sb3=model.zip); "
                             f"'default' = {','.join(DEFAULT_PLANNERS)}; "
                             "'all' = every registered planner that can be built")
    parser.add_argument("--trials", type=positive_int("trials"), default=50, metavar="N",
                        help="number of test missions (the same missions for every planner)")
    parser.add_argument("--seed", type=int, default=0, metavar="SEED",
                        help="run seed of the test missions")
    parser.add_argument("--terrain", default=None, metavar="KIND|FILE",
                        help=f"terrain kind ({', '.join(named_terrain_kinds())}) or a raster "
                             "FILE (.npy/.png/.tif; needs --threshold or --threshold-quantile); "
                             "default: the --config file's, else split")
    parser.add_argument("--threshold", type=finite_float, default=None, metavar="T",
                        help="raster threshold in the raster's units: cells whose mean value "
                             "is >= T are interesting (required with a terrain FILE; default: the "
                             "--config file's)")
    parser.add_argument("--threshold-quantile", type=finite_float, default=None, metavar="Q",
                        help="threshold as a quantile of the values instead (1 - Q of the "
                             "cells are interesting): a raster FILE, fractal or real (default: the "
                             "--config file's)")
    add_compute_flags(parser, workers_type=positive_int("workers"),
                      workers_default=min(2, os.cpu_count() or 1), workers_metavar="N",
                      workers_help="parallel evaluation processes; min(2, CPU count) "
                                   "(--backend ray: the CPUs of the local Ray)",
                      backend_help="where the missions fly: processes on this machine, or Ray "
                                   "tasks",
                      address_help=" (its CPUs fly the missions; results are written here, "
                                   "to --out)")
    parser.add_argument("--out", default=None, metavar="DIR",
                        help="output folder; rerunning into it resumes the same configuration "
                             "and refuses another one (default: results/compare-aN-dD for the "
                             "paper's configuration of N UAVs at range D; other settings add "
                             "what differs and a short hash of the run, e.g. "
                             "results/compare-a4-d25-r0.5-1a2b3c4d, so that no two "
                             "configurations share a default folder)")
    parser.add_argument("--config", type=Path, default=None, metavar="YAML",
                        help="YAML config: it wins over the defaults, and every flag given "
                             "explicitly wins over it (default: none, the paper's configuration)")
    _add_world_flags(parser)
    parser.add_argument("--reference", default=None, metavar="LABEL[,LABEL...]",
                        help="the planners of the summary's paired columns, one column each "
                             "(final entropy minus theirs on the same missions); each named "
                             "one must be flown (default: ig, the paper's baseline, and "
                             "ig_spatial, the best heuristic, each where flown)")
    parser.add_argument("--namespace", choices=("test", "validation"), default="test",
                        help="fly the held-out test missions, or the validation missions to "
                             "select policies on (the default --out then starts with "
                             "'validate-')")
    parser.add_argument("--animate", action="store_true", default=False,
                        help="also write animations/<planner>.gif of mission 0 per planner")
    add_progress_flag(parser, "hide the progress bar")
    add_force_flag(parser)
    return parser


def compare_main(argv: list[str] | None = None) -> int:
    """Entry point of ``ipp-compare``; returns the exit code (0 ok, 2 for bad input).

    Bad input (unknown planner, agents or trials < 1, unreadable terrain file, missing
    threshold, an --out folder holding results of another configuration, ...) prints
    ``ipp-compare: error: ...`` on stderr, returns 2 and writes nothing.
    """
    parser = _compare_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:  # --help (0) or an argparse error (2, already printed)
        return exit_.code if isinstance(exit_.code, int) else 2
    from .compare import compare

    def error(message: object) -> int:
        print(f"ipp-compare: error: {message}", file=sys.stderr)
        return 2

    try:
        env_config = build_env_config(
            args.config, agents=args.agents, comm=args.comm, terrain=args.terrain,
            threshold=args.threshold, threshold_quantile=args.threshold_quantile,
            resolution=args.resolution, budget=args.budget,
            area_size=args.area_size, grid_spacing=args.grid_spacing)
    except (ValueError, OSError) as err:
        return error(err)
    try:
        check_backend_flags(args.backend, args.address)
    except (ValueError, RayUnavailableError) as err:
        return error(err)
    try:
        out = args.out if args.out is not None else default_compare_out(
            env_config, args.seed, args.namespace, args.planners)
        out_dir = check_out_path(out)  # before Path("") turns into the current folder
    except (ValueError, OSError) as err:
        return error(err)
    print(setting_line(env_config, args.config), file=sys.stderr)
    try:
        with allow_foreign_files(args.force), sigterm_as_interrupt():
            comparison = compare(
                planners=args.planners, trials=args.trials, seed=args.seed,
                workers=args.workers, out=out_dir, config=env_config,
                progress=not args.no_progress, animate=args.animate, namespace=args.namespace,
                backend=args.backend, address=args.address, reference=args.reference)
    except (ValueError, OSError) as err:  # ConnectionError (no Ray at --address) included
        return error(err)
    except KeyboardInterrupt as interrupt:
        return interrupted("ipp-compare", out_dir, interrupt)
    # Everything left lives until the process exits: the interpreter's last collection would
    # walk it all (torch's and matplotlib's objects, about 1 s); frozen objects are skipped.
    gc.freeze()
    print(comparison.table)
    print("Planning time per step:")
    width = max(len(label) for label in comparison.summary.planners)
    for label, ms in comparison.plan_ms.items():
        print(f"  {label:<{width}}  {ms:10.3f} ms" if math.isfinite(ms)
              else f"  {label:<{width}}  {'-':>10}")
    print(f"\nwrote {out_dir}: summary.md, summary.csv, summary.tex, curves.png, curves.pdf, "
          f"trajectories/*.png/.pdf, results.csv" + (", animations/*.gif" if args.animate
                                                     else ""))
    return 0



TRAINERS = {"coma": "coma.cli", "ppo": "baselines.sb3.ppo_training",
            "sb3": "baselines.sb3.training", "prior": "baselines.field_prior.training",
            "rllib": "baselines.rllib.training"}


def train_main(argv: list[str] | None = None) -> int:
    """Entry point of ``ipp-train {coma,ppo,sb3,prior} ...``: run the trainer's ``main``.

    ``ipp-train sb3 --algo PPO|MaskablePPO|A2C|DQN|QRDQN|RecurrentPPO`` trains any supported
    SB3 algorithm; ``ipp-train ppo`` is the alias of its PPO case.

    Returns the trainer's exit code (0 ok, 1 training failed, 2 bad input).
    """
    import importlib

    argv = list(sys.argv[1:] if argv is None else argv)
    usage = (f"usage: ipp-train {{{','.join(TRAINERS)}}} [--force] [options]   "
             "(ipp-train coma --help, ipp-train sb3 --help for the options; --force: "
             f"{FORCE_HELP})")
    if not argv or argv[0] in ("-h", "--help"):
        print(usage)
        return 0 if argv else 2
    if argv[0] == "--version":
        print(version_line("ipp-train"))
        return 0
    if argv[0] not in TRAINERS:
        print(f"ipp-train: error: unknown trainer {argv[0]!r}; choose from {sorted(TRAINERS)}\n"
              f"{usage}", file=sys.stderr)
        return 2
    module = importlib.import_module(TRAINERS[argv[0]])
    force = "--force" in argv[1:]
    try:
        with allow_foreign_files(force):  # every trainer's --force: see FORCE_HELP
            code = int(module.main([item for item in argv[1:] if item != "--force"]))
    except SystemExit as exit_:  # argparse: --help (0) or a usage error (2, already printed)
        return exit_.code if isinstance(exit_.code, int) else 2
    out = _flag_value(argv, "--out")
    if argv[0] == "coma" and code in (0, 1) and out and (Path(out) / "progress.csv").is_file():
        from .training import plot_training

        paths = plot_training(out)
        print(f"training curves: {paths[0]}")
    return code


def command_parsers() -> dict[str, Callable[[], argparse.ArgumentParser]]:
    """The parser builder of every command line, by its name: each console script, each
    ``ipp-train`` trainer (``ipp-train sb3 --algo PPO`` takes ``ipp-train ppo``'s flags under
    its own name). What ``--help`` prints; building them imports no torch."""
    from baselines.field_prior import training as prior
    from baselines.rllib import training as rllib
    from baselines.sb3 import ppo_training, training
    from coma.cli import build_parser as coma_parser

    from .study_cli import _study_parser

    return {"ipp-simulate": _simulate_parser, "ipp-compare": _compare_parser,
            "ipp-study": _study_parser, "ipp-train coma": coma_parser,
            "ipp-train ppo": ppo_training._parser,
            "ipp-train sb3": training._parser,
            "ipp-train sb3 --algo PPO": lambda: ppo_training._parser(
                prog="ipp-train sb3 --algo PPO"),
            "ipp-train prior": prior._parser, "ipp-train rllib": rllib._parser}


def _flag_value(argv: list[str], flag: str) -> str | None:
    """The value of ``--flag VALUE`` or ``--flag=VALUE`` in ``argv`` (last one wins)."""
    value = None
    for k, item in enumerate(argv):
        if item == flag and k + 1 < len(argv):
            value = argv[k + 1]
        elif item.startswith(flag + "="):
            value = item.split("=", 1)[1]
    return value


def study_main(argv: list[str] | None = None) -> int:
    """Entry point of ``ipp-study robustness|credit|ablation|generalisation|sweep ...``; 0 ok,
    2 bad input (checked before anything is written or trained). The command lives in
    :mod:`reports.study_cli`.
    """
    from .study_cli import main

    return main(argv)
