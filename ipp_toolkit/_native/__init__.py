"""Compiled inner loops (Numba) with their NumPy reference code: internal, no public API."""
