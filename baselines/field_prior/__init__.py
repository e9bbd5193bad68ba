"""The learned field prior: its planner ``ig_learned`` (:mod:`.planner`) and its training,
``ipp-train prior`` (:mod:`.training`)."""
