"""The names of the shipped COMA policies and their files (``coma=shipped:NAME``,
``--init shipped:NAME``).

Nothing here imports torch: ``ipp-train coma``'s flags name them in ``--help`` without it.
:mod:`coma.persistence` re-exports every name and resolves them to files.
"""

from __future__ import annotations

__all__ = ["SHIPPED_POLICY", "SHIPPED_PRIOR_POLICY", "SHIPPED_POLICIES", "DEFAULT_SHIPPED"]

SHIPPED_POLICY = "coma_4agents_d25.pt"
#: The gain-prior policy (a residual over ``ig``'s objective), 4 agents, D = 25 m
#: (planner ``coma_prior``).
SHIPPED_PRIOR_POLICY = "coma_prior_4agents_d25.pt"
#: Shipped policies by name, as in ``coma=shipped:NAME`` and ``--init shipped:NAME``.
#: ``prior-mixture``: the ``prior`` policy fine-tuned on the terrain mixture (split, blobs,
#: fractal, real), selected by its worst gap to IG over those families on validation missions.
#: ``spatial-mixture``: the gain-prior actor over the ``ig_spatial`` objective
#: (``features.gain_smoothing`` = 5 m), its residual trained by COMA on the terrain mixture.
#: ``learned-mixture``: the same recipe over ``ig_learned``'s objective
#: (``features.gain_interest = learned``: the learned field prior in the gain planes).
#: ``scratch``: the paper's learner from random networks on the paper's inputs (the
#: ``scratch`` preset: no imitation, no IG-derived planes or logits).
#: Removed names (``mixed``) are refused with a hint: ``ipp_toolkit.planning.REMOVED_NAMES``.
SHIPPED_POLICIES = {"paper-actor": SHIPPED_POLICY, "prior": SHIPPED_PRIOR_POLICY,
                    "prior-mixture": "coma_prior_mixture_4agents_d25.pt",
                    "spatial-mixture": "coma_spatial_mixture_4agents_d25.pt",
                    "learned-mixture": "coma_learned_mixture_4agents_d25.pt",
                    "scratch": "coma_scratch_4agents_d25.pt"}
#: The shipped policy the ``coma`` planner flies by default: a policy COMA's training moved
#: (:func:`coma.persistence.untrained_reason`), chosen on validation missions (docs/training.md).
DEFAULT_SHIPPED = "scratch"
