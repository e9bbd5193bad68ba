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

# The gain-prior policies (a learned residual over an IG objective's logits): the manual keeps
# the default coma (scratch, from random networks) and the paper's actor; the records of these
# (each with the command that trained it) are in the repository's experiments/shipped-policies/.
_GAIN_PRIOR_GONE = ("removed 2026-12-03 with the other gain-prior policies (the default coma "
                    "learns from random networks); its record and command: "
                    "experiments/shipped-policies/{file}; use coma or ig_learned")
for _name in ("prior", "prior-mixture", "spatial-mixture", "learned-mixture"):
    _file = f"coma_{_name.replace('-', '_')}_4agents_d25.json"
    register_removed_name(f"coma=shipped:{_name}", _GAIN_PRIOR_GONE.format(file=_file))
register_removed_name("coma_prior", _GAIN_PRIOR_GONE.format(file="coma_prior_4agents_d25.json"))
