"""Identification of the equivalent idler dynamics."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from trackmj.machines import assembly as machines
from trackmj.machines import identify
from trackmj.machines.identify import (
    MAX_DAMPING_N_S_M,
    IdentificationError,
    check_single_dof,
    fit_modal,
    fit_single_dof,
    frequency_response,
    identify_idler,
    multisine,
    r2,
    skill_over_spring,
)
from trackmj.machines.idler import ModalTerm, load_idler, modal_compliance
from trackmj.machines.track_plant import load_plant


def test_single_dof_fit_recovers_a_known_system() -> None:
    k, m, c = 2.0e6, 150.0, 6.0e3
    freq = np.arange(1.0, 50.5, 0.5)
    omega = 2 * math.pi * freq
    compliance = 1.0 / (k - m * omega ** 2 + 1j * c * omega)
    mass, damping = fit_single_dof(freq, compliance, k)
    assert mass == pytest.approx(m, rel=1e-6)
    assert damping == pytest.approx(c, rel=1e-6)


def test_modal_fit_recovers_a_known_response() -> None:
    terms = (ModalTerm(4e-3, 6e-6, 27.0, 0.12), ModalTerm(6e-5, 0.0, 7.5, 0.07),
             ModalTerm(2e-5, 0.0, 0.0, 300.0))
    freq = np.arange(1.0, 50.5, 0.5)
    omega = 2 * math.pi * freq
    compliance = sum(t.compliance(omega) for t in terms)
    fitted = fit_modal(freq, compliance)
    assert r2(sum(t.compliance(omega) for t in fitted), compliance) > 0.999
    assert fitted[0].frequency_Hz == pytest.approx(27.0, rel=1e-3)
    assert fitted[1].frequency_Hz == pytest.approx(7.5, rel=1e-3)


@pytest.mark.slow
def test_modal_fit_of_m113s_response_is_passive_and_describes_it() -> None:
    """M113's rubber-bushed track, identified afresh: with every residue ≥ 0 (a passive
    driving-point compliance's modes are φ²/m) the modal model still describes the measured
    response (R² ≥ 0.85 on the lines of coherence ≥ 0.9; 0.90 over all lines, as the
    unbounded fit did with a cancelling pair), and its static compliance, the sum of the
    terms' r/ω² and r/p, is the static stiffness's within 25 % (1.05e6 against 8.4e5 N/m;
    the cancelling pair's terms were each 14x their difference)."""
    machine = machines.resolve("m113")
    idler = identify.identify_machine_idler(machine)[0]
    response = idler.response
    assert all(t.residue >= 0.0 for t in idler.modes)
    linear = response.coherence >= 0.9
    modal = modal_compliance(idler.modes, 2.0 * math.pi * response.frequency_Hz)
    assert linear.sum() >= 0.5 * linear.size
    assert r2(modal[linear], response.compliance_m_N[linear]) >= 0.85
    static = sum(t.compliance(np.array([0.0]))[0].real for t in idler.modes)
    assert 1.0 / static == pytest.approx(idler.stiffness_N_m, rel=0.25)


def test_shipped_idler_files_have_passive_modal_residues() -> None:
    """Every term of every shipped machine's modal model has a residue ≥ 0 (a driving-point
    compliance's modes are φ²/m), and its static compliance is positive."""
    for name in machines.names():
        idler = load_idler(machines.resolve(name).idler)
        assert all(t.residue >= 0.0 for t in idler.modes), name
        static = sum(t.compliance(np.array([0.0]))[0].real for t in idler.modes)
        assert static > 0.0, name


def test_frequency_response_of_a_sampled_oscillator() -> None:
    """Welch estimate of M·ÿ = F − k·y − c·ẏ integrated like MuJoCo (semi-implicit Euler,
    damping implicit) matches its discrete-time response within 2 % below 30 Hz."""
    k, m, c, h = 4e6, 100.0, 2e4, 1e-3
    force = multisine(8.0, (1.0, 50.0), 1500.0, seed=3)
    y, v, ys = np.empty_like(force), 0.0, 0.0
    for i, f in enumerate(force):
        v = (m * v / h + f - k * ys) / (m / h + c)
        ys += h * v
        y[i] = ys
    freq, compliance, coherence = frequency_response(force, y, (1.0, 30.0))
    z = np.exp(1j * 2 * math.pi * freq * h)
    # y_{n+1} − y_n = h·v_{n+1}, (m/h + c)·v_{n+1} = m/h·v_n + f_n − k·y_n, and sample n
    # records y_{n+1}: Y/F = h²·z² / (m·(z − 1)² + c·h·z·(z − 1) + k·h²·z)
    exact = h * h * z * z / (m * (z - 1) ** 2 + c * h * z * (z - 1) + k * h * h * z)
    np.testing.assert_allclose(compliance, exact, rtol=0.02)
    assert coherence.min() > 0.99


@pytest.mark.slow
def test_identified_idler_of_the_track() -> None:
    """The static stiffness and the dynamic fit come from separate experiments and agree;
    the modal model describes the measured response where it is linear in the force (R² >=
    0.9 on the lines of coherence >= 0.9: 0.94 on 88 of 99; over all lines 0.84, the body
    mode's lines at 7-11 Hz have coherence 0.76-0.86) better than the single-DOF model
    (R² 0.22 on the steel pins: neither the body mode nor the 41 Hz idler mode's shape is in
    it), whose fitted mass is at least the idler and carrier that move, 80 kg (the
    identification's floor; with the regularised ground friction the fit fell below it:
    the friction's slip-speed regularisation acted as a ~80 kN·s/m damper per pin and
    smeared the idler mode); the modes are the body mode and the idler mode, below the
    band's 50 Hz top."""
    idler = identify_idler(load_plant, min_mass_kg=80.0)
    response = idler.response
    assert response.coherence.mean() > 0.9
    linear = response.coherence >= 0.9
    modal = modal_compliance(idler.modes, 2.0 * math.pi * response.frequency_Hz)
    assert linear.sum() >= 0.8 * linear.size
    assert r2(modal[linear], response.compliance_m_N[linear]) >= 0.9
    assert idler.modal_fit_r2 > idler.fit_r2
    static = sum(t.compliance(np.array([0.0]))[0].real for t in idler.modes)
    assert 1.0 / static == pytest.approx(idler.stiffness_N_m, rel=0.25)
    assert idler.mass_kg >= 80.0
    assert idler.damping_N_s_m > 0.0
    frequencies = sorted(t.frequency_Hz for t in idler.modes if t.frequency_Hz > 0.0)
    assert 5.0 < frequencies[0] < 12.0 and 15.0 < frequencies[1] < 50.0


def test_a_response_no_mass_spring_damper_fits_is_refused() -> None:
    """A single mode k, M, c is fitted back from its own response (1-50 Hz) and passes the
    check; a carrier held by a damper ten times stiffer than the fit's bound
    (1/(k + i·1e9·ω)) drives c onto the bound and is refused with the numbers."""
    freq = np.linspace(1.0, 50.0, 99)
    omega = 2.0 * np.pi * freq
    k, m, c = 4.4e6, 100.0, 1.6e4
    mode = 1.0 / (k - m * omega ** 2 + 1j * c * omega)
    mass, damping = fit_single_dof(freq, mode, k)
    assert mass == pytest.approx(m, rel=1e-4) and damping == pytest.approx(c, rel=1e-4)
    fitted = 1.0 / (k - mass * omega ** 2 + 1j * damping * omega)
    assert skill_over_spring(fitted, mode, k) == pytest.approx(1.0, abs=1e-6)
    check_single_dof(mass, damping, skill_over_spring(fitted, mode, k), (1.0, 50.0))
    held = 1.0 / (k + 1j * 1e9 * omega)
    mass, damping = fit_single_dof(freq, held, k)
    assert damping == pytest.approx(MAX_DAMPING_N_S_M)
    fitted = 1.0 / (k - mass * omega ** 2 + 1j * damping * omega)
    with pytest.raises(IdentificationError, match=r"no mass-spring-damper.*c = 1e\+08"):
        check_single_dof(mass, damping, skill_over_spring(fitted, held, k), (1.0, 50.0))


def test_a_response_the_carriers_mass_cannot_describe_is_refused() -> None:
    """A compliance flat within ±10 % and lagging only 45° at 50 Hz, while the carrier's
    80 kg on k = 4.4e6 N/m must resonate at 37 Hz: the single mode fitted with M at that
    floor misses it by more than the static spring does (skill −0.99) and is refused; the
    same ripple lagging 90° at 50 Hz is a damped mode (skill 0.88) and passes."""
    freq = np.linspace(1.0, 50.0, 99)
    omega = 2.0 * np.pi * freq
    k = 4.4e6
    for lag, accepted in ((0.5, False), (1.0, True)):
        response = ((1.0 + 0.1 * np.sin(2.0 * np.pi * freq / 4.0)) / k
                    * np.exp(-1j * lag * (np.pi / 2.0) * freq / 50.0))
        mass, damping = fit_single_dof(freq, response, k, min_mass_kg=80.0)
        fitted = 1.0 / (k - mass * omega ** 2 + 1j * damping * omega)
        skill = skill_over_spring(fitted, response, k)
        if accepted:
            assert skill > 0.8
            check_single_dof(mass, damping, skill, (1.0, 50.0))
        else:
            assert skill < -0.5 and mass == pytest.approx(80.0)
            with pytest.raises(IdentificationError, match=r"no mass-spring-damper"):
                check_single_dof(mass, damping, skill, (1.0, 50.0))


def test_the_identification_cli_refuses_an_unknown_machine_in_one_line() -> None:
    """``python -m trackmj.machines.identify NAME`` with a name no machine ships nor a
    machine file: argparse's usage and one line naming the shipped machines, exit status 2,
    no traceback."""
    run = subprocess.run([sys.executable, "-m", "trackmj.machines.identify", "lf1353"],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2
    assert "Traceback" not in run.stderr
    assert "machine 'lf1353': not a shipped machine" in run.stderr and "lf1352" in run.stderr


def test_the_identification_cli_names_the_mechanics_file_it_refuses(monkeypatch) -> None:
    """A refused identification names the machine and its mechanics file, where the
    [tensioner] keys the reason points to live."""
    def refuse(*args, **kwargs):
        raise IdentificationError("the idler's settled stroke does not grow with the force")

    monkeypatch.setattr(identify, "identify_idler", refuse)
    with pytest.raises(SystemExit, match=r"^lf1352: the idler identified on lf1352\.toml: the "
                       r"idler's settled stroke does not grow with the force$"):
        identify.main(["lf1352"])


def test_a_stroke_that_does_not_grow_with_the_force_is_refused_in_one_line(monkeypatch) -> None:
    """A preload too small to tension the track (100 N on compact3) settles the idler
    further in at the higher force: a negative static stiffness, refused naming the keys
    before the fit takes its square root."""
    strokes = iter([0.0385, 0.0381])
    monkeypatch.setattr(identify, "_settled_stroke", lambda plant, force, settle: next(strokes))
    with pytest.raises(IdentificationError, match=r"^the idler's settled stroke does not grow "
                       r"with the force \(38\.50 mm at 80 N, 38\.10 mm at 100 N\).*"
                       r"\[tensioner\] nominal_tension_N \(default preload_N\)"):
        identify_idler(lambda: None, 80.0, 100.0)
