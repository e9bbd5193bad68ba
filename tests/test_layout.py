"""The tree is what the README says, and its imports go one way.

* Every path the README's ``## Layout`` block names exists (a renamed or removed folder
  fails here until the README follows).
* No module of the project imports itself in a circle: a static scan of every import in
  ``ipp_toolkit``, ``baselines``, ``coma`` and ``reports``, lazy ones inside functions
  included (only ``if TYPE_CHECKING:`` blocks, never run, are left out); a circle inside one
  package counts as much as one across packages.
* ``ipp_toolkit`` imports nothing from ``baselines``, ``coma`` or ``reports``.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("ipp_toolkit", "baselines", "coma", "reports")


# --------------------------------------------------------------------------------------------
# README layout


def layout_paths(readme: str) -> list[str]:
    """The paths of the README's Layout block: on each line, the leading words that end in
    ``/`` or ``.py``, nested under the folder of the line above with less indentation."""
    section = readme.split("\n## Layout\n", 1)[1]
    block = section.split("```", 2)[1]
    paths: list[str] = []
    parents: list[tuple[int, str]] = []  # (indentation, folder)
    for line in block.splitlines()[1:]:
        if not line.strip():
            continue
        indent = len(line) - len(line.lstrip())
        while parents and parents[-1][0] >= indent:
            parents.pop()
        prefix = parents[-1][1] if parents else ""
        named = []
        for word in line.split():
            if not re.fullmatch(r"[\w.-]+(/|\.py)", word):
                break
            named.append(prefix + word)
        assert named, f"a Layout line names no path: {line!r}"
        paths.extend(named)
        if named[-1].endswith("/"):
            parents.append((indent, named[-1]))
    return paths


def test_layout_parser_nests_folders():
    readme = "x\n## Layout\n\n```\na/   text\n  b/  text b/\n    c.py d.py\n  e/\nf/ g/\n```\n"
    assert layout_paths(readme) == ["a/", "a/b/", "a/b/c.py", "a/b/d.py", "a/e/", "f/", "g/"]


def test_every_path_of_the_readme_layout_exists():
    paths = layout_paths((ROOT / "README.md").read_text(encoding="utf-8"))
    assert len(paths) >= 10
    missing = [path for path in paths if not (ROOT / path).exists()
               or (ROOT / path).is_dir() != path.endswith("/")]
    assert not missing, f"README's Layout names paths that do not exist: {missing}"


def test_the_readme_layout_lists_every_subpackage_of_the_toolkit_and_baselines():
    paths = set(layout_paths((ROOT / "README.md").read_text(encoding="utf-8")))
    for package in ("ipp_toolkit", "baselines"):
        for child in sorted((ROOT / package).iterdir()):
            if child.is_dir() and (child / "__init__.py").exists():
                assert f"{package}/{child.name}/" in paths, \
                    f"README's Layout does not name {package}/{child.name}/"


# --------------------------------------------------------------------------------------------
# Imports


def _modules() -> dict[str, tuple[Path, bool]]:
    """Module name -> (file, is a package's __init__)."""
    modules = {}
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            is_package = parts[-1] == "__init__"
            if is_package:
                parts = parts[:-1]
            modules[".".join(parts)] = (path, is_package)
    return modules


def _is_type_checking(node: ast.AST) -> bool:
    return isinstance(node, ast.If) and (
        (isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING")
        or (isinstance(node.test, ast.Attribute) and node.test.attr == "TYPE_CHECKING"))


def _imports(tree: ast.AST) -> list[ast.Import | ast.ImportFrom]:
    """Every import statement of a module, at any depth, outside ``if TYPE_CHECKING:``."""
    found: list[ast.Import | ast.ImportFrom] = []
    stack = [tree]
    while stack:
        node = stack.pop()
        for child in ast.iter_child_nodes(node):
            if _is_type_checking(child):
                stack.extend(child.orelse)
                continue
            if isinstance(child, ast.Import | ast.ImportFrom):
                found.append(child)
            stack.append(child)
    return found


def import_graph() -> dict[str, set[str]]:
    """Module -> the project's modules it imports (a ``from package import name`` that names a
    submodule counts as that submodule; a package's ``__init__`` is only counted when imported
    by name, not as the parent of a submodule)."""
    modules = _modules()

    def resolve(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    graph: dict[str, set[str]] = {}
    for module, (path, is_package) in modules.items():
        package = module if is_package else module.rpartition(".")[0]
        targets: set[str] = set()
        for node in _imports(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                targets.update(filter(None, (resolve(alias.name) for alias in node.names)))
                continue
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            for alias in node.names:
                submodule = f"{source}.{alias.name}"
                target = submodule if submodule in modules else resolve(source)
                if target:
                    targets.add(target)
        targets.discard(module)
        graph[module] = targets
    return graph


def import_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    cycles = []
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    cycles.append(sorted(component))
    return cycles


def test_the_cycle_finder_finds_a_circle_of_lazy_imports():
    assert import_cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert import_cycles({"a": {"b"}, "b": set()}) == []


def test_no_module_imports_itself_in_a_circle():
    graph = import_graph()
    assert {"baselines.sb3.ppo", "coma.planner", "ipp_toolkit.world.terrain"} <= set(graph)
    assert "ipp_toolkit.world.registry" in graph["ipp_toolkit.config.schema"]  # lazy, counted
    cycles = import_cycles(graph)
    assert not cycles, "modules that import each other in a circle:\n" + "\n".join(
        " -> ".join(cycle) for cycle in cycles)


def test_the_toolkit_imports_nothing_of_the_packages_built_on_it():
    upward = sorted(f"{module} imports {target}" for module, targets in import_graph().items()
                    if module.split(".")[0] == "ipp_toolkit" for target in targets
                    if target.split(".")[0] != "ipp_toolkit")
    assert not upward, "\n".join(upward)


def test_the_bottom_layer_imports_nothing_of_the_toolkit():
    assert import_graph()["ipp_toolkit.io"] == set()
    assert import_graph()["ipp_toolkit.plugins"] == set()  # the terrain registry imports it
