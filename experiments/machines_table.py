"""The conditions × machines table of the README: each condition's acceptance on each machine,
from the result folders of ``trackmj report --machine NAME`` (one per machine).

Acceptance, as the scenario files state it (assumed engineering requirements, not the
study's) and :func:`trackmj.results.verdict.verdict` judges it (as ``trackmj run`` prints it):
the 0.5 s mean of F_ten stays in the run's band (its control file's [F_min, F_max], by
default [2/3, 4/3] × the machine's nominal tension), is back within ±5 % of the reference
2 s after each disturbance edge, and no steady 5 s window's mean error reaches 2 % (the band
and limits as each run recorded them, ``evaluation.*``; a report written before they were
recorded was judged with the default band, 2 s and 2 %). A cell gives the verdict
over the condition's runs (its
seeds, and W5's parameter variants: every run must pass), the lowest and highest 0.5 s mean
[kN], and the low-pass tension RMSE [kN] as mean ± std over the runs; a run that failed is
counted and its reason shortened.

Run: ``python experiments/machines_table.py lf1352=runs/report m113=runs/report-m113 ...``;
``NAME=FOLDER,FOLDER2`` takes a machine's conditions from several reports, a later folder's
condition replacing an earlier one's (a condition re-run on its own)
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq

from trackmj.machines.assembly import mechanics, resolve
from trackmj.results.verdict import RECOVERY_WITHIN_S, STEADY_OFFSET_MAX_REL, verdict

EDGE = "acceptance.edge_recovery_s."
"""Prefix of the results' columns of each edge's recovery [s] (NaN: never back, or no such
edge in that run's condition)."""
ORDER = ("W1", "W2", "W3", "W4", "W5", "NL1")
"""The built-in conditions' order in the table (others follow by name)."""


def cell(rows: dict[str, np.ndarray], nominal_N: float) -> str:
    """One condition on one machine: verdict, 0.5 s mean range [kN], low-pass RMSE [kN]."""
    error = rows["error"]
    failed = [str(e) for e in error if isinstance(e, str) and e]
    ok = np.array([not (isinstance(e, str) and e) for e in error])
    if not ok.any():
        return f"**fails**: {len(failed)} of {len(error)} runs failed ({failed[0][:80]}...)"

    def recorded(name: str, default: float) -> np.ndarray:
        """Each run's ``evaluation.NAME``, ``default`` where it recorded none (NaN: a run
        written before the column, in a table that has it)."""
        values = rows.get(f"evaluation.{name}", np.full(len(ok), np.nan))
        return np.where(np.isfinite(values), values, default)

    low = recorded("force_min_N", 2.0 * nominal_N / 3.0)
    high = recorded("force_max_N", 4.0 * nominal_N / 3.0)
    within = recorded("recovery_within_s", RECOVERY_WITHIN_S)
    limit = recorded("steady_offset_max_rel", STEADY_OFFSET_MAX_REL)
    mean_min = float(np.min(rows["acceptance.mean_min_N"][ok]))
    mean_max = float(np.max(rows["acceptance.mean_max_N"][ok]))
    # the condition's edges: the edge columns some run of it filled (the table holds every
    # condition's), so that a run's NaN there is an edge it never came back after
    edges = [name for name in rows if name.startswith(EDGE) and np.isfinite(rows[name][ok]).any()]
    broken: dict[str, None] = {}            # the rules some run broke, in the verdict's order
    for k in np.flatnonzero(ok):
        figures = {"mean_min_N": rows["acceptance.mean_min_N"][k],
                   "mean_max_N": rows["acceptance.mean_max_N"][k],
                   "steady_offset_max_rel": rows["acceptance.steady_offset_max_rel"][k],
                   "edge_recovery_s": {name.removeprefix(EDGE): rows[name][k] for name in edges}}
        band = (float(low[k]), float(high[k]))
        broken |= dict.fromkeys(verdict(figures, band, float(within[k]), float(limit[k])).broken)
    reasons = list(broken)
    if failed:
        reasons.append(f"{len(failed)} of {len(error)} runs failed: {failed[0][:60]}...")
    rmse = rows["rmse_lp_N"][ok] / 1e3
    said = "holds" if not reasons else "**fails** (" + "; ".join(reasons) + ")"
    return (f"{said}; {mean_min / 1e3:.1f}–{mean_max / 1e3:.1f} kN; "
            f"RMSE {rmse.mean():.2f} ± {rmse.std(ddof=1) if len(rmse) > 1 else 0.0:.2f} kN")


def table(folders: dict[str, list[Path]]) -> str:
    """Markdown table, conditions down, machines across; per machine its report folders,
    a later one's condition replacing an earlier one's."""
    found: dict[str, dict[str, str]] = {}
    for name, paths in folders.items():
        nominal = mechanics(resolve(name)).nominal_tension_N
        for folder in paths:
            data = pq.read_table(folder / "results.parquet").to_pydict()
            columns = {k: np.asarray(v, dtype=object if k == "error" else float)
                       for k, v in data.items()
                       if k in ("error", "rmse_lp_N", "evaluation.force_min_N",
                                "evaluation.force_max_N", "evaluation.recovery_within_s",
                                "evaluation.steady_offset_max_rel")
                       or k.startswith("acceptance.")}
            scenario = np.array(data["scenario"])
            for condition in set(scenario):
                keep = scenario == condition
                rows = {k: v[keep] for k, v in columns.items()}
                if "error" not in rows:
                    rows["error"] = np.full(int(keep.sum()), None, dtype=object)
                found.setdefault(condition, {})[name] = cell(rows, nominal)
    cells = {c: found[c] for c in sorted(found, key=lambda c: (
        c not in ORDER, ORDER.index(c) if c in ORDER else 0, c))}
    names = list(folders)
    lines = ["| condition | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]
    for condition, by_machine in cells.items():
        lines.append(f"| {condition} | "
                     + " | ".join(by_machine.get(n, "not run") for n in names) + " |")
    return "\n".join(lines)


def main(argv: list[str]) -> int:
    if not argv or any("=" not in a for a in argv):
        print(__doc__.strip().splitlines()[-1], file=sys.stderr)
        return 2
    folders = {a.split("=", 1)[0]: [Path(p) for p in a.split("=", 1)[1].split(",")]
               for a in argv}
    print(table(folders))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
