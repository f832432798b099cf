"""Identification of the equivalent idler-carrier dynamics seen by the cylinders.

The reduced models (NMPC prediction, the ``dp-a`` architecture) replace the track by
M·ÿ = F_ten − k·(y − y0) − c·ẏ on the cylinder stroke y. :func:`identify_idler` measures
the standing MuJoCo track itself:

1. static stiffness k = ΔF/Δy between two settled force levels (the "static dF/dy");
2. the frequency response H(f) = Y(f)/F(f) (Welch, 2 s Hann segments) of the stroke to
   a seeded multisine force about their mean, lines every 0.5 Hz in the band;
3. M and c of the single-DOF model fitted to H in the band with k fixed (relative
   complex error); ``fit_r2`` is that model's R² on H, which a single mode cannot make
   high: the track has a body mode near 7-8 Hz (the study's "track-idler-body mode",
   8-12 Hz), the idler mode near 25-30 Hz and damping-dominated contacts above;
4. the modal model: the idler mode (r + q·s)/(s² + 2ζω·s + ω²), whose velocity residue
   q carries the contacts' damping, the body mode r/(s² + 2ζω·s + ω²) and a relaxation
   r/(s + p), fitted in the same band; ``modal_fit_r2`` is its R².

R² on H: 1 − Σ|H_model − H|² / Σ|H − mean H|² over the band's lines.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable

import mujoco
import numpy as np
from scipy.optimize import least_squares
from scipy.signal import csd, welch

from trackmj.elements.prescribed import ConstantForce, ForceHistory
from trackmj.machines.assembly import (
    Machine,
    command_argument,
    is_shipped,
    mechanics,
    model_mjcf,
    names,
    resolve,
)
from trackmj.machines.idler import (
    IDENTIFICATION,
    EquivalentIdler,
    FrequencyResponse,
    Identification,
    ModalTerm,
    default_idler_path,
    identification_for,
    modal_compliance,
    write_idler_file,
)
from trackmj.machines.track_plant import load_plant
from trackmj.ports import COUPLING_STEP_S
from trackmj.track.mechanics import load_model_params
from trackmj.track.plant import TrackPlant
from trackmj.validator import ParameterError


def multisine(duration_s: float, band_Hz: tuple[float, float], amplitude_N: float,
              seed: int) -> np.ndarray:
    """Zero-mean multisine at 1 kHz [N], shape (steps,): lines every 0.5 Hz in ``band_Hz``
    with equal amplitudes (rms = amplitude_N / sqrt(2)) and seeded random phases."""
    t = np.arange(round(duration_s / COUPLING_STEP_S)) * COUPLING_STEP_S
    lines = np.arange(band_Hz[0], band_Hz[1] + 1e-9, 0.5)
    phases = np.random.default_rng(seed).uniform(0.0, 2.0 * math.pi, len(lines))
    each = amplitude_N / math.sqrt(len(lines))
    return each * np.sin(2.0 * math.pi * lines[None, :] * t[:, None] + phases).sum(axis=1)


def frequency_response(force_N: np.ndarray, stroke_m: np.ndarray, band_Hz: tuple[float, float],
                       segment_s: float = 2.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(frequency [Hz], compliance H = S_fy/S_ff [m/N], coherence [-]) in ``band_Hz``
    from 1 kHz samples (Welch, Hann segments of ``segment_s``, half overlap)."""
    fs, n = 1.0 / COUPLING_STEP_S, round(segment_s / COUPLING_STEP_S)
    f = force_N - force_N.mean()
    y = stroke_m - stroke_m.mean()
    freq, pff = welch(f, fs, nperseg=n)
    _, pfy = csd(f, y, fs, nperseg=n)
    _, pyy = welch(y, fs, nperseg=n)
    band = (freq >= band_Hz[0]) & (freq <= band_Hz[1])
    coherence = np.abs(pfy[band]) ** 2 / (pff[band] * pyy[band])
    return freq[band], pfy[band] / pff[band], coherence


def r2(model: np.ndarray, measured: np.ndarray) -> float:
    """R² of a complex response: 1 − Σ|model − measured|² / Σ|measured − mean|²."""
    spread = np.sum(np.abs(measured - measured.mean()) ** 2)
    return float(1.0 - np.sum(np.abs(model - measured) ** 2) / spread)


class IdentificationError(ParameterError):
    """An identification that cannot stand for the track (a clear one-line refusal)."""


def fit_single_dof(freq_Hz: np.ndarray, compliance: np.ndarray,
                   stiffness_N_m: float, min_mass_kg: float = 1e-3) -> tuple[float, float]:
    """(M [kg], c [N·s/m]) of 1/(k − Mω² + icω) fitted to ``compliance`` with k given
    (relative complex error; several starting frequencies, best kept). A fit below
    ``min_mass_kg`` (the idler and carrier's own mass: the equivalent mass cannot be less)
    is fitted again with M bounded there."""
    omega = 2.0 * math.pi * freq_Hz

    def residual(x: np.ndarray) -> np.ndarray:
        model = 1.0 / (stiffness_N_m - x[0] * omega ** 2 + 1j * x[1] * omega)
        err = (model - compliance) / np.abs(compliance)
        return np.concatenate([err.real, err.imag])

    def fit(low_kg: float) -> np.ndarray:
        best = None
        for f0 in (10.0, 20.0, 30.0, 45.0):
            mass = max(stiffness_N_m / (2.0 * math.pi * f0) ** 2, low_kg)
            trial = least_squares(residual, x0=[mass, 0.4 * math.sqrt(stiffness_N_m * mass)],
                                  bounds=([low_kg, 0.0], [MAX_MASS_KG, MAX_DAMPING_N_S_M]))
            if best is None or trial.cost < best.cost:
                best = trial
        return best.x

    x = fit(1e-3)
    if x[0] < min_mass_kg:
        x = fit(min_mass_kg)
    return float(x[0]), float(x[1])


MAX_MASS_KG, MAX_DAMPING_N_S_M = 1e5, 1e8
"""Upper bounds of the single-mode fit's M and c: a fit that ends on one explains nothing."""


def skill_over_spring(model: np.ndarray, measured: np.ndarray, stiffness_N_m: float) -> float:
    """How much better ``model`` describes the measured compliance than the static spring
    1/k alone, in the fit's own measure (relative complex error): 1 − Σ|m − H|²/|H|² /
    Σ|1/k − H|²/|H|². 1 is exact, 0 no better than the spring, below 0 worse."""
    weight = 1.0 / np.abs(measured) ** 2
    spring = np.sum(np.abs(1.0 / stiffness_N_m - measured) ** 2 * weight)
    return float(1.0 - np.sum(np.abs(model - measured) ** 2 * weight) / spring)


def check_single_dof(mass_kg: float, damping_N_s_m: float, skill: float,
                     band_Hz: tuple[float, float]) -> None:
    """IdentificationError unless the single-mode fit (M [kg], c [N·s/m]) is one: off its
    bounds and describing the response better than the static spring it adds M and c to
    (``skill`` > 0, :func:`skill_over_spring`). A layout whose idler is no mass-spring-damper
    over the band is refused here, with the numbers, instead of as an out-of-range parameter
    of the controller's model later. (R² against the response's mean is no such test: a
    stiff track's compliance is flat within ±25 % and jagged over 1-50 Hz, so its mean
    describes it nearly as well as any model; LF1352 with its sprocket in front, 4 wheels
    and a 6° slide on per-pin slides fits with R² −0.59 but skill 0.65, and holds W1's band
    in closed loop on that fit.)"""
    at_bound = mass_kg >= (1.0 - 1e-9) * MAX_MASS_KG or (
        damping_N_s_m >= (1.0 - 1e-9) * MAX_DAMPING_N_S_M)
    if at_bound or not skill > 0.0:
        raise IdentificationError(
            f"the idler's stroke response over {band_Hz[0]:g}-{band_Hz[1]:g} Hz is no "
            f"mass-spring-damper: the single-mode fit gives M = {mass_kg:.4g} kg, "
            f"c = {damping_N_s_m:.4g} N·s/m (bounds {MAX_MASS_KG:g} kg, "
            f"{MAX_DAMPING_N_S_M:g} N·s/m), {skill:.2f} of the static spring's error "
            "removed; the controllers' reduced model cannot be built on it: change the "
            "idler's wrap and slide ([idler] x_m, z_m, slide_angle_rad) or the tension it "
            "is identified at, 0.8-1.0 x [tensioner] nominal_tension_N (default preload_N)")


def fit_modal(freq_Hz: np.ndarray, compliance: np.ndarray) -> tuple[ModalTerm, ...]:
    """Idler mode (r + q·s)/(…), body mode r/(…) and a relaxation r/(s + p) fitted to
    ``compliance`` (errors weighted by |H|^-½), started from the idler mode at the largest
    |H|, body modes at 7-9 Hz and relaxation rates 100-1000 1/s; the best start kept.

    The residues r are bounded at 0 from below: ``compliance`` is a driving-point
    compliance (stroke over the force on the same carrier), and a passive structure's
    driving-point residues are φ²/m ≥ 0 for every mode (and a relaxation's, a spring
    behind a dashpot, likewise). Left free, two terms at one frequency with opposite
    residues cancel into a fit of the noise (M113's shipped file had +0.0106 at 5.37 Hz and
    −0.0102 at 5.46 Hz). A body residue at 0 says the band shows no body mode apart from the
    idler's. The velocity residue q (non-proportional damping) keeps its sign free."""
    omega = 2.0 * math.pi * freq_Hz
    peak = float(freq_Hz[np.argmax(np.abs(compliance))])

    def terms(x: np.ndarray) -> tuple[ModalTerm, ...]:
        return (ModalTerm(x[0], x[1], x[2], x[3]), ModalTerm(x[4], 0.0, x[5], x[6]),
                ModalTerm(x[7], 0.0, 0.0, x[8]))

    def residual(x: np.ndarray) -> np.ndarray:
        model = sum(t.compliance(omega) for t in terms(x))
        err = (model - compliance) / np.abs(compliance) ** 0.5
        return np.concatenate([err.real, err.imag])

    low = [0.0, -1.0, 0.5, 0.01, 0.0, 0.5, 0.01, 0.0, 1.0]
    high = [1.0, 1.0, 60.0, 1.5, 1.0, 60.0, 1.5, 1.0, 1e4]
    scale = [1e-2, 1e-4, 5.0, 0.1, 1e-4, 2.0, 0.1, 1e-4, 100.0]
    best = None
    for body in (7.0, 8.0, 9.0):
        for rate in (100.0, 300.0, 1000.0):
            x0 = [1.0 / 150.0, 0.0, peak, 0.15, 5e-5, body, 0.1, 1e-7 * rate, rate]
            fit = least_squares(residual, x0=np.clip(x0, low, high), x_scale=scale,
                                bounds=(low, high))
            if best is None or fit.cost < best.cost:
                best = fit
    return terms(best.x)


def _settled_stroke(plant, force_N: float, settle_s: float) -> float:
    """Mean stroke [m] over 0.3 s after ``settle_s`` [s] at a constant damped force."""
    element = ConstantForce(force_N, damping_N_s_m=2e4)
    plant.run(element, settle_s, park=False)
    samples: list[float] = []
    plant.run(element, 0.3, 0.0, lambda pl: samples.append(pl.stroke_m), park=False)
    return float(np.mean(samples))


def identify_idler(make_plant: Callable[[], TrackPlant], force_low_N: float = 12_000.0,
                   force_high_N: float = 15_000.0, settle_s: float = 1.5,
                   excitation_s: float = 8.0, band_Hz: tuple[float, float] = (1.0, 50.0),
                   amplitude_N: float = 1_500.0, seed: int = 0,
                   min_mass_kg: float = 1e-3) -> EquivalentIdler:
    """Identify the equivalent idler on a standing track, its sprocket held at 0 rad/s by
    the drive's velocity servo with the parking brake released (the sprocket's boundary
    condition when driving, where the controllers use the model);
    IdentificationError if the stroke does not grow between the force levels or the
    single-mode fit is none (:func:`check_single_dof`).

    make_plant: returns a fresh ``TrackPlant`` at its home keyframe. The multisine of
    ``amplitude_N`` [N] (rms amplitude/√2) runs about the mean of the two force levels;
    ``min_mass_kg`` [kg]: the idler and carrier's mass, the floor of the fitted M.
    """
    plant = make_plant()
    stroke_low = _settled_stroke(plant, force_low_N, settle_s)
    stroke_high = _settled_stroke(plant, force_high_N, settle_s)
    if not stroke_high > stroke_low:
        raise IdentificationError(
            f"the idler's settled stroke does not grow with the force ({stroke_low * 1e3:.2f} "
            f"mm at {force_low_N:g} N, {stroke_high * 1e3:.2f} mm at {force_high_N:g} N): no "
            "static stiffness for the controllers' reduced model; the forces, 0.8-1.0 x "
            "[tensioner] nominal_tension_N (default preload_N), must be ones that tension "
            "the track")
    stiffness = (force_high_N - force_low_N) / (stroke_high - stroke_low)
    mean = 0.5 * (force_low_N + force_high_N)
    _settled_stroke(plant, mean, settle_s)
    force = mean + multisine(excitation_s, band_Hz, amplitude_N, seed)
    strokes: list[float] = []
    plant.run(ForceHistory(force), excitation_s, 0.0, lambda pl: strokes.append(pl.stroke_m),
              park=False)
    freq, compliance, coherence = frequency_response(force, np.array(strokes), band_Hz)
    mass, damping = fit_single_dof(freq, compliance, stiffness, min_mass_kg)
    omega = 2.0 * math.pi * freq
    single = 1.0 / (stiffness - mass * omega ** 2 + 1j * damping * omega)
    check_single_dof(mass, damping, skill_over_spring(single, compliance, stiffness), band_Hz)
    modes = fit_modal(freq, compliance)
    return EquivalentIdler(
        stiffness_N_m=stiffness, mass_kg=mass, damping_N_s_m=damping,
        natural_frequency_Hz=math.sqrt(stiffness / mass) / (2.0 * math.pi),
        damping_ratio=damping / (2.0 * math.sqrt(stiffness * mass)),
        fit_r2=r2(single, compliance), stroke_m=stroke_low, modes=modes,
        modal_fit_r2=r2(modal_compliance(modes, omega), compliance),
        response=FrequencyResponse(freq, compliance, coherence))


def identify_packaged_idler() -> EquivalentIdler:
    """Identify the equivalent idler on the packaged track (a few seconds, deterministic)."""
    idler = load_model_params().idler   # the fitted mass floored at what moves for sure
    return identify_idler(load_plant, **IDENTIFICATION,
                          min_mass_kg=idler.mass_kg + idler.carrier_mass_kg)


def identify_machine_idler(machine: Machine) -> tuple[EquivalentIdler, str, Identification]:
    """Identify the equivalent idler of ``machine`` on its model (its reference MJCF, else
    generated) at force levels relative to its nominal tension (:func:`identification_for`);
    returns the idler, the MJCF text and the identification arguments."""
    params = mechanics(machine)
    text = model_mjcf(params, machine)
    arguments = identification_for(params.nominal_tension_N)
    idler = identify_idler(lambda: TrackPlant(mujoco.MjModel.from_xml_string(text), params),
                           **arguments, min_mass_kg=params.idler.mass_kg
                           + params.idler.carrier_mass_kg)
    return idler, text, arguments


def main(argv: list[str] | None = None) -> None:
    """Identify the idler on the packaged track and rewrite ``models/lf1352_idler.toml``;
    with machines (``python -m trackmj.machines.identify m113 mine_machine.toml``), a
    shipped machine's ``models/<name>_idler.toml`` or the file a machine file's ``idler``
    key names, from its model. A refused identification exits with its one-line reason."""
    parser = argparse.ArgumentParser(
        prog="python -m trackmj.machines.identify",
        description="Identify machines' equivalent idlers on their tracks and rewrite their "
                    "idler files.")
    parser.add_argument("machines", nargs="*", default=["lf1352"], metavar="MACHINE",
                        help=f"shipped machines ({', '.join(names())}; default lf1352) or "
                             "machine files naming an idler file")
    args = parser.parse_args(argv)
    try:
        machines = [resolve(name) for name in args.machines]
    except ParameterError as error:
        parser.error(str(error))
    for name, machine in zip(args.machines, machines, strict=True):
        try:
            write = _identify_and_write(machine)
        except IdentificationError as error:   # the keys it names are the mechanics file's
            raise SystemExit(f"{name}: the idler identified on {machine.mechanics.name}: "
                             f"{error}") from None
        except ParameterError as error:
            raise SystemExit(f"{name}: {error}") from None
        print(write)


def _identify_and_write(machine: Machine) -> str:
    """Identify ``machine``'s idler, write its file; the line to print."""
    if is_shipped(machine) and machine.name == "lf1352":
        idler = identify_packaged_idler()
        path = write_idler_file(idler, default_idler_path(), params=load_model_params())
    else:
        if machine.idler is None:
            raise ParameterError(f"{machine.file.name} names no [machine].idler file to "
                                 "write (add idler = \"NAME_idler.toml\")")
        idler, text, arguments = identify_machine_idler(machine)
        path = write_idler_file(idler, machine.idler, machine.mechanics,
                                params=mechanics(machine), identification=arguments,
                                machine=machine.name.upper(), model_text=text,
                                regenerate="python -m trackmj.machines.identify "
                                           f"{command_argument(machine)}")
    return (f"wrote {path}: k {idler.stiffness_N_m:.4g} N/m, M {idler.mass_kg:.4g} kg, "
            f"c {idler.damping_N_s_m:.4g} N s/m, fit R^2 {idler.fit_r2:.3f}")


if __name__ == "__main__":
    main()
