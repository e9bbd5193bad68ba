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
