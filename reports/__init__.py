"""Tables, figures and the console scripts: the top layer, free to import everything.

Python API::

    from reports import compare_planners
    comparison = compare_planners(agents=4, comm=25.0, planners="ig,coverage,random", trials=20)
    print(comparison.table)

- :func:`compare_planners`, :class:`Comparison`, :func:`build_config` (from the module
  ``reports.compare``, which also keeps the function under its earlier name ``compare``)
- :func:`summarise`, :class:`Summary`, :func:`to_markdown`, :func:`to_csv`, :func:`to_latex`,
  :func:`write_tables` (``reports.tables``)
- :func:`plot_curves`, :func:`plot_trajectories` (``reports.plots``)

``reports.compare`` is the module, as ``import reports.compare`` expects. Earlier versions
exported the function under that name; ``from reports import compare`` then ``compare(...)``
still works (the module is callable) and warns to use :func:`compare_planners`.

The figure functions import matplotlib when first asked for: ``ipp-compare``'s evaluation
workers (spawned processes, which import the console script and so this package) never draw,
and matplotlib's import cost each of them about 0.6 s.
"""

import sys
import types
import warnings
from typing import Any

from .compare import Comparison, build_config, compare_planners
from .tables import Summary, summarise, to_csv, to_latex, to_markdown, write_tables

__all__ = [
    "Comparison",
    "Summary",
    "build_config",
    "compare_planners",
    "plot_curves",
    "plot_trajectories",
    "summarise",
    "to_csv",
    "to_latex",
    "to_markdown",
    "write_tables",
]


class _CallableModule(types.ModuleType):
    """The module ``reports.compare``, callable as the function earlier versions exported
    under that name (``from reports import compare``), so their code keeps running."""

    def __call__(self, *args: Any, **kwargs: Any) -> Comparison:
        warnings.warn("calling reports.compare (the module) is deprecated: use "
                      "reports.compare_planners (from reports import compare_planners)",
                      FutureWarning, stacklevel=2)
        return compare_planners(*args, **kwargs)


# The import above bound the submodule to the package's ``compare``; only its class changes.
sys.modules[f"{__name__}.compare"].__class__ = _CallableModule


def __getattr__(name: str) -> Any:
    if name in ("plot_curves", "plot_trajectories"):
        from . import plots

        return getattr(plots, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
