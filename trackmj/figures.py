"""Figures of runs and comparisons (PNG, matplotlib Agg). Display units: kN, MPa, kJ.

Comparison figures follow the study's Figures 4-8 habit but stay readable in grayscale:
each architecture has its own line style and marker, not only its own colour.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from trackmj.io import write_bytes_atomic
from trackmj.results import Result

STYLES = {
    "tp": dict(color="black", linestyle="-", marker="o"),
    "tp-weak": dict(color="0.35", linestyle="--", marker="s"),
    "dp-a": dict(color="0.55", linestyle="-.", marker="^"),
    "dp-b": dict(color="0.7", linestyle=":", marker="D"),
}


def _save(fig: plt.Figure, path: Path) -> Path:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=110)
    plt.close(fig)
    write_bytes_atomic(path, buffer.getvalue())
    return path


def run_figure(result: Result, path: str | Path) -> Path:
    """Four panels: tension vs reference, chamber/supply pressures, valve mode and u,
    cumulative energies."""
    c = result.columns()
    t = c["t_s"]
    fig, axes = plt.subplots(4, 1, figsize=(9, 10), sharex=True)
    axes[0].plot(t, c["tension_N"] / 1e3, color="black", lw=0.8, label="F_ten")
    axes[0].plot(t, c["tension_ref_N"] / 1e3, color="0.5", ls="--", lw=1.2, label="reference")
    axes[0].set_ylabel("tension [kN]")
    axes[0].legend(loc="best")
    for name, style in (("p_head_Pa", "-"), ("p_rod_Pa", "--"), ("p_supply_Pa", ":")):
        axes[1].plot(t, c[name] / 1e6, color="black", ls=style, lw=0.8,
                     label=name.removesuffix("_Pa"))
    axes[1].set_ylabel("pressure [MPa]")
    axes[1].legend(loc="best")
    axes[2].step(t, c["valve_mode"], where="post", color="black", lw=0.8, label="valve mode")
    axes[2].plot(t, c["u"], color="0.5", lw=0.8, label="u")
    axes[2].set_ylabel("mode / u [-]")
    axes[2].legend(loc="best")
    for name, style in (("e_supply_J", "-"), ("p_work_J", "--"), ("mech_work_J", ":")):
        axes[3].plot(t, c[name] / 1e3, color="black", ls=style, lw=0.9,
                     label=name.removesuffix("_J"))
    axes[3].set_ylabel("energy [kJ]")
    axes[3].set_xlabel("time [s]")
    axes[3].legend(loc="best")
    fig.suptitle(f"{result.scenario} {result.architecture} {result.controller}/"
                 f"{result.estimator} seed {result.seed}")
    fig.tight_layout()
    return _save(fig, Path(path))


def compare_figure(results: Sequence[Result], path: str | Path, label_by: str = "architecture",
                   ) -> Path:
    """Tension histories overlaid (style per label, markers every ~1/15 of the run) and a
    bar chart of supply energy."""
    fig, (ax, bars) = plt.subplots(1, 2, figsize=(13, 5), gridspec_kw={"width_ratios": [3, 1]})
    first = results[0].columns()
    ax.plot(first["t_s"], first["tension_ref_N"] / 1e3, color="0.2", lw=1.6, ls=(0, (1, 1)),
            label="reference")
    labels, energies = [], []
    for k, res in enumerate(results):
        c = res.columns()
        label = getattr(res, label_by)
        style = STYLES.get(label, dict(color=str(0.2 + 0.15 * k), linestyle="-", marker="x"))
        ax.plot(c["t_s"], c["tension_N"] / 1e3, lw=0.9, markevery=max(len(c["t_s"]) // 15, 1),
                markersize=5, label=label, **style)
        labels.append(label)
        energies.append(res.metrics.get("supply_energy_J", np.nan) / 1e3)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("tension F_ten [kN]")
    ax.legend(loc="best")
    ax.grid(alpha=0.3)
    hatches = ["", "//", "..", "xx", "\\\\", "oo"]
    for k, energy in enumerate(energies):
        bars.bar(k, energy, color="0.85", edgecolor="black", hatch=hatches[k % len(hatches)])
    bars.set_xticks(range(len(labels)), labels, rotation=30)
    bars.set_ylabel("supply energy [kJ]")
    fig.suptitle(f"{results[0].scenario}: {', '.join(labels)}")
    fig.tight_layout()
    return _save(fig, Path(path))
