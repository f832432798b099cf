"""The house's shape: the import graph (every import, function-local ones included) has no
cycle, the domain packages import only the leaves, the root of trackmj holds only the leaves,
every package is installed, and the public API documents every parameter (numpydoc)."""

from __future__ import annotations

import ast
import inspect
import re
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = {"trackmj": ROOT / "trackmj", "trackmj.hydraulics": ROOT / "hydraulics",
            "trackmj.control": ROOT / "control"}
LEAVES = {"trackmj.ports", "trackmj.validator", "trackmj.io", "trackmj.errors", "trackmj.host",
          "trackmj.version"}
"""The modules at the root of trackmj besides the package itself and ``__main__``: what
hydraulics/ and control/ may import of trackmj's core. Each imports nothing of trackmj."""


def _modules() -> dict[str, Path]:
    mods = {}
    for package, folder in PACKAGES.items():
        for path in folder.rglob("*.py"):
            rel = path.relative_to(folder).with_suffix("")
            parts = [p for p in rel.parts if p != "__init__"]
            mods[".".join([package, *parts])] = path
    return mods


MODULES = _modules()


def _is_type_checking(node: ast.AST) -> bool:
    return isinstance(node, ast.If) and isinstance(node.test, ast.Name) \
        and node.test.id == "TYPE_CHECKING"


def _import_nodes(tree: ast.Module, *, annotations: bool) -> list[ast.AST]:
    """Every import statement of the module, at any depth; with ``annotations`` only those
    under ``if TYPE_CHECKING:``, else only those outside it (the ones that run)."""
    found: list[ast.AST] = []

    def walk(node: ast.AST, guarded: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inside = guarded or _is_type_checking(child)
            if isinstance(child, (ast.Import, ast.ImportFrom)) and inside == annotations:
                found.append(child)
            walk(child, inside)

    walk(tree, False)
    return found


def _named_modules(tree: ast.Module) -> set[str]:
    """Modules named by a string constant (a registry's lazy builder, the package's lazy
    exports): imports that run by name, so they count."""
    return {node.value for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str)
            and "." in node.value and node.value in MODULES}


def _imports(name: str, path: Path, *, annotations: bool = False) -> set[str]:
    """trackmj modules imported by module ``name`` (resolved to modules that exist): the
    imports that run, at module level, in a function or by name (:func:`_named_modules`),
    or with ``annotations`` those under ``if TYPE_CHECKING:``."""
    tree = ast.parse(path.read_text())
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = set() if annotations else _named_modules(tree) - {name}
    for node in _import_nodes(tree, annotations=annotations):
        targets = []
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package.split(".")[: len(package.split(".")) - node.level + 1]
                                + ([base] if base else []))
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES else base
                       for a in node.names]
        for target in targets:
            while target and target not in MODULES:
                target = target.rpartition(".")[0]
            if target and target != name:
                found.add(target)
    return found


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in graph[node]:
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for module in graph:
        if module not in index:
            visit(module)
    return found


def test_no_import_cycle_function_local_imports_included() -> None:
    """Every import that runs, at module level or inside a function, counts."""
    graph = {m: _imports(m, p) for m, p in MODULES.items()}
    assert not _cycles(graph)


def test_annotation_imports_close_no_cycle_either() -> None:
    """Imports under ``if TYPE_CHECKING:`` name types only; with them added the graph still
    has no cycle except where a type names the module that validates it (mechanics checks a
    layout through :mod:`trackmj.track.mjcf.layout`, whose functions take the mechanics)."""
    graph = {m: _imports(m, p) | _imports(m, p, annotations=True) for m, p in MODULES.items()}
    allowed = [["trackmj.track.mechanics", "trackmj.track.mjcf.layout"]]
    assert [c for c in _cycles(graph) if c not in allowed] == []


def test_cycle_finder_sees_a_function_local_import(tmp_path: Path) -> None:
    """The finder is not blind to what the house forbids: a cycle closed by a local import."""
    a, b = tmp_path / "a.py", tmp_path / "b.py"
    a.write_text("import trackmj.b\n")
    b.write_text("def f():\n    from trackmj import a\n")
    MODULES["trackmj.a"], MODULES["trackmj.b"] = a, b
    try:
        graph = {m: _imports(m, MODULES[m]) for m in ("trackmj.a", "trackmj.b")}
    finally:
        del MODULES["trackmj.a"], MODULES["trackmj.b"]
    assert _cycles(graph) == [["trackmj.a", "trackmj.b"]]


@pytest.mark.parametrize("domain", ["trackmj.hydraulics", "trackmj.control"])
def test_domain_packages_import_only_the_leaves(domain: str) -> None:
    offenders = {}
    for name, path in MODULES.items():
        if name != domain and not name.startswith(domain + "."):
            continue
        used = _imports(name, path) | _imports(name, path, annotations=True)
        bad = {m for m in used if m not in LEAVES and not m.startswith(domain)}
        if bad:
            offenders[name] = sorted(bad)
    assert not offenders, offenders
    source = "\n".join(p.read_text() for n, p in MODULES.items() if n.startswith(domain))
    assert "import mujoco" not in source


def test_the_leaves_import_nothing_of_trackmj() -> None:
    for leaf in LEAVES:
        assert _imports(leaf, MODULES[leaf]) | _imports(leaf, MODULES[leaf],
                                                        annotations=True) == set(), leaf


def test_the_package_itself_is_imported_by_no_module() -> None:
    """``trackmj/__init__.py`` is the public façade (lazy re-exports): a module that
    imported it would close a cycle through every module it re-exports."""
    users = [m for m, p in MODULES.items() if m != "trackmj" and "trackmj" in _imports(m, p)]
    assert users == []


def test_the_root_holds_only_the_leaves() -> None:
    root = {p.stem for p in (ROOT / "trackmj").glob("*.py")} - {"__init__", "__main__"}
    assert {f"trackmj.{name}" for name in root} == LEAVES
    assert len(root) + 2 <= 12


def test_no_two_names_differ_only_by_a_plural() -> None:
    """No ``machine`` beside ``machines`` anywhere in trackmj (modules or subpackages, in
    one package or across packages): a reader cannot tell which is which."""
    names = {p.stem for p in (ROOT / "trackmj").rglob("*.py") if p.stem != "__init__"}
    names |= {p.parent.name for p in (ROOT / "trackmj").rglob("__init__.py")}
    assert {n for n in names if n + "s" in names} == set()


def test_every_package_is_installed() -> None:
    """pyproject's package list names every folder with an ``__init__.py`` under trackmj/."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    listed = set(config["tool"]["setuptools"]["packages"])
    folders = {".".join(p.parent.relative_to(ROOT).parts)
               for p in (ROOT / "trackmj").rglob("__init__.py")}
    assert folders <= listed, sorted(folders - listed)


def _public_api() -> list[tuple[str, object]]:
    from trackmj.control.estimators import ExtendedKalmanFilter, UnscentedKalmanFilter
    from trackmj.control.lmpc import LinearMpc
    from trackmj.control.nmpc import NonlinearMpc
    from trackmj.control.pid import PidController
    from trackmj.hydraulics import HydraulicTensioner
    from trackmj.sim.run import simulate
    from trackmj.track.plant import TrackPlant

    return [(obj.__name__, obj) for obj in (simulate, TrackPlant, HydraulicTensioner,
                                             NonlinearMpc,
                                             LinearMpc, PidController, ExtendedKalmanFilter,
                                             UnscentedKalmanFilter)]


def _documented(doc: str) -> list[str]:
    """Names in the numpydoc ``Parameters`` section of ``doc``."""
    match = re.search(r"\n\s*Parameters\n\s*-+\n(.*?)(\n\s*\n\s*[A-Z][a-z]+\n\s*-+\n|\Z)",
                      doc, re.S)
    if not match:
        return []
    names = []
    for line in match.group(1).splitlines():   # getdoc dedents: names start in column 0
        head = re.match(r"([A-Za-z_]\w*(?:\s*,\s*[A-Za-z_]\w*)*)\s*:", line)
        if head:
            names += [n.strip() for n in head.group(1).split(",")]
    return names


@pytest.mark.parametrize(("name", "obj"), _public_api(), ids=lambda v: v if isinstance(v, str)
                         else "")
def test_public_api_documents_every_parameter(name: str, obj: object) -> None:
    """Like python-control's docstring test: each parameter of the signature is in the
    numpydoc Parameters section and the section names no parameter that does not exist."""
    doc = inspect.getdoc(obj) or ""
    signature = inspect.signature(obj)
    params = [p for p in signature.parameters if p not in ("self", "args", "kwargs")]
    documented = _documented(doc)
    assert documented, f"{name}: no numpydoc Parameters section"
    missing = [p for p in params if p not in documented]
    extra = [p for p in documented if p not in params]
    assert not missing and not extra, f"{name}: undocumented {missing}, unknown {extra}"



def _unexplained_local_imports(path: Path) -> list[int]:
    """Line numbers of function-local import groups (import lines with only blank lines
    between them) with no comment on their lines or the line before: a local import must
    say why it is local."""
    source = path.read_text()
    lines = source.splitlines()
    imports = sorted({(node.lineno, node.end_lineno or node.lineno)
                      for fn in ast.walk(ast.parse(source))
                      if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef))
                      for node in ast.walk(fn) if isinstance(node, (ast.Import, ast.ImportFrom))})
    groups: list[tuple[int, int]] = []
    for start, end in imports:
        if groups and all(not line.strip() for line in lines[groups[-1][1]:start - 1]):
            groups[-1] = (groups[-1][0], end)
        else:
            groups.append((start, end))
    return [start for start, end in groups
            if not any("#" in lines[k] for k in range(start - 2, end))]


def test_every_function_local_import_says_why() -> None:
    """Allowed reasons: an optional heavy dependency (fmpy, pythonfmu, rerun, matplotlib,
    dask), the command line's start-up, a registry's names that must not import what they
    name, the worker's pinned thread pools."""
    unexplained = {name: lines for name, path in MODULES.items()
                   if (lines := _unexplained_local_imports(path))}
    assert unexplained == {}


def test_the_reason_check_sees_a_silent_local_import(tmp_path: Path) -> None:
    module = tmp_path / "m.py"
    module.write_text("def f():\n    import json\n\n    return json\n\n\n"
                      "def g():\n    # start-up: why\n    import json\n    return json\n")
    assert _unexplained_local_imports(module) == [2]
