"""PPO training throughput through the SB3 adapter, and raw env throughput (run by hand).

    python benchmarks/ppo_throughput.py                       # 4 agents, 0.5 m, 4 copies
    python benchmarks/ppo_throughput.py --num-cpus 0,2 --timesteps 16384

Prints agent-transitions per second (SB3 timesteps; one joint step of N agents counts N):
  env           bare ``IPPEnv.step`` loop with random valid actions (one copy, this process);
  adapter       the same through ``make_sb3_vec_env`` (SuperSuit + IPPVecEnv), random actions;
  maskable_ppo  ``MaskablePPO.learn`` through the adapter (rollouts + updates), SmallCNN policy;
  ppo           plain ``PPO.learn`` (masks ignored, invalid samples fixed), same policy.
torch uses one thread: on this two-core machine more threads collapse under load.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from baselines.sb3.ppo import PPOTrainConfig  # noqa: E402
from baselines.sb3.ppo_training import train_ppo, training_env_config  # noqa: E402
from ipp_toolkit.config.schema import EnvConfig  # noqa: E402
from ipp_toolkit.env import IPPEnv  # noqa: E402
from ipp_toolkit.vec import make_sb3_vec_env  # noqa: E402


def env_rate(config: EnvConfig, agent_steps: int) -> float:
    """Agent-steps/s of a bare ParallelEnv loop (resets included)."""
    env = IPPEnv(config)
    rng = np.random.default_rng(0)
    observations, _ = env.reset(seed=0)
    done, start = 0, time.perf_counter()
    while done < agent_steps:
        actions = {agent: int((rng.random(6) * obs["action_mask"]).argmax())
                   for agent, obs in observations.items()}
        observations, _, terminations, _, _ = env.step(actions)
        done += len(actions)
        if all(terminations.values()):
            observations, _ = env.reset()
    return done / (time.perf_counter() - start)


def adapter_rate(config: EnvConfig, n_envs: int, num_cpus: int, agent_steps: int) -> float:
    """Agent-steps/s through the SB3 adapter with random valid actions."""
    vec = make_sb3_vec_env(config, n_envs, seed=0, num_cpus=num_cpus)
    try:
        rng = np.random.default_rng(0)
        vec.reset()
        done, start = 0, time.perf_counter()
        while done < agent_steps:
            masks = vec.action_masks()
            vec.step((rng.random(masks.shape) * masks).argmax(axis=1))
            done += vec.num_envs
        return done / (time.perf_counter() - start)
    finally:
        vec.close()


def ppo_rate(args: argparse.Namespace, num_cpus: int, masked: bool, out: str) -> float:
    """Agent-transitions/s of a short training run (setup excluded as far as possible)."""
    config = PPOTrainConfig(total_timesteps=args.timesteps, n_envs=args.n_envs,
                            n_steps=args.n_steps, batch_size=args.batch_size,
                            n_agents=args.agents, resolution=args.resolution,
                            num_cpus=num_cpus, masked=masked,
                            checkpoint_every=10 * args.timesteps)
    start = time.perf_counter()
    train_ppo(config, EnvConfig(), out, progress=False)
    return args.timesteps / (time.perf_counter() - start)


def main() -> None:
    import tempfile

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=int, default=4)
    parser.add_argument("--resolution", type=float, default=0.5)
    parser.add_argument("--n-envs", type=int, default=4)
    parser.add_argument("--n-steps", type=int, default=64)
    parser.add_argument("--batch-size", type=int, default=256)
    parser.add_argument("--timesteps", type=int, default=8192,
                        help="agent-transitions per PPO measurement")
    parser.add_argument("--num-cpus", default="0", help="comma-separated SuperSuit workers")
    args = parser.parse_args()
    torch.set_num_threads(1)
    config = training_env_config(PPOTrainConfig(n_agents=args.agents,
                                                resolution=args.resolution), EnvConfig())
    print(f"{args.agents} agents, resolution {args.resolution} m, {args.n_envs} copies, "
          f"os.cpu_count()={os.cpu_count()}, load average {os.getloadavg()[0]:.2f}")
    rate = env_rate(config, 4 * args.timesteps)
    print(f"env           {rate:9.0f} agent-steps/s ({rate / args.agents:.0f} joint steps/s)")
    for num_cpus in (int(n) for n in args.num_cpus.split(",")):
        rate = adapter_rate(config, args.n_envs, num_cpus, 4 * args.timesteps)
        print(f"adapter       {rate:9.0f} agent-steps/s (num_cpus={num_cpus})")
        for masked in (True, False):
            with tempfile.TemporaryDirectory() as out:
                rate = ppo_rate(args, num_cpus, masked, out)
            name = "maskable_ppo" if masked else "ppo"
            print(f"{name:13s} {rate:9.0f} agent-transitions/s (num_cpus={num_cpus}, "
                  "setup included)")


if __name__ == "__main__":
    main()
