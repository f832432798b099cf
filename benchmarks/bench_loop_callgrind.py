"""Callgrind instructions per step of the closed W1 loop (``run_loop``) against the bare step.

Two runs under valgrind's callgrind, each with collection off and switched on only around a
window of steps (a client request from a tiny C helper compiled here with the system
compiler and valgrind's ``callgrind.h``):

* ``loop``: ``trackmj run W1`` (tp, nmpc, ekf, flat ground, 1.5 m/s), counted over the
  steps ``--start`` .. ``--start + --steps`` (default 2.0 .. 4.0 s: the steady drive, the
  12 -> 15 kN step at 3 s inside), by wrapping the schedule's step inputs so that the
  toggles fall between two loop steps;
* ``bare``: the bare step as ``trackmj drive`` measures it (``plant_real_time_factor``):
  ``TrackPlant.step`` of the default machine with the passive tensioner (its MuJoCo step
  and ground foundation), driven to the same 1.5 m/s and counted over as many steps after
  the same start.

A short run first loads every compiled kernel and the settled track, so the counted window
holds the loop alone. Prints the instructions per step of both, their ratio, MuJoCo's share
of the loop (``mj_step1`` + ``mj_factorM`` + ``mj_step2`` inclusive, from
``callgrind_annotate``) and the rest of the loop by object file (CPython, DAQP, numpy,
numba's JIT code as ``???``, libc, ...).

Run: ``python benchmarks/bench_loop_callgrind.py [--steps 2000] [--start 2000] [--structure
slides]``; the interpreter it runs under decides which tree is measured (another checkout's
venv python measures that checkout). Takes about a quarter of an hour (both runs side by
side).
"""

from __future__ import annotations

import argparse
import ctypes
import dataclasses
import os
import re
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path

HELPER_C = """
#include <valgrind/callgrind.h>
void trackmj_collect(void) { CALLGRIND_TOGGLE_COLLECT; }
"""
SPEED_M_S = 1.5
"""W1's track speed [m/s]; the bare step is counted at the same speed."""
MUJOCO_STEP = ("mj_step1", "mj_factorM", "mj_step2", "mj_step")


def _helper() -> Path:
    """Compile the collect-toggle helper once into the temp directory; its path."""
    lib = Path(tempfile.gettempdir()) / "trackmj_callgrind_toggle.so"
    if not lib.exists():
        src = lib.with_suffix(".c")
        src.write_text(HELPER_C)
        subprocess.run(["cc", "-shared", "-fPIC", "-O1", "-o", str(lib), str(src)], check=True)
    return lib


def _windowed(items: list, start: int, steps: int, toggle: ctypes._CFuncPtr) -> Iterator:
    """``items`` with collection switched on before item ``start`` is handed out and off
    when item ``start + steps`` is asked for (or the items end)."""
    on = False
    for k, item in enumerate(items):
        if k == start:
            toggle()
            on = True
        elif k == start + steps:
            toggle()
            on = False
        yield item
    if on:
        toggle()


def inner_loop(start: int, steps: int, structure: str) -> None:
    """Under valgrind: warm-up run, then W1 with collection over its window."""
    toggle = ctypes.CDLL(str(_helper())).trackmj_collect
    import trackmj.sim.run as run_module
    from trackmj.sim.run import simulate

    # kernels compiled/loaded, settled track cached (a 50 ms run needs an earlier start of
    # the metrics' window; the counted run keeps the scenario's own)
    model = {"model.track.structure": structure}
    simulate("W1", duration=0.05, set={"scenario.evaluation.start_s": 0.01, **model})
    original = run_module.run_loop

    def counted(schedule, **blocks):
        window = _windowed(list(schedule.inputs), start, steps, toggle)
        return original(dataclasses.replace(schedule, inputs=window), **blocks)

    run_module.run_loop = counted
    simulate("W1", duration=(start + steps) * 1e-3 + 0.01, set=model)


def inner_bare(start: int, steps: int, structure: str) -> None:
    """Under valgrind: the default machine driven by the passive tensioner to W1's speed,
    collection over ``steps`` plant steps after ``start`` steps."""
    toggle = ctypes.CDLL(str(_helper())).trackmj_collect
    from trackmj.machines.track_plant import load_plant
    from trackmj.track.plant import PassiveTensioner

    plant = load_plant(overrides={"track.structure": structure})
    passive = PassiveTensioner.from_params(plant.params)
    plant.run(passive, start * 1e-3, lambda t: SPEED_M_S * min(1.0, t))
    plant.set_track_speed(SPEED_M_S)
    step = plant.step
    toggle()
    for _ in range(steps):
        step(passive)
    toggle()


def _total(out: str) -> int:
    """Instructions collected in a callgrind output file."""
    with open(out) as f:
        for line in f:
            if line.startswith(("summary:", "totals:")):
                return int(line.split()[1])
    raise ValueError(f"{out}: no totals")


def _annotate(out: str, inclusive: bool) -> str:
    return subprocess.run(["callgrind_annotate", f"--inclusive={'yes' if inclusive else 'no'}",
                           "--threshold=100", out],
                          capture_output=True, text=True, check=True).stdout


def _by_object(out: str) -> dict[str, int]:
    """Exclusive instructions per object file (shared library)."""
    totals: dict[str, int] = {}
    for line in _annotate(out, False).splitlines():
        m = re.match(r"\s*([\d,]+)\s+\([^)]*\)\s+.*\[(.*)\]\s*$", line)
        if m:
            obj = Path(m.group(2)).name
            totals[obj] = totals.get(obj, 0) + int(m.group(1).replace(",", ""))
    return totals


def _inclusive(out: str, functions: tuple[str, ...]) -> int:
    """Summed inclusive instructions of ``functions`` (none of which calls another)."""
    total = 0
    for line in _annotate(out, True).splitlines():
        m = re.match(r"\s*([\d,]+)\s+\([^)]*\)\s+\S*?:(\S+) \[", line)
        if m and m.group(2) in functions:
            total += int(m.group(1).replace(",", ""))
    return total


def _count(start: int, steps: int, structure: str) -> tuple[str, str]:
    """Run the loop and the bare step under callgrind side by side; their output files."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONHASHSEED="0")
    outs, runs = [], []
    for mode in ("loop", "bare"):
        out = os.path.join(tempfile.gettempdir(), f"callgrind.{mode}.{os.getpid()}.out")
        runs.append(subprocess.Popen(
            ["valgrind", "--tool=callgrind", "--collect-atstart=no",
             f"--callgrind-out-file={out}", sys.executable, __file__, "--inner", mode,
             "--start", str(start), "--steps", str(steps), "--structure", structure],
            env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
        outs.append(out)
    for mode, run in zip(("loop", "bare"), runs, strict=True):
        _, err = run.communicate()
        if run.returncode:
            raise SystemExit(f"{mode} run under callgrind failed:\n{err[-2000:]}")
    return outs[0], outs[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=2000, help="counted steps")
    parser.add_argument("--start", type=int, default=2000, help="steps before the count")
    parser.add_argument("--structure", choices=("chains", "slides", "free"), default="chains",
                        help="the track's [track] structure (default: chains, the machine's)")
    parser.add_argument("--inner", choices=("loop", "bare"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.inner:
        (inner_loop if args.inner == "loop" else inner_bare)(args.start, args.steps,
                                                             args.structure)
        return
    _helper()
    n = args.steps
    loop_out, bare_out = _count(args.start, n, args.structure)
    loop, bare = _total(loop_out), _total(bare_out)
    mujoco_in_loop = _inclusive(loop_out, MUJOCO_STEP)
    objects = _by_object(loop_out)
    mujoco_own = sum(v for k, v in objects.items() if k.startswith("libmujoco"))
    for k in [k for k in objects if k.startswith("libmujoco")]:
        del objects[k]
    # what MuJoCo's step spends in libc/libm/ld-linux (memset, memcpy, sqrt, TLS lookups)
    # is not the rest of the loop's
    system = ("libc.so.6", "libm.so.6", "ld-linux-x86-64.so.2")
    libc = sum(objects.pop(name, 0) for name in system) - (mujoco_in_loop - mujoco_own)
    print(f"W1 (tp, nmpc, ekf), structure {args.structure}, steps {args.start}.."
          f"{args.start + n} at {SPEED_M_S} m/s, "
          f"callgrind ({loop_out}, {bare_out}):")
    print(f"  bare step (TrackPlant.step, passive) {bare / n / 1e3:8.1f}k instructions per step")
    print(f"  whole loop                           {loop / n / 1e3:8.1f}k "
          f"(= {loop / bare:.3f}x the bare step)")
    print(f"    MuJoCo's step1 + factorM + step2   {mujoco_in_loop / n / 1e3:8.1f}k")
    print(f"    the rest                           {(loop - mujoco_in_loop) / n / 1e3:8.1f}k")
    print("  the rest by object (exclusive; libc, libm and the loader less MuJoCo's share):")
    rows = sorted([*objects.items(), ("libc + libm + ld-linux", libc)], key=lambda kv: -kv[1])
    for obj, count in rows[:12]:
        print(f"    {obj:44s} {count / n / 1e3:8.1f}k")


if __name__ == "__main__":
    main()
