"""TorchRL policies: the shared actor of a TorchRL run as a plain-weights file
(:mod:`.policy`) and the ``torchrl`` planner that flies it (:mod:`.planner`); flying needs
torch alone, not TorchRL."""
