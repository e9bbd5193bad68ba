"""The COMA learner (centralised critic, counterfactual baseline) built on :mod:`ipp_toolkit`.

Importing this package (not its modules: no torch) declares the names of COMA planners and
policies that were removed, so that asking for one says what to use instead
(:func:`ipp_toolkit.planning.removed_name` imports it for that).
"""

from ipp_toolkit.planning import register_removed_name

_MIXED_GONE = ("removed 2026-12-01: dominated by the default coma on validation missions, "
               "see experiments/generalisation/README.md; use coma (its default policy)")

# The mixed-team fine-tuning: its planner alias and its shipped policy (and so its recipe).
register_removed_name("coma_mixed", _MIXED_GONE)
register_removed_name("coma=shipped:mixed", _MIXED_GONE)

# The gain-prior actor on ig_learned's clean-up planes: no checkpoint of its training beat its
# start on validation, so the shipped file was its untrained start (ig_learned's choices).
register_removed_name("coma=shipped:learned-cleanup", (
    "removed 2026-12-03: training never moved it from its start, so it flew ig_learned's "
    "moves; use ig_learned, or coma (its default policy)"))
