"""Simulator speed of two versions side by side, interleaved mission by mission (run by hand).

    git archive bbe960b ipp_toolkit | tar -x -C /tmp/before     # the version to compare with
    taskset -c 1 python benchmarks/env_ab.py --old /tmp/before   # this tree against it
    taskset -c 1 python benchmarks/env_ab.py --old /tmp/before --observe --missions 0-9
    taskset -c 1 python benchmarks/env_ab.py --old /tmp/before --gain 5   # coma/ppo's planes

On a shared VM the speed of one core drifts by tens of percent within minutes, so two runs of
``env_throughput.py`` taken one after the other compare the machine's moods as much as the
code. Here both versions live in one process (the old package is copied under another name)
and fly the same missions with the same actions in turns, several times each, keeping each
one's fastest run of each mission: what is left of the drift hits both alike.

Prints, per version, the mean over missions of the fastest joint step (``step_mission``, with
``--observe`` also every agent's observations and the global state; ``--gain S`` adds the
three gain planes with smoothing S metres, as the shipped ``coma`` and ``ppo`` policies see
them) and of the fastest reset, and the new/old ratio mission by mission.
"""

from __future__ import annotations

import argparse
import importlib
import os
import shutil
import sys
import time
from pathlib import Path
from types import ModuleType

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

OLD_NAME = "ipp_toolkit_before"


def load_old(checkout: Path, workdir: Path) -> tuple[ModuleType, ModuleType, ModuleType]:
    """(config, mission, features) of the package ``checkout/ipp_toolkit``, imported as
    :data:`OLD_NAME` from a copy in ``workdir`` (kept: Numba's cache lives there)."""
    source = checkout / "ipp_toolkit"
    # the layered package (sim/, config/) or the flat one of earlier versions
    names = (("config.schema", "sim.mission", "sim.features")
             if (source / "sim" / "mission.py").is_file() else ("config", "mission", "features"))
    if not (source / names[1].replace(".", "/")).with_suffix(".py").is_file():
        raise SystemExit(f"--old {checkout}: no ipp_toolkit/sim/mission.py there")
    target = workdir / OLD_NAME
    if target.exists():
        shutil.rmtree(target)
    shutil.copytree(source, target, ignore=shutil.ignore_patterns("__pycache__", "data"))
    if (source / "data").exists():
        (target / "data").symlink_to((source / "data").resolve())
    sys.path.insert(0, str(workdir))
    return tuple(importlib.import_module(f"{OLD_NAME}.{name}")  # type: ignore[return-value]
                 for name in names)


def mission_list(text: str) -> list[int]:
    """``0-9`` or ``0,3,9`` -> list of mission indices."""
    if "-" in text:
        first, last = (int(v) for v in text.split("-"))
        return list(range(first, last + 1))
    return [int(v) for v in text.split(",")]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", type=Path, required=True,
                        help="a checkout or `git archive` holding the ipp_toolkit/ to compare with")
    parser.add_argument("--workdir", type=Path, default=Path("/tmp/ipp_toolkit_env_ab"))
    parser.add_argument("--resolution", type=float, default=0.1)
    parser.add_argument("--agents", type=int, default=4)
    parser.add_argument("--comm", type=float, default=25.0)
    parser.add_argument("--missions", type=mission_list, default=mission_list("0-9"))
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--observe", action="store_true",
                        help="also build every agent's observations and the global state")
    parser.add_argument("--gain", type=float, default=None, metavar="S",
                        help="observe with the gain planes, smoothing S metres (0: ig's)")
    args = parser.parse_args()
    args.observe = args.observe or args.gain is not None
    args.workdir.mkdir(parents=True, exist_ok=True)
    import ipp_toolkit.config.schema as new_config
    import ipp_toolkit.sim.features as new_features
    import ipp_toolkit.sim.mission as new_mission

    versions = {"old": load_old(args.old, args.workdir),
                "new": (new_config, new_mission, new_features)}
    setups = {}
    for name, (config_module, mission_module, features_module) in versions.items():
        features = ({} if args.gain is None
                    else {"features": {"gain": True, "gain_smoothing": args.gain}})
        config = config_module.EnvConfig().replace(
            world={"resolution": args.resolution},
            team={"n_agents": args.agents, "comm_range": args.comm}, **features)
        setups[name] = (config, mission_module.MissionGeometry(config), mission_module,
                        features_module)

    def fly(name: str, mission: int) -> tuple[float, float]:
        config, geometry, mission_module, features_module = setups[name]
        rng = np.random.default_rng(mission)
        start = time.perf_counter()
        state = mission_module.reset_mission(config, seed=0, mission=mission,
                                             geometry=geometry)
        reset = time.perf_counter() - start
        stepping = 0.0
        while not state.done:
            masks = state.masks()
            actions = (rng.random(masks.shape) * masks).argmax(axis=1)
            start = time.perf_counter()
            mission_module.step_mission(state, actions)
            if args.observe:
                features_module.actor_observations(state, config.features)
                features_module.global_state(state, config.features)
            stepping += time.perf_counter() - start
        return stepping / state.budget, reset

    for name in setups:  # compile / load both versions' kernels first
        fly(name, args.missions[0])
    step = {name: np.full(len(args.missions), np.inf) for name in setups}
    reset = {name: np.full(len(args.missions), np.inf) for name in setups}
    for i, mission in enumerate(args.missions):
        for repeat in range(args.repeats):
            for name in ("old", "new") if repeat % 2 == 0 else ("new", "old"):
                step_s, reset_s = fly(name, mission)
                step[name][i] = min(step[name][i], step_s)
                reset[name][i] = min(reset[name][i], reset_s)
    print(f"{args.agents} agents, D = {args.comm} m, r_M = {args.resolution} m, missions "
          f"{args.missions}, fastest of {args.repeats} runs each"
          + (", with observations" if args.observe else "")
          + (f" and gain planes (smoothing {args.gain} m)" if args.gain is not None else ""))
    for name in setups:
        mean = step[name].mean()
        print(f"{name}: step {mean * 1e3:.3f} ms ({1 / mean:.0f} joint steps/s), reset "
              f"{reset[name].mean() * 1e3:.2f} ms")
    print("new / old step, per mission:", " ".join(f"{r:.2f}" for r in step["new"] / step["old"]))


if __name__ == "__main__":
    main()
