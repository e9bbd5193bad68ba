"""No function in the toolkit runs past about 80 lines, and no module past about 600: a reader
can hold one step in view. The compiled kernels (ipp_toolkit/_native) are left out, since numba
wants a kernel's loops in one function."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("ipp_toolkit", "baselines", "coma", "reports")
EXCLUDED = (ROOT / "ipp_toolkit" / "_native",)
MAX_FUNCTION_LINES = 80
MAX_MODULE_LINES = 620


def _sources() -> list[Path]:
    files = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            if not any(path.is_relative_to(folder) for folder in EXCLUDED):
                files.append(path)
    return files


def _long_functions() -> list[str]:
    found = []
    for path in _sources():
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                # From the def line (decorators aside) to the last line of the body.
                lines = node.end_lineno - node.lineno + 1
                if lines > MAX_FUNCTION_LINES:
                    where = path.relative_to(ROOT)
                    found.append(f"{where}:{node.lineno} {node.name} ({lines} lines)")
    return found


def test_no_function_is_longer_than_80_lines():
    long = _long_functions()
    assert not long, "functions over 80 lines:\n" + "\n".join(long)


def test_no_module_is_longer_than_about_600_lines():
    long = [f"{path.relative_to(ROOT)} ({n} lines)" for path in _sources()
            if (n := len(path.read_text().splitlines())) > MAX_MODULE_LINES]
    assert not long, "modules over about 600 lines:\n" + "\n".join(long)
