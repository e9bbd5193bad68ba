"""Which UAV deserves the credit? COMA's counterfactual advantages at one step of a mission.

A trained COMA critic gives, for every UAV i, Q(s, (u_-i, a)) for each of its six actions a
with the teammates' actions held fixed. The counterfactual advantage of alternative a is
``Q(s, (u_-i, a)) - sum_b pi(b | o_i) Q(s, (u_-i, b))``: how much better (or worse) than its
average behaviour the team would do if only UAV i changed its mind. This script plays a
mission with the trained actor up to step ``--step``, prints those advantages per UAV, and
draws them on the global map: one coloured arrow per horizontal alternative, a triangle for
up / down, the action actually chosen outlined.

    python examples/02_uav_advantages.py                        # shipped policy, step 3
    python examples/02_uav_advantages.py --checkpoint RUN/best.pt --step 8 --out adv

The figure is ``OUT/uav_advantages.png`` (``--out``, default
``examples-output/02_uav_advantages``); its path is printed last.

The advantage is the toolkit's own function (``coma.advantages.counterfactual_advantage``).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from coma.advantages import counterfactual_advantage  # noqa: E402
from coma.inputs import critic_input  # noqa: E402
from coma.networks import bounded_softmax, greedy_actions  # noqa: E402
from coma.persistence import load_policy, resolve_policy  # noqa: E402
from ipp_toolkit.sim.features import actor_observations  # noqa: E402
from ipp_toolkit.sim.mission import reset_mission, step_mission  # noqa: E402
from ipp_toolkit.sim.team import ACTION_DELTAS, ACTION_NAMES  # noqa: E402


def advantages_at(networks, state) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The greedy joint action and every UAV's counterfactual advantages at ``state``.

    Returns:
        actions (N,), advantages (N, 6) of each alternative (NaN where masked),
        q_values (N, 6), policy (N, 6).
    """
    features = state.config.features
    obs = actor_observations(state, features)
    masks = state.masks().astype(bool)
    actions = greedy_actions(networks.actor, obs, masks)
    planes = critic_input(state, features, networks.coma_config.variant, actions, obs)
    with torch.no_grad():
        q = networks.critic(torch.from_numpy(planes))
        policy = bounded_softmax(networks.actor(torch.from_numpy(obs)),
                                 torch.from_numpy(masks), 0.0)
    n = len(actions)
    table = np.full((n, 6), np.nan)
    for a in range(6):
        alternative = torch.full((n,), a)
        table[:, a] = counterfactual_advantage(q, alternative, policy,
                                               torch.from_numpy(masks)).numpy()
    table[~masks] = np.nan
    return actions, table, q.numpy(), policy.numpy()


def draw(state, actions: np.ndarray, table: np.ndarray, path: Path) -> None:
    """Global map with each UAV's alternatives coloured by their advantage."""
    geometry = state.geometry
    area = state.config.world.area_size
    spacing = state.config.world.grid_spacing
    fig, ax = plt.subplots(figsize=(6.4, 5.6))
    ax.imshow(state.maps.prob[state.global_index], origin="lower", cmap="gray", vmin=0, vmax=1,
              extent=(0, area, 0, area))
    limit = np.nanmax(np.abs(table)) or 1.0
    norm = matplotlib.colors.Normalize(-limit, limit)
    cmap = plt.get_cmap("coolwarm_r")
    positions = geometry.positions_m(state.positions)
    for i, (x, y, _) in enumerate(positions):
        ax.plot(x, y, "o", color="yellow", markersize=7, markeredgecolor="black")
        ax.annotate(f"uav_{i}", (x, y), xytext=(4, 4), textcoords="offset points",
                    color="yellow", fontsize=8)
        for a in range(6):
            if np.isnan(table[i, a]):
                continue
            colour = cmap(norm(table[i, a]))
            edge = "black" if a == actions[i] else "none"
            dx, dy, dz = ACTION_DELTAS[a] * spacing * 0.6
            if dz == 0:
                ax.annotate("", (x + dx, y + dy), (x, y), arrowprops=dict(
                    arrowstyle="simple", color=colour, ec=edge, lw=1.2))
            else:
                ax.plot(x + 0.35 * spacing, y + (0.35 if dz > 0 else -0.35) * spacing,
                        "^" if dz > 0 else "v", color=colour, markersize=9,
                        markeredgecolor=edge)
    fig.colorbar(matplotlib.cm.ScalarMappable(norm=norm, cmap=cmap), ax=ax,
                 label="counterfactual advantage")
    ax.set(xlim=(0, area), ylim=(0, area), xlabel="x [m]", ylabel="y [m]",
           title=f"COMA advantages of each UAV's alternatives, step {state.step}")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--checkpoint", default=None, help="COMA policy (default: shipped)")
    parser.add_argument("--step", type=int, default=3, help="steps to play before looking")
    parser.add_argument("--mission", type=int, default=0, help="test mission index")
    parser.add_argument("--out", type=Path, default=Path("examples-output/02_uav_advantages"),
                        help="folder of the figure, OUT/uav_advantages.png (default: "
                             "examples-output/02_uav_advantages)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    networks, _ = load_policy(args.checkpoint or resolve_policy("shipped:paper-actor"))
    # The policy's own mission settings, at a coarse map resolution to keep this fast.
    config = networks.env_config.replace(world={"resolution": 0.5})
    if not 0 <= args.step < config.team.budget:
        parser.error(f"--step must lie in 0..{config.team.budget - 1}, got {args.step}")
    state = reset_mission(config, seed=0, mission=args.mission, namespace="test")
    for _ in range(args.step):
        actions, *_ = advantages_at(networks, state)
        step_mission(state, actions)
    actions, table, _, policy = advantages_at(networks, state)
    print(f"step {state.step}: counterfactual advantage of each alternative "
          "(teammates' actions fixed; '-' = masked, * = chosen)")
    print("        " + "".join(f"{name:>9}" for name in ACTION_NAMES))
    for i, row in enumerate(table):
        cells = "".join(f"{'-':>9}" if np.isnan(v) else
                        f"{v:+8.3f}{'*' if a == actions[i] else ' '}" for a, v in enumerate(row))
        print(f"uav_{i}  {cells}")
    best = np.nanargmax(table, axis=1)
    pushes = ", ".join(f"uav_{i} {ACTION_NAMES[b]}" for i, b in enumerate(best)
                       if b != actions[i])
    print("With a near-deterministic policy the baseline is about the chosen action's Q, so the\n"
          "chosen action scores about 0 and every other entry says how much better or worse\n"
          "the team would do had only this UAV chosen it. Where an alternative scores above 0,\n"
          f"the critic pushes the actor towards it: {pushes or 'none'}")
    args.out.mkdir(parents=True, exist_ok=True)
    figure = args.out / "uav_advantages.png"
    draw(state, actions, table, figure)
    print(f"figure: {figure}")


if __name__ == "__main__":
    main()
