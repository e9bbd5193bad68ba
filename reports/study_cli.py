"""The ``ipp-study`` command: its flags, their checks, then one study of :mod:`reports.studies`,
:mod:`reports.generalisation` or :mod:`reports.sweep` (``reports.cli.study_main`` runs it).

Writes one ``ipp-compare`` folder per setting plus the study's table and figure; ``sweep``
(:mod:`reports.sweep`) its run folders, ``validation/``, ``sweep.md`` and ``sweep.csv``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ipp_toolkit.config.settings import comm_label
from ipp_toolkit.runs.cli_flags import (
    add_compute_flags,
    add_force_flag,
    add_progress_flag,
    add_set_flag,
    comm_range_list,
    int_list,
    positive_float,
    positive_int,
)
from ipp_toolkit.runs.cli_help import HelpFormatter, add_version
from ipp_toolkit.runs.progress import sigterm_as_interrupt
from ipp_toolkit.runs.ray_backend import RayUnavailableError, check_backend_flags
from ipp_toolkit.runs.run_folder import allow_foreign_files, claim

from .compare import DEFAULT_PLANNERS, interrupted

__all__ = ["main"]


def main(argv: list[str] | None = None) -> int:
    """``ipp-study robustness|credit|ablation|generalisation|sweep ...``; 0 ok, 2 bad input
    (checked before anything is written or trained)."""
    try:
        args = _study_parser().parse_args(argv)
    except SystemExit as exit_:
        return exit_.code if isinstance(exit_.code, int) else 2
    out = f"results/{args.study}" if args.out is None else args.out  # "" is refused
    try:
        _check_flags(args)
    except (ValueError, RayUnavailableError) as err:
        print(f"ipp-study: error: {err}", file=sys.stderr)
        return 2
    backend = {"backend": args.backend, "address": args.address}
    seed = 0 if args.seed is None else args.seed
    agents = [2, 4, 8] if args.agents is None else args.agents
    comm = [0.0, 25.0, float("inf")] if args.comm is None else args.comm
    try:
        # The study's folder holds the folders of its runs: one study at a time.
        with (allow_foreign_files(args.force), claim(out, f"ipp-study {args.study}"),
              sigterm_as_interrupt()):
            return _study(args, out, backend, seed, agents, comm)
    except (ValueError, OSError, argparse.ArgumentTypeError) as err:
        # OSError: ConnectionError (no Ray at --address) included
        print(f"ipp-study: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as interrupt:
        return interrupted("ipp-study", Path(out), interrupt)


def _check_flags(args: argparse.Namespace) -> None:
    """Refuse flags that do not go together (ValueError, RayUnavailableError) before the
    study's folder is claimed."""
    check_backend_flags(args.backend, args.address)
    if args.sweep and args.study != "sweep":
        raise ValueError(f"--sweep is for ipp-study sweep, not {args.study}")
    if args.study == "generalisation":
        from .generalisation import check_families

        for flag, value in (("--families", args.families),
                            ("--team-families", args.team_families)):
            check_families([f for f in value.split(",") if f], flag)
    if args.seeds is not None and len(args.seeds) > 1:
        given = " and ".join(",".join(map(str, seeds)) for seeds in args.seeds)
        raise ValueError(f"--seeds is given {len(args.seeds)} times ({given}); give all seeds "
                         "in one --seeds S,S,...")


def _study_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ipp-study", allow_abbrev=False,
        description="Regenerate the paper's studies into a folder.",
        formatter_class=HelpFormatter)
    add_version(parser)
    parser.add_argument("study", choices=["robustness", "credit", "ablation", "generalisation",
                                          "sweep"],
                        help="generalisation: planners x terrain families (real test rasters "
                             "included) x team settings, paired differences to IG and "
                             "ig_spatial; "
                             "robustness: paper Table I (team sizes x communication ranges); "
                             "credit: COMA against its credit-assignment variants; ablation: "
                             "COMA with one input plane, the masking or the centring toggled; "
                             "each run trained alike, then compared on test missions; sweep: "
                             "a grid of COMA runs (--sweep FIELD=V1,V2 x --seeds) scored on "
                             "validation missions against IG")
    parser.add_argument("--planners", default=None,
                        help="planners, comma-separated (coma=PATH for your own policy, "
                             "LABEL:coma=PATH to name it); default: coma,ig,coverage, and "
                             f"for generalisation {','.join(DEFAULT_PLANNERS)}")
    parser.add_argument("--agents", type=int_list("--agents"), default=None,
                        help="team sizes, comma-separated (default 2,4,8); sweep: the one "
                             "team size of training and validation (default 4)")
    parser.add_argument("--comm", type=comm_range_list("--comm"), default=None,
                        help="ranges in metres, comma-separated (default 0,25,inf); sweep: "
                             "the one range (default 25)")
    parser.add_argument("--failures", type=int_list("--failures", minimum=0), default="0",
                        help="robustness: numbers of UAVs failing at a random step, "
                             "comma-separated (e.g. 0,1; beyond the paper)")
    parser.add_argument("--trials", type=positive_int("--trials"), default=50,
                        help="test missions per setting and planner")
    parser.add_argument("--seed", type=int, default=None,
                        help="run seed of the missions flown (default 0; sweep: "
                             "the validation missions of seed 10000, never a training seed)")
    add_compute_flags(parser, workers_type=positive_int("--workers"),
                      workers_help="evaluation processes and runs trained at once (--backend "
                                   "ray: the CPUs of the local Ray)",
                      backend_help="where missions fly and runs train: processes on this "
                                   "machine, or Ray tasks on one Ray for the whole study",
                      address_help=" (results are written here, to --out, a folder the nodes "
                                   "share for credit/ablation)")
    parser.add_argument("--resolution", type=positive_float, default=None,
                        help="map resolution of the missions flown, in metres (default: the "
                             "paper's 0.1)")
    parser.add_argument("--out", default=None, help="study folder (default results/STUDY)")
    parser.add_argument("--variants", default="coma,central_qv,actor_independent,decentralised",
                        help="credit: variants to train")
    parser.add_argument("--ablations",
                        default="own_position,centred,masking,other_actions,footprints",
                        help="ablation: feature switches to toggle, or masking / centred")
    parser.add_argument("--preset", choices=["cpu", "paper", "scratch"], default="cpu",
                        help="credit: the COMA preset every variant trains with (scratch: "
                             "from random networks, docs/training.md)")
    parser.add_argument("--missions", type=positive_int("--missions"), default=None,
                        help="credit, ablation, sweep: training missions per run (default "
                             "5000)")
    parser.add_argument("--train-resolution", type=positive_float, default=0.5,
                        help="credit, ablation, sweep: map resolution of the training "
                             "missions")
    add_set_flag(parser, "credit, ablation, sweep: a COMAConfig field for every run, read as "
                 "ipp-train coma --set reads it (repeatable)")
    parser.add_argument("--sweep", action="append", default=[], metavar="FIELD=V1,V2,...",
                        help="sweep: a COMAConfig field and its values (repeatable: the grid "
                             "is the product; a list field's items joined by +, e.g. "
                             "team_sizes=2+4,4)")
    parser.add_argument("--seeds", type=int_list("--seeds", minimum=0), action="append",
                        default=None, metavar="S,S,...",
                        help="credit, ablation, sweep: training seeds; with several, each run "
                             "is trained once per seed and the table gives mean and spread "
                             "over seeds (default: one seed, 0)")
    _add_generalisation_flags(parser)
    add_progress_flag(parser, None)
    add_force_flag(parser)
    return parser


def _add_generalisation_flags(parser: argparse.ArgumentParser) -> None:
    """The flags only ``ipp-study generalisation`` reads."""
    parser.add_argument("--families", default="split,blobs,fractal,real",
                        help="generalisation: terrain families at 4 UAVs / 25 m (real: one cell "
                             "per test raster)")
    parser.add_argument("--team-families", default="split,blobs",
                        help="generalisation: families flown in every --agents x --comm setting")
    parser.add_argument("--budget", type=positive_int("--budget"), default=None,
                        help="generalisation: steps B (default: the protocol's 15)")
    parser.add_argument("--reference", default=None, metavar="LABEL[,LABEL...]",
                        help="generalisation: the planners every other is compared with, "
                             "paired, on the same missions, one set of columns each; each "
                             "named one must be flown (the figure uses the first; default: "
                             "ig and ig_spatial, each where flown)")


def _study(args: argparse.Namespace, out: str, backend: dict[str, str | None], seed: int,
           agents: list[int], comm: list[float]) -> int:
    """Run the study ``args.study`` into ``out`` (claimed); ValueError on bad input."""
    if args.study == "sweep":  # the sweep takes one value of each, checked there
        return _sweep(args, out, backend)
    _distinct_items("--agents", agents)
    _distinct_items("--comm", comm)
    if args.study == "generalisation":
        _generalisation(args, out, backend, seed, agents, comm)
    elif args.study == "robustness":
        _robustness(args, out, backend, seed, agents, comm)
    else:
        _training_study(args, out, backend, seed)
    return 0


def _generalisation(args: argparse.Namespace, out: str, backend: dict[str, str | None],
                    seed: int, agents: list[int], comm: list[float]) -> None:
    """``ipp-study generalisation``: planners x terrain families x team settings."""
    from .generalisation import generalisation_study, study_cells

    planners = args.planners or ",".join(DEFAULT_PLANNERS)
    settings = [(a, c) for a in agents for c in comm]
    cells = study_cells([f for f in args.families.split(",") if f],
                        [f for f in args.team_families.split(",") if f], settings)
    study = generalisation_study(planners, cells, trials=args.trials, seed=seed,
                                 out=out, workers=args.workers,
                                 resolution=args.resolution, budget=args.budget,
                                 reference=args.reference,
                                 progress=not args.no_progress, **backend)
    print(study.table)
    print(f"written: {out}/generalisation.md, .csv, .tex, .png, .pdf")


def _robustness(args: argparse.Namespace, out: str, backend: dict[str, str | None],
                seed: int, agents: list[int], comm: list[float]) -> None:
    """``ipp-study robustness``: paper Table I (team sizes x communication ranges)."""
    from .studies import robustness_study

    study = robustness_study(args.planners or "coma,ig,coverage",
                             agents, comm,
                             trials=args.trials,
                             seed=seed, out=out, workers=args.workers,
                             resolution=args.resolution,
                             progress=not args.no_progress,
                             failures=args.failures,
                             **backend)
    print(study.table)
    print(f"written: {out}/robustness.md, .csv, .png, .pdf")


def _training_study(args: argparse.Namespace, out: str, backend: dict[str, str | None],
                    seed: int) -> None:
    """``ipp-study credit`` or ``ablation``: COMA runs trained alike, then compared."""
    from .studies import ablation_study, credit_assignment_study
    from .sweep import parse_assignments

    overrides = parse_assignments(args.set)
    seeds = None if args.seeds is None else args.seeds[0]
    common = dict(missions=args.missions or 5000, overrides=overrides, seeds=seeds,
                  train_resolution=args.train_resolution, trials=args.trials,
                  seed=seed, out=out, workers=args.workers,
                  eval_resolution=args.resolution, progress=not args.no_progress,
                  **backend)
    if args.study == "credit":
        result = credit_assignment_study([v for v in args.variants.split(",") if v],
                                         preset=args.preset, **common)
    else:
        result = ablation_study([a for a in args.ablations.split(",") if a], **common)
    print(result.table)
    print(f"written: {out}/{args.study}.md, {out}/compare/ (curves.png: entropy and "
          "F1 per step)")


def _distinct_items(flag: str, values: list[int] | list[float]) -> None:
    """Refuse a list flag that gives a value twice (a study would fly a duplicate row); an
    empty item is refused by the flag's type (:func:`~ipp_toolkit.runs.cli_flags.int_list`)."""
    repeated = sorted({value for value in values if values.count(value) > 1})
    if repeated:
        raise ValueError(f"{flag} {_listed(values)} gives "
                         f"{', '.join(_listed([v]) for v in repeated)} more than once")


def _listed(values: list[int] | list[float]) -> str:
    """A list flag's values as they would be written: ``2,4,8`` or ``0,25,inf``."""
    return ",".join(str(v) if isinstance(v, int) else comm_label(v) for v in values)


def _sweep(args: argparse.Namespace, out: str, backend: dict[str, str | None]) -> int:
    """``ipp-study sweep``: the grid from --sweep/--set/--seeds, trained and scored
    (ValueError on bad input, before anything is written)."""
    from .sweep import SCORING_SEED, parse_assignments, parse_sweep, sweep_study

    if not args.sweep:
        raise ValueError("ipp-study sweep needs at least one --sweep FIELD=V1,V2,...")
    missions = args.missions
    grid = parse_sweep(args.sweep)
    overrides = parse_assignments(args.set)
    if missions is not None and ("missions" in grid or "missions" in overrides):
        raise ValueError("missions is given by --missions and by --sweep/--set; give it once")
    if missions is None and "missions" not in grid:
        missions = overrides.pop("missions", 5000)  # --set missions=N is --missions N
    elif missions is None:
        missions = 5000  # swept (sweep_grid refuses it in --set as well)
    for flag, values in (("--agents", args.agents), ("--comm", args.comm)):
        if values is not None and len(values) > 1:
            raise ValueError(f"sweep: {flag} takes one value (the training and validation "
                             f"missions'), got {_listed(values)!r}")
    study = sweep_study(
        grid, seeds=[0] if args.seeds is None else args.seeds[0],
        overrides=overrides, missions=missions, train_resolution=args.train_resolution,
        agents=None if args.agents is None else args.agents[0],
        comm=None if args.comm is None else args.comm[0],
        trials=args.trials, seed=SCORING_SEED if args.seed is None else args.seed, out=out,
        workers=args.workers, eval_resolution=args.resolution,
        progress=not args.no_progress, **backend)
    print(study.table)
    print(f"best grid point: {study.best.label if study.best else 'none (no run has a policy)'}")
    print(f"written: {out}/sweep.md, {out}/sweep.csv, {out}/runs/ (one folder per run), "
          f"{out}/validation/ (the comparison on validation missions)")
    return 0
