"""RLlib's learners: the policy file (:mod:`.policy`), the ``rllib`` planner (:mod:`.planner`),
the training run's settings (:mod:`.train_config`), ``ipp-train rllib`` (:mod:`.training`) and
what imports Ray (:mod:`.module`, :mod:`.run`)."""
