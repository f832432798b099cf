"""``trackmj report``: W1-W5 x architectures x seeds -> report.md beside the study's figures.

The study's figures (Ding et al., Actuators 2025, 14(12), 615, its results tables) are
printed beside ours for comparison only; nothing in trackmj is tuned toward them. Metric
mapping (ours -> the study's wording):

* W1: ``rmse_N`` (tension RMSE), ``overshoot_N`` (peak error / overshoot);
* W2, W5: ``fluctuation_N`` (± band), ``rmse_N``;
* W3: ``disturbance_peak_error_N`` (overshoot under the pulses), ``recovery_time_s``
  (settling);
* W4: ``disturbance_peak_error_N`` (tension dip), ``recovery_time_s``;
* all: ``supply_energy_J`` (energy drawn from the supply; the study does not define its
  "energy consumption").
W5 aggregates every variant of the scenario file (bulk modulus, friction, contact
stiffness, pre-tension at 0.8/1.2) with the nominal case.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from trackmj.executor import Executor, RunSpec
from trackmj.figures import compare_figure
from trackmj.io import write_text_atomic
from trackmj.machine import machine
from trackmj.results import Result, write_result
from trackmj.scenarios import load_scenario
from trackmj.sim.registry import ARCHITECTURES

ARCHS = tuple(ARCHITECTURES)
STUDY_ARCHS = ("tp", "dp-a", "dp-b")

# (scenario, metric) -> study value per architecture, SI (Ding et al. 2025, results tables)
STUDY: dict[tuple[str, str], dict[str, float]] = {
    ("W1", "rmse_N"): {"tp": 420.0, "dp-a": 1150.0, "dp-b": 920.0},
    ("W1", "overshoot_N"): {"tp": 800.0, "dp-a": 2100.0},
    ("W1", "supply_energy_J"): {"tp": 82.4e3, "dp-a": 95.8e3, "dp-b": 91.7e3},
    ("W2", "fluctuation_N"): {"tp": 1300.0, "dp-a": 2600.0, "dp-b": 2100.0},
    ("W2", "rmse_N"): {"tp": 860.0, "dp-a": 1640.0, "dp-b": 1270.0},
    ("W2", "supply_energy_J"): {"tp": 83.1e3, "dp-a": 97.2e3, "dp-b": 93.0e3},
    ("W3", "disturbance_peak_error_N"): {"tp": 1600.0, "dp-a": 3800.0, "dp-b": 2700.0},
    ("W3", "recovery_time_s"): {"tp": 2.4, "dp-a": 4.1, "dp-b": 3.3},
    ("W3", "supply_energy_J"): {"tp": 83.1e3, "dp-a": 97.2e3, "dp-b": 93.0e3},
    ("W4", "disturbance_peak_error_N"): {"tp": 900.0, "dp-a": 2600.0, "dp-b": 1900.0},
    ("W4", "recovery_time_s"): {"tp": 1.8, "dp-a": 3.5, "dp-b": 2.7},
    ("W4", "supply_energy_J"): {"tp": 80.3e3, "dp-a": 96.1e3, "dp-b": 92.4e3},
    ("W5", "fluctuation_N"): {"tp": 1100.0, "dp-a": 2800.0, "dp-b": 2000.0},
    ("W5", "rmse_N"): {"tp": 790.0, "dp-a": 1750.0, "dp-b": 1280.0},
    ("W5", "supply_energy_J"): {"tp": 81.5e3, "dp-a": 98.2e3, "dp-b": 93.6e3},
}
DISPLAY = {"interface_energy_residual_J": (1.0, "J"), "solve_time_median_s": (1e3, "ms"),
           "_m_s2": (1.0, "m/s²"), "_Hz": (1.0, "Hz"), "real_time_factor": (1.0, "x"),
           "_N": (1e-3, "kN"), "_J": (1e-3, "kJ"), "_s": (1.0, "s")}
EXTRA_METRICS = ("valve_switch_rate_Hz", "chassis_acc_body_mode_rms_m_s2",
                 "interface_energy_residual_J", "solve_time_median_s", "real_time_factor")


def _display(metric: str) -> tuple[float, str]:
    for suffix, (scale, unit) in DISPLAY.items():
        if metric.endswith(suffix):
            return scale, unit
    return 1.0, "-"


def run_matrix(scenarios: Sequence[str], seeds: Sequence[int], duration: float | None,
               workers: int | None = None, scheduler: str | None = None) -> list[Result]:
    """Every run of the report (each scenario's variants x seeds x architectures) on the
    shared executor; a failed run is reported and left out."""
    specs = [RunSpec(scenario=name, architecture=arch, seed=seed, duration=duration,
                     variant=variant.name)
             for name in scenarios for variant in load_scenario(name).variants
             for seed in seeds for arch in ARCHITECTURES]
    with Executor(workers=workers, scheduler=scheduler) as executor:
        outcomes = executor.map(specs, progress="report")
    for o in outcomes:
        if not o.ok:
            print(f"trackmj: {o.spec.scenario} {o.spec.architecture} {o.spec.variant} seed "
                  f"{o.spec.seed}: {o.error}", file=sys.stderr)
    return [o.result for o in outcomes if o.ok]


def _cell(values: list[float], scale: float) -> str:
    finite = [v for v in values if v == v]
    if not finite:
        return "–"
    mean = np.mean(finite) * scale
    if len(finite) == 1:
        return f"{mean:.3g}"
    return f"{mean:.3g} ± {np.std(finite) * scale:.2g}"


def _verdict(ours: float, study: float) -> str:
    if ours != ours:
        return "not measured"
    ratio = ours / study
    if 0.67 <= ratio <= 1.5:
        return f"agrees (×{ratio:.2f})"
    return f"differs (×{ratio:.2f})"


def write_report(results: Sequence[Result], out_dir: str | Path) -> Path:
    """report.md with per-scenario tables, study values, verdicts and comparison figures."""
    out = Path(out_dir)
    scenarios = sorted({r.scenario for r in results})
    lines = ["# trackmj report", "",
             f"Machine: {machine()}. Seeds: {sorted({r.seed for r in results})}; duration "
             f"{results[0].metadata['duration_s']} s per run; values are mean ± std over seeds "
             "(and W5 variants). Study figures (Ding et al., Actuators 2025, 14(12), 615) are "
             "shown for comparison only; trackmj is never tuned toward them.", ""]
    for name in scenarios:
        runs = [r for r in results if r.scenario == name]
        sc = load_scenario(name)
        lines += [f"## {name}: {sc.title}", ""]
        header = "| metric | " + " | ".join(ARCHS) + " | study TP | study DP-A | study DP-B |"
        lines += [header, "|---|" + "---|" * (len(ARCHS) + 3)]
        metrics = [m for (s, m) in STUDY if s == name] + list(EXTRA_METRICS)
        verdicts = []
        for metric in metrics:
            scale, unit = _display(metric)
            row = [_cell([r.metrics.get(metric, np.nan) for r in runs if r.architecture == a],
                         scale) for a in ARCHS]
            study = STUDY.get((name, metric), {})
            row += [f"{study[a] * scale:.3g}" if a in study else "–" for a in STUDY_ARCHS]
            lines.append(f"| {metric} [{unit}] | " + " | ".join(row) + " |")
            for a in STUDY_ARCHS:
                if a in study:
                    ours = [r.metrics.get(metric, np.nan) for r in runs if r.architecture == a]
                    mean = float(np.nanmean(ours)) if np.isfinite(ours).any() else np.nan
                    verdicts.append(f"{metric} {a}: {_verdict(mean, study[a])}")
        lines += ["", "Against the study: " + "; ".join(verdicts) + ".", ""]
        seed0 = [r for r in runs if r.seed == min(r.seed for r in runs)
                 and r.metadata["variant"] == "nominal"]
        seed0.sort(key=lambda r: ARCHS.index(r.architecture))
        figure = compare_figure(seed0, out / f"{name}.png")
        lines += [f"![{name}]({figure.name})", ""]
        order = [r.metrics.get("rmse_N", np.nan) for r in seed0]
        ranking = ", ".join(r.architecture for _, r in sorted(zip(order, seed0, strict=True),
                                                              key=lambda x: x[0]))
        lines += [f"Tension RMSE ranking (seed {seed0[0].seed}, nominal): {ranking}.", ""]
    lines += ["## Where we agree and disagree, and why", "",
              "Verdicts above compare means within a factor of 1.5. The main cause of "
              "disagreement measured so far: the rigid 82-link track has no bushing "
              "compliance, so chordal action at the 14-tooth sprocket (link-passing frequency "
              "speed/pitch, 20 Hz at 1.5 m/s) makes the tension ripple by about ±2.4 kN (std) "
              "in hold mode against the stiff oil column; tension RMSE and fluctuation therefore "
              "carry that ripple whatever the architecture, and the controller spends valve "
              "switches on it. Energy is the hydraulic energy drawn from the supply over the "
              "run (pump work including relief losses in accumulator mode); the study does not "
              "define its energy figure, so magnitudes are not comparable, only rankings.", ""]
    for r in results:
        variant = r.metadata["variant"]
        write_result(r, out / "runs" / f"{r.scenario}-{r.architecture}-{variant}-s{r.seed}")
    path = out / "report.md"
    write_text_atomic(path, "\n".join(lines) + "\n")
    return path
