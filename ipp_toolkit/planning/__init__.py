"""The planner interface, the per-agent read-only view, and the registry of planners by name.

A planner decides a joint action from what each UAV knows: its own local map at full
resolution, its own pose, the teammates it hears within range and their latest footprints,
and its action mask; never the global map or the ground truth. The views it receives are
read-only numpy views into the mission, so a planner cannot change the mission by accident.

Register a planner with the decorator::

    from ipp_toolkit.planning import Planner, register_planner

    @register_planner("stay-low")
    class StayLow(Planner):
        def act(self, views):
            ...

or, from another package, with an entry point in the group ``ipp_toolkit.planners``
(``name = module:factory``); :func:`make_planner` finds both.
"""

from __future__ import annotations

import abc
import dataclasses
import importlib
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from ..belief.interest import block_means, square_cells
from ..config.schema import EnvConfig, FeatureConfig
from ..io import CheckpointError
from ..plugins import entry_points
from ..sim.features import actor_observations, square_means
from ..sim.mission import MissionState
from ..sim.team import choose_in_order

__all__ = [
    "FEATURES_NOTE",
    "AgentView",
    "TeamSquareMeans",
    "Planner",
    "PlannerFactory",
    "agent_views",
    "choose_for_views",
    "policy_inputs",
    "planner_views",
    "planners_in_process",
    "entry_point_planners",
    "check_planner_name",
    "register_planner",
    "make_planner",
    "available_planners",
    "planner_modules",
    "planner_factory",
    "check_policy_transfer",
    "resolve_shipped",
    "ENTRY_POINT_GROUP",
    "REMOVED_NAMES",
    "register_removed_name",
    "removed_name",
]

ENTRY_POINT_GROUP = "ipp_toolkit.planners"

#: Names that earlier versions accepted and that were removed, with when, why and what to use
#: instead: a planner name (``old_name``) or a shipped policy as ``PLANNER=shipped:NAME``. The
#: package that owned a name declares it (:func:`register_removed_name`, on import of its
#: top-level package); :func:`planner_factory` and :func:`resolve_shipped` consult it through
#: :func:`removed_name` before refusing a name as unknown, so an old command fails with the way
#: forward.
REMOVED_NAMES: dict[str, str] = {}


def register_removed_name(name: str, note: str) -> None:
    """Declare that ``name`` was removed: a planner name, or ``PLANNER=shipped:NAME``.

    ``note`` completes "planner NAME was ..." (or "shipped policy ... was ..."): when, why and
    what to use instead, e.g. ``"removed 2026-12-01: ...; use coma (its default policy)"``.
    Call it in the ``__init__`` of the package that owned the name: that module is what
    :func:`removed_name` imports to find it, not the planners' own (heavier) modules.
    """
    REMOVED_NAMES[name] = note


def _planner_packages() -> list[str]:
    """The top-level packages of the entry-point planners, each once."""
    return list(dict.fromkeys(entry.module.partition(".")[0]
                              for entry in _entry_points().values()))


def removed_name(name: str) -> str | None:
    """The note of a removed ``name`` (:data:`REMOVED_NAMES`), or None.

    A name not declared in this process yet may belong to a package not imported yet: the
    top-level packages of the entry-point planners are imported first (their ``__init__``
    declares what they removed; the planners' modules, torch for a learned one, are not).
    """
    if name not in REMOVED_NAMES:
        for package in _planner_packages():
            try:
                importlib.import_module(package)
            except Exception:  # noqa: BLE001 - a broken package: the name is then just unknown
                continue
    return REMOVED_NAMES.get(name)


def _read_only(array: np.ndarray) -> np.ndarray:
    view = array.view()
    view.flags.writeable = False
    return view


@dataclass(frozen=True)
class AgentView:
    """What one UAV knows at a decision point. Every array is read-only.

    Attributes:
        index: the agent's index k (``uav_k``).
        step: steps taken so far; ``budget - step`` steps are left.
        budget: the mission's budget B.
        position: (3,) int waypoint indices (ix, iy, iz).
        local_logodds: (H, W) float32 log-odds of the agent's local map.
        local_prob: (H, W) float32 probabilities of the local map.
        local_entropy: (H, W) float32 per-cell entropy (bits) of the local map.
        mask: (6,) int8 valid actions.
        teammates: (K,) int indices of the teammates it heard at the last exchange.
        teammate_positions: (K, 3) int their waypoint indices.
        teammate_footprints: (K, 4) int their latest footprint rectangles.
        footprint: (4,) int the agent's own latest footprint rectangle.
        observation: (C, G, G) float32 the actor observation planes (for learned planners).
        team_squares: where the view was built from a mission state, the team's kept square
            means of this step (:meth:`square_means` reads them); None otherwise.
    """

    index: int
    step: int
    budget: int
    position: np.ndarray
    local_logodds: np.ndarray
    local_prob: np.ndarray
    local_entropy: np.ndarray
    mask: np.ndarray
    teammates: np.ndarray
    teammate_positions: np.ndarray
    teammate_footprints: np.ndarray
    footprint: np.ndarray
    observation: np.ndarray
    team_squares: TeamSquareMeans | None = dataclasses.field(default=None, repr=False,
                                                             compare=False)

    def square_means(self, block: int) -> np.ndarray:
        """(H / block, W / block) float32 means of ``local_prob`` over block x block squares:
        :func:`~ipp_toolkit.belief.interest.block_means`, to the bit. At the ~0.5 m squares
        of :func:`~ipp_toolkit.belief.interest.square_cells` a view built from a mission
        reads the means the mission keeps up to date (the blocks a step touched are summed
        again, not the whole map); any other block, or a view built by hand, sums the map.
        """
        if self.team_squares is not None:
            kept = self.team_squares.means(block)
            if kept is not None:
                return kept[self.index]
        return block_means(self.local_prob, block)


class TeamSquareMeans:
    """The team's :func:`~ipp_toolkit.sim.features.square_means` at one decision point,
    read from the mission state on the first request (a planner that never asks costs
    nothing) and kept for the other agents' views. Asked after the state has moved on, or
    for another square size, it answers None (the view then sums its own map)."""

    def __init__(self, state: MissionState) -> None:
        self._state, self._step = state, state.step
        world = state.config.world
        self.block = square_cells(world.map_cells, world.resolution)
        self._means: np.ndarray | None = None

    def means(self, block: int) -> np.ndarray | None:
        """(N, H / block, W / block) read-only float32 means, or None (see the class)."""
        if block != self.block or self._state.step != self._step:
            return None
        if self._means is None:
            means = square_means(self._state)
            if not self._state.block_mean_cache.incremental:
                # Means of the stacked maps, which need not match each map's to the bit.
                self._step = -1
                return None
            self._means = _read_only(means.copy())
        return self._means


_NO_MAP = _read_only(np.zeros((0, 0), dtype=np.float32))
"""The local-map arrays of views built without them (``with_local_maps=False``)."""


def agent_views(state: MissionState, with_observations: bool = True,
                features: FeatureConfig | None = None,
                with_local_maps: bool = True) -> list[AgentView]:
    """One read-only :class:`AgentView` per agent of a mission.

    Args:
        state: the mission at a decision point.
        with_observations: build the (C, G, G) actor planes too (skip for planners that
            do not read them: an empty (0, G, G) array is given instead).
        features: which planes to build (default: the mission config's); a learned planner
            observes with the features it was trained on (``Planner.observation_features``).
        with_local_maps: give each view its local map's per-cell arrays (skip for planners
            that do not read them: empty (0, 0) arrays are given instead, and the maps'
            per-cell arrays are not brought up to date).
    """
    n = state.n_agents
    masks = state.masks()
    g = state.geometry.grid_points
    features = state.config.features if features is None else features
    planes = (actor_observations(state, features) if with_observations
              else np.zeros((n, 0, g, g), dtype=np.float32))
    squares = TeamSquareMeans(state) if with_local_maps else None
    views = []
    for k in range(n):
        heard = np.flatnonzero(state.heard[k])
        mates = heard[heard != k]
        views.append(AgentView(
            index=k,
            step=state.step,
            budget=state.budget,
            position=_read_only(state.positions[k].copy()),
            local_logodds=_read_only(state.maps.logodds[k]) if with_local_maps else _NO_MAP,
            local_prob=_read_only(state.maps.prob[k]) if with_local_maps else _NO_MAP,
            local_entropy=_read_only(state.maps.entropy[k]) if with_local_maps else _NO_MAP,
            mask=_read_only(masks[k]),
            teammates=_read_only(mates),
            teammate_positions=_read_only(state.positions[mates].copy()),
            teammate_footprints=_read_only(state.footprints[mates].copy()),
            footprint=_read_only(state.footprints[k].copy()),
            observation=_read_only(planes[k]),
            team_squares=squares,
        ))
    return views


def policy_inputs(views: Sequence[AgentView], expected_shape: tuple[int, ...] | None = None,
                  policy: str = "the policy") -> tuple[np.ndarray, np.ndarray]:
    """A learned planner's batch: the agents' observation planes and masks.

    Args:
        views: the N agents' views at this decision point.
        expected_shape: the (C, G, G) the policy was trained on; None skips the check.
        policy: how the error names the policy (e.g. its algorithm and file).

    Returns:
        ((N, C, G, G) float32 planes, (N, 6) bool masks).

    Raises:
        CheckpointError: the planes are not of ``expected_shape``, naming both shapes.
    """
    observations = np.stack([view.observation for view in views])
    if expected_shape is not None and observations.shape[1:] != tuple(expected_shape):
        raise CheckpointError(f"{policy} expects observations of shape "
                              f"{tuple(expected_shape)}, got {observations.shape[1:]}")
    masks = np.stack([view.mask for view in views]).astype(bool)
    return observations, masks


def choose_for_views(scores: np.ndarray, views: Sequence[AgentView],
                     rescore: Callable[[int, np.ndarray], np.ndarray] | None = None
                     ) -> np.ndarray:
    """Each agent's best valid option, chosen in agent order like ``ig`` chooses.

    A learned planner scores every agent's options in one batched pass, then decides in
    agent order: an agent skips the 2-D targets that teammates it heard, and who decided
    before it, already chose (:func:`ipp_toolkit.sim.team.choose_in_order`), instead of
    losing a same-target contest and holding its position.

    Args:
        scores: (N, 6) values of the agents' options (logits, Q-values); higher is better.
        views: the N agents' views at this decision point.
        rescore: optional ``rescore(k, targets)`` -> agent k's (6,) scores given its decided
            teammates' (K, 3) targets, as for :func:`~ipp_toolkit.sim.team.choose_in_order`.

    Returns:
        (N,) int64 actions, each valid.
    """
    n = len(views)
    heard = np.zeros((n, n), dtype=bool)
    for k, view in enumerate(views):
        heard[k, view.teammates] = True
    positions = np.stack([view.position for view in views])
    masks = np.stack([view.mask for view in views]).astype(bool)
    return choose_in_order(np.asarray(scores), positions, masks, heard, rescore)


def planner_views(state: MissionState, planner: Planner) -> list[AgentView]:
    """:func:`agent_views` with what ``planner`` reads: its observation planes
    (``needs_observations``, ``observation_features``) and its local maps
    (``needs_local_maps``); attributes a duck-typed planner lacks take the defaults."""
    return agent_views(state, planner.needs_observations,
                       getattr(planner, "observation_features", None),
                       getattr(planner, "needs_local_maps", True))


class Planner(abc.ABC):
    """A (possibly learned) policy for the whole team.

    Lifecycle: ``reset(config, seed)`` once per mission, then ``act(views)`` once per step.
    Set ``needs_observations = False`` on planners that never read ``AgentView.observation``
    to skip building the feature planes, and ``needs_local_maps = False`` on planners that
    never read ``AgentView.local_logodds`` / ``local_prob`` / ``local_entropy`` to skip
    bringing the maps' per-cell arrays up to date (they get empty (0, 0) arrays instead).
    """

    name: str = "planner"
    needs_observations: bool = True
    needs_local_maps: bool = True
    #: The feature planes ``AgentView.observation`` carries for this planner; ``None``: those
    #: of the mission config. Learned planners set the features they were trained on.
    observation_features: FeatureConfig | None = None

    def reset(self, config: EnvConfig, seed: int) -> None:  # noqa: B027 - optional hook
        """Prepare for a new mission of ``config``; ``seed`` seeds any randomness."""

    @abc.abstractmethod
    def act(self, views: list[AgentView]) -> np.ndarray:
        """Choose a joint action.

        Args:
            views: one view per agent, in agent order.

        Returns:
            (N,) int actions; each must be valid under its view's mask.
        """


PlannerFactory = Callable[..., Planner]
_REGISTRY: dict[str, PlannerFactory] = {}


def register_planner(name: str, replace: bool = False
                     ) -> Callable[[PlannerFactory], PlannerFactory]:
    """Class/function decorator registering a planner factory under ``name``.

    Args:
        name: the planner's name (no spaces, commas or ``=``).
        replace: replace a planner registered under ``name`` before (in this process) or
            installed under it (a built-in such as ``ig``, an entry point); without it, a
            taken name is refused instead of silently flying another planner.
    """
    if not isinstance(name, str) or not name or any(c in name for c in " ,="):
        raise ValueError(f"invalid planner name {name!r}: use a non-empty word without "
                         "spaces, commas or '='")

    def decorator(factory: PlannerFactory) -> PlannerFactory:
        existing = _REGISTRY.get(name)
        if existing is not None and existing is not factory and not replace:
            raise ValueError(f"planner name {name!r} is already registered by "
                             f"{existing.__module__}.{existing.__qualname__}; pass "
                             "replace=True to replace it")
        entry = None if existing is not None or replace else _entry_points().get(name)
        # The installed planner's own module may register it too: that is no replacement.
        if entry is not None and entry.value.replace(" ", "") != \
                f"{factory.__module__}:{factory.__qualname__}":
            raise ValueError(f"planner name {name!r} is taken by the installed planner "
                             f"{entry.value}; pass replace=True to replace it in this process")
        _REGISTRY[name] = factory
        return factory

    return decorator


def _entry_points() -> dict[str, metadata.EntryPoint]:
    # Through ipp_toolkit.plugins: IPP_TOOLKIT_NO_PLUGINS=1 keeps only the toolkit's own.
    return {ep.name: ep for ep in entry_points(ENTRY_POINT_GROUP)}


def planner_modules(names: Sequence[str]) -> list[str]:
    """The modules of the entry-point planners among ``names``, each once (a worker process
    imports them ahead of its tasks: :class:`ipp_toolkit.runs.process_pool.WorkerPool`)."""
    entries = _entry_points()
    return list(dict.fromkeys(entries[name].module for name in names if name in entries))


def entry_point_planners() -> list[str]:
    """Names of the planners registered by entry point (installed packages), sorted."""
    return sorted(_entry_points())


def check_planner_name(name: str) -> None:
    """Raise :func:`planner_factory`'s ValueError for an unknown or removed ``name``, without
    loading an entry point (which imports the planner's module: torch, for a learned one)."""
    if name not in _REGISTRY and name not in _entry_points():
        planner_factory(name)


def planners_in_process() -> list[str]:
    """Names whose factory this process holds already (registered by decorator, or an entry
    point loaded here), sorted. A spawned worker knows only the entry points until it loads
    them: a name registered here by decorator alone is unknown there."""
    return sorted(_REGISTRY)


def available_planners() -> list[str]:
    """Names of every planner registered by decorator or entry point, sorted."""
    return sorted(set(_REGISTRY) | set(_entry_points()))


def planner_factory(name: str) -> PlannerFactory:
    """The factory registered under ``name`` (loading its entry point if needed).

    Raises:
        ValueError: an unknown name (the message lists the registered ones) or a removed one
            (the message says what to use instead, :func:`removed_name`).
    """
    if name not in _REGISTRY:
        entry = _entry_points().get(name)
        if entry is None:
            removed = removed_name(name)
            if removed is not None:
                raise ValueError(f"planner {name!r} was {removed}")
            raise ValueError(f"unknown planner {name!r}; registered planners: "
                             f"{', '.join(available_planners()) or 'none'}")
        factory = entry.load()
        _REGISTRY.setdefault(name, factory)
    return _REGISTRY[name]


def make_planner(name: str, **kwargs: Any) -> Planner:
    """Build the planner registered under ``name`` with keyword options."""
    planner = planner_factory(name)(**kwargs)
    if not isinstance(planner, Planner):
        raise TypeError(f"planner factory {name!r} returned {type(planner).__name__}, "
                        "not a Planner")
    return planner


#: How a :func:`check_policy_transfer` note about the mission's feature switches begins: not
#: a transfer (the policy observes with its own planes), so reports may leave it out.
FEATURES_NOTE = "features: the policy observes with its own"


def check_policy_transfer(trained: EnvConfig, requested: EnvConfig, path: str = "") -> list[str]:
    """Check that a policy trained on ``trained`` can fly missions of ``requested``.

    A learned planner always observes with the feature planes it was trained on (it sets
    :attr:`Planner.observation_features`), so only what those planes cannot express is an
    error: another planning grid, or more agents than the id plane can number. Team size,
    communication range, budget, map resolution, terrain, sensor, reward and the mission's own
    feature switches may differ: the documented transfer of the paper's robustness study; so
    may the area and the waypoint spacing when the grid keeps its waypoint count (the paper's
    real-world field: 40 m with waypoints every 4 m, 11 x 11 like the 50 m field at 5 m).

    Returns:
        human-readable notes of the transferred settings (empty if none differ).

    Raises:
        CheckpointError: naming the setting and both values.
    """
    where = f"checkpoint {path!r}" if path else "the policy"
    if trained.world.grid_points != requested.world.grid_points:
        raise CheckpointError(f"{where} was trained on a {trained.world.grid_points}-waypoint "
                              f"grid, requested {requested.world.grid_points}")
    features = trained.features
    if features.agent_id and requested.team.n_agents > features.agent_id_scale:
        raise CheckpointError(f"{where} numbers agents up to features.agent_id_scale = "
                              f"{features.agent_id_scale}; requested "
                              f"{requested.team.n_agents} agents")
    notes = []
    for section, name in (("team", "n_agents"), ("team", "comm_range"), ("team", "budget"),
                          ("world", "resolution"), ("world", "area_size"),
                          ("world", "grid_spacing")):
        old = getattr(getattr(trained, section), name)
        new = getattr(getattr(requested, section), name)
        if old != new:
            notes.append(f"{section}.{name}: trained {old}, running {new}")
    if trained.features != requested.features:
        old = dataclasses.asdict(trained.features)
        new = dataclasses.asdict(requested.features)
        diffs = ", ".join(f"{k} {new[k]!r} -> {old[k]!r}" for k in old if old[k] != new[k])
        notes.append(f"{FEATURES_NOTE} ({diffs})")
    return notes


def resolve_shipped(policy: str | os.PathLike[str], shipped: Mapping[str, Path],
                    planner: str) -> Path:
    """A policy as a user names it: ``shipped:NAME`` (a key of ``shipped``), or a path.

    Learned planners (``coma=shipped:NAME``, ``ppo=shipped:NAME``, ``--init shipped:NAME``)
    resolve their names here, each with its own table of shipped files.

    Raises:
        ValueError: ``shipped:`` with an unknown name (the message lists ``planner``'s names)
            or a removed one (the message says what to use instead, :func:`removed_name`).
    """
    text = os.fspath(policy)
    if not text.startswith("shipped:"):
        return Path(text)
    name = text.removeprefix("shipped:")
    if name not in shipped:
        removed = removed_name(f"{planner}={text}")
        if removed is not None:
            raise ValueError(f"shipped policy {text!r} of the {planner} planner was {removed}")
        raise ValueError(f"unknown shipped policy {name!r}; shipped policies: "
                         f"{', '.join(f'shipped:{n}' for n in shipped)} (of the {planner} "
                         "planner)")
    return shipped[name]

