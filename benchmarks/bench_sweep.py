"""Sweep throughput: runs per hour on the Dask executor with 1 and 2 workers, and the
start-up cost of a run (process, imports, model load, settle, JIT cache, NMPC build).

Three parts, each in fresh Python processes so no part warms another:

* ``startup``: one process imports ``trackmj.sim.run`` and runs W1 three times (``--duration``
  s each): the first run carries the process's one-off costs, the later ones only the
  per-run start-up; timing wrappers split a warm run into prepare, model compile, settle,
  hydraulic element, controller and estimator build, loop and metrics. Also the warm-up of
  ``trackmj.study.worker`` (what the executor's forkserver does once for all workers).
* ``scaling``: for 1 and 2 workers, a new process starts an :class:`Executor` and maps
  ``--runs`` W1 runs of ``--duration`` s (seeds 0..N-1); reported: cluster start, time to
  the last result, runs per hour end to end (start included) and after the start.
* the machine and its load average (other processes share the cores) before and after.

Each part is repeated ``--repeat`` times and the best is kept (shared machine). Run:
``python benchmarks/bench_sweep.py [--runs 20] [--duration 2] [--repeat 2]``; on a quiet
machine the 2-worker speed-up is the figure to check (target >= 1.8x).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

STARTUP = r"""
import json, time
t0 = time.perf_counter()
import trackmj.sim.run as run_module
t_import = time.perf_counter() - t0
from collections import defaultdict
import trackmj.elements.hydraulic as hydraulic_element
import trackmj.sim.architectures as arch
import trackmj.sim.controllers as controllers
from trackmj.sim.entries import Entry
import mujoco

SPENT = defaultdict(float)

def timed(fn, bucket):
    def wrapper(*args, **kwargs):
        start = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            SPENT[bucket] += time.perf_counter() - start
    return wrapper

def wrap(owner, name, bucket):
    setattr(owner, name, timed(getattr(owner, name), bucket))

class TimedMujoco:   # arch.mujoco with MjModel.from_xml_string timed
    def __getattr__(self, name):
        return getattr(mujoco, name)
    class MjModel:
        from_xml_string = staticmethod(timed(mujoco.MjModel.from_xml_string,
                                             "model compile (MJCF -> MjModel)"))

arch.mujoco = TimedMujoco()
wrap(run_module, "prepare", "prepare (files, validation)")
wrap(arch.TrackPlant, "run", "settle (1 s standing, MuJoCo)")
wrap(hydraulic_element, "build", "hydraulic element (numba kernels)")
wrap(arch, "_control", "reduced model")
wrap(run_module, "run_loop", "closed loop")
wrap(run_module, "compute_metrics", "metrics")
for registry_dict, bucket in ((controllers.CONTROLLERS, "controller build (NMPC)"),
                              (controllers.ESTIMATORS, "estimator build")):
    for name, e in list(registry_dict.items()):
        registry_dict[name] = Entry(e.description, timed(e.build, bucket), e.needs)
runs = []
for seed in range(3):
    SPENT.clear()
    start = time.perf_counter()
    run_module.simulate("W1", duration=DURATION, seed=seed)
    wall = time.perf_counter() - start
    runs.append({"wall_s": wall, "split": dict(SPENT)})
print(json.dumps({"import_s": t_import, "runs": runs}))
"""

WARM = r"""
import json, time
t0 = time.perf_counter()
import trackmj.study.worker as w
print(json.dumps({"import_and_warm_s": time.perf_counter() - t0, "warm_s": w.warm_time_s}))
"""

SCALING = r"""
import json, time
def main():
    t0 = time.perf_counter()
    from trackmj.study.executor import Executor, RunSpec
    specs = [RunSpec("W1", duration=DURATION, seed=s) for s in range(RUNS)]
    with Executor(workers=WORKERS) as ex:
        t_up = time.perf_counter()
        cpu0 = ex.client.run(time.process_time)
        main0 = time.process_time()
        outcomes = ex.map(specs)
        t_end = time.perf_counter()
        main1 = time.process_time()
        cpu1 = ex.client.run(time.process_time)
    failed = [o.error for o in outcomes if not o.ok]
    cpu = sum(cpu1[w] - cpu0[w] for w in cpu0)
    print(json.dumps({"start_s": t_up - t0, "total_s": t_end - t0, "runs_s": t_end - t_up,
                      "run_wall_s": [o.wall_time_s for o in outcomes], "failed": failed,
                      "worker_cpu_s": cpu, "main_cpu_s": main1 - main0}))
if __name__ == "__main__":
    main()
"""


def _python(code: str, **constants: object) -> dict:
    """Run ``code`` in a fresh interpreter with ``constants`` defined; its JSON output."""
    header = "".join(f"{k} = {v!r}\n" for k, v in constants.items())
    path = f"/tmp/trackmj_bench_{os.getpid()}.py"
    with open(path, "w") as fh:
        fh.write(header + code)
    try:
        out = subprocess.run([sys.executable, path], capture_output=True, text=True,
                             check=True).stdout
    finally:
        os.unlink(path)
    return json.loads(out.strip().splitlines()[-1])


def _load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min) on {os.cpu_count()} cores"


def startup(duration: float, repeat: int) -> None:
    best = min((_python(STARTUP, DURATION=duration) for _ in range(repeat)),
               key=lambda r: r["runs"][1]["wall_s"])
    first, warm = best["runs"][0], min(best["runs"][1:], key=lambda r: r["wall_s"])
    print(f"import trackmj.sim.run: {best['import_s']:.2f} s")
    print(f"first W1 run of {duration:g} s in a process: {first['wall_s']:.2f} s; "
          f"warm run: {warm['wall_s']:.2f} s (one-off process cost "
          f"{first['wall_s'] - warm['wall_s']:.2f} s)")
    loop = warm["split"].get("closed loop", 0.0)
    print(f"warm run split [s] (start-up = everything but the loop: "
          f"{warm['wall_s'] - loop:.3f} s = {100 * (1 - loop / warm['wall_s']):.0f} %):")
    names = sorted({*warm["split"], *first["split"]},
                   key=lambda n: -max(warm["split"].get(n, 0.0), first["split"].get(n, 0.0)))
    for name in names:
        print(f"  {name:<36} {warm['split'].get(name, 0.0):7.3f}   (first run "
              f"{first['split'].get(name, 0.0):.3f})")
    rest = warm["wall_s"] - sum(warm["split"].values())
    print(f"  {'rest (schedule, recorder, result)':<36} {rest:7.3f}")
    try:
        warmed = min((_python(WARM) for _ in range(repeat)), key=lambda r: r["warm_s"])
    except subprocess.CalledProcessError:   # a trackmj before the forkserver warm-up
        print("no trackmj.study.worker: each worker pays the one-off cost at its first run")
        return
    print(f"trackmj.study.worker import + warm-up (once per forkserver): "
          f"{warmed['import_and_warm_s']:.2f} s (warm-up {warmed['warm_s']:.2f} s)")


def scaling(runs: int, duration: float, repeat: int) -> None:
    rate, cpu = {}, {}
    for workers in (1, 2):
        best = min((_python(SCALING, DURATION=duration, RUNS=runs, WORKERS=workers)
                    for _ in range(repeat)), key=lambda r: r["total_s"])
        if best["failed"]:
            raise SystemExit(f"runs failed: {best['failed']}")
        rate[workers] = (3600 * runs / best["total_s"], 3600 * runs / best["runs_s"])
        walls = best["run_wall_s"]
        cpu[workers] = best["worker_cpu_s"] / runs
        print(f"{workers} worker(s): cluster start {best['start_s']:.2f} s, {runs} runs done "
              f"after {best['total_s']:.2f} s -> {rate[workers][0]:.0f} runs/h end to end, "
              f"{rate[workers][1]:.0f} runs/h after the start; run wall time "
              f"{min(walls):.2f}..{max(walls):.2f} s, CPU per run: workers "
              f"{cpu[workers]:.2f} s, this process (client, scheduler, nannies) "
              f"{best['main_cpu_s'] / runs:.3f} s ({_load()})")
    print(f"2 workers / 1 worker: {rate[2][0] / rate[1][0]:.2f}x end to end, "
          f"{rate[2][1] / rate[1][1]:.2f}x after the start; CPU per run "
          f"{cpu[2] / cpu[1]:.2f}x (1.00x: the workers do not slow each other down, so with "
          "two free cores the ratio after the start approaches 2x)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20, help="runs per scaling measurement")
    parser.add_argument("--duration", type=float, default=2.0, help="simulated s per run")
    parser.add_argument("--repeat", type=int, default=2, help="best of N")
    parser.add_argument("--part", choices=("all", "startup", "scaling"), default="all")
    args = parser.parse_args()
    from trackmj.host import machine

    print(f"machine: {machine()}; {_load()}")
    start = time.perf_counter()
    if args.part in ("all", "startup"):
        startup(args.duration, args.repeat)
    if args.part in ("all", "scaling"):
        scaling(args.runs, args.duration, args.repeat)
    print(f"({time.perf_counter() - start:.0f} s; {_load()})")


if __name__ == "__main__":
    main()
