"""The ``ipp-train coma`` command: flags to configs, then :func:`coma.learner.train`.

This module owns the command line of COMA training: its flags (:func:`build_parser`), the
training defaults over the paper's mission (:data:`TRAINING_DEFAULTS`), how flags, a
``--config`` file and ``--set FIELD=VALUE`` become a :class:`~coma.config.COMAConfig` and an
:class:`~ipp_toolkit.config.schema.EnvConfig` (:func:`configs_from_args`; :func:`coerce_value`
also serves ``ipp-study``), and :func:`main` with its exit codes. ``--set``
names a nested field with a dot (``--set warm_start.missions=100``); the older flat names
(``--set warm_start_missions=100``) are still read (:func:`coma.config.nested_fields`).

Where the run computes is not part of its configs: ``--workers K`` flies each update's
missions (and the validation missions) on K workers, ``--backend local|ray`` in local
processes or on Ray actors (``--address`` of a cluster, else a local Ray with K CPUs), and
``--device cpu|cuda`` is where the networks learn (``coma.parallel``). The same seed trains
the same weights whatever ``--workers`` and ``--backend``; each is checked before anything is
written (a missing Ray, an address that does not answer, ``cuda`` where there is none: exit
code 2). ``--precision bfloat16`` is part of the config (``COMAConfig.precision``), since it
trains other numbers; where the hardware has no bfloat16 instructions a note says so.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.config.settings import (
    build_env_config,
    merge_sections,
    parse_feature_flags,
    setting_line,
)
from ipp_toolkit.planning import removed_name
from ipp_toolkit.runs.cli_flags import (
    add_compute_flags,
    add_progress_flag,
    add_set_flag,
    comm_range,
    comm_range_list,
    int_list,
    positive_float,
    positive_int,
)
from ipp_toolkit.runs.cli_help import HelpFormatter, add_version
from ipp_toolkit.runs.progress import continue_hint, run_reporting
from ipp_toolkit.runs.ray_backend import check_backend_flags, probe
from ipp_toolkit.runs.run_folder import COMA_COMMAND, check_out_path, claim

from .config import (
    PRECISIONS,
    PRESETS,
    VARIANTS,
    COMAConfig,
    mission_settings,
    nested_fields,
    preset,
)
from .recipes import RECIPES, Stage, recipe

# Nothing that imports torch at the top: the learner, networks, files and validation are
# imported where a run is checked or trained, so the flags, --help and a refused flag answer
# without torch's import (seconds).
from .shipped import DEFAULT_SHIPPED, SHIPPED_POLICIES

__all__ = ["TRAINING_DEFAULTS", "PAPER_TRAINING_DEFAULTS", "build_parser", "coerce_value",
           "configs_from_args", "main"]


TRAINING_DEFAULTS = {"world": {"resolution": 0.5}, "features": {"own_position": True}}
"""``ipp-train coma``'s defaults over the paper's mission: training at r_M = 0.5 m (the policy
flies at any resolution) with the own-position plane (docs/departures.md). A ``--config`` file
wins over them, an explicit flag over the file."""

PAPER_TRAINING_DEFAULTS = {"world": {"resolution": 0.5}}
"""With ``--preset paper`` or ``scratch`` the actor sees the paper's inputs: no own-position
plane."""

PAPER_INPUT_PRESETS = ("paper", "scratch")
"""The presets trained on the paper's inputs (:data:`PAPER_TRAINING_DEFAULTS`)."""


def _preset_name(value: str) -> str:
    """``--preset``'s value; the recipe of a removed shipped policy is refused with what to use
    instead (argparse then checks the name against the presets and recipes)."""
    removed = removed_name(f"coma=shipped:{value}")
    if removed is not None:
        raise argparse.ArgumentTypeError(f"the recipe of shipped:{value} was {removed}")
    return value


def _preset_default(field: str) -> str:
    """``default: the preset's`` and each preset's value of COMAConfig ``field`` (a dotted
    name for a nested one), for --help: the flag's default comes from --preset."""
    values = {}
    for name in PRESETS:
        value: Any = preset(name)
        for part in field.split("."):
            value = getattr(value, part)
        values[name] = ("none" if value in ("", ()) else
                        ",".join(f"{v:g}" for v in value) if isinstance(value, tuple)
                        else str(value))
    if len(set(values.values())) == 1:
        return f"default: the preset's, {next(iter(values.values()))} in every preset"
    return "default: the preset's: " + ", ".join(f"{k} {v}" for k, v in values.items())


def _add_beyond_paper_flags(parser: argparse.ArgumentParser) -> None:
    """The training flags beyond the paper's: several team settings (domain randomisation)
    and a start from a policy (fine-tuning)."""
    parser.add_argument("--team-sizes", type=int_list("--team-sizes"), metavar="N,N,...",
                        help="train on these team sizes, one per update, e.g. 2,4,8 (domain "
                             "randomisation; not in the paper; "
                             f"{_preset_default('team_sizes')}: the mission's own)")
    parser.add_argument("--comm-ranges", type=comm_range_list("--comm-ranges"),
                        metavar="D,D,...",
                        help="train on these communication ranges in metres, e.g. 0,25,inf "
                             f"({_preset_default('comm_ranges')}: the mission's own)")
    parser.add_argument("--init", metavar="POLICY",
                        help="start from this COMA policy file instead of a warm start "
                             "(fine-tuning), or a shipped one: --init shipped:NAME "
                             f"({', '.join(SHIPPED_POLICIES)}; plain 'shipped': coma's "
                             "default; default: none, the preset's warm start or random "
                             "networks)")


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``ipp-train coma``; the flags it shares with ``ipp-compare`` and
    ``ipp-study`` come from :mod:`ipp_toolkit.runs.cli_flags`."""
    parser = argparse.ArgumentParser(
        prog="ipp-train coma",
        allow_abbrev=False,  # a prefix of another flag must not be taken for it
        description="Train COMA (or a credit-assignment variant) on the UAV mapping missions.",
        formatter_class=HelpFormatter)
    add_version(parser)
    parser.add_argument("--preset", type=_preset_name,
                        choices=sorted(set(PRESETS) | set(RECIPES)), default="cpu",
                        help="hyper-parameter preset (default: cpu), or the recipe of a "
                             "shipped policy (its name in coma=shipped:NAME; every stage, "
                             "see coma/recipes.py); the flags whose default is the preset's "
                             "take its value (a recipe: its stages')")
    parser.add_argument("--variant", choices=VARIANTS,
                        help=f"credit-assignment variant ({_preset_default('variant')})")
    parser.add_argument("--config", help="YAML mission config (world, team, features, ...) "
                             "over the training defaults (the paper's mission at r_M 0.5 m "
                             "with features.own_position on); explicit flags win over it (default: "
                             "none)")
    parser.add_argument("--seed", type=int, help=f"run seed ({_preset_default('seed')})")
    parser.add_argument("--out", required=True, help="run folder")
    parser.add_argument("--resume", action="store_true", help="continue the run in --out")
    parser.add_argument("--missions", type=positive_int("missions"),
                        help="training missions in total, rounded up to whole updates of "
                             f"missions_per_update ({_preset_default('missions')})")
    parser.add_argument("--width", type=int,
                        help=f"convolution channels ({_preset_default('width')})")
    parser.add_argument("--precision", choices=PRECISIONS,
                        help="what the learning passes compute in (default float32): "
                             "bfloat16 is mixed precision, faster on CPUs with bfloat16 "
                             "instructions (AVX512-BF16, AMX) and on GPUs, slower elsewhere; "
                             "the same as --set precision=NAME")
    parser.add_argument("--agents", type=positive_int("agents"),
                        help="team size (default: from --config, 4)")
    parser.add_argument("--comm", type=comm_range, metavar="METRES|inf",
                        help="communication range in metres, or inf (default: from "
                             "--config, 25)")
    parser.add_argument("--terrain", metavar="KIND",
                        help="terrain kind of the training missions, e.g. mixture (default: "
                             "the --config file's, else split)")
    parser.add_argument("--resolution", type=positive_float, default=None,
                        help="map resolution for training in metres (default: the --config "
                             "file's, else 0.5)")
    parser.add_argument("--warm-start", metavar="PLANNER",
                        help="first imitate this registered planner (e.g. ig; 'none' to "
                             "switch the preset's off; the same as --set "
                             "warm_start.planner=NAME); not in the paper "
                             f"({_preset_default('warm_start.planner')})")
    _add_beyond_paper_flags(parser)
    parser.add_argument("--feature", action="append", default=[], metavar="NAME=VALUE",
                        help="set a feature of the mission config, e.g. --feature "
                             "own_position=true or --feature gain_smoothing=5 (repeatable)")
    add_set_flag(parser, "any COMAConfig field, e.g. --set lr_actor=1e-4; a warm-start field "
                 "with a dot, e.g. --set warm_start.missions=100 (the older "
                 "warm_start_missions / warm_start_epochs are still read) (repeatable)")
    add_compute_flags(parser, workers_type=positive_int("--workers"), workers_metavar="K",
                      workers_help="workers that fly each update's missions and the validation "
                                   "missions (default 1: this process); the same seed trains "
                                   "the same weights with any K (--backend ray: K Ray actors "
                                   "of one CPU)",
                      backend_help="where the workers run: processes on this machine, or Ray "
                                   "actors", address_help="")
    parser.add_argument("--device", default="cpu", metavar="cpu|cuda",
                        help="where the networks learn (default cpu); the missions always fly "
                             "on CPUs, with a copy of the actor")
    add_progress_flag(parser, "hide the progress bar")
    return parser


def _check_compute(args: argparse.Namespace) -> None:
    """Refuse a bad --backend / --address / --device before anything is written
    (ValueError, ImportError or ConnectionError with the message to print)."""
    from .parallel import resolve_device

    check_backend_flags(args.backend, args.address)  # RayUnavailableError names the install
    resolve_device(args.device)
    if args.backend == "ray" and args.address is not None:
        probe(args.address)  # fails within seconds where nothing answers


def coerce_value(text: str) -> Any:
    """A ``--set`` value as written: a bool (true/false), an int, a float, else the text."""
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def _changes_from_args(args: argparse.Namespace) -> dict[str, Any]:
    """The COMAConfig fields the flags set (ValueError on bad input)."""
    changes: dict[str, Any] = {}
    for item in args.set:
        name, sep, value = item.partition("=")
        if not sep:
            raise ValueError(f"--set expects FIELD=VALUE, got {item!r}")
        changes[name.strip()] = coerce_value(value.strip())
    for name in ("variant", "seed", "missions", "width", "precision"):
        if getattr(args, name) is not None:
            changes[name] = getattr(args, name)
    if args.warm_start is not None:
        changes["warm_start.planner"] = "" if args.warm_start == "none" else args.warm_start
    if args.team_sizes is not None:
        changes["team_sizes"] = args.team_sizes
    if args.comm_ranges is not None:
        changes["comm_ranges"] = args.comm_ranges
    if args.init is not None:
        from .persistence import resolve_policy

        init = f"shipped:{DEFAULT_SHIPPED}" if args.init == "shipped" else args.init
        changes["init_policy"] = str(resolve_policy(init))
        if not Path(changes["init_policy"]).is_file():
            raise ValueError(f"--init {args.init!r}: no such policy file")
    return changes


def _env_from_args(args: argparse.Namespace,
                   defaults: dict[str, dict[str, Any]]) -> EnvConfig:
    return build_env_config(args.config, defaults=defaults, agents=args.agents,
                            comm=args.comm, resolution=args.resolution, terrain=args.terrain,
                            features=parse_feature_flags(args.feature))


def configs_from_args(args: argparse.Namespace) -> tuple[COMAConfig, EnvConfig]:
    """The configs a parsed ``ipp-train coma`` command asks for (ValueError on bad input).

    With a recipe (``--preset`` naming a shipped policy) these are its last stage's.
    """
    if args.preset in RECIPES:
        return stage_configs(args)[-1][1:]
    coma_config = preset(args.preset, **_changes_from_args(args))
    defaults = PAPER_TRAINING_DEFAULTS if args.preset in PAPER_INPUT_PRESETS else TRAINING_DEFAULTS
    return coma_config, _env_from_args(args, defaults)


def stage_configs(args: argparse.Namespace) -> list[tuple[Stage, COMAConfig, EnvConfig]]:
    """Every stage of the recipe ``args.preset`` with the flags applied to each.

    A stage that starts from the previous one gets its ``init_policy`` when it runs (the
    file does not exist yet); ``--init`` replaces the first stage's start.
    """
    from .persistence import resolve_policy

    changes = _changes_from_args(args)
    stages = []
    for k, stage in enumerate(recipe(args.preset)):
        fields = nested_fields(stage.coma, changes)
        if k == 0 and "init_policy" not in changes and stage.init is not None:
            fields["init_policy"] = str(resolve_policy(stage.init))
        elif k > 0 and stage.init == "previous":
            fields.pop("init_policy", None)
        defaults = merge_sections(TRAINING_DEFAULTS, stage.env)
        stages.append((stage, preset("cpu", **fields), _env_from_args(args, defaults)))
    return stages


def _stage_folders(out: str, stages: Sequence[Stage]) -> list[Path]:
    if len(stages) == 1:
        return [Path(out)]
    return [Path(out) / f"stage-{k + 1}-{stage.name}" for k, stage in enumerate(stages)]


def main(argv: Sequence[str] | None = None) -> int:
    """``ipp-train coma``: returns 0 on success, 1 on divergence, 2 on bad input."""
    parser = build_parser()
    args = parser.parse_args(argv)
    # ImportError: a planner or Ray that cannot be imported; FileExistsError: --out holds a
    # run; ConnectionError: no Ray at --address.
    return run_reporting("ipp-train coma", lambda: _run(args), continue_hint(
        args.out, "last.pt", f"continue with --resume --out {args.out} (from the last checkpoint)"),
        errors=(ImportError, FileExistsError, ConnectionError))


def _run(args: argparse.Namespace) -> int:
    """:func:`main` once its flags are parsed; bad input raises (reported by ``main``)."""
    from .networks import bfloat16_hardware
    from .parallel import resolve_device
    from .validation import validation_settings

    if args.preset in RECIPES:
        stages = stage_configs(args)
    else:
        stages = [(Stage(args.preset), *configs_from_args(args))]
    for _, coma_config, env_config in stages:
        # An invalid team, range or validation terrain fails here, before any writing.
        validation_settings(coma_config, mission_settings(coma_config, env_config))
        if coma_config.warm_start.enabled:
            from ipp_toolkit.planning import planner_factory

            planner_factory(coma_config.warm_start.planner)  # an unknown name fails here
    _check_compute(args)
    check_out_path(args.out)  # an empty --out is not the current folder
    for note in dict.fromkeys(_rounding_note(config) for _, config, _ in stages):
        if note:
            print(f"ipp-train coma: note: {note}", file=sys.stderr)
    if any(config.precision == "bfloat16" for _, config, _ in stages) \
            and bfloat16_hardware(resolve_device(args.device)) is False:
        hardware = "this CPU" if args.device == "cpu" else "this GPU"
        print(f"ipp-train coma: note: {hardware} has no bfloat16 instructions (AVX512-BF16, "
              "AMX): --precision bfloat16 trains correctly but likely slower than float32 "
              "here", file=sys.stderr)
    folders = _stage_folders(args.out, [stage for stage, _, _ in stages])
    compute = {"workers": args.workers, "backend": args.backend, "address": args.address,
               "device": args.device}
    try:
        with contextlib.ExitStack() as stack:
            if args.backend == "ray":  # one Ray for every stage
                from ipp_toolkit.runs.ray_backend import session

                stack.enter_context(session(args.address, args.workers))
            if len(stages) > 1:
                # A recipe's folder holds its stages' folders: held as one run, so a second
                # recipe (or another command) into it is refused before any stage starts.
                stack.enter_context(claim(args.out, COMA_COMMAND))
            code = _train_stages(args, stages, folders, compute)
            if code != 0:
                raise _Failed(code)  # the claim removes the folder if nothing was written
    except _Failed as failed:
        return int(failed.args[0])
    return code


def _rounding_note(config: COMAConfig) -> str:
    """What a run of ``config`` trains when its missions are not whole updates (training
    flies ``missions_per_update`` missions per update, so it rounds up), else empty: asked
    for 8, a run trained 50 without a word."""
    per = config.missions_per_update
    updates = -(-config.missions // per)
    if updates * per == config.missions:
        return ""
    return (f"{config.missions} training missions are not whole updates of "
            f"missions_per_update = {per}: training {updates * per} missions ({updates} "
            f"update{'s' if updates != 1 else ''}); ask for a multiple of {per} (--missions), "
            "or change --set missions_per_update")


class _Failed(Exception):
    """A run that ended with a nonzero exit code (already reported)."""


def _train_stages(args: argparse.Namespace, stages: list[tuple[Stage, COMAConfig, EnvConfig]],
                  folders: list[Path], compute: dict[str, Any]) -> int:
    """Train every stage into its folder; the exit code of :func:`main` (bad input raises)."""
    from .learner import TrainingDiverged, train

    for k, (stage, coma_config, env_config) in enumerate(stages):
        if k > 0 and stage.init == "previous":
            coma_config = coma_config.replace(init_policy=str(folders[k - 1] / "best.pt"))
        # A later stage not begun yet starts afresh; the first one must exist to resume.
        resume = args.resume and (k == 0 or (folders[k] / "last.pt").exists())
        if len(stages) > 1:
            print(f"stage {k + 1}/{len(stages)} ({stage.name}): {folders[k]}", file=sys.stderr)
        try:
            result = train(coma_config, env_config, folders[k], resume=resume,
                           progress=not args.no_progress,
                           announce=setting_line(env_config, args.config), **compute)
        except TrainingDiverged as error:  # not bad input: the run failed (exit code 1)
            print(f"ipp-train coma: {error}", file=sys.stderr)
            return 1
    criterion = ("worst gap to IG's final entropy" if coma_config.selection == "worst_vs_ig"
                 else "final entropy")
    print(f"trained {result.updates} updates ({result.missions} missions); best validation "
          f"{criterion} {result.best_entropy:+.3f}; policy: {result.best_policy}")
    return 0
