"""The names of the shipped COMA policies and their files (``coma=shipped:NAME``,
``--init shipped:NAME``).

Nothing here imports torch: ``ipp-train coma``'s flags name them in ``--help`` without it.
:mod:`coma.persistence` re-exports every name and resolves them to files.
"""

from __future__ import annotations

__all__ = ["SHIPPED_POLICY", "SHIPPED_POLICIES", "DEFAULT_SHIPPED"]

SHIPPED_POLICY = "coma_4agents_d25.pt"
#: Shipped policies by name, as in ``coma=shipped:NAME`` and ``--init shipped:NAME``.
#: ``scratch``: the paper's learner from random networks on the paper's inputs (the
#: ``scratch`` preset: no imitation, no IG-derived planes or logits).
#: ``paper-actor``: the paper's actor warm-started by imitating ``ig``, then trained by COMA.
#: Removed names (``mixed``, the gain-prior policies ``prior``, ``prior-mixture``,
#: ``spatial-mixture``, ``learned-mixture``) are refused with a hint:
#: ``ipp_toolkit.planning.REMOVED_NAMES``.
SHIPPED_POLICIES = {"paper-actor": SHIPPED_POLICY, "scratch": "coma_scratch_4agents_d25.pt"}
#: The shipped policy the ``coma`` planner flies by default: a policy COMA's training moved
#: (:func:`coma.persistence.untrained_reason`), chosen on validation missions (docs/training.md).
DEFAULT_SHIPPED = "scratch"
