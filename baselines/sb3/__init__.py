"""PPO and the other Stable-Baselines3 learners: the policies and their files (:mod:`.ppo`,
:mod:`.policies`, :mod:`.loading`, :mod:`.zips`, :mod:`.normalization`), the ``ppo`` and ``sb3``
planners (:mod:`.planner`), training (:mod:`.ppo_training`, :mod:`.training`, :mod:`.runner`),
evaluation by missions (:mod:`.evaluation`) and the shipped PPO policies (``checkpoints/``)."""
