"""The toolkit's subpackages are layers: a module-level import never goes up the list of
the package docstring (:mod:`ipp_toolkit`); lazy imports inside functions are allowed."""

from __future__ import annotations

import ast
from pathlib import Path

import ipp_toolkit

ROOT = Path(ipp_toolkit.__file__).parent
#: Rank of each top-level part of the package; a module may import its own rank or lower.
LAYERS = {
    "probability": 0, "io": 0, "_native": 0, "extras": 0, "plugins": 0,
    "config": 1,
    "world": 2,
    "belief": 3,
    "sim": 4,
    "env": 5, "vec": 5, "team_env": 5, "uav_env": 5, "torchrl_env": 5,
    "planning": 6,
    "runs": 7,
    "data": 0,
}


def _part(path: Path) -> str:
    relative = path.relative_to(ROOT).with_suffix("")
    return relative.parts[0]


def _imported_parts(path: Path) -> set[str]:
    """Top-level parts of ipp_toolkit a module imports at module level (not in functions)."""
    tree = ast.parse(path.read_text())
    package = ".".join(("ipp_toolkit",) + path.relative_to(ROOT).with_suffix("").parts[:-1])
    parts = set()
    for node in tree.body:  # module level only: imports inside functions are lazy
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                name = ".".join(base + ([node.module] if node.module else []))
            else:
                name = node.module or ""
            names = [name] if node.module else [f"{name}.{a.name}" for a in node.names]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        else:
            continue
        for full in names:
            pieces = full.split(".")
            if pieces[0] == "ipp_toolkit" and len(pieces) > 1:
                parts.add(pieces[1])
    return parts


def test_every_module_level_import_goes_down_the_layers():
    upward = []
    for path in sorted(ROOT.rglob("*.py")):
        if path == ROOT / "__init__.py":
            continue  # the package's front door re-exports from every layer
        own = _part(path)
        assert own in LAYERS, f"{path}: add {own!r} to the layers of this test and the docs"
        for part in _imported_parts(path):
            if part in LAYERS and LAYERS[part] > LAYERS[own]:
                upward.append(f"{path.relative_to(ROOT)} imports ipp_toolkit.{part}")
    assert not upward, "imports up the layers:\n" + "\n".join(upward)
