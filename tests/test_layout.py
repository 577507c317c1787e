"""The house: the folders show the architecture, and imports run one way.

Read from the source (every import, the ones inside functions too), not from what Python loaded:
no module imports itself through others; each imports only layers at or below its own; the
convenience layer is imported by nothing in the library; usd-core is imported in one module; and
plugins use flockkit's public names only.
"""

import ast
from pathlib import Path

import networkx as nx
import pytest

ROOT = Path(__file__).resolve().parents[1]
LIBRARY = ROOT / "flockkit"

# Lowest first. A module may import its own layer and those below; "flockkit" is the package's
# public API, which only the command line (a thin layer over it) imports.
LAYERS = [
    ("core", ["_version", "errors", "_arrays", "validate", "rigid", "_files", "_atomic", "_npzfile", "_tomlfile",
              "_progress", "parallel", "motion", "mesh", "skeleton", "regions", "interfaces", "kinds", "hookspecs",
              "registry"]),
    ("io", ["io"]),
    ("systems", ["graphs", "constrained"]),
    ("scene", ["scene"]),
    ("crowd", ["crowd"]),
    ("testing", ["testing"]),
    ("viz", ["viz"]),
    ("convenience", ["convenience"]),
    ("api", ["flockkit"]),
    ("cli", ["cli", "blender"]),  # blender: the Blender add-on, which runs flockkit through the command line's worker
]  # fmt: skip
# The imports that run back up, each with the reason it must.
UPWARD = {}


def _module(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {_module(p): p for p in LIBRARY.rglob("*.py")}


def _imports(path: Path, modules) -> set[str]:
    """The flockkit modules `path` imports, wherever in it."""
    name = _module(path)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names if a.name.split(".")[0] == "flockkit")
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            if source.split(".")[0] != "flockkit":
                continue
            for alias in node.names:  # a submodule imported by name depends on the submodule
                found.add(f"{source}.{alias.name}" if f"{source}.{alias.name}" in modules else source)
    return {m for m in found if m != name}


def _layer(module: str) -> int:
    parts = module.split(".")
    key = parts[1] if len(parts) > 1 else "flockkit"
    for rank, (_, names) in enumerate(LAYERS):
        if key in names:
            return rank
    raise AssertionError(f"{module} is in no layer of tests/test_layout.py; add it where it belongs")


@pytest.fixture(scope="module")
def graph():
    modules = _modules()
    found = nx.DiGraph()
    for name, path in modules.items():
        found.add_node(name)
        found.add_edges_from((name, target) for target in _imports(path, modules) if target in modules)
    return found


def test_no_import_circles(graph):
    # a package's __init__ gathers its modules: circles through it are not circles of the code
    code = graph.subgraph([m for m in graph if not (ROOT / m.replace(".", "/") / "__init__.py").exists()])
    circles = [sorted(c) for c in nx.strongly_connected_components(code) if len(c) > 1]
    assert circles == []


def test_imports_run_down_the_layers(graph):
    upward = sorted(
        (a, b) for a, b in graph.edges if _layer(b) > _layer(a) and not (b == "flockkit" and a.startswith("flockkit."))
    )
    assert [edge for edge in upward if edge not in UPWARD] == []
    assert len(UPWARD) <= 1


def test_the_convenience_layer_is_imported_by_nothing_inside(graph):
    importers = sorted(a for a, b in graph.edges if b == "flockkit.convenience" and a != "flockkit")
    assert importers == []


def test_the_package_api_is_imported_only_by_the_command_line(graph):
    importers = sorted(a for a, b in graph.edges if b == "flockkit")
    assert [m for m in importers if _layer(m) < _layer("flockkit")] == []


def test_usd_core_is_imported_in_one_module():
    importers = sorted(
        _module(p)
        for p in LIBRARY.rglob("*.py")
        for node in ast.walk(ast.parse(p.read_text()))
        if isinstance(node, ast.ImportFrom | ast.Import)
        and any((getattr(node, "module", None) or a.name).split(".")[0] == "pxr" for a in node.names)
    )
    assert set(importers) == {"flockkit.io.usd"}


def test_plugins_use_public_names_only():
    private = []
    for path in (ROOT / "plugins").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("flockkit"):
                names = [node.module, *(a.name for a in node.names)]
                private += [f"{path.relative_to(ROOT)}: {n}" for n in names if any(p.startswith("_") for p in
                                                                                    n.split("."))]  # fmt: skip
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "flockkit":
                if node.attr.startswith("_"):
                    private.append(f"{path.relative_to(ROOT)}: flockkit.{node.attr}")
    assert private == []


def test_the_top_level_lists_the_four_systems_over_one_core():
    folders = sorted(p.name for p in LIBRARY.iterdir() if p.is_dir() and (p / "__init__.py").exists())
    assert {"graphs", "constrained", "scene", "crowd", "io"} <= set(folders)


def test_one_public_name_one_thing():
    """A name exported by two public modules is the same object in both, and no name of the
    package shadows a subpackage."""
    import importlib

    modules = [m for m in _modules() if not any(part.startswith("_") for part in m.split("."))]
    seen: dict[str, dict] = {}
    for name in modules:
        module = importlib.import_module(name)
        for exported in getattr(module, "__all__", []):
            seen.setdefault(exported, {})[name] = getattr(module, exported)
    clashes = {n: sorted(where) for n, where in seen.items() if len({id(o) for o in where.values()}) > 1}
    assert clashes == {}
    import flockkit

    for exported in flockkit.__all__:
        if f"flockkit.{exported}" in _modules():
            assert getattr(flockkit, exported) is importlib.import_module(f"flockkit.{exported}")
