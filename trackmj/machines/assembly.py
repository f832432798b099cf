"""Machines: a machine is its files, assembled by one small machine file.

``models/<name>_machine.toml`` names the machine's subsystem files by path relative to
itself (Project Chrono::Vehicle's JSON habit: a file per subsystem, assembled by reference,
no value entered twice)::

    [machine]
    name = "lf1352"
    description = "the study's forestry crawler, one track side (82 links, rear sprocket)"
    mechanics = "lf1352.toml"               # the track model's parameters (ModelParams)
    hydraulics = "lf1352_hydraulics.toml"   # the hydraulic plugin
    control = "lf1352_control.toml"         # controllers, estimators, sensors
    idler = "lf1352_idler.toml"             # optional: the equivalent idler identified on
                                            # the reference model (else identified on demand)
    reference_mjcf = "lf1352_scene.xml"     # optional: the generator's committed output, a
                                            # scene (ground, light) including lf1352.xml

:data:`MACHINES` is the registry of the shipped machines (every ``*_machine.toml`` in the
packaged ``models/``); :func:`resolve` takes a registered name or a machine file path.
Every other module asks here which files a machine is made of.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from pathlib import Path

from trackmj.control.params import BAND_REL
from trackmj.hydraulics.params import HydraulicParams
from trackmj.machines.default import DEFAULT_MACHINE
from trackmj.machines.idler import load_identification
from trackmj.machines.sizing import (
    CYLINDER_COUNT,
    PULSE_REL,
    VALVE_DROP_PA,
    head_path_area_m2,
    holding_force_N,
    restrictor_for,
)
from trackmj.track.mechanics import ModelParams, load_model_params, mechanics_sha256, models_dir
from trackmj.track.mjcf.builders import mjcf_parts, read_mjcf, recorded_mechanics_sha256
from trackmj.track.mjcf.cache import cached_mjcf
from trackmj.validator import ParameterError, Parameters, build, param, read_toml

MACHINE_SUFFIX = "_machine.toml"
_NAME = r"[a-z0-9][a-z0-9_-]*"
_FILE = r".*\S.*"


@dataclass(frozen=True)
class MachineTable(Parameters):
    """``[machine]``: a name and the machine's files, relative to the machine file."""

    name: str = param(pattern=_NAME, max_len=40, doc="short name (lower case), e.g. lf1352")
    description: str = param(max_len=200, doc="one line: what machine this is")
    mechanics: str = param(pattern=_FILE, max_len=400, doc="model parameter file (.toml)")
    hydraulics: str = param(pattern=_FILE, max_len=400, doc="hydraulic parameter file (.toml)")
    control: str = param(pattern=_FILE, max_len=400, doc="control parameter file (.toml)")
    idler: str = param(max_len=400, default="",
                       doc="identified equivalent idler file (optional: identified on "
                           "demand when absent)")
    reference_mjcf: str = param(max_len=400, default="",
                                doc="the generator's committed output for the mechanics "
                                    "file: the scene MJCF, which includes the machine's "
                                    "(optional: generated and cached when absent)")


@dataclass(frozen=True)
class MachineFile(Parameters):
    """A machine file: one table ``[machine]``."""

    machine: MachineTable


@dataclass(frozen=True)
class Machine:
    """A resolved machine: its name, description and absolute file paths.

    ``idler`` and ``reference_mjcf`` are None when the machine file names none.
    """

    name: str
    description: str
    file: Path
    mechanics: Path
    hydraulics: Path
    control: Path
    idler: Path | None = None
    reference_mjcf: Path | None = None


def load_machine(path: str | Path) -> Machine:
    """Read a machine file; every file it names must exist (ParameterError naming the key)."""
    path = Path(path).resolve()
    if not path.is_file():
        raise ParameterError(f"machine file not found: {path}")
    data = read_toml(path)
    if "machine" not in data and "track" in data:
        raise ParameterError(f"{path.name} is a model parameter file, not a machine file: "
                             "give it as --model, "
                             f"or write a machine file (*{MACHINE_SUFFIX}) naming it")
    table = build(MachineFile, data, file=path.name, require_source=False).machine
    return Machine(name=table.name, description=table.description, file=path,
                   mechanics=_named_file(path, table, "mechanics"),
                   hydraulics=_named_file(path, table, "hydraulics"),
                   control=_named_file(path, table, "control"),
                   idler=_named_file(path, table, "idler") if table.idler else None,
                   reference_mjcf=(_named_file(path, table, "reference_mjcf")
                                   if table.reference_mjcf else None))


def _named_file(path: Path, table: MachineTable, key: str) -> Path:
    """The file ``table.<key>`` of the machine file ``path`` names, resolved against its
    folder; ParameterError naming the key if there is no such file."""
    rel = getattr(table, key)
    full = (path.parent / rel).resolve()
    if not full.is_file():
        raise ParameterError(f"{path.name} [machine].{key} = {rel!r}: no such file {full}")
    return full


@functools.cache
def shipped() -> dict[str, Machine]:
    """The machines shipped in the packaged ``models/``, by name, sorted."""
    found = {}
    for path in sorted(models_dir().glob(f"*{MACHINE_SUFFIX}")):
        m = load_machine(path)
        if m.name in found:
            raise ParameterError(f"{path.name}: machine name {m.name!r} is also "
                                 f"{found[m.name].file.name}'s")
        found[m.name] = m
    return found


def names() -> list[str]:
    """Names of the shipped machines."""
    return list(shipped())


def resolve(machine: str | Path | Machine | None = None) -> Machine:
    """The machine named ``machine`` (a shipped name, or a machine file path); None: the
    default machine (lf1352). A name that is neither is a ParameterError listing the
    shipped ones."""
    if isinstance(machine, Machine):
        return machine
    if machine is None or str(machine).strip() == "":
        machine = DEFAULT_MACHINE
    text = str(machine).strip()
    registry = shipped()
    if text.lower() in registry:
        return registry[text.lower()]
    path = Path(text)
    if path.suffix == ".toml" or path.exists():
        return _not_posing(load_machine(path), registry)
    raise ParameterError(f"machine {text!r}: not a shipped machine ({', '.join(registry)}) "
                         f"nor a machine file (*{MACHINE_SUFFIX})")


def _files(machine: Machine) -> tuple[Path | None, ...]:
    """The files a machine is made of (what decides what it is, not its name)."""
    return (machine.mechanics, machine.hydraulics, machine.control, machine.idler,
            machine.reference_mjcf)


def _not_posing(machine: Machine, registry: dict[str, Machine]) -> Machine:
    """``machine``, unless it takes a shipped machine's name for other files
    (ParameterError): its name would give it that machine's tuned weights, W3 forces and
    scenario bindings."""
    known = registry.get(machine.name)
    if known is not None and _files(known) != _files(machine):
        raise ParameterError(f"{machine.file.name} [machine].name = {machine.name!r} is the "
                             f"shipped machine {known.file.name}'s, but its files are not "
                             "that machine's: give it a name of its own")
    return machine


def is_shipped(machine: Machine) -> bool:
    """Whether ``machine``'s files are those of a shipped machine (whatever its name)."""
    return any(_files(m) == _files(machine) for m in shipped().values())


def command_argument(machine: Machine) -> str:
    """How a command names ``machine``: a shipped machine's name, else its file's path."""
    return machine.name if is_shipped(machine) else str(machine.file)


@functools.cache
def mechanics(machine: Machine) -> ModelParams:
    """The validated mechanics file of ``machine`` (once per process)."""
    return load_model_params(machine.mechanics)


def reference_mjcf(params: ModelParams, machine: Machine) -> Path | None:
    """The machine's committed reference MJCF (its scene) for ``params``: None unless it
    names one and ``params`` are exactly its own mechanics (no override). ParameterError
    naming the file and the command that regenerates it if the file (or the machine part
    it includes) records other mechanics than the mechanics file's now
    (:func:`~trackmj.track.mechanics.mechanics_sha256`)."""
    if machine.reference_mjcf is None or params != mechanics(machine):
        return None
    digest = mechanics_sha256(params)
    for path, text in mjcf_parts(machine.reference_mjcf):
        if recorded_mechanics_sha256(text) != digest:
            raise ParameterError(
                f"{machine.file.name} [machine].reference_mjcf: {path.name} is stale, not "
                f"generated from {machine.mechanics.name} as it is now: regenerate it with "
                f"`trackmj model generate --machine {command_argument(machine)}` (or remove "
                "the key: the model is then generated and cached)")
    return machine.reference_mjcf


def idler_file(params: ModelParams, machine: Machine) -> Path | None:
    """The machine's identified idler file for ``params``: None unless it names one and
    ``params`` are exactly its own mechanics. ParameterError naming the file and the
    command that regenerates it if the file's ``[identification].mechanics_sha256`` is
    not that of the mechanics file now."""
    if machine.idler is None or params != mechanics(machine):
        return None
    if load_identification(machine.idler).mechanics_sha256 != mechanics_sha256(params):
        raise ParameterError(
            f"{machine.file.name} [machine].idler: {machine.idler.name} is stale, not "
            f"identified on {machine.mechanics.name} as it is now: regenerate it with "
            f"`python -m trackmj.machines.identify {command_argument(machine)}` (or remove "
            "the key: the idler is then identified and cached)")
    return machine.idler


STROKE_TOLERANCE_M = 1e-9
"""Rounding allowed where the carrier's travel meets the cylinder's end stops [m]
(0.05 + 0.05 is 0.1 in floating point, but not every sum is)."""


def check_cylinder_stroke(params: ModelParams, model_file: str, hydraulics: HydraulicParams,
                          hydraulics_file: str) -> None:
    """ParameterError naming both files' keys unless the mechanics' cylinder stroke at the
    layout ([idler].stroke_at_layout_m [m]) and the carrier's whole travel about it
    (stroke_at_layout_m + [idler].slide_range_m [m]) lie within the hydraulic file's
    cylinder stroke [0, [cylinder].stroke_max_m] [m]: the two files describe one cylinder,
    whose end stops the carrier cannot pass. A key given with --set is named as the
    option."""
    def idler(key: str) -> str:             # the mechanics key, or the --set option
        at = params.origin
        return at.key("idler", key) if at.file is not None else f"{model_file} [idler].{key}"

    stroke, top = params.idler.stroke_at_layout_m, hydraulics.cylinder.stroke_max_m
    cylinder = f"{hydraulics_file} [cylinder].stroke_max_m = {top:g} m"
    if stroke > top:
        raise ParameterError(f"{idler('stroke_at_layout_m')} = {stroke:g} m is beyond the "
                             f"cylinder's stroke, {cylinder}: allowed [0, {top:g}] m (or a "
                             "longer cylinder)")
    lo, hi = params.idler.slide_range_m
    if stroke + lo < -STROKE_TOLERANCE_M or stroke + hi > top + STROKE_TOLERANCE_M:
        raise ParameterError(
            f"{idler('slide_range_m')} = [{lo:g}, {hi:g}] m moves the carrier over the "
            f"cylinder stroke {stroke + lo:g} .. {stroke + hi:g} m (about "
            f"{idler('stroke_at_layout_m')} = {stroke:g} m), beyond the cylinder's stroke, "
            f"{cylinder}: allowed slide_range_m within [{-stroke:g}, {top - stroke:g}] m (or "
            "a longer cylinder)")


def cylinder_force_shortfall(params: ModelParams, model_file: str,
                             hydraulics: HydraulicParams, hydraulics_file: str,
                             band_top_N: float) -> str | None:
    """One line naming both files' keys, or None if the hydraulic file's cylinders hold the
    band's top ``band_top_N`` [N] (the control file's [controller].force_max_N, which a
    scenario's [limits] must equal: 4/3 of the nominal tension unless given) with the heads
    at the file's supply set-point less :data:`~trackmj.machines.sizing.VALVE_DROP_PA`
    across the metering and the rods at tank
    (:func:`~trackmj.machines.sizing.holding_force_N`): the rule every shipped hydraulic
    file is sized by (:func:`~trackmj.machines.sizing.size_cylinders`).

    The set-point is the hydraulic file's (with its --set overrides), not a scenario's:
    NL1 and W4 drop it to 0.75 x on purpose, to run where the supply binds (M113's heads
    hold 22.3 kN at 9 MPa against its 26.7 kN top); a machine is sized for its own supply,
    and a scenario's [[supply.drops]] is how a run studies a lower one. A shortfall is not
    refused: a sizing study runs cylinders that cannot hold the band, to see them fail."""
    cyl, tank = hydraulics.cylinder, hydraulics.tank_pressure_Pa
    supply = hydraulics.supply.setpoint_Pa
    held = holding_force_N(cyl.area_head_m2, cyl.area_rod_m2, supply, tank)
    if held >= band_top_N:
        return None
    t = params.tensioner
    nominal = (f"{model_file} [tensioner]."
               f"{'preload_N' if t.nominal_tension_N is None else 'nominal_tension_N'} = "
               f"{params.nominal_tension_N / 1e3:g} kN")
    band = (f"4/3 of {nominal}" if math.isclose(band_top_N, BAND_REL[1] * params.nominal_tension_N)
            else f"the control file's [controller].force_max_N; {nominal}")
    per_cylinder = band_top_N / CYLINDER_COUNT + cyl.area_rod_m2 * tank
    allowed = f"setpoint_Pa >= {(VALVE_DROP_PA + per_cylinder / cyl.area_head_m2) / 1e6:.4g} MPa"
    if supply > VALVE_DROP_PA:
        allowed = (f"area_head_m2 >= {per_cylinder / (supply - VALVE_DROP_PA):.4g} m² "
                   f"(this annulus) or {allowed}")
    return (
        f"{hydraulics_file} [cylinder].area_head_m2 = {cyl.area_head_m2:g} m², area_rod_m2 = "
        f"{cyl.area_rod_m2:g} m²: the {CYLINDER_COUNT} cylinders hold {held / 1e3:.2f} kN at "
        f"[supply].setpoint_Pa = {supply / 1e6:g} MPa less {VALVE_DROP_PA / 1e6:g} MPa across "
        f"the metering (rods at tank, {tank / 1e6:g} MPa), below the band's top "
        f"{band_top_N / 1e3:.2f} kN ({band}); the run goes on, the band's top out of the "
        f"cylinders' reach: to hold it, {allowed} (trackmj.machines.sizing.size_cylinders)")


METERING_FACTOR = 1.5
"""How far a hydraulic file's head restrictor may lie from the metering rule's
(:func:`metering_rule_m2`) before a run warns, either way [-]. The tension one
minimum-hold pulse moves grows with the area (the head flow is Cq·A·v): 1.5 x the rule
moves 1.1 % of the nominal tension per pulse, past the PID's 1 % dead band and 1.5 x
the 0.75 % window the MPC's offset trim leaves alone (the control file), so one pulse
overshoots the window the controllers were tuned to stop in and the valves chatter (a
20 t machine at 1.6 x switched at 14-19 Hz against ~3/s on compact3). Below the rule the
same ratio down (0.5 % per pulse) leaves the tension rate two thirds of the tuned one. The
shipped files follow the rule to 2 %."""


def metering_rule_m2(params: ModelParams, hydraulics: HydraulicParams,
                     idler_stiffness_N_m: float, min_hold_s: float) -> float:
    """The head-branch restrictor [m²] docs/sizing.md's metering rule gives for the
    hydraulic file's cylinders on ``params``' machine: at the nominal tension, the layout
    stroke and the supply set-point, one minimum-hold pulse (``min_hold_s`` [s]) at full
    pressurizing opening moves :data:`~trackmj.machines.sizing.PULSE_REL` of the nominal
    tension against the identified idler (``idler_stiffness_N_m`` [N/m]); the restrictor
    in series with the 2/2 valve that gives half that head path area."""
    nominal, cyl = params.nominal_tension_N, hydraulics.cylinder
    area = head_path_area_m2(
        PULSE_REL * nominal / min_hold_s, force_N=nominal,
        area_head_m2=CYLINDER_COUNT * cyl.area_head_m2,
        area_rod_m2=CYLINDER_COUNT * cyl.area_rod_m2,
        volume_head_m3=CYLINDER_COUNT * (cyl.dead_volume_head_m3 + cyl.area_head_m2
                                         * params.idler.stroke_at_layout_m),
        idler_stiffness_N_m=idler_stiffness_N_m, supply_Pa=hydraulics.supply.setpoint_Pa,
        tank_Pa=hydraulics.tank_pressure_Pa, bulk_modulus_Pa=hydraulics.fluid.bulk_modulus_Pa,
        density_kg_m3=hydraulics.fluid.density_kg_m3,
        discharge_coefficient=hydraulics.orifice.discharge_coefficient,
        critical_pressure_Pa=hydraulics.orifice.critical_pressure_Pa)
    return restrictor_for(area / CYLINDER_COUNT, hydraulics.switching_valves.open_area_m2)


def metering_mismatch(params: ModelParams, hydraulics: HydraulicParams, hydraulics_file: str,
                      idler_stiffness_N_m: float, min_hold_s: float) -> str | None:
    """One line naming the hydraulic file's ``[metering].head_branch_area_m2`` (or the
    ``--set`` that gave it), its value and the rule's (:func:`metering_rule_m2`) when they
    differ by more than :data:`METERING_FACTOR` either way; None within it, or when the rule
    has no answer (a set-point below the nominal tension's head pressure, no minimum hold).
    Not refused: a metering study runs other restrictors on purpose."""
    if min_hold_s <= 0.0:
        return None
    try:
        rule = metering_rule_m2(params, hydraulics, idler_stiffness_N_m, min_hold_s)
    except ValueError:
        return None
    given = hydraulics.metering.head_branch_area_m2
    ratio = given / rule
    if 1.0 / METERING_FACTOR <= ratio <= METERING_FACTOR:
        return None
    key = hydraulics.sources.get("metering.head_branch_area_m2", "").split("=")[0] or \
        f"{hydraulics_file} [metering].head_branch_area_m2"
    effect = ("a minimum-hold pulse overshoots the tension window the controllers stop in "
              "(valve chatter)" if ratio > 1.0 else "the tension moves slower than the "
              "controllers were tuned for")
    return (f"{key} = {given:.3g} m² is {ratio:.2g} x the metering rule's {rule:.3g} m² "
            f"(docs/sizing.md, Metering: one {min_hold_s * 1e3:g} ms pulse moves "
            f"{PULSE_REL * 100:g} % of the nominal {params.nominal_tension_N / 1e3:g} kN; "
            f"{ratio * PULSE_REL * 100:.2g} % with this restrictor): {effect}; the run goes on "
            f"(trackmj.machines.assembly.metering_rule_m2)")


def model_mjcf(params: ModelParams, machine: Machine | None = None) -> str:
    """MJCF text of the track model of ``params``: the machine's committed reference file
    when ``params`` are its own mechanics (:func:`reference_mjcf`), else generated and
    cached by content hash (:func:`trackmj.track.mjcf.cache.cached_mjcf`)."""
    machine = resolve(machine)
    reference = reference_mjcf(params, machine)
    if reference is not None:
        return read_mjcf(reference)
    return cached_mjcf(params, machine.name)
