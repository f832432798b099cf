"""Cost of the native track FMU against the Python plant, side by side in one process.

Exports the default machine's track (flat ground, FMI 2.0, this platform only) and
measures through fmpy, as an importer calls it:

* instantiate + initialise [s] (median of 5 fresh instances);
* doStep (1 ms, 1.5 m/s, constant force) [ms]: the median over 2000 steps, against the
  Python plant's bare step (``TrackPlant.apply`` + ``TrackPlant.step`` with a constant
  force) over the same steps;
* get + set FMU state [ms] (median of 200);
* memory per instance [MB]: the process's resident set grown by 5 more instances, / 5.

Wall-clock figures: name the machine with them; the ratio doStep / bare step is the one to
compare across machines. Run: ``python benchmarks/bench_native_fmu.py``.
"""

from __future__ import annotations

import math
import shutil
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import fmpy
from fmpy.fmi2 import FMU2Slave

from trackmj.elements.prescribed import ConstantForce
from trackmj.fmi.native.export import export_track
from trackmj.ports import StepInputs
from trackmj.sim.mechanics import settled_track
from trackmj.sim.setup import prepare

FORCE_N = 13e3
STEPS = 2000


def resident_mb() -> float:
    """This process's resident set [MB] (Linux /proc)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return float(line.split()[1]) / 1024.0
    return math.nan


def instance(md: Any, unzipped: str, name: str) -> FMU2Slave:
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped,
                    modelIdentifier=md.coSimulation.modelIdentifier, instanceName=name)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    return fmu


def main() -> None:
    work = Path(tempfile.mkdtemp(prefix="bench-native-"))
    path = export_track(work / "track.fmu", force_N=FORCE_N, platforms=("linux",)).path
    md = fmpy.read_model_description(str(path))
    unzipped = fmpy.extract(str(path))

    starts = []
    for k in range(5):
        t0 = time.perf_counter()
        fmu = instance(md, unzipped, f"start{k}")
        starts.append(time.perf_counter() - t0)
        fmu.terminate()
        fmu.freeInstance()

    fmu = instance(md, unzipped, "steps")
    fmu.setReal([1, 3], [FORCE_N, 1.5])
    fmu_ms = []
    for k in range(STEPS):
        t0 = time.perf_counter()
        fmu.doStep(k * 1e-3, 1e-3)
        fmu_ms.append((time.perf_counter() - t0) * 1e3)
    states_ms = []
    for _ in range(200):
        t0 = time.perf_counter()
        state = fmu.getFMUstate()
        fmu.setFMUstate(state)
        states_ms.append((time.perf_counter() - t0) * 1e3)
        fmu.freeFMUstate(state)

    plant = settled_track(prepare("W1"), FORCE_N)
    element = ConstantForce(FORCE_N)
    inputs = StepInputs(1.5, 0.0, 0.0, math.nan)
    bare_ms = []
    for _ in range(STEPS):
        t0 = time.perf_counter()
        plant.apply(inputs)
        plant.step(element)
        bare_ms.append((time.perf_counter() - t0) * 1e3)

    before = resident_mb()
    more = [instance(md, unzipped, f"memory{k}") for k in range(5)]
    per_instance = (resident_mb() - before) / len(more)
    for extra in (*more, fmu):
        extra.terminate()
        extra.freeInstance()
    shutil.rmtree(unzipped, ignore_errors=True)
    shutil.rmtree(work, ignore_errors=True)

    step, bare = statistics.median(fmu_ms), statistics.median(bare_ms)
    print(f"instantiate + initialise: {statistics.median(starts):.3f} s (median of 5)")
    print(f"doStep 1 ms: {step:.3f} ms; Python plant bare step: {bare:.3f} ms; "
          f"ratio {step / bare:.2f}")
    print(f"get + set FMU state: {statistics.median(states_ms):.4f} ms (median of 200)")
    print(f"memory per instance: {per_instance:.1f} MB")


if __name__ == "__main__":
    main()
