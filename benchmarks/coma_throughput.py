"""COMA training throughput in agent-transitions per second (run by hand, one core).

    python benchmarks/coma_throughput.py                    # cpu preset, r_M = 0.5 m
    python benchmarks/coma_throughput.py --preset paper --resolution 0.1
    python benchmarks/coma_throughput.py --preset paper --resolution 0.1 --device cuda
    python benchmarks/coma_throughput.py --precision bfloat16   # mixed-precision learning

Prints, per preset: rollout only (simulator + features + actor sampling), one update only
(TD(lambda) targets, critic and actor mini-batch steps) and the whole training step, each in
agent-transitions per second, plus seconds per update (the authors' code: about 42 s per
300-transition update on a 2-core VM, i.e. ~7 transitions/s). The first update (``--warmup``)
is not timed: it loads Numba's kernels and has oneDNN compile its convolutions, which a
training run pays once. With ``--device cuda`` the
networks learn on the GPU and the rollouts fly on a CPU copy of the actor, refreshed after
every update, as ``ipp-train coma --device cuda`` does.
"""

from __future__ import annotations

import argparse
import copy
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import torch  # noqa: E402

from coma.config import PRECISIONS, preset  # noqa: E402
from coma.learner import make_optimisers, to_channels_last, update  # noqa: E402
from coma.parallel import cpu_actor_state, resolve_device  # noqa: E402
from coma.persistence import build_networks  # noqa: E402
from coma.rollout import collect_rollout  # noqa: E402
from ipp_toolkit.config.schema import EnvConfig  # noqa: E402
from ipp_toolkit.runs.process_pool import limit_blas_threads, retain_freed_memory  # noqa: E402
from ipp_toolkit.sim.mission import MissionGeometry  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="cpu", choices=["cpu", "paper"])
    parser.add_argument("--resolution", type=float, default=0.5)
    parser.add_argument("--updates", type=int, default=3)
    parser.add_argument("--gain", type=float, default=None, metavar="SMOOTHING",
                        help="with the gain planes: 0 = ig's objective, > 0 = the smoothed "
                             "objective of a gain-prior policy over ig_spatial (metres)")
    parser.add_argument("--warmup", type=int, default=1,
                        help="untimed updates first (the first calls load and compile kernels)")
    parser.add_argument("--device", default="cpu", help="where the networks learn: cpu or cuda")
    parser.add_argument("--precision", default="float32", choices=PRECISIONS,
                        help="what the learning passes compute in (COMAConfig.precision)")
    args = parser.parse_args()
    try:
        device = resolve_device(args.device)
    except ValueError as error:
        parser.error(str(error))
    torch.set_num_threads(1)  # the process set up as ipp-train coma sets up its own
    limit_blas_threads()
    retain_freed_memory()
    torch.manual_seed(0)
    config = preset(args.preset, precision=args.precision)
    env = EnvConfig().replace(world={"resolution": args.resolution})
    if args.gain is not None:
        env = env.replace(features={"gain": True, "gain_smoothing": args.gain})
    networks = build_networks(config, env)
    to_channels_last(networks)  # as the trainer does
    flying = networks  # on the CPU the rollouts fly the learning networks themselves
    if device.type != "cpu":
        flying = copy.deepcopy(networks)
        for module in (networks.actor, networks.critic, networks.value):
            if module is not None:
                module.to(device)
    optimisers = make_optimisers(networks)
    target = copy.deepcopy(networks.critic)
    geometry = MissionGeometry(env)
    generator = torch.Generator().manual_seed(0)
    rollout_s = update_s = 0.0
    transitions = 0
    for k in range(args.warmup + args.updates):
        if k == args.warmup:  # first calls behind: the kernels are loaded and compiled
            rollout_s = update_s = 0.0
            transitions = 0
        start = time.perf_counter()
        if flying is not networks:
            flying.actor.load_state_dict(cpu_actor_state(networks))
        rollout = collect_rollout(flying, env, geometry, 0, k * config.missions_per_update,
                                  config.missions_per_update, 0.3)
        middle = time.perf_counter()
        update(networks, target, optimisers, rollout, 0.3, generator)
        if device.type == "cuda":
            torch.cuda.synchronize(device)  # the update's kernels have run, not just queued
        rollout_s += middle - start
        update_s += time.perf_counter() - middle
        transitions += rollout.transitions
    gain = "" if args.gain is None else f", gain planes (smoothing {args.gain:g} m)"
    print(f"preset={args.preset} width={config.width} r_M={args.resolution} m{gain}, "
          f"networks on {device} in {args.precision}, "
          f"{config.missions_per_update} missions ({transitions // args.updates} "
          f"agent-transitions) per update, {config.epochs} epochs, one thread, "
          f"{args.updates} updates timed after {args.warmup} untimed")
    print(f"  rollout only     {transitions / rollout_s:8.0f} agent-transitions/s")
    print(f"  update only      {transitions / update_s:8.0f} agent-transitions/s")
    print(f"  training         {transitions / (rollout_s + update_s):8.0f} agent-transitions/s "
          f"({(rollout_s + update_s) / args.updates:.2f} s per update)")


if __name__ == "__main__":
    main()
