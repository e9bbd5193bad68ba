"""Configuration of a mission: dataclasses with validation (YAML in and out:
:mod:`ipp_toolkit.config.files`).

Every number of the simulator is a field here; the defaults reproduce the paper.
Validation happens at construction and names the bad field and value, so a typo in a YAML
file fails at load time rather than deep inside numpy.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from .field_types import check_field_types, is_integer, short_repr
from .limits import MAX_REWARD_SCALE
from .starts import START_POSITIONS, fixed_start_waypoints, fixed_starts_fit
from .terrain_checks import check_blob_lattice, check_fractal_lattice, terrain_range

__all__ = ["WorldConfig", "SensorConfig", "TerrainConfig", "TeamConfig", "RewardConfig",
           "FeatureConfig", "EnvConfig", "terrain_kinds", "start_for_team_size",
           "fixed_starts_fit", "fixed_start_waypoints", "check_int"]

REAL_SOURCES = ("mission", "train", "validation", "test", "all")
DEFAULT_MIXTURE = (("split", 1.0), ("blobs", 1.0), ("fractal", 1.0), ("real", 1.0))
NAN_POLICIES = ("raise", "min", "max", "mean")
_NO_QUANTILE = ("split", "split-axis", "blobs")  # kinds that draw their own share
OBSERVATION_KINDS = ("dict", "box", "rllib")  # IPPEnv's observation (features.observation)


def check_int(name: str, value: Any, minimum: int) -> int:
    """``value`` as an int if it is an integer >= ``minimum`` (not a bool); else a ValueError
    naming ``name`` and the value."""
    if not is_integer(value, minimum):
        raise ValueError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _fail(section: str, name: str, value: Any, why: str) -> None:
    raise ValueError(f"invalid config: {section}.{name} = {short_repr(value)}: {why}")


def _positive(section: str, name: str, value: float) -> None:
    if not isinstance(value, int | float) or not math.isfinite(value) or value <= 0:
        _fail(section, name, value, "must be a positive finite number")


@dataclass(frozen=True)
class WorldConfig:
    """The area and its discretisations.

    Attributes:
        area_size: side of the square area in metres.
        resolution: map cell side r_M in metres; ``area_size / resolution`` must be an integer.
        grid_spacing: horizontal distance between planning waypoints in metres (also the
            length of a horizontal step).
        altitudes: the flight levels in metres, lowest first; a vertical action moves one
            level, whatever the horizontal spacing (the paper's real-world field: 4 m between
            waypoints, levels at 5, 10 and 15 m).
        prior: prior probability of "interesting" for every map cell.
    """

    area_size: float = 50.0
    resolution: float = 0.1
    grid_spacing: float = 5.0
    altitudes: tuple[float, ...] = (5.0, 10.0, 15.0)
    prior: float = 0.5

    def __post_init__(self) -> None:
        check_field_types(self, "world")
        object.__setattr__(self, "altitudes", tuple(float(a) for a in self.altitudes))
        _positive("world", "area_size", self.area_size)
        _positive("world", "resolution", self.resolution)
        _positive("world", "grid_spacing", self.grid_spacing)
        cells = self.area_size / self.resolution
        if abs(cells - round(cells)) > 1e-6 * cells:
            _fail("world", "resolution", self.resolution,
                  f"area_size {self.area_size} is not a whole number of cells")
        waypoints = self.area_size / self.grid_spacing
        if abs(waypoints - round(waypoints)) > 1e-9 * waypoints or round(waypoints) < 1:
            _fail("world", "grid_spacing", self.grid_spacing,
                  f"area_size {self.area_size} is not a whole number of grid steps")
        if len(self.altitudes) < 1:
            _fail("world", "altitudes", self.altitudes, "needs at least one altitude")
        if any((not math.isfinite(a)) or a <= 0 for a in self.altitudes):
            _fail("world", "altitudes", self.altitudes, "altitudes must be positive")
        if list(self.altitudes) != sorted(set(self.altitudes)):
            _fail("world", "altitudes", self.altitudes, "must be strictly increasing")
        if not 0.0 < self.prior < 1.0:
            _fail("world", "prior", self.prior, "must lie strictly between 0 and 1")

    @property
    def map_cells(self) -> int:
        """Number of map cells per side (500 at the defaults)."""
        return int(round(self.area_size / self.resolution))

    @property
    def grid_points(self) -> int:
        """Number of waypoints per side of the planning grid (11 at the defaults)."""
        return int(round(self.area_size / self.grid_spacing)) + 1


@dataclass(frozen=True)
class SensorConfig:
    """The downward camera and its altitude-dependent noise.

    Attributes:
        fov_deg: full square field of view in degrees.
        accuracy: probability that a cell reading is correct, one per altitude of the world.
    """

    fov_deg: float = 60.0
    accuracy: tuple[float, ...] = (0.99, 0.735, 0.625)

    def __post_init__(self) -> None:
        check_field_types(self, "sensor")
        object.__setattr__(self, "accuracy", tuple(float(a) for a in self.accuracy))
        if not 0.0 < self.fov_deg < 180.0:
            _fail("sensor", "fov_deg", self.fov_deg, "must lie in (0, 180)")
        if any(not 0.5 < a < 1.0 for a in self.accuracy):
            _fail("sensor", "accuracy", self.accuracy,
                  "each accuracy must lie in (0.5, 1): a reading must carry information "
                  "and a perfect sensor breaks the log-odds filter")


def terrain_kinds() -> tuple[str, ...]:
    """Every terrain kind: the names of the terrain registry
    (:data:`ipp_toolkit.world.registry.TERRAIN_GENERATORS`, the one owner of them; the
    built-in kinds, every kind added with ``register_terrain`` and those of installed packages'
    entry points, ``ipp_toolkit.terrains``)."""
    from ..world import registry  # imports the world package, which registers the kinds

    registry.load_entry_point_terrains()
    return tuple(registry.TERRAIN_GENERATORS)


@dataclass(frozen=True)
class TerrainConfig:
    """How the ground truth of a mission is generated.

    Attributes:
        kind: ``split`` (straight boundary at any angle), ``split-axis`` (the authors' four
            axis-aligned splits), ``blobs`` (thresholded smooth random field), ``fractal``
            (thresholded random field with a power-law spectrum: hotspots of many sizes),
            ``real`` (crops of the bundled real rasters, :mod:`ipp_toolkit.world.families`),
            ``mixture`` (one of several kinds per mission, see ``mixture``), ``raster`` (one
            raster file), or a kind added with :func:`ipp_toolkit.world.terrain.register_terrain`
            or by an installed package (entry-point group ``ipp_toolkit.terrains``).
        share_min, share_max: range of the interesting share for ``split``/``blobs``.
        blob_scale: correlation length of the ``blobs`` field in metres.
        raster: path of a .npy/.png/.tif file for ``raster`` (or pass an array to the
            terrain generator directly).
        threshold: raster cells whose area-averaged value is >= threshold are interesting (in
            the raster's units).
        threshold_quantile: the threshold as a quantile of the values instead, a fraction q
            (1 - q of the cells are interesting) or a range (q_min, q_max) drawn per mission.
            ``fractal`` and ``real`` use it (default (0.4, 0.9): 10-60 % interesting);
            ``raster`` uses it in place of ``threshold``.
        nan_policy: what to do with NaN raster cells: ``raise`` or fill with the raster's
            ``min``, ``max`` or ``mean``.
        spectral_exponent: range of the ``fractal`` field's exponent b (power ~ 1/f^b): near
            2 rough, many small hotspots; near 4 smooth, few large regions.
        real_sources: which bundled rasters ``real`` crops: ``mission`` (those of the
            mission's namespace: train, validation or test), one split, ``all``, or one
            raster by name (e.g. ``jacksboro_dem``, whatever its split).
        crop_fraction: range of a ``real`` crop's side as a fraction of the raster's shorter
            side.
        mixture: ``(kind, weight)`` pairs for ``mixture`` (a mapping in YAML); empty means
            split, blobs, fractal and real, equally weighted.
    """

    kind: str = "split"
    share_min: float = 0.30
    share_max: float = 0.60
    blob_scale: float = 5.0
    raster: str | None = None
    threshold: float | None = None
    nan_policy: str = "raise"
    threshold_quantile: float | tuple[float, float] | None = None
    spectral_exponent: tuple[float, float] = (2.0, 4.0)
    real_sources: str = "mission"
    crop_fraction: tuple[float, float] = (0.4, 1.0)
    mixture: tuple[tuple[str, float], ...] = ()

    def __post_init__(self) -> None:
        check_field_types(self, "terrain")
        kinds = terrain_kinds()
        if self.kind not in kinds:
            _fail("terrain", "kind", self.kind, f"unknown terrain kind; choose one of {kinds}")
        if not 0.0 < self.share_min <= self.share_max < 1.0:
            _fail("terrain", "share_min/share_max", (self.share_min, self.share_max),
                  "need 0 < share_min <= share_max < 1")
        _positive("terrain", "blob_scale", self.blob_scale)
        if self.nan_policy not in NAN_POLICIES:
            _fail("terrain", "nan_policy", self.nan_policy, f"choose one of {NAN_POLICIES}")
        if self.threshold is not None and not math.isfinite(self.threshold):
            _fail("terrain", "threshold", self.threshold, "must be finite")
        if self.threshold_quantile is not None and self.kind in _NO_QUANTILE:
            _fail("terrain", "threshold_quantile", self.threshold_quantile,
                  f"terrain kind {self.kind!r} does not use it (fractal, real, raster and "
                  "mixture do)")
        if self.threshold_quantile is not None:
            object.__setattr__(self, "threshold_quantile", terrain_range(
                "threshold_quantile", self.threshold_quantile, 0.0, 1.0, open_ends=True))
            if self.threshold is not None:
                _fail("terrain", "threshold_quantile", self.threshold_quantile,
                      "give either threshold (raster units) or threshold_quantile, not both")
        object.__setattr__(self, "spectral_exponent", terrain_range(
            "spectral_exponent", self.spectral_exponent, 0.0, 8.0, open_ends=False))
        object.__setattr__(self, "crop_fraction", terrain_range(
            "crop_fraction", self.crop_fraction, 0.0, 1.0, open_ends=False))
        if self.crop_fraction[0] <= 0.0:
            _fail("terrain", "crop_fraction", self.crop_fraction, "must lie in (0, 1]")
        if self.real_sources not in REAL_SOURCES:
            from ..world.registry import real_raster_names  # imports the world package

            if self.real_sources not in real_raster_names():
                _fail("terrain", "real_sources", self.real_sources,
                      f"choose one of {REAL_SOURCES} or a bundled raster: "
                      f"{', '.join(real_raster_names())}")
        object.__setattr__(self, "mixture", self._checked_mixture(kinds))
        if self.kind == "raster" or (self.kind == "mixture" and any(
                kind == "raster" for kind, _ in self.mixture_weights())):
            if self.raster is None:
                _fail("terrain", "raster", self.raster, "kind 'raster' needs a file path")
            if self.threshold is None and self.threshold_quantile is None:
                _fail("terrain", "threshold", self.threshold,
                      "kind 'raster' needs a threshold (or a threshold_quantile)")
        if self.raster is not None:
            object.__setattr__(self, "raster", os.fspath(self.raster))

    def _checked_mixture(self, kinds: tuple[str, ...]) -> tuple[tuple[str, float], ...]:
        items = self.mixture.items() if isinstance(self.mixture, Mapping) else self.mixture
        try:
            pairs = tuple((str(kind), float(weight)) for kind, weight in items)
        except (TypeError, ValueError):
            _fail("terrain", "mixture", self.mixture,
                  "must map terrain kinds to weights, e.g. {split: 1, fractal: 2}")
        for kind, weight in pairs:
            if kind not in kinds or kind == "mixture":
                _fail("terrain", "mixture", self.mixture,
                      f"unknown terrain kind {kind!r}; choose from {kinds} (not mixture)")
            if not math.isfinite(weight) or weight < 0:
                _fail("terrain", "mixture", self.mixture,
                      f"weight of {kind!r} must be a finite number >= 0, got {weight!r}")
        if pairs and sum(weight for _, weight in pairs) <= 0:
            _fail("terrain", "mixture", self.mixture, "needs a positive weight")
        if len({kind for kind, _ in pairs}) != len(pairs):
            _fail("terrain", "mixture", self.mixture, "names a kind twice")
        return pairs

    def mixture_weights(self) -> tuple[tuple[str, float], ...]:
        """The ``mixture`` pairs in force (the default four kinds when it is empty)."""
        return self.mixture or DEFAULT_MIXTURE


def start_for_team_size(start: str, n_agents: int, world: WorldConfig | None = None) -> str:
    """``start`` for a team of ``n_agents``: ``fixed`` falls back to ``random`` for team sizes
    without documented fixed starts (:data:`START_POSITIONS`) or, given ``world``, whose fixed
    starts do not snap to distinct waypoints of it (:func:`fixed_start_waypoints`)."""
    if start != "fixed":
        return start
    return "fixed" if fixed_starts_fit(world or WorldConfig(), n_agents) else "random"


@dataclass(frozen=True)
class TeamConfig:
    """The UAV team, its starts, its communication and its action rules.

    Attributes:
        n_agents: team size N.
        budget: number of steps B after the start measurement.
        start: ``fixed`` (documented positions for N = 2, 4, 8; the paper's) or ``random``
            (distinct 2-D cells from the mission's seed). ``fixed`` for another N is an error.
        start_altitude: altitude of every start position in metres.
        comm_range: communication radius D in metres (3-D distance); 0 = none, ``inf`` = full.
        message_drop: probability that one message (sender, receiver, step) is lost.
        invalid_action: ``raise`` (a masked action is an error) or ``hold`` (the UAV stays and
            still measures; the no-mask ablation).
        failures: ``(agent, step)`` pairs: that UAV fails at that step (1..budget): from then
            on it neither moves, senses nor communicates, and no longer holds its cell; what
            it measured before stays in its teammates' maps. Beyond the paper.
        random_failures: that many further UAVs fail, each drawn with its step (uniform in
            1..budget) from the mission's own ``failures`` stream. At least one UAV always
            survives.
    """

    n_agents: int = 4
    budget: int = 15
    start: str = "fixed"
    start_altitude: float = 15.0
    comm_range: float = 25.0
    message_drop: float = 0.0
    invalid_action: str = "raise"
    failures: tuple[tuple[int, int], ...] = ()
    random_failures: int = 0

    def __post_init__(self) -> None:
        if isinstance(self.comm_range, str):
            try:
                object.__setattr__(self, "comm_range", float(self.comm_range))
            except ValueError:
                _fail("team", "comm_range", self.comm_range, "must be a number of metres or 'inf'")
        check_field_types(self, "team")
        if not isinstance(self.n_agents, int | np.integer) or isinstance(self.n_agents, bool) \
                or self.n_agents < 1:
            _fail("team", "n_agents", self.n_agents, "must be an integer >= 1")
        if not isinstance(self.budget, int | np.integer) or self.budget < 1:
            _fail("team", "budget", self.budget, "must be an integer >= 1")
        if self.start not in ("fixed", "random"):
            _fail("team", "start", self.start, "choose 'fixed' or 'random'")
        if self.start == "fixed" and self.n_agents not in START_POSITIONS:
            _fail("team", "start", self.start,
                  f"fixed starts exist for {sorted(START_POSITIONS)} agents, not {self.n_agents}; "
                  "use start: random")
        if not isinstance(self.comm_range, int | float) or math.isnan(self.comm_range) \
                or self.comm_range < 0:
            _fail("team", "comm_range", self.comm_range, "must be >= 0 (metres) or inf")
        if not 0.0 <= self.message_drop <= 1.0:
            _fail("team", "message_drop", self.message_drop, "must lie in [0, 1]")
        if self.invalid_action not in ("raise", "hold"):
            _fail("team", "invalid_action", self.invalid_action, "choose 'raise' or 'hold'")
        self._check_failures()

    def _check_failures(self) -> None:
        try:
            pairs = tuple((int(agent), int(step)) for agent, step in self.failures)
            if any(isinstance(v, bool) or int(v) != v for pair in self.failures for v in pair):
                raise ValueError
        except (TypeError, ValueError):
            _fail("team", "failures", self.failures, "must be a list of [agent, step] pairs")
        object.__setattr__(self, "failures", pairs)
        agents = [agent for agent, _ in pairs]
        if any(not 0 <= a < self.n_agents for a in agents) or len(set(agents)) < len(agents):
            _fail("team", "failures", self.failures,
                  f"agents must be distinct indices in 0..{self.n_agents - 1}")
        if any(not 1 <= step <= self.budget for _, step in pairs):
            _fail("team", "failures", self.failures, f"steps must lie in 1..{self.budget}")
        if isinstance(self.random_failures, bool) or not isinstance(
                self.random_failures, int | np.integer) or self.random_failures < 0:
            _fail("team", "random_failures", self.random_failures, "must be an integer >= 0")
        if len(pairs) + self.random_failures >= self.n_agents:
            _fail("team", "random_failures", self.random_failures,
                  f"with {len(pairs)} given failures it leaves no UAV of {self.n_agents} "
                  "flying; at least one must survive")

    @property
    def has_failures(self) -> bool:
        """Whether any UAV fails during a mission."""
        return bool(self.failures) or self.random_failures > 0


@dataclass(frozen=True)
class RewardConfig:
    """Team reward and the class weights of the weighted entropy.

    Attributes:
        alpha: scale of the relative weighted-entropy reduction (in (0, 1e6]).
        beta: constant added every step (a time penalty when negative; |beta| <= 1e6).
        weight_interesting: weight w1 of cells believed interesting (p > 0.5).
        weight_uninteresting: weight w2 of cells believed uninteresting (p < 0.5).
    """

    alpha: float = 22.0
    beta: float = -0.5
    weight_interesting: float = 1.0
    weight_uninteresting: float = 0.0

    def __post_init__(self) -> None:
        check_field_types(self, "reward")
        _positive("reward", "alpha", self.alpha)
        if self.alpha > MAX_REWARD_SCALE:
            _fail("reward", "alpha", self.alpha, f"must be at most {MAX_REWARD_SCALE:g}")
        if not math.isfinite(self.beta) or abs(self.beta) > MAX_REWARD_SCALE:
            _fail("reward", "beta", self.beta,
                  f"must be finite, between -{MAX_REWARD_SCALE:g} and {MAX_REWARD_SCALE:g}")
        for name in ("weight_interesting", "weight_uninteresting"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                _fail("reward", name, value, "must lie in [0, 1]")
        if self.weight_interesting == 0 and self.weight_uninteresting == 0:
            _fail("reward", "weight_interesting", self.weight_interesting,
                  "and weight_uninteresting are both 0: the reward would count no entropy")


#: ``features.gain_interest``: the Gaussian smoothing of ``gain_smoothing`` metres.
GAIN_INTEREST_SMOOTHED = "smoothed"
#: ``features.gain_interest``: the packaged learned field prior.
GAIN_INTEREST_LEARNED = "learned"


@dataclass(frozen=True)
class FeatureConfig:
    """Which 11 x 11 feature planes the actor and the critic see.

    Actor planes, in this order when switched on: ``budget``, ``agent_id``, ``position`` (a),
    ``own_position`` (off by default: not in the paper),
    ``local_map`` (b), ``local_entropy`` (c), ``measurement_entropy`` (d), ``footprints`` (e),
    ``gain`` (three planes, off by default: not in the paper).
    Critic-only planes: ``all_positions`` (f), ``global_map`` (g), ``global_entropy`` (h),
    ``all_footprints`` (i), ``other_actions`` (j, six planes).

    Attributes:
        centred: the position plane (a) is an 11 x 11 window centred on the agent (+-25 m at
            the defaults) with out-of-area cells marked -1; otherwise it is the absolute grid.
        own_position: an extra plane in the map's absolute frame marking only the agent's own
            cell (altitude code). The paper's centred plane (a) shows the agent always at the
            centre, so relating it to the absolute map planes (b)-(e) must be learned from the
            out-of-area border; this plane gives it directly (a departure, see
            docs/departures.md).
        gain: three planes ``gain_level``, ``gain_up``, ``gain_down`` in an 11 x 11 window
            centred on the agent: at every waypoint of the agent's current altitude, the one
            above and the one below (0 outside the area or where that altitude does not
            exist), the expected weighted-entropy reduction of the agent's local map by one
            reading taken there, divided by the cell count of the largest footprint and the
            larger class weight (so in [0, 1]). It is the quantity the ``ig`` planner
            maximises, given to the actor at full map resolution instead of the 5 m block
            means of (b)-(e) (a departure, see docs/departures.md;
            :func:`ipp_toolkit.sim.features.gain_planes`).
        gain_smoothing: 0 keeps ``ig``'s objective in the ``gain`` planes; > 0 (metres) puts
            the ``ig_spatial`` objective there instead: the entropy a reading removes from
            interesting cells, weighted by each cell's probability of being interesting
            smoothed over its neighbourhood with a Gaussian of this standard deviation
            (:mod:`ipp_toolkit.belief.interest`; the maps treat cells as independent, real fields
            are not). Same scale, divided by the largest footprint's cell count.
        gain_interest: where the ``ig_spatial`` objective's probability of interest comes
            from. ``smoothed`` (default): the Gaussian smoothing of ``gain_smoothing``
            (0: ``ig``'s objective). ``learned``: the packaged learned field prior, the one
            ``ig_learned`` flies (:mod:`ipp_toolkit.belief.field_prior`); or the path of a
            field-prior file (``ipp-train prior`` writes ``RUN/best.pt``). With a learned
            prior the planes hold ``ig_learned``'s objective and ``gain_smoothing`` is unused.
        gain_false_positive: w >= 0; with the ``ig_spatial`` objective in the planes (a
            smoothing or a learned prior), w > 0 adds ``w * (1 - pi) * false_positive_gain``
            per cell: the value of checking cells the local map holds above 0.5 that are
            probably not interesting (``false_positive_weight`` of ``ig_spatial`` and
            ``ig_learned``). 0 (default) leaves the planes as they were.
        gain_false_positive_steps: k >= 1 adds that term only in the last k steps
            (``false_positive_steps``); 0 (default): at every step.
        agent_id_scale: the id plane holds (id + 1) / agent_id_scale, so a policy trained with
            N agents reads valid ids for any team of up to this many agents.
        observation: ``IPPEnv``'s per-agent observation: ``dict`` (planes and mask),
            ``box`` (the planes alone; the mask in ``info["action_mask"]``) or ``rllib``
            (RLlib's action-masking layout: ``observations``, the planes flattened, and
            ``action_mask``).
    """

    budget: bool = True
    agent_id: bool = True
    position: bool = True
    own_position: bool = False
    local_map: bool = True
    local_entropy: bool = True
    measurement_entropy: bool = True
    footprints: bool = True
    gain: bool = False
    all_positions: bool = True
    global_map: bool = True
    global_entropy: bool = True
    all_footprints: bool = True
    other_actions: bool = True
    centred: bool = True
    gain_smoothing: float = 0.0
    gain_interest: str = GAIN_INTEREST_SMOOTHED
    gain_false_positive: float = 0.0
    gain_false_positive_steps: int = 0
    agent_id_scale: int = 8
    observation: str = "dict"

    def __post_init__(self) -> None:
        check_field_types(self, "features")
        if self.observation not in OBSERVATION_KINDS:
            _fail("features", "observation", self.observation, f"one of {OBSERVATION_KINDS}")
        for name, meaning in (("gain_smoothing", "of metres >= 0 (0: ig's objective)"),
                              ("gain_false_positive", ">= 0 (0: no false-positive term)")):
            value = getattr(self, name)
            if (isinstance(value, bool)
                    or not isinstance(value, int | float | np.integer | np.floating)
                    or not 0 <= value < math.inf):
                _fail("features", name, value, f"must be a finite number {meaning}")
        if (self.gain_interest not in (GAIN_INTEREST_SMOOTHED, GAIN_INTEREST_LEARNED)
                and not os.path.isfile(self.gain_interest)):
            _fail("features", "gain_interest", self.gain_interest,
                  f"must be {GAIN_INTEREST_SMOOTHED!r}, {GAIN_INTEREST_LEARNED!r} or the path "
                  "of a field-prior file (`ipp-train prior` writes RUN/best.pt); no such file")
        for name, least in (("agent_id_scale", 1), ("gain_false_positive_steps", 0)):
            value = getattr(self, name)
            if not is_integer(value, least):
                _fail("features", name, value, f"must be an integer >= {least}")
        if not any(getattr(self, name) for name in ACTOR_PLANES):
            _fail("features", "actor planes", "all off", "the actor needs at least one plane")


ACTOR_PLANES = ("budget", "agent_id", "position", "own_position", "local_map", "local_entropy",
                "measurement_entropy", "footprints", "gain")


@dataclass(frozen=True)
class EnvConfig:
    """Everything that defines a mission; nested sections mirror the YAML file."""

    world: WorldConfig = field(default_factory=WorldConfig)
    sensor: SensorConfig = field(default_factory=SensorConfig)
    terrain: TerrainConfig = field(default_factory=TerrainConfig)
    team: TeamConfig = field(default_factory=TeamConfig)
    reward: RewardConfig = field(default_factory=RewardConfig)
    features: FeatureConfig = field(default_factory=FeatureConfig)

    def __post_init__(self) -> None:
        for name, cls in _SECTIONS.items():
            value = getattr(self, name)
            if isinstance(value, Mapping):  # EnvConfig(world={...}): the section's fields
                object.__setattr__(self, name, _build(cls, value, name))
            elif not isinstance(value, cls):
                raise ValueError(f"invalid config: section {name!r} must be a {cls.__name__} "
                                 f"or a dict of its fields, got {short_repr(value)}")
        if len(self.sensor.accuracy) != len(self.world.altitudes):
            _fail("sensor", "accuracy", self.sensor.accuracy,
                  f"needs one value per altitude {self.world.altitudes}")
        cells_2d = self.world.grid_points ** 2
        if self.team.n_agents > cells_2d:
            _fail("team", "n_agents", self.team.n_agents,
                  f"more agents than the {cells_2d} 2-D cells of the planning grid")
        if not any(math.isclose(self.team.start_altitude, a) for a in self.world.altitudes):
            _fail("team", "start_altitude", self.team.start_altitude,
                  f"unknown altitude; choose one of {self.world.altitudes}")
        if self.team.start == "fixed" and not fixed_starts_fit(self.world, self.team.n_agents):
            _fail("team", "start", self.team.start,
                  f"the fixed starts {START_POSITIONS.get(self.team.n_agents)} snap to fewer than "
                  f"{self.team.n_agents} distinct waypoints of this world; use random")
        if self.features.agent_id and self.team.n_agents > self.features.agent_id_scale:
            _fail("features", "agent_id_scale", self.features.agent_id_scale,
                  f"smaller than the team ({self.team.n_agents} agents)")
        check_blob_lattice(self.terrain, self.world)
        check_fractal_lattice(self.terrain, self.world)

    def replace(self, **sections: Any) -> EnvConfig:
        """Copy with some fields replaced, e.g. ``cfg.replace(team={"n_agents": 8})``.

        A section may be given as a dataclass or as a dict of field overrides.
        """
        updates = {}
        for name, value in sections.items():
            if name not in _SECTIONS:
                raise ValueError(f"invalid config: unknown section {name!r}; "
                                 f"choose from {sorted(_SECTIONS)}")
            if isinstance(value, Mapping):
                value = _build(_SECTIONS[name], {**dataclasses.asdict(getattr(self, name)),
                                                  **value}, name)
            elif not isinstance(value, _SECTIONS[name]):
                raise ValueError(f"invalid config: section {name!r} must be a "
                                 f"{_SECTIONS[name].__name__} or a dict of its fields, "
                                 f"got {value!r}")
            updates[name] = value
        return dataclasses.replace(self, **updates)


_SECTIONS: dict[str, type] = {
    "world": WorldConfig,
    "sensor": SensorConfig,
    "terrain": TerrainConfig,
    "team": TeamConfig,
    "reward": RewardConfig,
    "features": FeatureConfig,
}



def _build(cls: type, values: Mapping[str, Any], section: str) -> Any:
    if not isinstance(values, Mapping):
        raise ValueError(f"invalid config: section {section!r} must be a mapping, got {values!r}")
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"invalid config: unknown key(s) {unknown} in section {section!r}; "
                         f"known keys: {sorted(known)}")
    return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in values.items()})
