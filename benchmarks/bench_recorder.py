"""Microbenchmark: µs per TimeseriesRecorder.append call (the 1 ms sim loop's logging cost).

Appends the 15 contract columns (plus 0 or 4 extras) for 30 s at 1 kHz, then builds the
Arrow table and serialises it. Not run by CI: ``python benchmarks/bench_recorder.py``.
"""

from __future__ import annotations

import time

from trackmj.results.store import TimeseriesRecorder, _parquet_bytes, run_metadata

STEPS = 30_000


def bench(n_extra: int) -> tuple[float, float]:
    """(median µs per append over 3 repeats, s to build + serialise the table)."""
    extra = {f"extra_{k}": "1" for k in range(n_extra)}
    runs = []
    for _ in range(3):
        rec = TimeseriesRecorder(STEPS, extra)
        row = (15e3, 15e3, 6e6, 1e6, 12e6, 0.05, 1e-3, 1e-6, 1, 0.3, 1.0, 2.0, 1.9, 0.1)
        row = row + (0.0,) * n_extra
        append = rec.append
        t0 = time.perf_counter()
        for i in range(STEPS):
            append(i, i * 1e-3, *row)
        runs.append((time.perf_counter() - t0) / STEPS * 1e6)
    t0 = time.perf_counter()
    _parquet_bytes(rec.table(run_metadata("W1", "tp", "nmpc", "ekf", 0, machine="bench")))
    return sorted(runs)[1], time.perf_counter() - t0


if __name__ == "__main__":
    from trackmj.host import machine

    print(machine())
    for n_extra in (0, 4):
        us, build = bench(n_extra)
        print(
            f"{15 + n_extra} columns: {us:.2f} µs per append "
            f"({us / 1000 * 100:.2f} % of a 1 ms real-time step); "
            f"table + Parquet of {STEPS} rows: {build * 1e3:.0f} ms"
        )
