"""EKF/UKF consistency (NEES, NIS in 95 % chi-square bands over Monte-Carlo runs) and RMSE."""

import dataclasses

import numpy as np
import pytest
from scipy.stats import chi2

from trackmj.control.estimators import ExtendedKalmanFilter, UnscentedKalmanFilter
from trackmj.control.model import ReducedModel, ReducedPlant
from trackmj.control.params import EstimatorParams
from trackmj.control.sensors import Sensors
from trackmj.control.valves import ValveLogic
from trackmj.sim.control_plant import nominal_plant_params, packaged_control

RUNS, STEPS, DT = 30, 400, 1e-3
CFG = packaged_control()
PLANT = nominal_plant_params(control_config=CFG)


def _monte_carlo(
    cls: type, est: EstimatorParams, truth: EstimatorParams | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Truth: RK4 plant + process noise Q and sensor noise R of ``truth`` (default: the
    filter's own), valve pulses; filter tuned with ``est``.

    Returns NEES (RUNS, STEPS), NIS (RUNS, STEPS) and tension errors [N] (RUNS, STEPS).
    """
    model = ReducedModel(PLANT)
    truth = est if truth is None else truth
    q_std = np.array(truth.process_std)
    q_y0 = truth.free_position_process_std_m
    r_std = truth.measurement_std
    sens_p = dataclasses.replace(CFG.sensors, pressure_noise_std_Pa=r_std[0],
                                 stroke_noise_std_m=r_std[2])
    nees = np.empty((RUNS, STEPS))
    nis = np.empty((RUNS, STEPS))
    ferr = np.empty((RUNS, STEPS))
    for r in range(RUNS):
        rng = np.random.default_rng(100 + r)
        x0 = model.equilibrium(12e3 + 1e3 * rng.standard_normal())
        plant = ReducedPlant(PLANT, x0)
        sensors = Sensors(sens_p, rng)
        x_init = x0 + np.array(est.initial_std) * rng.standard_normal(4)
        filt = cls(model, est, DT, x_init)
        # the filter starts at the model's y0; the truth's y0 is one initial std away
        y0 = PLANT.free_position_m + est.free_position_initial_std_m * rng.standard_normal()
        valves = ValveLogic(CFG.valves, DT)
        for k in range(STEPS):
            mode = valves.step(0.6 * np.sin(2 * np.pi * 3.0 * k * DT))
            y0 += q_y0 * rng.standard_normal()   # the disturbance state is a random walk
            x = plant.step(float(mode), 12e6, y0=y0) + q_std * rng.standard_normal(4)
            plant.x = x
            filt.step(sensors.measure(x), float(mode), 12e6)
            nees[r, k] = filt.nees(np.append(x, y0))
            nis[r, k] = filt.nis
            ferr[r, k] = model.force(filt.x) - model.force(x)
    return nees, nis, ferr


@pytest.mark.slow
@pytest.mark.parametrize("cls", [ExtendedKalmanFilter, UnscentedKalmanFilter])
def test_nees_nis_inside_chi_square_bands(cls: type) -> None:
    nees, nis, ferr = _monte_carlo(cls, CFG.estimator)
    lo4, hi4 = chi2.ppf([0.025, 0.975], 5 * RUNS) / RUNS
    lo3, hi3 = chi2.ppf([0.025, 0.975], 3 * RUNS) / RUNS
    a_nees, a_nis = nees.mean(axis=0), nis.mean(axis=0)
    in_nees = np.mean((a_nees > lo4) & (a_nees < hi4))
    in_nis = np.mean((a_nis > lo3) & (a_nis < hi3))
    rmse_f = np.sqrt(np.mean(ferr**2))
    print(
        f"{cls.__name__}: mean NEES {a_nees.mean():.2f} (band {lo4:.2f}-{hi4:.2f}, "
        f"{100 * in_nees:.0f} % in), mean NIS {a_nis.mean():.2f} (band {lo3:.2f}-{hi3:.2f}, "
        f"{100 * in_nis:.0f} % in), tension RMSE {rmse_f:.0f} N"
    )
    # 95 % bands: about 95 % of the time steps should fall inside; allow sampling scatter
    assert in_nees >= 0.88 and in_nis >= 0.88
    assert lo4 < a_nees.mean() < hi4 and lo3 < a_nis.mean() < hi3


def test_overconfident_filter_is_detected() -> None:
    """The same NEES check fails when the filter's Q is 10x too small in std (test can fail)."""
    est = CFG.estimator
    small = dataclasses.replace(est, process_std=tuple(0.1 * s for s in est.process_std))
    nees, _, _ = _monte_carlo(ExtendedKalmanFilter, small, truth=est)
    hi4 = chi2.ppf(0.975, 5 * RUNS) / RUNS
    assert nees.mean() > hi4


def test_ukf_weights_well_conditioned() -> None:
    ukf = UnscentedKalmanFilter(ReducedModel(PLANT), CFG.estimator, DT, np.zeros(4) + 1.0)
    assert ukf.wm.sum() == pytest.approx(1.0)
    assert np.abs(ukf.wm).max() < 2.0 and np.abs(ukf.wc).max() < 3.0
