"""COMA rollout throughput with K workers, in agent-transitions per second (run by hand).

    python benchmarks/coma_rollout_workers.py                   # K = 1 and 2, local processes
    python benchmarks/coma_rollout_workers.py --workers 1,2,4 --backend ray
    python benchmarks/coma_rollout_workers.py --workers 2 --backend ray --address 127.0.0.1:6379

Flies the rollouts of ``--updates`` updates of the ``cpu`` preset (50 missions of 4 UAVs,
r_M = 0.5 m, the ``own_position`` plane, random networks, eps = 0.1) through
``coma.parallel``'s workers, as ``ipp-train coma --workers K`` does, after one warm-up
rollout (worker start-up, Numba's cache load), and prints the rollouts' agent-transitions per
second for each K. It also checks that every K flew the same rollouts, bit for bit.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import torch  # noqa: E402

from coma.config import preset  # noqa: E402
from coma.parallel import RunSpec, make_workers, to_channels_last  # noqa: E402
from coma.persistence import build_networks  # noqa: E402
from ipp_toolkit.config.schema import EnvConfig  # noqa: E402
from ipp_toolkit.runs.process_pool import limit_blas_threads  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", default="1,2", help="worker counts, e.g. 1,2")
    parser.add_argument("--backend", default="local", choices=["local", "ray"])
    parser.add_argument("--address", default=None,
                        help="a running Ray cluster (with --backend ray), e.g. 127.0.0.1:6379")
    parser.add_argument("--updates", type=int, default=4)
    parser.add_argument("--resolution", type=float, default=0.5)
    args = parser.parse_args()
    torch.set_num_threads(1)
    limit_blas_threads()
    config = preset("cpu")
    env = EnvConfig().replace(world={"resolution": args.resolution},
                              features={"own_position": True})
    torch.manual_seed(0)
    networks = build_networks(config, env)
    to_channels_last(networks)
    per_update = config.missions_per_update
    spec = RunSpec(config, env, (env,), (env,), 0)
    reference = None
    for count in (int(k) for k in args.workers.split(",")):
        with make_workers(spec, count, args.backend, args.address) as pool:
            pool.rollout(networks, 0, 10 ** 6, per_update, 0.1)  # warm-up, not timed
            start = time.perf_counter()
            rollouts = [pool.rollout(networks, 0, k * per_update, per_update, 0.1)
                        for k in range(args.updates)]
            seconds = time.perf_counter() - start
        transitions = sum(r.transitions for r in rollouts)
        same = ""
        if reference is None:
            reference = rollouts
        else:
            same = ", the same rollouts as K={}".format(args.workers.split(",")[0]) if all(
                torch.equal(a.actor_obs, b.actor_obs) and torch.equal(a.actions, b.actions)
                and torch.equal(a.behaviour_probs, b.behaviour_probs)
                for a, b in zip(reference, rollouts, strict=True)) else ", OTHER ROLLOUTS"
        print(f"K={count} ({args.backend}): {transitions / seconds:7.0f} agent-transitions/s "
              f"({seconds / args.updates:.2f} s per rollout of {per_update} missions){same}")


if __name__ == "__main__":
    main()
