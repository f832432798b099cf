"""The controller's reduced plant, derived from the hydraulic file and the identified idler.

The reduced model (:class:`~trackmj.control.params.PlantParams`) has no file of its own:
:func:`reduced_plant_params` lumps the two cylinders of the hydraulic parameters into one,
puts each valve edge in series with its restrictor, adds line B to the rod node, and takes
k, M, c from the equivalent idler identified on the MuJoCo track. The idler is identified
once from the committed track and stored in ``models/lf1352_idler.toml``
(:func:`write_idler_file`, regenerate with ``python -m trackmj.sim.config``);
:func:`load_idler` reads it through the one validator.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

from trackmj.control.params import ControlConfig, PlantParams, load_config
from trackmj.hydraulics import HydraulicParams, load_hydraulic_params
from trackmj.hydraulics.components import series_area
from trackmj.identify import EquivalentIdler, ModalTerm
from trackmj.model import default_xml_path, load_model_params, models_dir
from trackmj.params import Location, Parameters, load_file, param

IDLER_FILE = "lf1352_idler.toml"
NOMINAL_FORCE_N = 15e3
"""Operating point of :func:`nominal_plant_params`: the reference tension of W2-W5 [N]..."""
NOMINAL_SUPPLY_PA = 12e6
"""... at the study's simulation supply pressure [Pa], with the force at mid stroke."""


@dataclass(frozen=True)
class ModeTable(Parameters):
    """One term of the modal compliance model (``trackmj.identify.ModalTerm``)."""

    residue: float = param(unit="1/kg", doc="r of (r + q s)/(s^2 + 2 zeta w s + w^2), or "
                           "of r/(s + rate) for the relaxation")
    velocity_residue: float = param(unit="s/kg", doc="q (0 for a plain mode)")
    frequency_Hz: float = param(0.0, 1e4, doc="w / 2 pi; 0 marks the relaxation term")
    damping_ratio: float = param(0.0, None, unit="1 or 1/s",
                                 doc="zeta of a mode [-], or the relaxation rate [1/s]")


@dataclass(frozen=True)
class IdlerTable(Parameters):
    """The equivalent idler M·ÿ = F − k·(y − y0) − c·ẏ on the cylinder stroke, and the
    modal model of the measured frequency response."""

    stiffness_N_m: float = param(0.0, 1e10, open_low=True, doc="k, static dF/dy")
    mass_kg: float = param(0.0, 1e5, open_low=True, doc="M fitted to the frequency response")
    damping_N_s_m: float = param(0.0, 1e8, doc="c fitted to the frequency response")
    natural_frequency_Hz: float = param(0.0, 1e3, open_low=True, doc="sqrt(k / M) / 2 pi")
    damping_ratio: float = param(0.0, None, unit="1", doc="c / (2 sqrt(k M))")
    fit_r2: float = param(None, 1.0, unit="1", doc="R² of the single-DOF model on the response")
    stroke_m: float = param(0.0, 1.0, doc="stroke at the lower force level")
    modal_fit_r2: float = param(None, 1.0, unit="1", doc="R² of the modal model")
    modes: tuple[ModeTable, ...] = param(doc="terms of the modal model")


@dataclass(frozen=True)
class IdentificationTable(Parameters):
    """How the idler was identified (the arguments of ``trackmj.identify.identify_idler``)."""

    model_file: str = param(doc="the MuJoCo model identified (in the models directory)")
    model_sha256: str = param(pattern="[0-9a-f]{64}", doc="SHA-256 of that file")
    force_low_N: float = param(0.0, 1e6, doc="lower settled force level")
    force_high_N: float = param(0.0, 1e6, doc="upper settled force level")
    settle_s: float = param(0.0, 100.0, open_low=True, doc="settling time at each level")
    excitation_s: float = param(0.0, 1000.0, open_low=True, doc="multisine record length")
    band_Hz: tuple[float, float] = param(0.0, 500.0, doc="band of the multisine lines")
    amplitude_N: float = param(0.0, 1e5, open_low=True, doc="multisine amplitude")
    seed: int = param(0, None, unit="1", doc="seed of the multisine phases")

    def cross_check(self, at: Location) -> None:
        if self.force_high_N <= self.force_low_N:
            raise at.error("force_high_N", self.force_high_N,
                           f"must be > force_low_N = {self.force_low_N!r}")


@dataclass(frozen=True)
class IdlerFile(Parameters):
    """``models/lf1352_idler.toml``: the identified idler and how it was identified."""

    idler: IdlerTable
    identification: IdentificationTable


def identification_for(nominal_tension_N: float) -> dict[str, object]:
    """Arguments of ``identify_idler`` for a machine of nominal tension [N]: settled levels
    at 0.8 and 1.0 x nominal, a multisine of 0.1 x nominal (LF1352: 12, 15, 1.5 kN)."""
    return {"force_low_N": 0.8 * nominal_tension_N, "force_high_N": nominal_tension_N,
            "settle_s": 1.5, "excitation_s": 8.0, "band_Hz": (1.0, 50.0),
            "amplitude_N": 0.1 * nominal_tension_N, "seed": 0}


IDENTIFICATION = identification_for(15e3)
"""The identification of :func:`identify_packaged_idler` (``identify_idler``'s defaults)."""

SCALARS = ("stiffness_N_m", "mass_kg", "damping_N_s_m", "natural_frequency_Hz",
           "damping_ratio", "fit_r2", "stroke_m", "modal_fit_r2")
"""The idler's scalar fields stored in the file."""


def default_idler_path() -> Path:
    """The packaged ``models/lf1352_idler.toml``."""
    return models_dir() / IDLER_FILE


def load_idler(path: str | Path | None = None) -> EquivalentIdler:
    """Read the identified equivalent idler.

    Parameters
    ----------
    path : str or Path, optional
        Default the packaged ``models/lf1352_idler.toml``.

    Returns
    -------
    EquivalentIdler
    """
    data = load_file(IdlerFile, default_idler_path() if path is None else path)
    t = data.idler
    modes = tuple(ModalTerm(m.residue, m.velocity_residue, m.frequency_Hz, m.damping_ratio)
                  for m in t.modes)
    return EquivalentIdler(**{name: getattr(t, name) for name in SCALARS}, modes=modes)


def load_identification(path: str | Path | None = None) -> IdentificationTable:
    """The ``[identification]`` table of the idler file (model hash, step used)."""
    return load_file(IdlerFile, default_idler_path() if path is None else path).identification


def file_sha256(path: str | Path) -> str:
    """Hex SHA-256 of a file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def identify_packaged_idler() -> EquivalentIdler:
    """Identify the equivalent idler on the packaged track (a few seconds, deterministic)."""
    from trackmj.identify import identify_idler
    from trackmj.plant import TrackPlant

    idler = load_model_params().idler   # the fitted mass floored at what moves for sure
    return identify_idler(TrackPlant.load, **IDENTIFICATION,
                          min_mass_kg=idler.mass_kg + idler.carrier_mass_kg)


def write_idler_file(idler: EquivalentIdler, path: str | Path,
                     model_path: str | Path | None = None, *,
                     identification: dict[str, object] | None = None,
                     machine: str = "LF1352", model_text: str | None = None) -> Path:
    """Write ``idler`` as an idler file (with its generated-file header) to ``path``.

    Parameters
    ----------
    idler : EquivalentIdler
        Usually :func:`identify_packaged_idler`.
    path : str or Path
        Target file.
    model_path : str or Path, optional
        The model it was identified on (default the packaged ``lf1352.xml``); its name and
        SHA-256 are recorded.
    identification : dict, optional
        The arguments used (default :data:`IDENTIFICATION`).
    machine : str
        The machine's name in the header.
    model_text : str, optional
        The generated MJCF identified on when no file is committed (its SHA-256 is
        recorded, ``model_path`` names the mechanics file it was generated from).

    Returns
    -------
    Path
    """
    model = Path(model_path) if model_path is not None else default_xml_path()
    digest = (file_sha256(model) if model_text is None
              else hashlib.sha256(model_text.encode()).hexdigest())
    values = {name: float(getattr(idler, name)) for name in SCALARS}
    identification = {name: list(v) if isinstance(v, tuple) else v
                      for name, v in (identification or IDENTIFICATION).items()}
    lines = [
        f"# GENERATED FILE - do not edit. The equivalent idler of the {machine} track, "
        "identified",
        f"# on the {'committed' if model_text is None else 'generated'} MuJoCo model by "
        "trackmj.identify.identify_idler(TrackPlant.load):",
        "# static stiffness between two settled force levels, then the frequency response of",
        "# the stroke to a multisine force, fitted by a single-DOF model (k fixed) and by a",
        "# modal model. Written by trackmj.sim.config.write_idler_file; regenerate after any",
        ("# change of models/lf1352.xml with:  python -m trackmj.sim.config"
         if model_text is None else
         f"# change of its mechanics with:  python -m trackmj.sim.config {machine.lower()}"),
        "# tests/test_sim_config.py checks this file equals a fresh identification.",
        "# Read by trackmj.sim.config.load_idler; the reduced plant of the controller takes",
        "# k, M and c from it (trackmj.sim.config.reduced_plant_params). Units SI.",
        "",
        "[idler]",
        'source = "identified on the MuJoCo track by trackmj.identify (see [identification])"',
        *(f"{name} = {value!r}" for name, value in values.items()),
        "",
        *(line for term in idler.modes for line in (
            "[[idler.modes]]", 'source = "trackmj.identify.fit_modal"',
            f"residue = {float(term.residue)!r}",
            f"velocity_residue = {float(term.velocity_residue)!r}",
            f"frequency_Hz = {float(term.frequency_Hz)!r}",
            f"damping_ratio = {float(term.damping_ratio)!r}", "")),
        "[identification]",
        'source = "the arguments of trackmj.identify.identify_idler used for [idler]"',
        f'model_file = "{model.name}"',
        f'model_sha256 = "{digest}"',
        *(f"{name} = {value!r}" for name, value in identification.items()),
        "",
    ]
    path = Path(path)
    path.write_text("\n".join(lines), encoding="utf-8")
    load_idler(path)   # what was written must read back
    return path


def packaged_control(overrides: dict[str, object] | None = None) -> ControlConfig:
    """The packaged control file with the values derived from the packaged machine's nominal
    tension (``models/lf1352.toml`` [tensioner].nominal_tension_N)."""
    return load_config(overrides=overrides,
                       nominal_tension_N=load_model_params().nominal_tension_N)


def reduced_plant_params(hydraulics: HydraulicParams, idler: EquivalentIdler,
                         control_config: ControlConfig, *, supply_pressure_Pa: float,
                         free_position_m: float) -> PlantParams:
    """The controller's reduced model from the hydraulic circuit and the equivalent idler.

    The two identical cylinders act as one with twice the areas, volumes and seal leakage;
    line B belongs to the rod node. Each full-opening path area is its valve edge in series
    with its restrictor (turbulent orifices: A = (A1^-2 + A2^-2)^-1/2): the head path is the
    two branches (2/2 valve + head restrictor) in parallel, the rod path the main valve's
    P -> B edge with the release-feed restrictor. The rod vent and the opening smoothing are
    the control file's own (``[reduced_model]``).

    Parameters
    ----------
    hydraulics : HydraulicParams
        The plugin's circuit (per-cylinder values).
    idler : EquivalentIdler
        k [N/m], M [kg], c [N·s/m] of the idler seen by the stroke.
    control_config : ControlConfig
        Supplies ``reduced_model.vent_area_rod_m2`` and ``opening_smoothing``.
    supply_pressure_Pa : float
        Nominal supply pressure of the model [Pa gauge].
    free_position_m : float
        Stroke y0 [m] at which the idler spring is unloaded.

    Returns
    -------
    PlantParams
    """
    cyl, met, own = hydraulics.cylinder, hydraulics.metering, control_config.reduced_model
    return PlantParams(
        area_head_m2=2.0 * cyl.area_head_m2,
        area_rod_m2=2.0 * cyl.area_rod_m2,
        stroke_m=cyl.stroke_max_m,
        dead_volume_head_m3=2.0 * cyl.dead_volume_head_m3,
        dead_volume_rod_m3=2.0 * cyl.dead_volume_rod_m3 + hydraulics.lines.line_b_volume_m3,
        bulk_modulus_Pa=hydraulics.fluid.bulk_modulus_Pa,
        density_kg_m3=hydraulics.fluid.density_kg_m3,
        discharge_coefficient=hydraulics.orifice.discharge_coefficient,
        valve_area_head_m2=2.0 * series_area(hydraulics.switching_valves.open_area_m2,
                                             met.head_branch_area_m2),
        valve_area_rod_m2=series_area(hydraulics.main_valve.open_area_m2, met.rod_feed_area_m2),
        vent_area_rod_m2=own.vent_area_rod_m2,
        critical_pressure_Pa=hydraulics.orifice.critical_pressure_Pa,
        opening_smoothing=own.opening_smoothing,
        supply_pressure_Pa=supply_pressure_Pa,
        tank_pressure_Pa=hydraulics.tank_pressure_Pa,
        leakage_m3_s_Pa=2.0 * cyl.leakage_m3_s_Pa,
        mass_kg=idler.mass_kg,
        stiffness_N_m=idler.stiffness_N_m,
        damping_N_s_m=idler.damping_N_s_m,
        free_position_m=free_position_m,
    )


def nominal_plant_params(hydraulics: HydraulicParams | None = None,
                         idler: EquivalentIdler | None = None,
                         control_config: ControlConfig | None = None, *,
                         force_N: float = NOMINAL_FORCE_N,
                         supply_pressure_Pa: float = NOMINAL_SUPPLY_PA) -> PlantParams:
    """The reduced plant of the packaged files at an operating point: ``force_N`` [N] at mid
    stroke (y0 = stroke_max/2 − F/k) and ``supply_pressure_Pa`` [Pa]; defaults 15 kN and
    12 MPa. The control unit tests run on it; a coupled run sets y0 from the settled track.

    Parameters
    ----------
    hydraulics, idler, control_config : optional
        Default: the packaged hydraulic file, idler file and control file.
    force_N : float
        Idler force at mid stroke [N].
    supply_pressure_Pa : float
        Supply pressure [Pa gauge].

    Returns
    -------
    PlantParams
    """
    hydraulics = load_hydraulic_params() if hydraulics is None else hydraulics
    idler = load_idler() if idler is None else idler
    control_config = packaged_control() if control_config is None else control_config
    y0 = 0.5 * hydraulics.cylinder.stroke_max_m - force_N / idler.stiffness_N_m
    return reduced_plant_params(hydraulics, idler, control_config,
                                supply_pressure_Pa=supply_pressure_Pa, free_position_m=y0)


def identify_machine_idler(name: str) -> tuple[EquivalentIdler, str, dict[str, object]]:
    """Identify the equivalent idler of shipped machine ``name`` on its generated model at
    force levels relative to its nominal tension (:func:`identification_for`); returns the
    idler, the MJCF text and the identification arguments."""
    import mujoco

    from trackmj.identify import identify_idler
    from trackmj.machines import mechanics, model_mjcf, resolve
    from trackmj.plant import TrackPlant

    machine = resolve(name)
    params = mechanics(machine)
    text = model_mjcf(params, machine)
    arguments = identification_for(params.nominal_tension_N)
    idler = identify_idler(lambda: TrackPlant(mujoco.MjModel.from_xml_string(text), params),
                           **arguments, min_mass_kg=params.idler.mass_kg
                           + params.idler.carrier_mass_kg)
    return idler, text, arguments


def main(argv: list[str] | None = None) -> None:
    """Identify the idler on the packaged track and rewrite ``models/lf1352_idler.toml``;
    with machine names (``python -m trackmj.sim.config m113``), each shipped machine's
    ``models/<name>_idler.toml`` from its generated model."""
    import sys

    from trackmj.machines import resolve

    for name in (sys.argv[1:] if argv is None else argv) or ["lf1352"]:
        if name == "lf1352":
            idler = identify_packaged_idler()
            path = write_idler_file(idler, default_idler_path())
        else:
            idler, text, arguments = identify_machine_idler(name)
            machine = resolve(name)
            path = write_idler_file(idler, models_dir() / f"{name}_idler.toml",
                                    machine.mechanics, identification=arguments,
                                    machine=name.upper(), model_text=text)
        print(f"wrote {path}: k {idler.stiffness_N_m:.4g} N/m, M {idler.mass_kg:.4g} kg, "
              f"c {idler.damping_N_s_m:.4g} N s/m, fit R^2 {idler.fit_r2:.3f}")


if __name__ == "__main__":
    main()
