"""The house is one-way: each layer imports only the layers below it, and no module imports itself back.

Layers (docs/architecture.md): the foundation (types, geometry, detmath, errors, robot, fsutil, compiling), io
(readers, with evaluation and info beside them), scanmatch, pipeline (which sees only the foundation: no
log format, no report, no replay loop, no simulator), config, report, replay, sim, rerun (a run re-run up
to one tick, above both the replay and the simulator it re-runs), batch, cli. Every
``import`` in gndreplay/ is read from the source, the lazy ones inside functions included, so a layer
cannot be crossed by importing late. Only cli.py imports typer.
"""

from __future__ import annotations

import ast
from pathlib import Path

import gndreplay

ROOT = Path(gndreplay.__file__).resolve().parent

FOUNDATION = {"gndreplay", "types", "geometry", "detmath", "errors", "robot", "fsutil", "compiling"}
#: Top-level package or module -> the ones it may import (besides itself and the foundation).
ALLOWED: dict[str, set[str]] = {
    "io": set(),
    "evaluation": {"io"},
    "info": {"io"},
    "scanmatch": {"io", "evaluation"},
    "pipeline": set(),
    "config": {"io", "scanmatch", "pipeline"},
    "report": {"io", "evaluation", "scanmatch", "pipeline", "config"},
    "replay": {"io", "evaluation", "scanmatch", "pipeline", "config", "report"},
    "sim": {"io", "evaluation", "scanmatch", "pipeline", "config", "report", "replay"},
    "rerun": {"io", "evaluation", "scanmatch", "pipeline", "config", "report", "replay", "sim"},
    "batch": {"io", "evaluation", "info", "scanmatch", "pipeline", "config", "report", "replay", "sim"},
    "cli": {"io", "evaluation", "info", "scanmatch", "pipeline", "config", "report", "replay", "sim",
            "rerun", "batch"},
}


def module_name(path: Path) -> str:
    """``gndreplay.pipeline.stack`` for gndreplay/pipeline/stack.py (a package for its __init__)."""
    parts = list(path.relative_to(ROOT.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def is_module(name: str) -> bool:
    """Whether the dotted ``name`` is a module or package of gndreplay (not an attribute)."""
    rel = ROOT.parent.joinpath(*name.split("."))
    return rel.with_suffix(".py").is_file() or (rel / "__init__.py").is_file()


def imports(path: Path) -> set[str]:
    """Every module ``path`` imports (absolute names; relative imports resolved), lazy ones included."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                target = ".".join(base + ([node.module] if node.module else []))
                out.add(target)
                if not node.module:  # from . import x: x may be a module of the package
                    out.update(f"{target}.{a.name}" for a in node.names if is_module(f"{target}.{a.name}"))
            elif node.module:
                out.add(node.module)
    return out


def layer(module: str) -> str:
    """The layer of a gndreplay module: its top-level package or module under gndreplay."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "gndreplay"


def graph() -> dict[str, set[str]]:
    """Module -> the gndreplay modules it imports."""
    return {module_name(p): {m for m in imports(p) if m.split(".")[0] == "gndreplay"}
            for p in sorted(ROOT.rglob("*.py"))}


def test_each_layer_imports_only_the_layers_below_it() -> None:
    crossings = []
    for module, targets in graph().items():
        src = layer(module)
        allowed = FOUNDATION if src in FOUNDATION else FOUNDATION | ALLOWED[src] | {src}
        crossings += [f"{module} imports {t}" for t in sorted(targets) if layer(t) not in allowed]
    assert not crossings, "imports against the layering:\n" + "\n".join(crossings)


def test_every_module_has_a_layer() -> None:
    unknown = {layer(m) for m in graph()} - FOUNDATION - set(ALLOWED)
    assert not unknown, f"modules without a layer in tests/test_layering.py: {sorted(unknown)}"


def test_only_cli_imports_typer() -> None:
    users = [module_name(p) for p in ROOT.rglob("*.py")
             if any(m.split(".")[0] in ("typer", "click") for m in imports(p)) and p.name != "cli.py"]
    assert not users, f"only cli.py may import typer: {users}"


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in edges.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycle_between_modules() -> None:
    g = graph()
    # a module importing its own package (``from . import x`` in a submodule) is how packages work
    edges = {m: {t for t in targets if t in g and t != m and not m.startswith(t + ".")}
             for m, targets in g.items()}
    found = cycles(edges)
    assert not found, "modules importing each other: " + "; ".join(" <-> ".join(c) for c in found)
