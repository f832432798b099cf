"""Callgrind instructions per step of the closed W1 loop (``run_loop``), split into
``mj_step`` and the rest.

Runs ``trackmj run W1`` (tp, nmpc, ekf) under valgrind's callgrind with collection off, and
switches it on only around ``run_loop`` (a client request from a tiny C helper compiled
here with the system compiler and valgrind's ``callgrind.h``). A short run first loads
every compiled kernel and the settled track, so the counted run (``--steps``, default 1500
= 1.5 s) holds the loop alone. ``mj_step``'s inclusive count comes from
``callgrind_annotate`` (valgrind's ``--toggle-collect=mj_step`` loses part of the step, so
it is not used). Prints the instructions per step and
the part outside ``mj_step`` by object file (CPython, CasADi, DAQP, numpy, numba kernels,
libc, ...).

Run: ``python benchmarks/bench_loop_callgrind.py [--steps 1500] [--scenario W1]``; the
interpreter it runs under decides which tree is measured (e.g. ``/work/base/.venv/bin/python
benchmarks/bench_loop_callgrind.py`` for another checkout). Takes a few minutes.
"""

from __future__ import annotations

import argparse
import ctypes
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

HELPER_C = """
#include <valgrind/callgrind.h>
void trackmj_collect(void) { CALLGRIND_TOGGLE_COLLECT; }
"""


def _helper() -> Path:
    """Compile the collect-toggle helper once into the temp directory; its path."""
    lib = Path(tempfile.gettempdir()) / "trackmj_callgrind_toggle.so"
    if not lib.exists():
        src = lib.with_suffix(".c")
        src.write_text(HELPER_C)
        subprocess.run(["cc", "-shared", "-fPIC", "-O1", "-o", str(lib), str(src)], check=True)
    return lib


def inner(scenario: str, steps: int) -> None:
    """Under valgrind: warm-up run, then the counted run with collection around run_loop."""
    toggle = ctypes.CDLL(str(_helper())).trackmj_collect
    import trackmj.sim.run as run_module
    from trackmj.sim.run import simulate

    # kernels compiled/loaded, settled track cached (a 50 ms run needs an earlier start of
    # the metrics' window; the counted run keeps the scenario's own)
    simulate(scenario, duration=0.05, set={"scenario.evaluation.start_s": 0.01})
    original = run_module.run_loop

    def counted(*args, **kwargs):
        toggle()
        try:
            return original(*args, **kwargs)
        finally:
            toggle()

    run_module.run_loop = counted
    simulate(scenario, duration=steps * 1e-3)


def _total(out: str) -> int:
    """Instructions collected in a callgrind output file."""
    with open(out) as f:
        for line in f:
            if line.startswith(("summary:", "totals:")):
                return int(line.split()[1])
    raise ValueError(f"{out}: no totals")


def _by_object(out: str) -> list[tuple[str, int]]:
    """Exclusive instructions per object file (shared library), largest first."""
    text = subprocess.run(["callgrind_annotate", "--threshold=100", out],
                          capture_output=True, text=True, check=True).stdout
    totals: dict[str, int] = {}
    for line in text.splitlines():
        m = re.match(r"\s*([\d,]+)\s+\([^)]*\)\s+.*\[(.*)\]\s*$", line)
        if m:
            obj = Path(m.group(2)).name
            totals[obj] = totals.get(obj, 0) + int(m.group(1).replace(",", ""))
    return sorted(totals.items(), key=lambda kv: -kv[1])


def _inclusive(out: str, function: str) -> int:
    """Inclusive instructions of ``function`` (callgrind_annotate --inclusive)."""
    text = subprocess.run(["callgrind_annotate", "--inclusive=yes", "--threshold=100", out],
                          capture_output=True, text=True, check=True).stdout
    for line in text.splitlines():
        m = re.match(r"\s*([\d,]+)\s+\([^)]*\)\s+\S*?:(\S+) \[", line)
        if m and m.group(2) == function:
            return int(m.group(1).replace(",", ""))
    raise ValueError(f"{out}: no function {function}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1500, help="counted loop steps")
    parser.add_argument("--scenario", default="W1")
    parser.add_argument("--inner", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--out", default=None, help="callgrind output file (kept)")
    args = parser.parse_args()
    if args.inner:
        inner(args.scenario, args.steps)
        return
    _helper()
    out = args.out or os.path.join(tempfile.gettempdir(), f"callgrind.loop.{os.getpid()}.out")
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", PYTHONHASHSEED="0")
    subprocess.run(["valgrind", "--tool=callgrind", "--collect-atstart=no",
                    f"--callgrind-out-file={out}", sys.executable, __file__, "--inner",
                    "--scenario", args.scenario, "--steps", str(args.steps)],
                   check=True, env=env, capture_output=True, text=True)
    n = args.steps
    whole, step = _total(out), _inclusive(out, "mj_step")
    objects = dict(_by_object(out))
    mujoco_own = objects.pop("libmujoco.so.4.0.0", 0)
    # what mj_step spends in libc/libm/ld-linux (memset, memcpy, sqrt, TLS lookups) is not
    # MuJoCo's own
    inside_libc = step - mujoco_own
    print(f"{args.scenario} (tp, nmpc, ekf), {n} steps, callgrind of run_loop ({out}):")
    print(f"  whole loop      {whole / n / 1e3:8.1f}k instructions per step")
    print(f"  mj_step         {step / n / 1e3:8.1f}k")
    print(f"  outside mj_step {(whole - step) / n / 1e3:8.1f}k "
          f"(loop = {whole / step:.3f}x the bare step)")
    print("  outside mj_step by object (exclusive; libc, libm and the loader's TLS lookups less "
          "mj_step's share):")
    system = ("libc.so.6", "libm.so.6", "ld-linux-x86-64.so.2")
    libc = sum(objects.pop(name, 0) for name in system) - inside_libc
    rows = sorted([*objects.items(), ("libc + libm + ld-linux", libc)], key=lambda kv: -kv[1])
    for obj, count in rows[:12]:
        print(f"    {obj:44s} {count / n / 1e3:8.1f}k")


if __name__ == "__main__":
    main()
