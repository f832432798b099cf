"""Coupled step (MuJoCo track + hydraulic plugin, strong coupling) vs the bare step (MuJoCo and
the ground foundation, no element port).

Both run in one process on the same spun-up state (driving at 1.5 m/s, hold mode), so the
ratio is measured, not assembled from separate runs. The coupled step logs the plugin's
per-step values as ``trackmj run`` does (``log()``); the plugin alone (force_law +
complete_step + log) is timed inside the coupled loop. Best of three alternating blocks.
Run: ``python benchmarks/bench_coupled.py [--seconds 3] [--supply MODEL]`` (default: the
hydraulic file's default supply model).
"""

from __future__ import annotations

import argparse
import time

from driving import DrivingSnapshot

from trackmj.host import machine
from trackmj.hydraulics import HydraulicTensioner
from trackmj.hydraulics.params import SUPPLY_MODELS


class _TimedElement:
    """Wraps a tensioner element and accumulates the wall time spent inside it."""

    def __init__(self, inner: HydraulicTensioner) -> None:
        self.inner = inner
        self.seconds = 0.0

    def force_law(self, t_s: float, stroke_m: float, velocity_m_s: float):
        start = time.perf_counter()
        law = self.inner.force_law(t_s, stroke_m, velocity_m_s)
        self.seconds += time.perf_counter() - start
        return law

    def complete_step(self, t_s: float, stroke_m: float, velocity_m_s: float) -> None:
        start = time.perf_counter()
        self.inner.complete_step(t_s, stroke_m, velocity_m_s)
        self.seconds += time.perf_counter() - start

    def log(self) -> None:
        start = time.perf_counter()
        self.inner.log()
        self.seconds += time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="simulated time per block")
    parser.add_argument("--supply", choices=SUPPLY_MODELS, default=None,
                        help="supply model (default: the hydraulic file's)")
    args = parser.parse_args()
    steps = round(args.seconds / 1e-3)

    snapshot = DrivingSnapshot()
    plant = snapshot.plant
    force = plant.idler_force_N

    def coupled() -> tuple[float, float]:
        snapshot.restore()
        probe = HydraulicTensioner(stroke_m=plant.stroke_m)
        head = (force + 2 * probe.Ar * probe.pT) / (2 * probe.Ah)
        element = _TimedElement(HydraulicTensioner(stroke_m=plant.stroke_m,
                                                   head_pressure_Pa=head, t0_s=plant.time_s,
                                                   supply_model=args.supply))
        element.inner.set_mode(0)
        start = time.perf_counter()
        for _ in range(steps):
            plant.step(element)
            element.log()
        return (time.perf_counter() - start) / steps, element.seconds / steps

    element_model = HydraulicTensioner(supply_model=args.supply).supply_model
    bare_t, coupled_t, plugin_t = [], [], []
    for _ in range(3):
        bare_t.append(snapshot.bare_step_s(steps))
        total, plugin = coupled()
        coupled_t.append(total)
        plugin_t.append(plugin)
    b, c, p = min(bare_t), min(coupled_t), min(plugin_t)
    print(f"machine: {machine()}; supply {element_model}")
    print(f"bare step (MuJoCo + foundation) {b * 1e6:8.1f} us/step  ({1e-3 / b:.2f}x real time)")
    print(f"coupled step (strong)           {c * 1e6:8.1f} us/step  ({1e-3 / c:.2f}x real time)")
    print(f"  plugin inside it              {p * 1e6:8.1f} us/step  ({p / b:.1%} of the bare step)")
    print(f"ratio coupled / bare            {c / b:.3f}")


if __name__ == "__main__":
    main()
