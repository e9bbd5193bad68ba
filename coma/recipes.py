"""Recipes: how every shipped COMA policy was trained, as named, runnable presets.

``ipp-train coma --preset NAME --out DIR`` retrains the shipped policy ``NAME`` (the names of
``coma=shipped:NAME``): the learner's fields, the training missions (terrain, features, team
settings) and, for fine-tuned policies, every stage in order. A multi-stage recipe trains
stage k into ``DIR/stage-k`` and starts stage k + 1 from stage k's ``best.pt``; with
``--resume`` a finished stage is kept and the first unfinished one continues. Flags given
with a recipe (``--seed``, ``--missions``, ``--set``, ``--feature``, ...) change every stage,
e.g. ``--missions 200`` for a quick try.

The values are those recorded with the shipped weights (``coma/checkpoints/*.json``, the
``command`` entries), so a recipe is documentation that runs. Training is stochastic in the
order of floating-point sums across torch builds; the same seed on the same build gives the
same policy.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from .config import PRESETS

__all__ = ["Stage", "RECIPES", "recipe"]


@dataclass(frozen=True)
class Stage:
    """One training run of a recipe.

    Attributes:
        name: short label (the stage's folder is ``stage-K-NAME``).
        coma: COMAConfig fields over the ``cpu`` preset (the warm start's as a nested
            dict, ``{"warm_start": {"planner": ""}}``; see :func:`coma.config.nested_fields`).
        env: mission config sections over ``ipp-train coma``'s defaults (r_M = 0.5 m, the
            own-position plane), e.g. ``{"features": {"gain": True}}``.
        init: where the networks start: None (fresh), ``shipped:NAME``, or ``previous`` for
            the previous stage's ``best.pt``.
    """

    name: str
    coma: dict[str, Any] = field(default_factory=dict)
    env: dict[str, dict[str, Any]] = field(default_factory=dict)
    init: str | None = None


#: Every shipped policy's recipe, by its ``shipped:NAME``.
RECIPES: dict[str, tuple[Stage, ...]] = {
    "paper-actor": (
        Stage("coma", {"missions": 37_000}),
    ),
    # The paper's learner from random networks (the scratch preset, the paper's inputs): the
    # best of three training seeds on validation missions.
    "scratch": (
        Stage("scratch", {**PRESETS["scratch"], "seed": 1},
              {"features": {"own_position": False}}),
    ),
}


def recipe(name: str) -> tuple[Stage, ...]:
    """The stages of the shipped policy ``name``; ValueError naming the known ones."""
    if name not in RECIPES:
        raise ValueError(f"no recipe named {name!r}; recipes: {sorted(RECIPES)}")
    return RECIPES[name]
