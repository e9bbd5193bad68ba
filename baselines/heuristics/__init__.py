"""The non-learning planners: ``random``, ``coverage`` (``coverage_paper``), ``ig``
(``ig_paper``, greedy information gain with lookahead) and ``ig_spatial``."""
