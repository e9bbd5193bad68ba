"""Evaluating an SB3 model by missions: :func:`evaluate_missions` and
:class:`MissionEvalCallback`.

On the per-UAV view (:func:`ipp_toolkit.vec.make_sb3_vec_env`) every UAV is an SB3 env slot,
so SB3's ``evaluate_policy(model, vec_env, n_eval_episodes=k)`` counts UAV slots: with N UAVs,
one mission gives N "episodes" with the same team return, and ``n_eval_episodes=3`` on a team
of 4 is three copies of one mission's return. Here an episode is a mission: every UAV is
flown by the model (one batched ``predict`` per step, the masks given to a MaskablePPO
model, the LSTM state kept per UAV for RecurrentPPO), and each mission reports the team
return and the task metrics, final entropy and F1 of the global map.
"""

from __future__ import annotations

import inspect
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from ipp_toolkit.config.files import ConfigLike, as_env_config
from ipp_toolkit.config.schema import check_int
from ipp_toolkit.env import IPPEnv
from ipp_toolkit.world.seeding import check_namespace

__all__ = ["MissionResult", "evaluate_missions", "mission_means", "MissionEvalCallback"]


@dataclass(frozen=True)
class MissionResult:
    """One mission flown by a model.

    Attributes:
        mission: its index in the run.
        team_return: the sum of the team rewards over the mission (one team, counted once).
        final_entropy, final_f1: of the global map after the last step.
        invalid_actions: masked moves the model chose (held in place), over all UAVs.
    """

    mission: int
    team_return: float
    final_entropy: float
    final_f1: float
    invalid_actions: int


def mission_means(results: list[MissionResult]) -> dict[str, float]:
    """Means over missions of ``team_return``, ``final_entropy``, ``final_f1`` and
    ``invalid_actions``."""
    rows = [asdict(result) for result in results]
    return {key: float(np.mean([row[key] for row in rows]))
            for key in ("team_return", "final_entropy", "final_f1", "invalid_actions")}


def _predict(model: Any, planes: np.ndarray, masks: np.ndarray, state: Any,
             starts: np.ndarray, deterministic: bool) -> tuple[np.ndarray, Any]:
    """(N,) actions of the N UAVs from (N, C, G, G) planes and (N, 6) bool masks."""
    extra = {"action_masks": masks} if "action_masks" in inspect.signature(
        model.predict).parameters else {}
    actions, state = model.predict(planes, state=state, episode_start=starts,
                                   deterministic=deterministic, **extra)
    return np.asarray(actions).reshape(len(planes)), state


def _fly(model: Any, env: IPPEnv, seed: int, mission: int, normalize: Any,
         deterministic: bool) -> MissionResult:
    observations, _ = env.reset(seed=seed, options={"mission": mission})
    agents = env.possible_agents
    state, starts = None, np.ones(len(agents), dtype=bool)
    total, invalid = 0.0, 0
    while env.agents:
        planes = np.stack([observations[a]["observation"] for a in agents])
        masks = np.stack([observations[a]["action_mask"] for a in agents]).astype(bool)
        if normalize is not None:
            planes = normalize.normalize_obs(planes)
        actions, state = _predict(model, planes, masks, state, starts, deterministic)
        starts[:] = False
        observations, _, _, _, infos = env.step(
            {agent: int(actions[k]) for k, agent in enumerate(agents)})
        total += float(env.mission.reward)  # the team's, once (a failed UAV's own is 0)
        invalid += sum(bool(infos[agent]["invalid_action"]) for agent in agents)
    last = env.mission.history[-1]
    return MissionResult(mission, total, float(last.entropy), float(last.f1), invalid)


def evaluate_missions(model: Any, config: ConfigLike, missions: int = 10, seed: int = 0,
                      namespace: str = "validation", deterministic: bool = True,
                      vec_normalize: Any = None) -> list[MissionResult]:
    """Fly missions ``0 .. missions - 1`` of run ``seed`` with an SB3 model on every UAV.

    Args:
        model: an SB3 or sb3-contrib model trained on the per-UAV view or on
            ``ipp_toolkit/UAV-v0`` (observations (C, G, G), ``Discrete(6)`` actions).
        config: the missions' configuration (an ``EnvConfig``, a dict of sections or a YAML
            path); its team size may differ from training's.
        missions: missions to fly (>= 1).
        seed: run seed (>= 0); the same seed flies the same missions.
        namespace: random-stream namespace (``validation`` by default, to select policies
            on; ``test`` for the held-out missions ``ipp-compare`` flies).
        deterministic: greedy actions (default) or sampled ones.
        vec_normalize: SB3's ``VecNormalize`` whose observation statistics the model
            learnt under; None uses the model's own (``model.get_vec_normalize_env()``), if
            any.

    Returns:
        one :class:`MissionResult` per mission, in mission order (:func:`mission_means`
        averages them).

    Raises:
        ValueError: a bad ``missions``, ``seed``, ``namespace`` or config (named).
    """
    config = as_env_config(config)
    missions = check_int("missions", missions, 1)
    seed = check_int("seed", seed, 0)
    normalize = vec_normalize if vec_normalize is not None else model.get_vec_normalize_env()
    # Masked moves hold (counted), whatever the algorithm: a model that cannot mask still flies.
    env = IPPEnv(config, namespace=namespace, keep_failed=True, invalid_action="hold",
                 observation="dict")
    return [_fly(model, env, seed, mission, normalize, deterministic)
            for mission in range(missions)]


class MissionEvalCallback(BaseCallback):
    """SB3 callback that evaluates the model by missions every ``eval_freq`` calls.

    Logs the means over missions as ``eval/team_return``, ``eval/final_entropy``,
    ``eval/final_f1`` and ``eval/invalid_actions`` (TensorBoard, CSV, ...) and keeps every
    evaluation in :attr:`evaluations` as ``(num_timesteps, [MissionResult, ...])``.

    Args:
        config: the evaluation missions' configuration.
        missions: missions per evaluation (>= 1); the same ones every time.
        eval_freq: evaluate every this many callback calls (>= 1); one call is one step of
            the training vec env, ``n_envs * N`` agent-transitions on the per-UAV view.
        seed, namespace, deterministic: as in :func:`evaluate_missions`.
        verbose: 1 prints one line per evaluation.
    """

    def __init__(self, config: ConfigLike, missions: int = 5, eval_freq: int = 1000,
                 seed: int = 0, namespace: str = "validation", deterministic: bool = True,
                 verbose: int = 0) -> None:
        super().__init__(verbose)
        self.config = as_env_config(config)
        self.missions = check_int("missions", missions, 1)
        self.eval_freq = check_int("eval_freq", eval_freq, 1)
        self.seed = check_int("seed", seed, 0)
        self.namespace = check_namespace(namespace)
        self.deterministic = deterministic
        self.evaluations: list[tuple[int, list[MissionResult]]] = []

    def _on_step(self) -> bool:
        if self.n_calls % self.eval_freq == 0:
            self.evaluate()
        return True

    def evaluate(self) -> dict[str, float]:
        """Fly the missions now, log and keep the results; returns their means."""
        results = evaluate_missions(self.model, self.config, self.missions, self.seed,
                                    self.namespace, self.deterministic)
        self.evaluations.append((int(self.num_timesteps), results))
        means = mission_means(results)
        for key, value in means.items():
            self.logger.record(f"eval/{key}", value)
        if self.verbose:
            print(f"{self.num_timesteps} agent-steps: team return {means['team_return']:.3f}, "
                  f"final entropy {means['final_entropy']:.3f}, final F1 "
                  f"{means['final_f1']:.3f} over {self.missions} missions")
        self.logger.dump(self.num_timesteps)
        return means
