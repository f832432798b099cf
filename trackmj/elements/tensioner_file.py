"""Tensioner files: the element that replaces the built-in hydraulic plugin of a run
(``--tensioner FILE.toml``, ``simulate(tensioner=...)``), read by the one validator
(:mod:`trackmj.validator`).

A tensioner file holds exactly one of two tables:

* ``[passive]``: a preload spring-damper (``preload_N``, ``stiffness_N_m``,
  ``damping_N_s_m``, ``stroke_ref_m``, ``travel_m``), element ``passive``;
* ``[fmu]``: a Functional Mock-up Unit (FMI 2.0 or 3.0, co-simulation or model exchange),
  element ``fmu``: the FMU's ``path`` (relative to the file), ``[fmu.inputs]`` and
  ``[fmu.outputs]`` mapping FMU variable names to the port quantities (:data:`FMU_INPUTS`,
  :data:`FMU_OUTPUTS`), ``[fmu.parameters]`` FMU name = value set before initialisation,
  the force limit and the travel the physics guard holds it to. The FMU itself (a zip with a
  binary for this platform, the mapped variables with the right causality and type) is
  checked when the file is loaded (:func:`check_fmu`), before any run.

Sign conventions at the interface are trackmj's (:mod:`trackmj.ports`): stroke s [m] grows
outward, velocity v = ds/dt [m/s], force F [N] > 0 pushes the idler outward; the FMU sees
``s − stroke_offset_m``. SI units at the port (:data:`FMU_UNITS`): a mapped variable's
declared unit is converted to its quantity's (mm, kN, MPa, bar; one of another dimension or
with an offset is refused at load, :func:`trackmj.fmi.fmu.unit_factor`), a variable without
a unit is taken as SI. ``[fmu.parameters]`` are set as written, in the FMU's own units.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from trackmj.fmi.fmu import FmuDescription, describe
from trackmj.io import file_sha256
from trackmj.validator import Location, ParameterError, Parameters, load_file, param, sources_field

FMU_INPUTS: dict[str, str] = {
    "stroke_m": "stroke at the end of the step, s_{k+1} − stroke_offset_m [m]",
    "velocity_m_s": "stroke velocity over the step, v_{k+1} [m/s]",
    "valve_mode": "applied valve mode +1 pressurize, 0 hold, −1 release [-]",
    "u": "controller opening in force, in [−1, 1] [-]",
    "supply_pressure_Pa": "supply pressure set value of the step [Pa gauge]",
}
"""Port quantities an FMU input can be mapped to (what trackmj sets before each step)."""
FMU_OUTPUTS: dict[str, str] = {
    "force_N": "force on the idler carrier, > 0 outward [N] (required)",
    "p_head_Pa": "head chamber pressure [Pa gauge] (not output: the equivalent of force_N)",
    "p_rod_Pa": "rod chamber pressure [Pa gauge] (not output: the tank pressure)",
    "p_supply_Pa": "supply pressure [Pa gauge]",
    "port_power_W": "the FMU's own mechanical port power F·v [W], booked beside ∫F·v dt",
}
"""Port quantities an FMU output can be mapped to (what trackmj reads after each step)."""
FMU_UNITS: dict[str, str] = {
    "stroke_m": "m", "velocity_m_s": "m/s", "valve_mode": "1", "u": "1",
    "supply_pressure_Pa": "Pa", "force_N": "N", "p_head_Pa": "Pa", "p_rod_Pa": "Pa",
    "p_supply_Pa": "Pa", "port_power_W": "W"}
"""Port quantity -> its SI unit (a key of :data:`trackmj.fmi.fmu.PORT_UNITS`), to which a
mapped variable's declared unit is converted."""
INTERFACES = ("auto", "co-simulation", "model-exchange")


@dataclass(frozen=True)
class PassiveTable(Parameters):
    """A preload spring-damper F = preload − k·(s − s_ref) − c·v (valves act on nothing)."""

    preload_N: float = param(0.0, 1e7, doc="force at stroke_ref_m")
    stiffness_N_m: float = param(0.0, 1e10, doc="k: force drop per metre of stroke")
    damping_N_s_m: float = param(0.0, 1e8, doc="c: force drop per m/s of stroke velocity")
    stroke_ref_m: float = param(-1.0, 1.0, doc="stroke at which the spring gives preload_N")
    travel_m: tuple[float, float] = param(-1.0, 1.0, doc="lowest and highest stroke the "
                                          "tensioner admits; outside it the run stops")

    def cross_check(self, at: Location) -> None:
        if not self.travel_m[0] < self.travel_m[1]:
            raise at.error("travel_m", self.travel_m, "must be [lowest, highest] stroke")


@dataclass(frozen=True)
class FmuTable(Parameters):
    """An FMU as the tensioner element (see the module docstring)."""

    path: str = param(max_len=4096, doc="the .fmu file, relative to the tensioner file")
    force_limit_N: float = param(0.0, 1e8, open_low=True, doc="largest |force| the FMU may "
                                 "output; beyond it the run stops")
    travel_m: tuple[float, float] = param(-1.0, 1.0, doc="lowest and highest stroke "
                                          "(trackmj's) the FMU's cylinder admits; outside "
                                          "it the run stops")
    inputs: Mapping[str, str] = param(doc="FMU input name = port quantity (stroke_m, "
                                      "velocity_m_s, valve_mode, u, supply_pressure_Pa)")
    outputs: Mapping[str, str] = param(doc="FMU output name = port quantity (force_N, "
                                       "p_head_Pa, p_rod_Pa, p_supply_Pa, port_power_W)")
    parameters: Mapping[str, Any] = param(default_factory=dict, doc="FMU variable name = "
                                          "value set before initialisation (default none)")
    interface: str = param(choices=INTERFACES, default="auto", doc="which FMI interface to "
                           "use; auto: co-simulation if it can roll back (strong), else "
                           "model exchange, else co-simulation (weak)")
    stroke_offset_m: float = param(-1.0, 1.0, default=0.0, doc="trackmj's stroke at the "
                                   "FMU's stroke zero (default 0)")
    difference_velocity_m_s: float = param(1e-9, 1.0, default=1e-6, doc="velocity step δv "
                                       "of the strong co-simulation's central difference "
                                       "on dF/dv (and of finite differences in model "
                                       "exchange); small against the seal-friction "
                                       "smoothing velocity, large against the FMU's "
                                       "solver noise / |dF/dv|")
    max_correction_N: float = param(0.0, 1e6, default=200.0, doc="bound on the NEPCE "
                                    "energy-correction force of the strong coupling")
    min_correction_velocity_m_s: float = param(0.0, 1.0, default=1e-4, doc="no energy "
                                               "correction below this |v|")
    newton_tol_rel: float = param(1e-14, 1e-2, default=1e-10, unit="1", doc="model "
                                  "exchange: Newton stops when every state moved less "
                                  "than this times its nominal")

    def cross_check(self, at: Location) -> None:
        if not self.travel_m[0] < self.travel_m[1]:
            raise at.error("travel_m", self.travel_m, "must be [lowest, highest] stroke")
        for table, allowed in (("inputs", FMU_INPUTS), ("outputs", FMU_OUTPUTS)):
            seen: dict[str, str] = {}
            for name, quantity in getattr(self, table).items():
                if quantity not in allowed:
                    raise at.error((table, name), quantity,
                                   f"is not a port quantity; allowed: {', '.join(allowed)}")
                if quantity in seen:
                    raise at.error((table, name), quantity, f"is mapped twice (also to FMU "
                                   f"variable {seen[quantity]!r})")
                seen[quantity] = name
        if "force_N" not in self.outputs.values():
            raise ParameterError(f"{at.table()}: no FMU output mapped to \"force_N\" (the "
                                 "force on the idler), e.g. [fmu.outputs] F = \"force_N\"")
        if not {"stroke_m", "velocity_m_s"} & set(self.inputs.values()):
            raise ParameterError(f"{at.table()}: map an FMU input to \"velocity_m_s\" or "
                                 "\"stroke_m\": the FMU must see the idler's motion")

    def quantity(self, table: str) -> dict[str, str]:
        """Port quantity -> FMU variable name of ``table`` ("inputs" or "outputs")."""
        return {q: name for name, q in getattr(self, table).items()}


def check_fmu(table: FmuTable, base: Path, at: Location) -> FmuDescription:
    """Check a tensioner file's ``[fmu]`` table against its FMU (``path`` relative to
    ``base``, the file's folder): the mapped variables exist with the port's kinds and
    units of its quantities' dimensions."""
    real = ("real",)
    input_kinds = {q: real for q in FMU_INPUTS} | {"valve_mode": ("real", "int")}
    output_kinds = {q: real for q in FMU_OUTPUTS}
    return describe((base / table.path).resolve(), table.interface, at, table.inputs,
                    table.outputs, table.parameters, input_kinds, output_kinds, FMU_UNITS)


@dataclass(frozen=True)
class TensionerKind:
    """One table a tensioner file may hold: the element it makes (a key of
    :data:`trackmj.sim.registry.ELEMENTS`), the check run when the file is loaded
    (``check(table, folder, at)``, its result kept as the file's ``description``), and the
    files besides the tensioner file that the element reads (``files(table, folder)``),
    whose content belongs to a run's identity."""

    element: str
    check: Callable[[Any, Path, Location], Any] | None = None
    files: Callable[[Any, Path], tuple[Path, ...]] = lambda table, folder: ()


TENSIONER_KINDS: dict[str, TensionerKind] = {
    "passive": TensionerKind(element="passive"),
    "fmu": TensionerKind(element="fmu", check=check_fmu,
                         files=lambda table, folder: ((folder / table.path).resolve(),)),
}
"""Tensioner kinds by their table's name in the file. A new kind is its table class, its
field in :class:`TensionerFile` and one line here (its element is one line in
:data:`trackmj.sim.registry.ELEMENTS`)."""


@dataclass(frozen=True)
class TensionerFile(Parameters):
    """A tensioner file: exactly one of ``[passive]`` and ``[fmu]``.

    file: the file it was read from (set by :func:`load_tensioner`); fmu_file: the FMU's
    resolved path; description: the checked FMU (``trackmj.fmi.fmu.FmuDescription``).
    """

    passive: PassiveTable | None = param(  # noqa: RUF009 (param() returns a dataclasses.Field)
        default=None, doc="a preload spring-damper")
    fmu: FmuTable | None = param(  # noqa: RUF009 (param() returns a dataclasses.Field)
        default=None, doc="an FMU")
    sources: Mapping[str, str] = sources_field()
    file: Path | None = dataclasses.field(default=None, compare=False,
                                          metadata={"loader": "file"})
    description: Any = dataclasses.field(default=None, compare=False, repr=False,
                                         metadata={"loader": "fmu"})

    def cross_check(self, at: Location) -> None:
        given = [kind for kind in TENSIONER_KINDS if getattr(self, kind) is not None]
        if len(given) != 1:
            tables = " and ".join(f"[{kind}]" for kind in TENSIONER_KINDS)
            raise ParameterError(f"{at.table()}: give exactly one of the tables {tables}")

    @property
    def kind(self) -> str:
        """The key of :data:`TENSIONER_KINDS` whose table this file holds."""
        return next(kind for kind in TENSIONER_KINDS if getattr(self, kind) is not None)

    @property
    def element(self) -> str:
        """The key of :data:`trackmj.sim.registry.ELEMENTS` this file makes."""
        return TENSIONER_KINDS[self.kind].element

    def identity(self) -> str:
        """What determines a run with this file: every validated table (all kinds, so a
        new kind cannot drop out) and the SHA-256 of each file its kind reads."""
        tables = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.compare
                  and f.name != "sources"}
        text = repr(tables)
        if self.file is not None:
            folder = self.file.parent
            for path in TENSIONER_KINDS[self.kind].files(getattr(self, self.kind), folder):
                text += file_sha256(path)
        return text

    @property
    def name(self) -> str:
        """A short name for messages and metrics: the FMU's file name or the file's."""
        if self.fmu is not None:
            return Path(self.fmu.path).name
        return self.file.name if self.file is not None else "passive"


def load_tensioner(path: str | Path) -> TensionerFile:
    """Read and validate a tensioner file; an FMU is opened and its modelDescription checked
    against the mapping (ParameterError naming the file, the table and the variable)."""
    path = Path(path)
    tensioner = load_file(TensionerFile, path, require_source=True)
    object.__setattr__(tensioner, "file", path)
    kind = TENSIONER_KINDS[tensioner.kind]
    if kind.check is not None:
        description = kind.check(getattr(tensioner, tensioner.kind), path.parent,
                                 Location(file=path.name, path=(tensioner.kind,)))
        object.__setattr__(tensioner, "description", description)
    return tensioner
