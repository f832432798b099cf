"""The identified equivalent idler of a machine and its file (``models/<name>_idler.toml``):
the mass-spring-damper M·ÿ = F − k·(y − y0) − c·ẏ on the cylinder stroke y and the modal
model of the track's measured compliance, read and written through the one validator.
How it is identified: :mod:`trackmj.machines.identify` (regenerate the files with
``python -m trackmj.machines.identify [MACHINE ...]``)."""

from __future__ import annotations

import hashlib
import math
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TypedDict

import numpy as np

from trackmj.io import file_sha256
from trackmj.track.mechanics import ModelParams, default_xml_path, mechanics_sha256, models_dir
from trackmj.validator import Location, Parameters, load_file, param

IDLER_FILE = "lf1352_idler.toml"
"""The default machine's idler file, in the models directory."""


@dataclass(frozen=True)
class ModalTerm:
    """One term of the modal compliance model [SI]: a mode (r + q·s)/(s² + 2ζωs + ω²) with
    residue r [1/kg], velocity residue q [s/kg] (0 for a plain mode), frequency_Hz = ω/2π
    and damping ratio ζ; or, with frequency_Hz = 0, a relaxation r/(s + ζ) whose rate
    [1/s] sits in ``damping_ratio``."""

    residue: float
    velocity_residue: float
    frequency_Hz: float
    damping_ratio: float

    def compliance(self, omega: np.ndarray) -> np.ndarray:
        """Complex compliance [m/N] at angular frequencies ``omega`` [rad/s]."""
        s = 1j * omega
        if self.frequency_Hz == 0.0:
            return self.residue / (s + self.damping_ratio)
        w = 2.0 * math.pi * self.frequency_Hz
        return (self.residue + self.velocity_residue * s) / (
            s * s + 2.0 * self.damping_ratio * w * s + w * w)


@dataclass(frozen=True)
class FrequencyResponse:
    """Measured compliance of the stroke to the tensioner force in the identification band:
    frequency_Hz, compliance_m_N (complex) [m/N] and coherence [-], each shape (lines,)."""

    frequency_Hz: np.ndarray
    compliance_m_N: np.ndarray
    coherence: np.ndarray


@dataclass(frozen=True)
class EquivalentIdler:
    """Equivalent mass-spring-damper on the stroke (SI) and the modal model of the track.

    stiffness_N_m: k, static dF/dy; mass_kg: M and damping_N_s_m: c fitted to the
    frequency response with k fixed; natural_frequency_Hz: sqrt(k/M)/2π; damping_ratio:
    c/(2·sqrt(k·M)); fit_r2: R² of that single-DOF model on the frequency response;
    stroke_m: stroke at the lower force level; modes, modal_fit_r2: the modal model and its
    R²; response: the measured frequency response (None when read from the idler file).
    """

    stiffness_N_m: float
    mass_kg: float
    damping_N_s_m: float
    natural_frequency_Hz: float
    damping_ratio: float
    fit_r2: float
    stroke_m: float
    modes: tuple[ModalTerm, ...]
    modal_fit_r2: float
    response: FrequencyResponse | None = None

    def single_dof_compliance(self, omega: np.ndarray) -> np.ndarray:
        """1/(k − M·ω² + i·c·ω) [m/N] at ``omega`` [rad/s]."""
        return 1.0 / (self.stiffness_N_m - self.mass_kg * omega ** 2
                      + 1j * self.damping_N_s_m * omega)

    def modal_compliance(self, omega: np.ndarray) -> np.ndarray:
        """The modal model's compliance [m/N] at ``omega`` [rad/s]."""
        return modal_compliance(self.modes, omega)


def modal_compliance(modes: Iterable[ModalTerm], omega: np.ndarray) -> np.ndarray:
    """Σ of the ``modes``' compliances [m/N] at ``omega`` [rad/s], in their order (zeros for
    no mode)."""
    return sum((term.compliance(omega) for term in modes), np.zeros_like(omega, dtype=complex))


def first_mode_Hz(modes: Iterable[ModalTerm]) -> float | None:
    """Frequency [Hz] of the lowest mode of a modal model that the response shows (residue
    > 0; the relaxation term is no mode); None if it shows none."""
    shown = [t.frequency_Hz for t in modes if t.frequency_Hz > 0.0 and t.residue > 0.0]
    return min(shown) if shown else None


def body_mode_band_Hz(idler: EquivalentIdler, reference: EquivalentIdler,
                      reference_band_Hz: tuple[float, float]) -> tuple[float, float]:
    """The track–idler–body mode band [Hz] (low, high) of the machine whose idler is
    ``idler``: ``reference_band_Hz``, the band on the machine of ``reference``, moved with
    the ratio of the two machines' first identified modes (:func:`first_mode_Hz`), so its
    edges sit at the same multiples of the machine's own mode. ValueError if either modal
    model shows no mode."""
    own, ref = first_mode_Hz(idler.modes), first_mode_Hz(reference.modes)
    if own is None or ref is None:
        raise ValueError("no body-mode band: the idler's modal model shows no mode "
                         "(every residue 0)")
    ratio = own / ref
    return reference_band_Hz[0] * ratio, reference_band_Hz[1] * ratio


@dataclass(frozen=True)
class ModeTable(Parameters):
    """One term of the modal compliance model (``trackmj.machines.idler.ModalTerm``)."""

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
    """How the idler was identified (the arguments of
    ``trackmj.machines.identify.identify_idler``)."""

    model_file: str = param(doc="the MuJoCo model identified (in the models directory)")
    model_sha256: str = param(pattern="[0-9a-f]{64}", doc="SHA-256 of that file")
    force_low_N: float = param(0.0, 1e6, doc="lower settled force level")
    force_high_N: float = param(0.0, 1e6, doc="upper settled force level")
    settle_s: float = param(0.0, 100.0, open_low=True, doc="settling time at each level")
    excitation_s: float = param(0.0, 1000.0, open_low=True, doc="multisine record length")
    band_Hz: tuple[float, float] = param(0.0, 500.0, doc="band of the multisine lines")
    amplitude_N: float = param(0.0, 1e5, open_low=True, doc="multisine amplitude")
    seed: int = param(0, None, unit="1", doc="seed of the multisine phases")
    mechanics_sha256: str = param(pattern="([0-9a-f]{64})?", default="",
                                  doc="SHA-256 of the mechanics' values the model was "
                                      "generated from (trackmj.track.mechanics."
                                      "mechanics_sha256); optional: a file written before "
                                      "it was recorded has none, and counts as stale")

    def cross_check(self, at: Location) -> None:
        if self.force_high_N <= self.force_low_N:
            raise at.error("force_high_N", self.force_high_N,
                           f"must be > force_low_N = {self.force_low_N!r}")


@dataclass(frozen=True)
class IdlerFile(Parameters):
    """``models/lf1352_idler.toml``: the identified idler and how it was identified."""

    idler: IdlerTable
    identification: IdentificationTable


class Identification(TypedDict):
    """Keyword arguments of :func:`trackmj.machines.identify.identify_idler` that describe an
    identification: the two settled force levels [N], the settle and excitation durations
    [s], the multisine's band [Hz], amplitude [N] and seed."""

    force_low_N: float
    force_high_N: float
    settle_s: float
    excitation_s: float
    band_Hz: tuple[float, float]
    amplitude_N: float
    seed: int


def identification_for(nominal_tension_N: float) -> Identification:
    """Arguments of ``identify_idler`` for a machine of nominal tension [N]: settled levels
    at 0.8 and 1.0 x nominal, a multisine of 0.1 x nominal (LF1352: 12, 15, 1.5 kN)."""
    return {"force_low_N": 0.8 * nominal_tension_N, "force_high_N": nominal_tension_N,
            "settle_s": 1.5, "excitation_s": 8.0, "band_Hz": (1.0, 50.0),
            "amplitude_N": 0.1 * nominal_tension_N, "seed": 0}



IDENTIFICATION = identification_for(15e3)
"""The default machine's identification (LF1352, nominal 15 kN)."""

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


def write_idler_file(idler: EquivalentIdler, path: str | Path,
                     model_path: str | Path | None = None, *, params: ModelParams,
                     identification: Identification | None = None,
                     machine: str = "LF1352", model_text: str | None = None,
                     regenerate: str = "python -m trackmj.machines.identify") -> Path:
    """Write ``idler`` as an idler file (with its generated-file header) to ``path``.

    Parameters
    ----------
    idler : EquivalentIdler
        Usually :func:`identify_packaged_idler`.
    path : str or Path
        Target file.
    params : ModelParams
        The mechanics the model was generated from (their SHA-256 is recorded: a file of
        other mechanics is refused as stale).
    model_path : str or Path, optional
        The model it was identified on (default the packaged ``lf1352.xml``); its name and
        SHA-256 are recorded.
    identification : dict, optional
        The arguments used (default :data:`IDENTIFICATION`).
    machine : str
        The machine's name in the header.
    regenerate : str
        The command that regenerates the file, in the header.
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
    arguments = {name: list(v) if isinstance(v, tuple) else v
                 for name, v in (identification or IDENTIFICATION).items()}
    lines = [
        f"# GENERATED FILE - do not edit. The equivalent idler of the {machine} track, "
        "identified",
        f"# on the {'committed' if model_text is None else 'generated'} MuJoCo model by "
        "trackmj.machines.identify.identify_idler(load_plant):",
        "# static stiffness between two settled force levels, then the frequency response of",
        "# the stroke to a multisine force, fitted by a single-DOF model (k fixed) and by a",
        "# modal model. Written by trackmj.machines.idler.write_idler_file; regenerate after "
        "any",
        f"# change of {model.name if model_text is None else 'its mechanics'} with:  "
        f"{regenerate}",
        "# tests/test_sim_config.py checks this file equals a fresh identification.",
        "# Read by trackmj.machines.idler.load_idler; the reduced plant of the controller takes",
        "# k, M and c from it (trackmj.sim.control_plant.reduced_plant_params). Units SI.",
        "",
        "[idler]",
        'source = "identified on the MuJoCo track by trackmj.machines.identify '
        '(see [identification])"',
        *(f"{name} = {value!r}" for name, value in values.items()),
        "",
        *(line for term in idler.modes for line in (
            "[[idler.modes]]", 'source = "trackmj.machines.identify.fit_modal"',
            f"residue = {float(term.residue)!r}",
            f"velocity_residue = {float(term.velocity_residue)!r}",
            f"frequency_Hz = {float(term.frequency_Hz)!r}",
            f"damping_ratio = {float(term.damping_ratio)!r}", "")),
        "[identification]",
        'source = "the arguments of trackmj.machines.identify.identify_idler used for [idler]"',
        f'model_file = "{model.name}"',
        f'model_sha256 = "{digest}"',
        f'mechanics_sha256 = "{mechanics_sha256(params)}"',
        *(f"{name} = {value!r}" for name, value in arguments.items()),
        "",
    ]
    path = Path(path)
    path.write_text("\n".join(lines), encoding="utf-8")
    load_idler(path)   # what was written must read back
    return path
