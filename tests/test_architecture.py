"""The package's layering, read from its import statements.

Every module of ``modelgen`` is parsed (``ast``), and every ``import`` in it,
including those inside functions, becomes an edge of the import graph.  A
module belongs to a *part*: its subpackage (``model``, ``derivation``,
``codegen``...) or, for a top-level module, its own name (``cli``, ``jobs``,
``errors``).  :data:`ALLOWED` is the layering, as data: the parts each part
may import.  Read bottom-up:

* ``errors`` and ``version`` import nothing;
* ``fileio`` (finding shipped files, reading YAML, atomic writing) is the I/O floor;
* ``model`` says what a model is; ``derivation`` turns it into matrices and numbers;
* ``codegen`` prints a derived model as code; ``checks`` test that code and the
  derivation; ``analysis`` and ``simulation`` use derived models (the
  simulation also flies the generated code); ``table2``, the core paper's
  covariance analysis, builds on ``analysis``' recursions; the ``navigator`` builds on the
  code generator and the simulation's Earth and strapdown kernels;
* ``jobs`` composes them; ``cli`` only parses arguments, calls ``jobs`` and
  stages its reports with ``fileio`` (and adds the navigator's own command);
  ``api`` is the Python API over ``jobs``, offered by the package root (lazily, on first use).

A new import that runs against this table fails here, and so does a cycle
between parts or between modules.
"""

from __future__ import annotations

import ast
from pathlib import Path

from conftest import REPO

PACKAGE = REPO / "modelgen"

_FLOOR = {"version", "errors"}
_MODEL = _FLOOR | {"fileio", "model"}
_DERIVED = _MODEL | {"derivation"}

#: part -> the parts it may import (besides itself).
ALLOWED: dict[str, set[str]] = {
    # the package root: the Python API on top (lazily), the version and ModelError re-exported
    "modelgen": {"errors", "version", "api"},
    "version": set(),
    "errors": set(),
    "fileio": _FLOOR,
    "model": _FLOOR | {"fileio"},
    "derivation": _MODEL,
    "codegen": _DERIVED,
    "checks": _DERIVED | {"codegen"},
    # export: F, G, H, Q, R for other tools (LaTeX, Octave, CasADi, JSON); free text through codegen's escapers
    "export": _DERIVED | {"codegen"},
    # cluster: dask client and task runner for many independent runs (Monte Carlo, trade cases)
    "cluster": _FLOOR,
    "analysis": _DERIVED,
    # table2: the core paper's covariance analysis (its six systems, Table 2, Figs 2-7) on analysis' recursions
    "table2": _DERIVED | {"analysis"},
    "simulation": _DERIVED | {"codegen", "cluster"},
    "navigator": _DERIVED | {"codegen", "simulation"},
    # study: trade studies run covariance cases (analysis) and Monte Carlo (simulation) on one cluster
    "study": _DERIVED | {"analysis", "table2", "simulation", "cluster"},
    "jobs": _DERIVED | {"codegen", "checks", "analysis", "table2", "simulation", "navigator", "export", "cluster", "study"},
    "cli": _FLOOR | {"fileio", "jobs", "navigator"},
    "api": _DERIVED | {"jobs"},
    "__main__": {"cli"},
}


def module_name(path: Path, root: Path = REPO) -> str:
    """``modelgen/derivation/symbolic.py`` -> ``modelgen.derivation.symbolic`` (a package is its ``__init__``)."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def part_of(module: str) -> str:
    """The layer a module belongs to: its subpackage, or its own name for a top-level module."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else parts[0]


def imported_modules(path: Path, modules: set[str], root: Path = REPO) -> set[str]:
    """The modelgen modules that ``path`` imports anywhere in its body (function-local imports too)."""
    me = module_name(path, root)
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                package = me.split(".") if path.name == "__init__.py" else me.split(".")[:-1]
                base = ".".join(package[: len(package) - node.level + 1] + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            names = [base] + [f"{base}.{alias.name}" for alias in node.names]
        else:
            continue
        for name in names:
            while name and name not in modules:  # ``from modelgen.x import f`` -> ``modelgen.x``
                name = name.rpartition(".")[0]
            if name and name != me:
                found.add(name)
    return found


def import_graph() -> dict[str, set[str]]:
    """Every modelgen module -> the modelgen modules it imports."""
    paths = {module_name(p): p for p in PACKAGE.rglob("*.py")}
    modules = set(paths)
    return {m: imported_modules(p, modules) for m, p in paths.items()}


def cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` as a list of nodes (first == last), or None if it has none."""
    state: dict[str, int] = {}  # 1 on the current path, 2 done
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        stack.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state and (found := visit(start)):
            return found
    return None


def part_graph(graph: dict[str, set[str]]) -> dict[str, set[str]]:
    """The import graph between parts (edges inside one part dropped)."""
    parts: dict[str, set[str]] = {}
    for module, targets in graph.items():
        parts.setdefault(part_of(module), set()).update(part_of(t) for t in targets if part_of(t) != part_of(module))
    return parts


def test_the_graph_reads_function_local_and_relative_imports(tmp_path):
    module = tmp_path / "modelgen" / "sub" / "mod.py"
    module.parent.mkdir(parents=True)
    module.write_text("import os\n\ndef f():\n    from modelgen.model.loading import load_model\n\nfrom . import other\n")
    modules = {"modelgen.sub.mod", "modelgen.sub.other", "modelgen.model.loading", "modelgen.model"}
    assert imported_modules(module, modules, tmp_path) == {"modelgen.model.loading", "modelgen.sub.other"}


def test_every_part_of_the_package_has_a_row_in_the_layering_table():
    assert set(part_graph(import_graph())) <= set(ALLOWED)


def test_every_import_between_parts_follows_the_layering():
    wrong = sorted(
        f"{module} imports {target} ({part_of(module)} may import only {sorted(ALLOWED[part_of(module)])})"
        for module, targets in import_graph().items()
        for target in targets
        if part_of(target) != part_of(module) and part_of(target) not in ALLOWED.get(part_of(module), set())
    )
    assert not wrong, "\n".join(wrong)


def test_no_cycle_between_parts():
    assert cycle(part_graph(import_graph())) is None


def test_no_cycle_between_modules():
    assert cycle(import_graph()) is None


def test_the_layering_table_itself_has_no_cycle():
    assert cycle({part: set(allowed) for part, allowed in ALLOWED.items()}) is None


def test_a_cycle_and_a_forbidden_import_are_found():
    assert cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert cycle({"a": {"b"}, "b": set()}) is None
    assert "derivation" not in ALLOWED["model"] and "cli" not in ALLOWED["jobs"]


def test_every_package_folder_has_a_docstring_paragraph():
    for init in PACKAGE.rglob("__init__.py"):
        doc = ast.get_docstring(ast.parse(init.read_text(encoding="utf-8")))
        assert doc and len(doc.split()) >= 20, f"{init.relative_to(REPO)} needs a one-paragraph docstring"
