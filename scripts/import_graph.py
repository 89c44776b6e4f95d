"""The project's packages and which of them each imports, read from the code.

Prints the block docs/design.md shows under "Packages and the way their imports point" (a test
keeps the two equal): every import counts, lazy ones inside functions included, with the
layout tests' own scan (``tests/stack/test_layout.py``). Run: ``python scripts/import_graph.py``.
"""
from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "stack"))

from test_layout import PACKAGE_DIRS, PROJECT, sources, top_levels  # noqa: E402

#: The block's first and last lines in docs/design.md.
START = "<!-- import graph: python scripts/import_graph.py -->"
END = "<!-- end of the import graph -->"


def package_imports() -> dict[str, list[str]]:
    """Each package and the project's packages it imports (itself and the generated
    messages' own package aside)."""
    graph = {name: sorted(top_levels(sources(name)) & PROJECT - {name}) for name in PACKAGE_DIRS}
    graph["qg_interfaces"] = []
    return graph


def block() -> str:
    """The block as design.md shows it: packages in dependency order, each with its imports."""
    graph = package_imports()
    order: list[str] = []
    while len(order) < len(graph):
        ready = sorted(p for p in graph if p not in order and set(graph[p]) <= set(order))
        if not ready:
            raise RuntimeError(f"an import cycle among {sorted(set(graph) - set(order))}")
        order += ready
    width = max(len(p) for p in graph)
    lines = [START, "```"]
    for package in order:
        lines.append(f" {package:<{width}}  -> {', '.join(graph[package]) or '-'}")
    lines += ["```", END]
    return "\n".join(lines)


if __name__ == "__main__":
    print(block())
