"""The element port: the loop and the run never ask which element, controller or plant they
have; a new element is its own module plus one registry line."""

from __future__ import annotations

import ast
import math
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from trackmj.ports import ElementLog, ForceLaw

ROOT = Path(__file__).resolve().parent.parent
SIM = ROOT / "trackmj" / "sim"
VALUE_TYPES = {"bool", "int", "float", "str", "tuple", "list", "dict", "Mapping", "Sequence",
               "Path", "Scenario"}
"""What ``isinstance`` may test in trackmj/sim/: the plain data types of the public API's
arguments (a scenario given as an object or a name, overrides as a mapping or items), never
a block (element, controller, estimator, plant, mechanics)."""


def _offences(path: Path) -> list[str]:
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if not isinstance(node, ast.Call) or not isinstance(node.func, ast.Name):
            continue
        name, where = node.func.id, f"{path.name}:{node.lineno}"
        if name == "isinstance":
            kinds = node.args[1]
            names = ([e for e in kinds.elts] if isinstance(kinds, ast.Tuple) else [kinds])
            for kind in names:
                label = kind.id if isinstance(kind, ast.Name) else ast.unparse(kind)
                if label not in VALUE_TYPES:
                    found.append(f"{where}: isinstance(..., {label})")
        elif name == "hasattr":
            found.append(f"{where}: hasattr")
        elif name == "getattr" and (len(node.args) > 2 or isinstance(node.args[1],
                                                                       ast.Constant)):
            found.append(f"{where}: getattr with a literal name or a default "
                         f"({ast.unparse(node)})")
        elif name == "type" and path.suffix == ".py":
            found.append(f"{where}: type(...) (dispatch on a type)")
    return found


def test_no_isinstance_or_getattr_dispatch_in_sim() -> None:
    offences = [o for path in sorted(SIM.glob("*.py")) for o in _offences(path)]
    assert not offences, offences


def test_the_dispatch_check_catches_the_old_forms(tmp_path) -> None:
    """The check fails on what trackmj/sim/run.py did before the element port."""
    old = tmp_path / "old.py"
    old.write_text("guard = 1 if isinstance(element, HydraulicTensioner) else 2\n"
                   "fallbacks = getattr(controller, 'fallbacks', 0)\n")
    assert len(_offences(old)) == 2


class _ConstantElement:
    """A test element: a constant force with no valves or pressures (its own 'module')."""

    pressure_nodes = ()
    stroke_range_m = (-1.0, 1.0)
    channels: ClassVar[dict[str, str]] = {}

    def __init__(self, force_N: float) -> None:
        self.force_N, self.t_s, self.work_J = force_N, 0.0, 0.0

    def set_valves(self, mode: int, u: float, supply_set_Pa: float) -> None:
        """No valves."""

    def force_law(self, t_s: float, stroke_m: float, velocity_m_s: float) -> ForceLaw:
        return ForceLaw(self.force_N)

    def complete_step(self, t_s: float, stroke_m: float, velocity_m_s: float) -> None:
        self.work_J += self.force_N * velocity_m_s * (t_s - self.t_s)
        self.t_s = t_s

    def log(self) -> ElementLog:
        nan = math.nan   # the sensors see a fixed head and rod pressure
        return ElementLog(self.t_s, 8e6, 1e5, nan, nan, self.force_N, 0.0, nan, self.work_J)

    def channel_values(self) -> tuple[()]:
        return ()

    def node_pressures(self) -> tuple[float, ...]:
        return ()

    def run_metrics(self, duration_s: float) -> dict:
        return {"energy_J": {"mechanical": self.work_J}}


def test_a_new_element_is_its_module_and_one_registry_line(monkeypatch) -> None:
    """Registered with one ELEMENTS line (and an architecture to choose it), the element runs
    in the closed loop: the tension is its force at every step and its metrics reach the
    result."""
    from trackmj import simulate
    from trackmj.sim import registry
    from trackmj.sim.entries import Entry

    monkeypatch.setitem(registry.ELEMENTS, "constant", Entry(
        "a constant force", lambda ctx: _ConstantElement(ctx.setup.force0_N)))
    monkeypatch.setitem(registry.ARCHITECTURES, "tp-constant", registry.Architecture(
        "track with a constant force", "track", "constant"))
    result = simulate("W1", architecture="tp-constant", duration=1.2, controller="pid")
    cols = result.columns()
    force0 = float(cols["tension_ref_N"][0])
    assert np.all(cols["tension_N"] == force0)
    work = float(np.sum(force0 * cols["stroke_velocity_m_s"] * 1e-3))
    assert result.metrics["energy_J"]["mechanical"] == pytest.approx(work, rel=1e-9,
                                                                     abs=1e-9)
