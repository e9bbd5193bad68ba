"""Tables, figures and the console scripts: the top layer, free to import everything.

Python API::

    from reports import compare
    comparison = compare(agents=4, comm=25.0, planners="ig,coverage,random", trials=20)
    print(comparison.table)

- :func:`compare`, :class:`Comparison`, :func:`build_config` (``reports.compare``)
- :func:`summarise`, :class:`Summary`, :func:`to_markdown`, :func:`to_csv`, :func:`to_latex`,
  :func:`write_tables` (``reports.tables``)
- :func:`plot_curves`, :func:`plot_trajectories` (``reports.plots``)

Note: ``reports.compare`` is the function; the module is ``sys.modules["reports.compare"]``.

The figure functions import matplotlib when first asked for: ``ipp-compare``'s evaluation
workers (spawned processes, which import the console script and so this package) never draw,
and matplotlib's import cost each of them about 0.6 s.
"""

from typing import Any

from .compare import Comparison, build_config, compare
from .tables import Summary, summarise, to_csv, to_latex, to_markdown, write_tables

__all__ = [
    "Comparison",
    "Summary",
    "build_config",
    "compare",
    "plot_curves",
    "plot_trajectories",
    "summarise",
    "to_csv",
    "to_latex",
    "to_markdown",
    "write_tables",
]


def __getattr__(name: str) -> Any:
    if name in ("plot_curves", "plot_trajectories"):
        from . import plots

        return getattr(plots, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
