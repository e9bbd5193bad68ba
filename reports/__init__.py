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
"""

from .compare import Comparison, build_config, compare
from .plots import plot_curves, plot_trajectories
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
