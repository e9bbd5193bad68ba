"""COMA's rollout: missions flown in lock-step by the shared actor (or by demonstrators).

This module owns :class:`Rollout` (one update's data: actor, critic and value inputs, masks,
actions, the behaviour policy's probabilities, rewards; :meth:`Rollout.concatenate` joins the
parts flown by several workers) and :func:`collect_rollout`, which plays E missions of B steps
at once, sampling every agent's action from the bounded softmax of the actor (one forward
pass per group of missions and step); the missions are reset and stepped by the mission
driver (:mod:`ipp_toolkit.sim.driver`), this module decides the actions and records the learner's
inputs. The learner (``coma.learner``) trains on rollouts,
``coma.parallel`` splits their missions over workers, the warm start (``coma.warm_start``)
fills them with a demonstrator's actions, and the throughput benchmark times them.

Each mission samples its actions from its own stream (:func:`sampling_generator`, derived from
the run seed, the namespace and the mission's index), and the actor scores the agents of
fixed groups of missions per forward pass (:func:`actor_batches`: missions grouped by index,
:data:`ACTOR_BATCH_MISSIONS` to a group), so mission k of a rollout is the same, to the last
bit, whichever missions are flown beside it: the rollout of an update does not depend on how
its missions are split over workers (at group boundaries, ``coma.parallel``). A forward pass
over all the missions at once would not do: a batch of another size may round differently
(seen on this VM: one behaviour probability 1 ulp apart between batches of 6 and 2 agents).
(Until this change, one generator drew for all the missions of the run in turn and the actor
scored them all at once; the same seed now trains other numbers than it did then.)
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.planning import Planner, planner_views
from ipp_toolkit.sim.driver import fly_missions, start_missions
from ipp_toolkit.sim.features import actor_observations
from ipp_toolkit.sim.mission import MissionGeometry, MissionState
from ipp_toolkit.sim.team import N_ACTIONS
from ipp_toolkit.world.seeding import planner_seed

from .inputs import critic_input, value_input
from .networks import bounded_softmax
from .persistence import COMANetworks

__all__ = ["ACTOR_BATCH_MISSIONS", "Rollout", "actor_batches", "collect_rollout",
           "sampling_generator"]

ACTOR_BATCH_MISSIONS = 5
"""Missions whose agents the actor scores in one forward pass: missions 0-4 of a run, 5-9,
... (for the ``cpu`` preset's 50 missions of 4 agents, 10 passes of 20 agents per step cost
about 7 ms more per step than one of 200, about 5 % of the rollout, measured on this VM)."""


@dataclass
class Rollout:
    """One update's data: E missions of T steps with N agents, in lock-step.

    Attributes:
        actor_obs: (E, N, T, C_actor, G, G) float32.
        critic_obs: (E, N, T, C_critic, G, G) float32.
        value_obs: (E, N, T, C_value, G, G) float32, or None unless ``central_qv``.
        masks: (E, N, T, 6) bool valid actions.
        actions: (E, N, T) int64.
        behaviour_probs: (E, N, T) probability of each action under the policy that chose
            it (1 for a demonstrator's actions).
        rewards: (E, T) float32 team rewards.
        returns: (E,) undiscounted return of each mission.
        final_entropy: (E,) entropy metric at the end of each mission.
    """

    actor_obs: torch.Tensor
    critic_obs: torch.Tensor
    value_obs: torch.Tensor | None
    masks: torch.Tensor
    actions: torch.Tensor
    behaviour_probs: torch.Tensor
    rewards: torch.Tensor
    returns: np.ndarray
    final_entropy: np.ndarray

    @property
    def transitions(self) -> int:
        """Agent-transitions in the rollout: E * N * T."""
        return int(np.prod(self.actions.shape))

    def to(self, device: torch.device | str) -> Rollout:
        """The rollout with its tensors on ``device`` (itself when they are there already, so
        a CPU learner trains on the very tensors the rollout made)."""
        tensors = {name: getattr(self, name) for name in _TENSORS}
        if all(t is None or t.device == torch.device(device) for t in tensors.values()):
            return self
        return dataclasses.replace(self, **{name: None if t is None else t.to(device)
                                            for name, t in tensors.items()})

    @classmethod
    def concatenate(cls, parts: Sequence[Rollout]) -> Rollout:
        """One rollout of ``parts`` (consecutive blocks of missions, in mission order).

        A single part is returned as it is; the tensors of several are joined along the
        mission axis.
        """
        if not parts:
            raise ValueError("Rollout.concatenate needs at least one part")
        if len(parts) == 1:
            return parts[0]

        def joined(name: str) -> torch.Tensor | None:
            tensors = [getattr(p, name) for p in parts]
            return None if tensors[0] is None else torch.cat(tensors)

        return cls(**{name: joined(name) for name in _TENSORS},
                   returns=np.concatenate([p.returns for p in parts]),
                   final_entropy=np.concatenate([p.final_entropy for p in parts]))


_TENSORS = ("actor_obs", "critic_obs", "value_obs", "masks", "actions", "behaviour_probs",
            "rewards")
"""The fields of a :class:`Rollout` that are tensors (``value_obs`` may be None)."""


def actor_batches(first_mission: int, n_missions: int,
                  size: int = ACTOR_BATCH_MISSIONS) -> list[tuple[int, int]]:
    """``(start, stop)`` positions, within missions ``first_mission ..`` of a call, of the
    groups the actor scores together: cut wherever a mission index is a multiple of ``size``,
    so a mission is scored beside the same missions whichever call flies it."""
    cuts = [m - first_mission for m in range(first_mission + 1, first_mission + n_missions)
            if m % size == 0]
    bounds = [0, *cuts, n_missions]
    return list(zip(bounds[:-1], bounds[1:], strict=True))


def sampling_generator(seed: int, mission: int, namespace: str = "train") -> torch.Generator:
    """The torch Generator that samples the actions of mission ``mission`` of run ``seed``.

    Seeded with the mission's planner stream (:func:`ipp_toolkit.world.seeding.planner_seed`: the
    actor is the planner that flies the mission), independent of its terrain, start, sensor
    and message streams, and of every other mission's.
    """
    return torch.Generator().manual_seed(planner_seed(seed, mission, namespace))


def _stack_time(frames: list[np.ndarray]) -> torch.Tensor:
    """T frames of (E, N, ...) -> (E, N, T, ...)."""
    return torch.from_numpy(np.stack(frames, axis=2))


def _learning_masks(state: MissionState) -> np.ndarray:
    """(N, 6) bool masks the learner uses: the valid actions, or all actions in the no-mask
    ablation (``team.invalid_action = "hold"``: a masked choice holds the UAV in place)."""
    if state.config.team.invalid_action == "hold":
        return np.ones((state.n_agents, N_ACTIONS), dtype=bool)
    return state.masks().astype(bool)


def collect_rollout(networks: COMANetworks, env_config: EnvConfig, geometry: MissionGeometry,
                    seed: int, first_mission: int, n_missions: int, eps: float,
                    namespace: str = "train",
                    demonstrators: Sequence[Planner] | None = None) -> Rollout:
    """Play ``n_missions`` missions in lock-step with the bounded-softmax policy.

    Missions ``first_mission ... first_mission + n_missions - 1`` of run ``seed`` are used, so
    consecutive updates see fresh terrains; :func:`ipp_toolkit.sim.driver.fly_missions` flies them,
    and the policy callback here records a step's inputs before the step. The actor runs once
    per step for all agents of each group of :func:`actor_batches`; the critic inputs are built
    with the joint action just sampled. Mission k draws its actions from its own stream
    (:func:`sampling_generator`), so its content does not depend on the other missions of the
    call (as long as the call cuts no group: ``coma.parallel`` splits at group boundaries).

    Args:
        demonstrators: one planner per mission that acts instead of the actor (demonstrations
            for a warm start, see ``coma.warm_start``); ``eps`` is then unused.
    """
    variant = networks.coma_config.variant
    features = env_config.features
    states = start_missions(env_config, seed, first_mission, n_missions, namespace, geometry)
    groups = actor_batches(first_mission, n_missions)
    if demonstrators is not None:
        if len(demonstrators) != n_missions:
            raise ValueError(f"need one demonstrator per mission ({n_missions}), got "
                             f"{len(demonstrators)}")
        for e, planner in enumerate(demonstrators):
            planner.reset(env_config, planner_seed(seed, first_mission + e, namespace))
        streams = []
    else:
        streams = [sampling_generator(seed, first_mission + e, namespace)
                   for e in range(n_missions)]
    actor_frames, critic_frames, value_frames, mask_frames, action_frames = [], [], [], [], []
    behaviour_frames: list[np.ndarray] = []

    def act(states: Sequence[MissionState]) -> np.ndarray:
        """(E, N) actions of this step; records the step's inputs (the critic's with them)."""
        obs = np.stack([actor_observations(s, features) for s in states])  # (E, N, C, G, G)
        masks = np.stack([_learning_masks(s) for s in states])  # (E, N, 6)
        if demonstrators is None:
            planes, valid = torch.from_numpy(obs), torch.from_numpy(masks)
            with torch.no_grad():
                per_mission = torch.cat([
                    bounded_softmax(networks.actor(planes[a:b].flatten(0, 1)),
                                    valid[a:b].flatten(0, 1), eps).view(b - a, -1, N_ACTIONS)
                    for a, b in groups])
            # Each mission's agents draw from the mission's stream, in agent order.
            chosen = torch.stack([torch.multinomial(p, 1, generator=stream)
                                  for p, stream in zip(per_mission, streams, strict=True)])
            behaviour = per_mission.gather(-1, chosen).squeeze(-1).numpy()
            actions = chosen.squeeze(-1).numpy()
        else:
            actions = np.stack([np.asarray(planner.act(planner_views(s, planner)),
                                           dtype=np.int64)
                                for planner, s in zip(demonstrators, states, strict=True)])
            behaviour = np.ones(actions.shape, dtype=np.float32)
        critic_frames.append(np.stack([critic_input(s, features, variant, actions[e], obs[e])
                                       for e, s in enumerate(states)]))
        if networks.value is not None:
            value_frames.append(np.stack([value_input(s, features, obs[e])
                                          for e, s in enumerate(states)]))
        actor_frames.append(obs)
        mask_frames.append(masks)
        action_frames.append(actions)
        behaviour_frames.append(behaviour)
        return actions

    flight = fly_missions(states, act)
    return Rollout(
        actor_obs=_stack_time(actor_frames),
        critic_obs=_stack_time(critic_frames),
        value_obs=_stack_time(value_frames) if value_frames else None,
        masks=_stack_time(mask_frames),
        actions=_stack_time(action_frames).long(),
        behaviour_probs=_stack_time(behaviour_frames).float(),
        rewards=torch.from_numpy(flight.rewards).float(),
        returns=flight.returns(),
        final_entropy=flight.curve("entropy")[:, -1],
    )
