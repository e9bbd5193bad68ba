"""Planners to compare against, built on :mod:`ipp_toolkit`, one subpackage per kind:

- :mod:`baselines.heuristics`: the non-learning planners (``random``, ``coverage``, ``ig``,
  ``ig_paper``, ``ig_spatial``);
- :mod:`baselines.field_prior`: the learned field prior's planner (``ig_learned``) and its
  training (``ipp-train prior``);
- :mod:`baselines.sb3`: PPO and the other Stable-Baselines3 learners, their planners (``ppo``,
  ``sb3``), files and training (``ipp-train ppo``, ``ipp-train sb3``), and the shipped PPO
  policies (``checkpoints/``);
- :mod:`baselines.rllib`: RLlib's learners, their planner (``rllib``) and training
  (``ipp-train rllib``; Ray is imported only there).

In each, what flies a planner never imports its training code.
"""

from ipp_toolkit.planning import register_removed_name

# The PPO policies on other gain planes: the manual keeps the default (learned-mixture) and the
# one from random networks (split); their records (with the commands that trained them) are in
# the repository's experiments/shipped-policies/.
for _name in ("spatial-mixture", "learned-cleanup"):
    register_removed_name(f"ppo=shipped:{_name}", (
        "removed 2026-12-03 (the manual keeps the default ppo and split); its record and "
        f"command: experiments/shipped-policies/ppo_{_name.replace('-', '_')}_4agents_d25.json; "
        "use ppo or ig_learned"))
