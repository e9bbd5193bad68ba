"""The optional extras (``ray``, ``rllib``, ``torchrl``, ...): how to install one, and the
one way the toolkit imports an optional package.

A feature that needs an optional package imports it through :func:`require_extra` when it is
used, never at module level, so the toolkit imports without it; where the package is missing
the user gets one line naming the feature, the package and the command that installs it,
instead of a bare ``ModuleNotFoundError`` from deep inside a run. Each feature keeps its own
error class (``RayUnavailableError``, ``RLlibUnavailableError``), since the commands catch
them to exit with code 2.
"""

from __future__ import annotations

import importlib
from types import ModuleType

__all__ = ["install_command", "require_extra"]


def install_command(extra: str, constraints: str = "constraints.txt") -> str:
    """The command that installs the optional ``extra`` from the repository root, with the
    pinned versions of ``constraints`` (the README's install line plus ``.[extra]``)."""
    return f'pip install -c {constraints} -e ".[{extra}]"'


def require_extra(module: str, purpose: str, install: str, *, package: str | None = None,
                  error: type[Exception] = ImportError) -> ModuleType:
    """Import and return ``module``, or raise ``error`` saying how to install it.

    Args:
        module: the module to import, e.g. ``"ray"`` or ``"ray.rllib"``.
        purpose: what needs it, the subject of the message (``"the ray backend"``).
        install: the command that installs it (:func:`install_command`).
        package: the package's name for people (default: ``module``), e.g. ``"ray[rllib]"``.
        error: the exception class to raise (a feature's own, which its command catches).

    Raises:
        error: ``module`` cannot be imported; the message names ``purpose``, ``package``,
            why the import failed and ``install``.
    """
    try:
        return importlib.import_module(module)
    except ImportError as err:
        raise error(f"{purpose} needs {package or module}, which cannot be imported here "
                    f"({err}); install the optional extra with: {install}") from None
