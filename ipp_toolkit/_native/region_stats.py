"""The names and count of the statistics the map updates return in one vector; shared by the
NumPy reference (:mod:`ipp_toolkit._native.kernels`) and the compiled kernels
(:mod:`ipp_toolkit._native.compiled_kernels`)."""

REGION_STATS = ("entropy_interesting", "squared_error_interesting", "true_positive",
                "predicted_positive", "new_weights_old_entropy", "old_weighted_entropy",
                "new_weighted_entropy")
"""The statistics vector of :func:`apply_values_with_stats` (and of
:meth:`ipp_toolkit.belief.mapping.BeliefMaps.refresh_with_stats`), in order: the changes inside the
region of the sum of H over interesting cells, of the sum of (1 - p)^2 over them, of the true
and of the predicted positives (p > 0.5), then the sums of W' H (posterior weights, prior
entropies), of W H before and of W' H' after."""

N_STATS = len(REGION_STATS)
