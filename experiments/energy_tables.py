"""The energy tables of docs/sizing.md ("Energy"): W1-W5 (tp, nmpc, seed 0, 30 s) on the
default machine with the default supply (``compensated``) and with the study's
(``fixed_relief``), each run's ``metrics.json`` ``energy_J`` as rows in joules.

Run: ``python experiments/energy_tables.py [--workers N]``; prints the two Markdown tables
and, per run, the shares of the circuit energy the docs' bullets quote (main valve,
restrictors, ``numerical``).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from typing import Any

from trackmj.sim.run import simulate

SCENARIOS = ("W1", "W2", "W3", "W4", "W5")
SUPPLIES = {"compensated": "Default supply (`compensated`), J:",
            "fixed_relief": "Study's supply (`fixed_relief`), J:"}

Run = tuple[dict[str, Any], float, float]
"""One run's ``energy_J`` table, valve switches and raw RMSE [N]."""


def _run(scenario: str, supply: str) -> Run:
    result = simulate(scenario, architecture="tp", controller="nmpc", seed=0, duration=30.0,
                      set=[f"scenario.supply.model={supply}"])
    m = result.metrics
    return m["energy_J"], m["valve_switches"], m["rmse_N"]


def _sum(*keys: str) -> Callable[[dict[str, Any]], float]:
    """A row's value [J]: the sum of the table's entries at the dotted ``keys``."""
    def value(e: dict[str, Any]) -> float:
        total = 0.0
        for key in keys:
            node: Any = e
            for part in key.split("."):
                node = node[part]
            total += float(node)
        return total
    return value


NUMERICAL = _sum("numerical.volume_term", "numerical.interface")
RESTRICTORS = _sum("throttling.rod_feed_restrictor", "throttling.head_restrictor_L",
                   "throttling.head_restrictor_R")
ROWS: tuple[tuple[str, Callable[[dict[str, Any]], float]], ...] = (
    ("pump", _sum("pump")),
    ("  pump: volumetric (its leakage)", _sum("pump_losses.volumetric")),
    ("  pump: mechanical", _sum("pump_losses.mechanical")),
    ("  pump: unloaded", _sum("pump_losses.unloaded")),
    ("relief", _sum("relief")),
    ("stored: supply oil + accumulator", _sum("stored_change.supply_oil",
                                              "stored_change.accumulator")),
    ("numerical: supply", _sum("numerical.supply")),
    ("circuit", _sum("circuit")),
    ("  throttling: main valve", _sum("throttling.main_valve")),
    ("  throttling: rod-feed restrictor", _sum("throttling.rod_feed_restrictor")),
    ("  throttling: V_L + V_R", _sum("throttling.V_L", "throttling.V_R")),
    ("  throttling: head restrictors", _sum("throttling.head_restrictor_L",
                                            "throttling.head_restrictor_R")),
    ("  makeup", _sum("makeup")),
    ("  leakage", _sum("leakage")),
    ("  cavitation (air out of solution)", _sum("cavitation")),
    ("  return line", _sum("return_line")),
    ("  stored: circuit oil", _sum("stored_change.circuit_oil")),
    ("  numerical: volume term + interface", NUMERICAL),
    ("  friction (+ end stop)", _sum("friction", "endstop")),
    ("  mechanical (into the track)", _sum("mechanical")),
)
"""The tables' rows: label (indented under ``circuit`` for its parts) and value [J]."""


def table(runs: list[Run]) -> str:
    """The Markdown table of the runs (one column per scenario, in SCENARIOS order)."""
    lines = ["| term | " + " | ".join(SCENARIOS) + " |",
             "|---|" + "---:|" * len(SCENARIOS)]
    for label, value in ROWS:
        lines.append(f"| {label} | " + " | ".join(f"{value(e):.1f}" for e, _, _ in runs)
                     + " |")
    lines.append("| residual | " + " | ".join(f"{e['residual']:.2e}" for e, _, _ in runs)
                 + " |")
    lines.append("| valve switches | " + " | ".join(f"{n:.0f}" for _, n, _ in runs) + " |")
    lines.append("| RMSE [kN] | " + " | ".join(f"{r / 1e3:.2f}" for _, _, r in runs) + " |")
    return "\n".join(lines)


def shares(runs: list[Run]) -> str:
    """Each run's main-valve, restrictor and numerical share of its circuit energy [%]."""
    parts = []
    for scenario, (e, _, _) in zip(SCENARIOS, runs, strict=True):
        c = e["circuit"]
        parts.append(f"{scenario}: main valve {100 * _sum('throttling.main_valve')(e) / c:.0f}"
                     f", restrictors {100 * RESTRICTORS(e) / c:.0f}"
                     f", numerical {100 * NUMERICAL(e) / c:.2f}")
    return "; ".join(parts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--workers", type=int, default=1)
    workers = parser.parse_args().workers
    jobs = [(s, supply) for supply in SUPPLIES for s in SCENARIOS]
    with ProcessPoolExecutor(workers) as pool:
        results = list(pool.map(_run, *zip(*jobs, strict=True)))
    for i, (supply, title) in enumerate(SUPPLIES.items()):
        runs = results[i * len(SCENARIOS):(i + 1) * len(SCENARIOS)]
        print(f"\n{title}\n\n{table(runs)}\n\nshares of the circuit [%] ({supply}): "
              f"{shares(runs)}")


if __name__ == "__main__":
    main()
