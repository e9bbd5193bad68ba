"""Hyper-parameters of COMA training, in one dataclass.

Two presets: ``paper`` (the paper's network size and schedule, from random networks) and
``cpu`` (the default, measured to train on one CPU core in under an hour: a narrower
network, a warm start that imitates the ``ig`` planner before COMA improves on it, so
exploration starts at eps = 0.1, and PPO's clipped surrogate with normalised counterfactual
advantages for the actor; see the README for what each choice measured).
The mission itself (team, world, features) is an
:class:`~ipp_toolkit.config.schema.EnvConfig`, kept separately and stored beside this in
checkpoints.

The warm start's settings are one nested section, :class:`WarmStartConfig` (``warm_start``);
dicts, ``--set`` and :meth:`COMAConfig.replace` name its fields ``warm_start.missions`` or
``{"warm_start": {"missions": ...}}``. Older files wrote them flat (``warm_start`` = the
planner's name, ``warm_start_missions``, ``warm_start_epochs``): :func:`nested_fields` is the
one place that reads those names, so old checkpoints, run folders and commands still load;
saving writes the nested form.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, NoReturn

from ipp_toolkit.config.field_types import check_integers, is_integer, is_real
from ipp_toolkit.config.limits import check_layer_size
from ipp_toolkit.config.schema import EnvConfig, start_for_team_size

__all__ = ["VARIANTS", "ADVANTAGES", "CRITIC_TARGETS", "PRECISIONS", "PRESETS", "FLAT_NAMES",
           "WarmStartConfig", "COMAConfig", "from_dict", "nested_fields", "preset",
           "mission_settings"]

#: The credit-assignment variants of the paper's study.
VARIANTS = ("coma", "central_qv", "actor_independent", "decentralised")

#: How the critic's targets are computed (:attr:`COMAConfig.critic_targets`).
CRITIC_TARGETS = ("td_lambda", "reference")

#: What the actor's advantage takes for the action taken (:attr:`COMAConfig.advantage`).
ADVANTAGES = ("critic", "return")

#: What the learning passes compute in (:attr:`COMAConfig.precision`).
PRECISIONS = ("float32", "bfloat16")


def _is_number(value: Any) -> bool:
    return is_real(value) and math.isfinite(value)


def _float_or_text(text: str) -> float | str:
    """``text`` as a float where it reads as one, else as is (refused by the caller)."""
    try:
        return float(text)
    except ValueError:
        return text


def _resolutions(value: Any) -> tuple[float, ...]:
    """``validation_resolutions`` as a tuple of metres, from a list, one number
    (``--set validation_resolutions=0.1``) or a ``+``-separated text (``0.1+0.5``)."""
    if is_real(value):
        value = (value,)
    if isinstance(value, str):
        value = tuple(_float_or_text(t) for t in value.split("+") if t)
    if not isinstance(value, list | tuple):
        _fail("validation_resolutions", value, "must be a list of metres")
    for metres in value:
        if not _is_number(metres) or metres <= 0:
            _fail("validation_resolutions", tuple(value),
                  f"{metres!r} is not a positive number of metres")
    if len(set(value)) != len(value):
        _fail("validation_resolutions", tuple(value), "repeats a value")
    return tuple(value)


def _fail(name: str, value: Any, why: str) -> NoReturn:
    raise ValueError(f"invalid COMA config: {name} = {value!r}: {why}")


def _check_counts(config: Any, names: tuple[str, ...], minimum: int, why: str,
                  prefix: str = "") -> None:
    """:func:`_fail`'s refusal of the first field of ``names`` that is not a Python integer
    >= ``minimum`` (``prefix``: the section's, as in ``warm_start.``)."""
    check_integers(config, dict.fromkeys(names, minimum),
                   f"invalid COMA config: {prefix}{{name}} = {{value!r}}: {why}", numpy=False)


#: The flat names older configs gave the warm start's fields (still read, never written), by
#: their dotted names now. A plain string as ``warm_start`` is ``warm_start.planner``.
FLAT_NAMES: dict[str, str] = {
    "warm_start_missions": "warm_start.missions",
    "warm_start_epochs": "warm_start.epochs",
}


@dataclass(frozen=True)
class WarmStartConfig:
    """How to imitate a demonstrator before COMA training (``coma.warm_start``; not in the
    paper). Held as :attr:`COMAConfig.warm_start`; every field is validated at construction.

    Attributes:
        planner: registered planner name of the demonstrator, or ``""`` for no warm start
            (the networks start at random, or from ``init_policy``).
        missions: demonstration missions.
        missions_per_batch: missions flown in lock-step per collection batch.
        epochs: passes over the demonstrations when fitting each network.
        minibatch_size: transitions per gradient step.
        lr: Adam learning rate of the imitation and the critic fit.
        holdout: share of the missions kept out of training to measure the imitation.
    """

    planner: str = "ig"
    missions: int = 1_500
    missions_per_batch: int = 50
    epochs: int = 8
    minibatch_size: int = 600
    lr: float = 1e-3
    holdout: float = 0.1

    def __post_init__(self) -> None:
        if not isinstance(self.planner, str) or any(c in self.planner for c in " ,="):
            _fail("warm_start.planner", self.planner, "must be a planner name or ''")
        _check_counts(self, ("missions", "missions_per_batch", "epochs", "minibatch_size"), 1,
                      "must be an integer >= 1", prefix="warm_start.")
        if not _is_number(self.lr) or self.lr <= 0:
            _fail("warm_start.lr", self.lr, "must be a positive finite number")
        if not _is_number(self.holdout) or not 0 <= self.holdout < 1:
            _fail("warm_start.holdout", self.holdout, "must lie in [0, 1)")

    @property
    def enabled(self) -> bool:
        """Whether a run imitates a planner first (``planner`` is not ``""``)."""
        return bool(self.planner)

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-safe dict of the fields (the ``warm_start`` section of a saved config)."""
        return dataclasses.asdict(self)


@dataclass(frozen=True)
class COMAConfig:
    """COMA hyper-parameters. Every field is validated at construction.

    Attributes:
        variant: credit assignment: ``coma`` (counterfactual baseline over the agent's own
            actions, the critic sees the others' actions), ``central_qv`` (A = Q - V with a
            second critic for V), ``actor_independent`` (the critic does not see the other
            agents' actions), ``decentralised`` (the critic sees only the agent's observation).
        width: channels of each of the three convolutions (paper: 256).
        hidden: units of the hidden fully connected layer (paper: 256).
        missions: training missions in total (one mission = one episode of B steps).
        missions_per_update: missions collected in lock-step per update; with N agents and
            B steps an update sees ``missions_per_update * N * B`` agent-transitions (paper:
            50 missions = 3,000 transitions at N = 4, B = 15).
        minibatch_size: agent-transitions per gradient step (paper: 600).
        epochs: passes over each update's data (paper: 5).
        lr_actor: Adam learning rate of the actor (paper: 1e-5).
        lr_critic: Adam learning rate of the critic(s) (paper: 1e-4).
        gamma: discount.
        td_lambda: lambda of the per-episode TD(lambda) targets.
        target_update_transitions: the target critic is refreshed after this many
            agent-transitions (paper: 30,000).
        eps_start: exploration weight of the bounded softmax at the first mission.
        eps_end: its final value.
        eps_anneal_missions: missions over which eps falls linearly (paper: 10,000).
        max_grad_norm: gradient clipping (global L2 norm) of every network.
        normalise_advantage: scale each mini-batch's advantages to zero mean and unit
            standard deviation before the actor step (not in the paper).
        clip_ratio: 0 for the paper's actor loss ``-log pi(u) A``; > 0 for PPO's clipped
            surrogate with ratios ``pi(u) / pi_behaviour(u)`` clipped to 1 +- clip_ratio, which
            keeps several epochs on one batch from moving the policy too far (not in the
            paper).
        entropy_coef: weight of an entropy bonus in the actor loss (not in the paper: 0).
        eval_every: updates between greedy evaluations on held-out (``validation``) terrains.
        eval_missions: missions per evaluation.
        checkpoint_every: updates between checkpoints (the last one is always written).
        seed: seed of the run: terrains, sensor noise, network initialisation and sampling.
        warm_start: the warm start, a :class:`WarmStartConfig` (not in the paper): imitate
            the planner ``warm_start.planner`` (default ``ig``) on ``warm_start.missions``
            demonstration missions, ``warm_start.epochs`` passes per network, before COMA
            training; ``warm_start.planner = ""`` starts from random networks. The
            constructor also takes a planner's name (``warm_start=""``) or a dict of its
            fields.
        team_sizes: train on these team sizes, one drawn per update (domain randomisation,
            not in the paper; ``()``: the mission config's own ``n_agents``).
        comm_ranges: train on these communication ranges in metres (``inf`` allowed), one
            drawn per update like ``team_sizes`` (``()``: the mission config's own range).
            With several settings, validation scores the mean final entropy over all of
            them, ``eval_missions`` missions each.
        critic_warmup_updates: the first updates of the run fit only the critic(s), the
            actor stays as it starts (not in the paper): for fine-tuning with ``init_policy``
            on settings the critic has not seen, where a critic's early errors would otherwise
            move a good actor.
        gain_prior: 0 for the paper's actor; > 0 for a :class:`~coma.networks.GainPriorActor`
            whose logits add ``beta * expected gain`` of each option (needs the ``gain``
            feature planes) to a residual network that starts at zero: COMA then trains a
            correction of the ``ig`` planner's choice, starting from it (not in the paper);
            the value is beta's start. Use it with ``warm_start = ""``.
        residual_penalty: with ``gain_prior``, the actor loss adds this times the mean squared
            residual logit (centred over the valid actions: softmax ignores a shift), so the
            policy stays at the ``ig`` prior where the advantage does not consistently push
            it away (not in the paper; 0 = off).
        validation_terrains: terrain kinds of the validation missions, each flown in every
            setting (``()``: the training terrain), e.g. ``("split", "blobs", "fractal",
            "real")`` to select on every family.
        validation_resolutions: map resolutions (metres per cell) the validation missions are
            flown at, each in every validation setting (``()``: the training resolution),
            e.g. ``(0.1, 0.5)`` to select a policy trained at 0.5 m on the paper's 0.1 m maps
            too (a policy's lead can shrink at another resolution). Missions at 0.1 m cost
            several times those at 0.5 m.
        selection: how ``best.pt`` is chosen: ``mean`` (lowest mean final entropy over the
            validation settings) or ``worst_vs_ig`` (lowest worst-case, over validation
            terrains and settings, of the mean final entropy minus ``ig``'s on the same
            missions: a policy must not fall behind IG on any family).
        init_policy: a COMA policy file (``best.pt``, ``last.pt`` or a shipped policy) whose
            actor and critic start this run instead of random networks or a warm start
            (fine-tuning, not in the paper); its variant, size and feature planes must match.
        precision: what the learning passes (the warm start's fits and the updates) compute
            their convolutions in: ``float32``, or ``bfloat16`` (mixed precision: torch's
            autocast; the fully connected heads, weights, gradients, optimiser state and
            losses stay float32). bfloat16 is faster where the hardware has bfloat16
            instructions (recent CPUs with AVX512-BF16 or AMX, GPUs) and slower elsewhere;
            it trains other weights than float32 from the same seed. Missions always fly,
            and policies are validated and deployed, in float32.
        critic_targets: ``td_lambda`` (the paper's per-episode TD(lambda) targets from a
            target critic refreshed every ``target_update_transitions``) or ``reference``
            (what the authors' code computed: a target critic never refreshed from its random
            start, their episode-boundary errors, lambda-weights that do not sum to one and
            the reward paid one step late; :func:`coma.advantages.reference_td_targets`).
        advantage: what the actor's advantage takes for the action taken: ``critic`` (the
            paper: the critic's ``Q(s, u)``, so ``A = Q(s, u) - baseline``) or ``return`` (the
            mission's flown lambda-return, the critic's own target: ``A = G - baseline``,
            the baseline unchanged; unbiased whatever the critic's errors, since the
            counterfactual baseline does not depend on the agent's own action).
    """

    variant: str = "coma"
    width: int = 64
    hidden: int = 128
    missions: int = 20_000
    missions_per_update: int = 50
    minibatch_size: int = 600
    epochs: int = 4
    lr_actor: float = 1e-4
    lr_critic: float = 5e-4
    gamma: float = 0.99
    td_lambda: float = 0.8
    target_update_transitions: int = 30_000
    eps_start: float = 0.1
    eps_end: float = 0.02
    eps_anneal_missions: int = 2_000
    max_grad_norm: float = 10.0
    normalise_advantage: bool = True
    clip_ratio: float = 0.2
    entropy_coef: float = 0.0
    eval_every: int = 20
    eval_missions: int = 50
    checkpoint_every: int = 10
    seed: int = 0
    warm_start: WarmStartConfig = WarmStartConfig()
    team_sizes: tuple[int, ...] = ()
    comm_ranges: tuple[float, ...] = ()
    init_policy: str = ""
    critic_warmup_updates: int = 0
    gain_prior: float = 0.0
    residual_penalty: float = 0.0
    validation_terrains: tuple[str, ...] = ()
    validation_resolutions: tuple[float, ...] = ()
    selection: str = "mean"
    precision: str = "float32"
    critic_targets: str = "td_lambda"
    advantage: str = "critic"

    def __post_init__(self) -> None:
        if not isinstance(self.warm_start, WarmStartConfig):
            # A planner's name or a dict of fields (from JSON): read like from_dict does.
            object.__setattr__(self, "warm_start",
                               _warm_start_from(_warm_start_fields(self.warm_start)))
        # JSON and YAML hand back lists: keep tuples so configs compare and hash alike.
        if isinstance(self.validation_terrains, str):
            object.__setattr__(self, "validation_terrains", tuple(
                t for t in self.validation_terrains.split("+") if t))
        object.__setattr__(self, "validation_terrains", tuple(self.validation_terrains))
        object.__setattr__(self, "validation_resolutions",
                           _resolutions(self.validation_resolutions))
        if self.selection not in ("mean", "worst_vs_ig"):
            _fail("selection", self.selection, "choose 'mean' or 'worst_vs_ig'")
        if self.advantage not in ADVANTAGES:
            _fail("advantage", self.advantage, f"choose from {list(ADVANTAGES)}")
        if self.critic_targets not in CRITIC_TARGETS:
            _fail("critic_targets", self.critic_targets, f"choose from {list(CRITIC_TARGETS)}")
        if self.precision not in PRECISIONS:
            _fail("precision", self.precision, f"choose from {list(PRECISIONS)}")
        for name in ("team_sizes", "comm_ranges"):
            value = getattr(self, name)
            if isinstance(value, list | tuple):
                object.__setattr__(self, name, tuple(
                    math.inf if isinstance(v, str) and v.strip().lower() == "inf" else v
                    for v in value))
            else:
                _fail(name, value, "must be a list of values")
        for size in self.team_sizes:
            if not is_integer(size, 1, numpy=False):
                _fail("team_sizes", self.team_sizes, f"{size!r} is not an integer >= 1")
        if len(set(self.team_sizes)) != len(self.team_sizes):
            _fail("team_sizes", self.team_sizes, "repeats a value")
        for radius in self.comm_ranges:
            if not is_real(radius) or math.isnan(radius) or radius < 0:
                _fail("comm_ranges", self.comm_ranges,
                      f"{radius!r} is not a range >= 0 (inf allowed)")
        if len(set(self.comm_ranges)) != len(self.comm_ranges):
            _fail("comm_ranges", self.comm_ranges, "repeats a value")
        if not isinstance(self.init_policy, str):
            _fail("init_policy", self.init_policy, "must be a file path or ''")
        if self.variant not in VARIANTS:
            _fail("variant", self.variant, f"choose from {list(VARIANTS)}")
        _check_counts(self, ("width", "hidden", "missions", "missions_per_update",
                             "minibatch_size", "epochs", "target_update_transitions",
                             "eval_every", "eval_missions", "checkpoint_every"), 1,
                      "must be an integer >= 1")
        for name in ("width", "hidden"):
            check_layer_size(name, getattr(self, name), "invalid COMA config")
        if not is_integer(self.seed, 0, numpy=False):
            _fail("seed", self.seed, "must be a non-negative integer")
        for name in ("lr_actor", "lr_critic", "max_grad_norm"):
            value = getattr(self, name)
            if not _is_number(value) or value <= 0:
                _fail(name, value, "must be a positive finite number")
        if not isinstance(self.normalise_advantage, bool):
            _fail("normalise_advantage", self.normalise_advantage, "must be true or false")
        for name in ("clip_ratio", "entropy_coef", "gain_prior", "residual_penalty"):
            value = getattr(self, name)
            if not _is_number(value) or value < 0:
                _fail(name, value, "must be a non-negative finite number")
        for name in ("gamma", "td_lambda"):
            value = getattr(self, name)
            if not _is_number(value) or not 0 <= value <= 1:
                _fail(name, value, "must lie in [0, 1]")
        for name in ("eps_start", "eps_end"):
            value = getattr(self, name)
            if not _is_number(value) or not 0 <= value < 1:
                _fail(name, value, "must lie in [0, 1)")
        _check_counts(self, ("eps_anneal_missions", "critic_warmup_updates"), 0,
                      "must be a non-negative integer")

    def replace(self, **changes: Any) -> COMAConfig:
        """Copy with some fields changed (validated; unknown names are refused).

        Nested fields by their dotted name, ``replace(**{"warm_start.missions": 100})``, or
        as a dict of the fields to change, ``replace(warm_start={"missions": 100})``.
        """
        return from_dict(nested_fields(dataclasses.asdict(self), changes))

    def to_dict(self) -> dict[str, Any]:
        """Plain JSON-safe dict of the fields (tuples as lists, inf as the string 'inf', the
        warm start as a nested dict)."""
        values = dataclasses.asdict(self)
        values["team_sizes"] = list(self.team_sizes)
        values["comm_ranges"] = ["inf" if math.isinf(r) else r for r in self.comm_ranges]
        return values


def nested_fields(*layers: Mapping[str, Any]) -> dict[str, Any]:
    """Merge mappings of COMAConfig fields, later layers winning, into the nested form.

    The one owner of the old flat names (:data:`FLAT_NAMES`; a string as ``warm_start`` is
    ``warm_start.planner``). A nested field may also be named with a dot
    (``warm_start.missions``) or given as a dict (``{"warm_start": {"missions": 100}}``) or a
    :class:`WarmStartConfig`; a layer changes only the nested fields it names. Keys are not
    checked here (:func:`from_dict` refuses unknown ones by name).

    Raises:
        ValueError: ``warm_start`` is neither a string, a mapping nor a WarmStartConfig.
    """
    merged: dict[str, Any] = {}
    for layer in layers:
        if not isinstance(layer, Mapping):
            raise ValueError(f"invalid COMA config: expected a mapping, got {layer!r}")
        for key, value in layer.items():
            name = FLAT_NAMES.get(key, str(key))
            if name == "warm_start":
                fields = _warm_start_fields(value)
            elif name.startswith("warm_start."):
                fields = {name.removeprefix("warm_start."): value}
            else:
                merged[key] = value
                continue
            merged.setdefault("warm_start", {}).update(fields)
    return merged


def _warm_start_fields(value: Any) -> Mapping[str, Any]:
    """The warm-start fields a ``warm_start`` value names (all of a WarmStartConfig's)."""
    if isinstance(value, str):
        return {"planner": value}
    if isinstance(value, WarmStartConfig):
        return value.to_dict()
    if isinstance(value, Mapping):
        return value
    _fail("warm_start", value, "must be a planner name ('' for none), a mapping of "
          "WarmStartConfig fields or a WarmStartConfig")


def _warm_start_from(fields: Mapping[str, Any]) -> WarmStartConfig:
    known = {f.name for f in dataclasses.fields(WarmStartConfig)}
    unknown = sorted(set(fields) - known)
    if unknown:
        raise ValueError(f"invalid COMA config: unknown key(s) "
                         f"{[f'warm_start.{k}' for k in unknown]}; known keys: "
                         f"{[f'warm_start.{k}' for k in sorted(known)]}")
    return WarmStartConfig(**fields)


def from_dict(values: Mapping[str, Any]) -> COMAConfig:
    """Build a :class:`COMAConfig` from a mapping, nested or flat (:func:`nested_fields`);
    unknown keys are refused by name."""
    if not isinstance(values, Mapping):
        raise ValueError(f"invalid COMA config: expected a mapping, got {values!r}")
    fields = nested_fields(values)
    known = {f.name for f in dataclasses.fields(COMAConfig)}
    unknown = sorted(set(fields) - known)
    if unknown:
        raise ValueError(f"invalid COMA config: unknown key(s) {unknown}; "
                         f"known keys: {sorted(known)}")
    if "warm_start" in fields:
        fields["warm_start"] = _warm_start_from(fields["warm_start"])
    return COMAConfig(**fields)


#: Named starting points; ``cpu`` is the default of :class:`COMAConfig`.
PRESETS: dict[str, dict[str, Any]] = {
    "cpu": {},
    "paper": {
        "width": 256, "hidden": 256, "missions": 75_000, "missions_per_update": 50,
        "minibatch_size": 600, "epochs": 5, "lr_actor": 1e-5, "lr_critic": 1e-4,
        "target_update_transitions": 30_000, "eps_start": 0.5, "eps_end": 0.02,
        "eps_anneal_missions": 10_000, "eval_every": 50, "warm_start": {"planner": ""},
        "normalise_advantage": False, "clip_ratio": 0.0, "entropy_coef": 0.0,
    },
}
#: ``scratch``: the paper's learner from random networks, with the departures its ablations
#: showed are needed to learn on two cores (docs/departures.md): the actor's advantage takes the
#: flown lambda-return for the action taken (the counterfactual baseline unchanged), normalised
#: and clipped like PPO's at lr 3e-4, and narrower networks (64 channels, 128 hidden units).
PRESETS["scratch"] = {
    **PRESETS["paper"], "width": 64, "hidden": 128, "missions": 20_000,
    "advantage": "return", "normalise_advantage": True, "clip_ratio": 0.2, "lr_actor": 3e-4,
    "eval_every": 10, "eval_missions": 50,
}


def preset(name: str, **changes: Any) -> COMAConfig:
    """The named preset (``cpu`` or ``paper``) with optional field changes (names as in
    :func:`nested_fields`: ``preset("cpu", **{"warm_start.missions": 100})``)."""
    if name not in PRESETS:
        raise ValueError(f"unknown COMA preset {name!r}; choose from {sorted(PRESETS)}")
    return from_dict(nested_fields(PRESETS[name], changes))


def mission_settings(coma_config: COMAConfig, env_config: EnvConfig) -> list[EnvConfig]:
    """The mission configs a run trains on: ``env_config`` for every (team size, range) pair.

    Without ``team_sizes`` / ``comm_ranges`` this is ``[env_config]``. A team size without
    documented fixed starts gets random ones. Raises ValueError (naming the value) where a
    pair is not a valid mission, e.g. more agents than ``features.agent_id_scale``.
    """
    if not coma_config.team_sizes and not coma_config.comm_ranges:
        return [env_config]
    team = env_config.team
    sizes = coma_config.team_sizes or (team.n_agents,)
    ranges = coma_config.comm_ranges or (team.comm_range,)
    return [env_config.replace(team={"n_agents": n_agents, "comm_range": comm_range,
                                     "start": start_for_team_size(team.start, n_agents,
                                                                  env_config.world)})
            for n_agents in sizes for comm_range in ranges]
