"""The COMA learner (centralised critic, counterfactual baseline) built on :mod:`ipp_toolkit`."""
