"""The house's shape: no import cycles, the domain packages import only the leaves, the
public API documents every parameter (numpydoc)."""

from __future__ import annotations

import ast
import inspect
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = {"trackmj": ROOT / "trackmj", "trackmj.hydraulics": ROOT / "hydraulics",
            "trackmj.control": ROOT / "control"}
LEAVES = {"trackmj", "trackmj.ports", "trackmj.params", "trackmj.io"}
"""What hydraulics/ and control/ may import of trackmj's core (trackmj itself is the
package that holds them; its __init__ imports nothing)."""


def _modules() -> dict[str, Path]:
    mods = {}
    for package, folder in PACKAGES.items():
        for path in folder.rglob("*.py"):
            rel = path.relative_to(folder).with_suffix("")
            parts = [p for p in rel.parts if p != "__init__"]
            name = ".".join([package, *parts])
            if name.startswith("trackmj.") and name.split(".")[1] in ("hydraulics", "control") \
                    and package == "trackmj":
                continue
            mods[name] = path
    return mods


MODULES = _modules()


def _imports(name: str, path: Path, *, top_level_only: bool) -> set[str]:
    """trackmj modules imported by module ``name`` (resolved to modules that exist)."""
    tree = ast.parse(path.read_text())
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    nodes = tree.body if top_level_only else list(ast.walk(tree))
    found = set()
    for node in nodes:
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


def test_module_level_imports_have_no_cycle() -> None:
    graph = {m: _imports(m, p, top_level_only=True) for m, p in MODULES.items()}
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> None:
        state[node] = 1
        stack.append(node)
        for nxt in graph[node]:
            if state.get(nxt) == 1:
                pytest.fail("import cycle: " + " -> ".join([*stack[stack.index(nxt):], nxt]))
            elif nxt not in state:
                visit(nxt)
        stack.pop()
        state[node] = 2

    for module in graph:
        if module not in state:
            visit(module)


@pytest.mark.parametrize("domain", ["trackmj.hydraulics", "trackmj.control"])
def test_domain_packages_import_only_the_leaves(domain: str) -> None:
    offenders = {}
    for name, path in MODULES.items():
        if name != domain and not name.startswith(domain + "."):
            continue
        bad = {m for m in _imports(name, path, top_level_only=False)
               if m not in LEAVES and not m.startswith(domain)}
        if bad:
            offenders[name] = sorted(bad)
    assert not offenders, offenders
    source = "\n".join(p.read_text() for n, p in MODULES.items() if n.startswith(domain))
    assert "import mujoco" not in source


def _public_api() -> list[tuple[str, object]]:
    from trackmj.control.estimators import ExtendedKalmanFilter, UnscentedKalmanFilter
    from trackmj.control.lmpc import LinearMpc
    from trackmj.control.nmpc import NonlinearMpc
    from trackmj.control.pid import PidController
    from trackmj.hydraulics import HydraulicTensioner
    from trackmj.plant import TrackPlant
    from trackmj.sim.run import simulate

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

