"""Everything one run is made of, loaded and validated before anything is built.

:func:`prepare` reads the scenario and the parameter files (packaged defaults or the user's
files), checks the choices (architecture, controller, estimator, variant, duration) against
the registries and the scenario, and returns a frozen :class:`RunSetup`; the architectures
build the run's blocks from it.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import sys
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import mujoco

from trackmj.control.model import ReducedModel
from trackmj.control.params import ControlConfig, load_config, resolved
from trackmj.elements.tensioner_file import TensionerFile, load_tensioner
from trackmj.fmi.controller_fmu import load_controller_file
from trackmj.hydraulics.params import HydraulicParams, load_hydraulic_params
from trackmj.io import cache_dir, write_text_atomic
from trackmj.machines.assembly import (
    Machine,
    check_cylinder_stroke,
    cylinder_force_shortfall,
    idler_file,
    mechanics,
    metering_mismatch,
    model_mjcf,
    reference_mjcf,
    resolve,
)
from trackmj.machines.default import DEFAULT_MACHINE
from trackmj.machines.identify import IdentificationError, identify_idler
from trackmj.machines.idler import (
    SCALARS,
    EquivalentIdler,
    ModalTerm,
    body_mode_band_Hz,
    identification_for,
    load_idler,
)
from trackmj.machines.sizing import input_weight_scale
from trackmj.ports import COUPLING_STEP_S
from trackmj.scenarios.events import check_duration
from trackmj.scenarios.load import load_scenario
from trackmj.scenarios.resolved import Scenario
from trackmj.scenarios.schema import STUDY_BODY_MODE_BAND_HZ, Variant
from trackmj.sim.control_plant import nominal_plant_params
from trackmj.sim.controllers import CONTROLLERS, ESTIMATORS
from trackmj.sim.entries import by_name
from trackmj.sim.registry import ARCHITECTURES, REFERENCE_ARCHITECTURE, REPLACEABLE_ELEMENT
from trackmj.track.mechanics import ModelParams, load_model_params
from trackmj.track.mjcf.builders import on_grade, with_heightfield
from trackmj.track.mjcf.cache import model_key
from trackmj.track.mjcf.geometry import derive_geometry, static_strand_tension_N
from trackmj.track.mjcf.layout import compute_layout
from trackmj.track.plant import TrackPlant
from trackmj.track.terrain import RoadProfile
from trackmj.validator import FILE_KINDS, ParameterError, parse_overrides, split_override_key

MAX_DURATION_S = 3600.0


@functools.cache
def _idler(params: ModelParams, machine: Machine) -> EquivalentIdler:
    """The machine's identified idler for its own mechanics, or an identification on another
    model (cached by content hash beside its generated MJCF) at force levels relative to its
    nominal tension (:func:`trackmj.machines.idler.identification_for`: 0.8 and 1.0 x nominal,
    the LF1352's 12 and 15 kN), the fitted mass floored at the idler and carrier's."""
    own = idler_file(params, machine)
    if own is not None:
        return load_idler(own)
    path = cache_dir() / f"{machine.name}-{model_key(params)[:32]}-idler.json"
    try:
        data = json.loads(path.read_text())
        return EquivalentIdler(**data["idler"], modes=tuple(ModalTerm(**m)
                                                            for m in data["modes"]))
    except (FileNotFoundError, ValueError, KeyError, TypeError):
        pass
    slack = slack_nominal_text(params)      # before the identification's seconds of work
    if slack is not None:
        raise IdentificationError(f"{machine.file.name}: {slack}")
    try:
        idler = identify_idler(lambda: TrackPlant(
            mujoco.MjModel.from_xml_string(model_mjcf(params, machine)), params),
            **identification_for(params.nominal_tension_N),
            min_mass_kg=params.idler.mass_kg + params.idler.carrier_mass_kg)
    except IdentificationError as error:
        changed = ("" if params == mechanics(machine)
                   else " with this run's changes to it (--set model.*, --model)")
        raise IdentificationError(f"{machine.file.name}: the idler identified on "
                                  f"{machine.mechanics.name}{changed}: {error}") from None
    record = {"idler": {name: float(getattr(idler, name)) for name in SCALARS},
              "modes": [dataclasses.asdict(m) for m in idler.modes]}
    try:
        write_text_atomic(path, json.dumps(record))
    except OSError:
        pass
    return idler


def slack_nominal_text(params: ModelParams) -> str | None:
    """Why an idler identification failed, when the cause is the nominal tension: the
    identification holds the idler at 0.8-1.0 x ``params.nominal_tension_N`` F [N]; at a
    frictionless idler both strands then carry T = F / f (f the idler geometry factor,
    :func:`~trackmj.track.mjcf.geometry.static_strand_tension_N`, the carrier's weight on an
    inclined slide included). Below :attr:`TrackPlant.SLACK_TENSION_N` the upper strand
    hangs on its own weight (the drive's slack-strand check), so there is no tensioned
    idler to identify. One line naming the key (``preload_N`` or ``nominal_tension_N``),
    T, and the least value that keeps the strand above slack, with 1000 x a value below
    1 kN when that would (a force typed in kN); None when T is above slack."""
    t, at = params.tensioner, params.origin
    key = "preload_N" if t.nominal_tension_N is None else "nominal_tension_N"
    value = params.nominal_tension_N
    factor = derive_geometry(params, compute_layout(params)).idler_factor
    low = static_strand_tension_N(params, factor, 0.8 * value)
    slack = TrackPlant.SLACK_TENSION_N
    if low >= slack:
        return None
    least_N = (slack - static_strand_tension_N(params, factor, 0.0)) * factor / 0.8
    hint = f"{key} >= {least_N:.4g} N"
    if value < 1e3 and static_strand_tension_N(params, factor, 0.8e3 * value) >= slack:
        hint += f" ({value * 1e3:.6g} if {value:g} was meant in kN)"
    return (f"{at.key('tensioner', key)} = {value:g} N: the idler, identified at 0.8-1.0 x "
            f"it, holds the strands at {low:.4g} N, below the {slack:g} N under which the "
            f"upper strand hangs slack on its own weight (idler geometry factor "
            f"{factor:.4g}): no tensioned idler to identify; use {hint}")


@functools.cache
def _rate_gain(params: ModelParams, hydraulics: HydraulicParams, cfg: ControlConfig,
               machine: Machine) -> float:
    """Tension-rate gain g [N/s per unit u] of the reduced plant of ``params`` (its idler:
    :func:`_idler` on ``machine``), ``hydraulics`` and ``cfg`` at the nominal tension (mid
    stroke) and the supply set-point."""
    plant = nominal_plant_params(hydraulics, _idler(params, machine), cfg,
                                 force_N=params.nominal_tension_N,
                                 supply_pressure_Pa=hydraulics.supply.setpoint_Pa)
    return ReducedModel(plant).tension_rate_gain(params.nominal_tension_N)


def _own_rate_gain(machine: Machine) -> float:
    """g of ``machine``'s own files (:func:`_rate_gain`): its mechanics, hydraulics and
    control file."""
    params = mechanics(machine)
    return _rate_gain(params, load_hydraulic_params(machine.hydraulics),
                      load_config(machine.control, nominal_tension_N=params.nominal_tension_N),
                      machine)


def machine_weights(cfg: ControlConfig, machine: Machine) -> ControlConfig:
    """``cfg`` with the MPC's u and u-rate weights scaled by (g/g_tuned)²: g of the
    machine's own files, g_tuned of those of the machine they were tuned on
    ([mpc].tuned_on_machine); ``cfg`` itself where the two gains are the same (decided by
    the files' content, not by the name). A run's --set/--model/--hydraulics changes do
    not retune them: the controller is tuned for the machine as its files describe it, and
    a changed plant is what a sensitivity study (W5's variants, a calibration's truth run)
    puts it against."""
    gain, tuned_gain = _own_rate_gain(machine), _own_rate_gain(
        resolve(cfg.mpc.tuned_on_machine))
    if gain == tuned_gain:
        return cfg
    scale = input_weight_scale(gain, tuned_gain)
    mpc = dataclasses.replace(cfg.mpc, weight_input=cfg.mpc.weight_input * scale,
                              weight_input_rate=cfg.mpc.weight_input_rate * scale)
    return dataclasses.replace(cfg, mpc=mpc)


@dataclass(frozen=True)
class RunSetup:
    """A validated run: scenario, choices and parameters (SI).

    files: the parameter file of each kind ("model", "hydraulics", "control", "scenario",
    "tensioner", "controller") that made the run ("packaged" for the package's own, "built-in"
    for the architecture's own element and a registered controller); overrides: the
    ``--set`` items. ``hydraulics`` carries the variant's bulk-modulus and friction scales
    already. element: the key of ``ELEMENTS`` the run's tensioner is (the architecture's, or
    the tensioner file's); tensioner: the loaded tensioner file (None: built-in);
    controller_file: the loaded controller FMU file of ``--controller fmu:FILE`` (None: a
    registered controller).
    """

    scenario: Scenario
    variant: Variant
    architecture: str
    controller: str
    estimator: str
    seed: int
    duration_s: float
    model: ModelParams
    hydraulics: HydraulicParams
    control: ControlConfig
    files: dict[str, str] = field(default_factory=dict)
    overrides: dict[str, Any] = field(default_factory=dict)
    element: str = "hydraulic"
    tensioner: TensionerFile | None = None
    controller_file: Any = None
    machine: Machine = field(default_factory=lambda: resolve(DEFAULT_MACHINE))
    body_mode_band_Hz: tuple[float, float] | None = None
    """The machine's body-mode band [Hz] for a scenario that states none
    (:func:`machine_body_mode_band`)."""

    @property
    def steps(self) -> int:
        """Coupling steps of the run [-]."""
        return round(self.duration_s / COUPLING_STEP_S)

    @property
    def force0_N(self) -> float:
        """Initial tensioner force: the reference at t = 0 times the pre-tension scale [N]."""
        return float(self.scenario.reference_N(0.0)) * self.variant.pretension_scale

    @property
    def supply0_Pa(self) -> float:
        """Supply set-point at t = 0 [Pa gauge] (the hydraulic file's, with the scenario's
        set-point changes)."""
        return float(self.scenario.supply_setpoint_Pa(0.0, self.hydraulics.supply.setpoint_Pa))

    @property
    def head_pressure0_Pa(self) -> float:
        """Head pressure [Pa gauge] holding force0_N with the rods at tank pressure."""
        cyl, tank = self.hydraulics.cylinder, self.hydraulics.tank_pressure_Pa
        return (self.force0_N + 2.0 * cyl.area_rod_m2 * tank) / (2.0 * cyl.area_head_m2)

    @property
    def idler(self) -> EquivalentIdler:
        """Equivalent idler of the run's track model (identified once per process)."""
        return _idler(self.model, self.machine)

    @property
    def contact_stiffness_scale(self) -> float:
        """The variant's scale of every contact stiffness [-]."""
        return self.variant.contact_stiffness_scale

    def track_mjcf(self) -> str:
        """MJCF text of the run's track on the scenario's terrain for its seed and length."""
        return self.mjcf(self.scenario.terrain_profile(self.seed, self.duration_s))

    def mjcf(self, terrain: RoadProfile | None) -> str:
        """MJCF text of the run's track model, on ``terrain`` (None: flat ground), on the
        scenario's grade."""
        text = model_mjcf(self.model, self.machine)
        if terrain is not None:
            text = with_heightfield(text, terrain)
        grade = self.scenario.terrain.grade
        return text if grade == 0.0 else on_grade(text, grade)


Overrides = Sequence[str] | Mapping[str, Any]
"""Parameter overrides: ``--set`` items ``"KIND.TABLE.KEY=VALUE"`` or a mapping
``{"KIND.TABLE.KEY": value}`` (KIND one of model, hydraulics, control, scenario)."""


def overrides_by_kind(overrides: Overrides | None) -> dict[str, dict[str, Any]]:
    """``{kind: {"TABLE.KEY": value}}`` for every file kind from either form of overrides;
    ParameterError naming the item for an unknown kind or a malformed key."""
    if not overrides:
        return {kind: {} for kind in FILE_KINDS}
    if isinstance(overrides, Mapping):
        out: dict[str, dict[str, Any]] = {kind: {} for kind in FILE_KINDS}
        for key, value in overrides.items():
            kind, dotted = split_override_key(str(key), f"set[{key!r}]")
            out[kind][dotted] = value
        return out
    return parse_overrides(list(overrides))


def _choice(kind: str, value: str, allowed: dict[str, Any] | tuple[str, ...]) -> str:
    if value not in allowed:
        raise ParameterError(f"{kind} = {value!r}: allowed {', '.join(allowed)}")
    return value


FMU_CONTROLLER_PREFIX = "fmu:"


def controller_choice(value: str) -> tuple[str, Any]:
    """A registered controller's key, or ``"fmu:FILE.toml"`` -> ("fmu", the loaded
    controller file, its FMU checked)."""
    if value.startswith(FMU_CONTROLLER_PREFIX):
        return "fmu", load_controller_file(value[len(FMU_CONTROLLER_PREFIX):])
    named = by_name(CONTROLLERS)
    if value not in named:
        raise ParameterError(f"controller = {value!r}: allowed {', '.join(named)} or "
                             "fmu:FILE.toml (a controller FMU)")
    return value, None


def scaled_hydraulics(base: HydraulicParams, variant: Variant) -> HydraulicParams:
    """``base`` with the variant's bulk-modulus and cylinder-friction scales applied."""
    fluid = dataclasses.replace(base.fluid, bulk_modulus_Pa=base.fluid.bulk_modulus_Pa
                                * variant.bulk_modulus_scale)
    cyl = base.cylinder
    cylinder = dataclasses.replace(
        cyl, coulomb_friction_N=cyl.coulomb_friction_N * variant.friction_scale,
        viscous_friction_N_s_m=cyl.viscous_friction_N_s_m * variant.friction_scale)
    return dataclasses.replace(base, fluid=fluid, cylinder=cylinder)


def _check_bands_agree(sc: Scenario, control: ControlConfig, control_file: str) -> None:
    """The scenario's [limits] band (what the metrics judge) must be the control file's
    [controller] band (what the controllers enforce): a run judged on a band its controller
    does not know would read as a controller failure."""
    judged = (sc.limits.force_min_N, sc.limits.force_max_N)
    enforced = (control.controller.force_min_N, control.controller.force_max_N)
    if judged != enforced:
        raise ParameterError(
            f"{sc.source.name} [limits] force_min_N, force_max_N = {judged[0]:g}, "
            f"{judged[1]:g} N but the control file ({control_file}) [controller] has "
            f"{enforced[0]:g}, {enforced[1]:g} N: the band the metrics judge must be the one "
            "the controllers enforce; set both (e.g. --set scenario.limits.force_max_N=... "
            "--set control.controller.force_max_N=...)")


def machine_body_mode_band(sc: Scenario, machine: Machine) -> tuple[float, float] | None:
    """The track–idler–body mode band [Hz] the metrics take on ``machine`` when the scenario
    states none: the study's 8-12 Hz on LF1352, moved with the ratio of the machine's first
    identified mode to LF1352's (its own mechanics' idler, as the MPC weights;
    :func:`trackmj.machines.idler.body_mode_band_Hz`). ParameterError, naming the scenario
    key, where that band does not lie above the scenario's low-pass cut-off (the band splits
    the ripple the low-pass leaves). None if the scenario states a band."""
    ev = sc.evaluation
    if ev.body_mode_band_Hz is not None:
        return None
    own = _idler(mechanics(machine), machine)
    try:
        band = body_mode_band_Hz(own, load_idler(), STUDY_BODY_MODE_BAND_HZ)
    except ValueError as error:
        raise ParameterError(f"{sc.source.name} [evaluation] body_mode_band_Hz: {machine.name}: "
                             f"{error}; state the band") from None
    if not band[0] > ev.lowpass_cutoff_Hz:
        raise ParameterError(
            f"{sc.source.name} [evaluation] body_mode_band_Hz: {machine.name}'s band "
            f"{band[0]:.3g}-{band[1]:.3g} Hz (the study's {STUDY_BODY_MODE_BAND_HZ[0]:g}-"
            f"{STUDY_BODY_MODE_BAND_HZ[1]:g} Hz moved with its first identified mode) does "
            f"not lie above lowpass_cutoff_Hz = {ev.lowpass_cutoff_Hz:g}; state the band "
            "or a lower cut-off")
    return band


@functools.cache
def _say_once(line: str | None) -> None:
    """Print ``line`` (if any) on stderr, once per process (a sweep prepares a run per
    point)."""
    if line is not None:
        print(f"trackmj: {line}", file=sys.stderr)


def prepare(scenario: Scenario | str | Path, *, architecture: str = REFERENCE_ARCHITECTURE,
            controller: str | None = None, estimator: str | None = None, seed: int = 0,
            duration: float | None = None, variant: str = "nominal",
            model: str | Path | None = None, hydraulics: str | Path | None = None,
            control: str | Path | None = None, overrides: Overrides | None = None,
            tensioner: str | Path | None = None,
            machine: str | Path | Machine | None = None,
            whole_events: bool = False) -> RunSetup:
    """Load and validate every input of one run; ParameterError (a ValueError) naming the
    file, key or option and what is allowed, before anything is built.

    ``overrides`` (see :data:`Overrides`) change keys of the scenario and parameter files;
    they pass the same validation as the files. ``tensioner``: a tensioner file
    (:mod:`trackmj.elements.tensioner_file`) replacing the architecture's hydraulic element, its FMU
    checked here. ``controller`` may be ``"fmu:FILE.toml"`` (:mod:`trackmj.fmi.controller_fmu`).
    ``machine``: a shipped machine's name or a machine file (:mod:`trackmj.machines.assembly`;
    default lf1352) whose mechanics, hydraulics and control files the run takes unless
    ``model``, ``hydraulics`` or ``control`` override them. ``whole_events``: refuse a
    ``duration`` that cuts off one of the scenario's events
    (:func:`trackmj.scenarios.events.check_duration`, what ``run`` and ``compare`` apply)
    before any model is generated or identified.
    """
    mach = resolve(machine)
    sets = overrides_by_kind(overrides)
    model_params = (load_model_params(model or mach.mechanics, overrides=sets["model"])
                    if model or sets["model"] else mechanics(mach))
    reference_mjcf(model_params, mach)   # a stale generated file is refused before any work
    idler_file(model_params, mach)
    hydraulics_params = load_hydraulic_params(hydraulics or mach.hydraulics,
                                              overrides=sets["hydraulics"])
    check_cylinder_stroke(model_params, Path(model or mach.mechanics).name, hydraulics_params,
                          Path(hydraulics or mach.hydraulics).name)
    nominal = model_params.nominal_tension_N
    if isinstance(scenario, Scenario) and (sets["scenario"]
                                           or scenario.nominal_tension_N != nominal):
        scenario = scenario.source   # resolved for another machine: read it again
    sc = (scenario if isinstance(scenario, Scenario)
          else load_scenario(scenario, overrides=sets["scenario"], nominal_tension_N=nominal,
                             supply_setpoint_Pa=hydraulics_params.supply.setpoint_Pa))
    sc.check_machine(mach.name)
    sc.check_grade(model_params.track.ground_friction,
                   f"{Path(model or mach.mechanics).name} [track].ground_friction")
    _choice("architecture", architecture, ARCHITECTURES)
    controller, controller_file = controller_choice(controller or sc.controller)
    estimator = _choice("estimator", estimator or sc.estimator, ESTIMATORS)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ParameterError(f"seed = {seed!r}: must be an integer >= 0")
    duration_s = sc.duration_s if duration is None else float(duration)
    if not (math.isfinite(duration_s) and COUPLING_STEP_S <= duration_s <= MAX_DURATION_S):
        raise ParameterError(f"duration = {duration!r} s: allowed "
                             f"[{COUPLING_STEP_S:g}, {MAX_DURATION_S:g}] s")
    sc.check_inputs(duration_s)
    if sc.evaluation.start_s >= duration_s:
        raise ParameterError(f"duration = {duration_s:g} s ends before the evaluation starts "
                             f"({sc.source.name} [evaluation].start_s = "
                             f"{sc.evaluation.start_s:g} s): no metric could be computed")
    if whole_events:
        check_duration(sc, duration_s)
    try:
        var = sc.variant(variant)
    except KeyError as exc:
        raise ParameterError(exc.args[0]) from None
    element = ARCHITECTURES[architecture].element
    tensioner_file = None
    if tensioner is not None:
        if element != REPLACEABLE_ELEMENT:
            replaceable = [a for a, e in ARCHITECTURES.items()
                           if e.element == REPLACEABLE_ELEMENT]
            raise ParameterError(f"--tensioner {tensioner}: architecture {architecture} has "
                                 f"no hydraulic element to replace ({element}); a tensioner "
                                 f"file applies to {', '.join(replaceable)}")
        tensioner_file = load_tensioner(tensioner)
        element = tensioner_file.element
    own = "packaged" if mach.file.parent == resolve(DEFAULT_MACHINE).file.parent else None
    files = {"scenario": str(sc.source), "machine": mach.name,
             "model": str(model) if model else own or str(mach.mechanics),
             "hydraulics": str(hydraulics) if hydraulics else own or str(mach.hydraulics),
             "control": str(control) if control else own or str(mach.control)}
    if tensioner is not None:
        files["tensioner"] = str(tensioner)
    if controller_file is not None:
        files["controller"] = str(controller_file.file)
    control_params = load_config(control or mach.control, overrides=sets["control"],
                                 nominal_tension_N=model_params.nominal_tension_N)
    _check_bands_agree(sc, control_params, files["control"])
    if tensioner_file is None:
        _say_once(cylinder_force_shortfall(
            model_params, Path(model or mach.mechanics).name, hydraulics_params,
            Path(hydraulics or mach.hydraulics).name,
            resolved(control_params.controller, "force_max_N")))
    try:
        control_config = machine_weights(control_params, mach)
    except IdentificationError as error:
        if model_params == mechanics(mach):
            raise
        raise IdentificationError(
            f"{error}; this run's model changes (--set model.*, --model) do not reach it: the "
            "MPC weights are scaled by the tension-rate gain of the machine's own files, "
            f"so write the changes into {mach.mechanics.name}, or into a copy that a machine "
            "file of its own names") from None
    if tensioner_file is None:   # the machine's own mechanics and idler, as the MPC weights
        _say_once(metering_mismatch(
            mechanics(mach), hydraulics_params, Path(hydraulics or mach.hydraulics).name,
            _idler(mechanics(mach), mach).stiffness_N_m, control_params.valves.min_hold_s))
    return RunSetup(
        scenario=sc, variant=var, architecture=architecture, controller=controller,
        estimator=estimator, seed=seed, duration_s=duration_s, model=model_params,
        hydraulics=scaled_hydraulics(hydraulics_params, var),
        control=control_config, files=files,
        overrides={f"{kind}.{key}": value for kind, keys in sets.items()
                   for key, value in keys.items()},
        element=element, tensioner=tensioner_file, controller_file=controller_file,
        machine=mach, body_mode_band_Hz=machine_body_mode_band(sc, mach))
