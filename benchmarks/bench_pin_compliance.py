"""Per-pin compliance candidates against the default chains and free links (issue 30).

Candidates, built on the default machine's model file:

* ``chainsN`` / ``free``: the generator's structures (``[track] structure``, ``chain_links``),
  as ``bench_structure.py`` builds them;
* ``slidesN``: ``[track] structure = "slides"`` with chains of at most N links: a slide
  along the parent link's pitch before every pin hinge carrying the pin's K and B of
  ``[pins]`` as joint stiffness and damping, every connect carrying one pin; the plant
  integrates the slides' springs implicitly (``trackmj.track.foundation.ImplicitSprings``:
  no armature; the armature candidates ``+armX`` of the record were measured before that);
* suffix ``+discrete`` (MuJoCo 4's ``discrete`` integrator instead of ``implicitfast``);
* suffix ``+kin`` on ``chainsN``: every connect carries one pin's K and B (not its chain's
  m pins in series), and after each step every hinged pin's stretch s moves towards T/K
  kinematically: the child link's ``body_pos`` is its pitch offset plus s along it, s ←
  s + α·(max(T, 0)/K − s) with α = :data:`KIN_RELAXATION`, T the pin's tension
  interpolated along its chain between the tensions of the chain's two connects (exact on
  a free span; a wheel or tooth loading a chain's inner link bends T there), all in one
  compiled call (:func:`_kinematic_stretch`). No degree of freedom per pin: the chains'
  nv. A lagged T/K without the relaxation diverges within 30 ms (the span between two
  connects answers a stretch of its three hinged pins with 1.5 times its tension change).
  Measured and not kept: benchmarks/README.md, "A stretch without a degree of freedom".

Every candidate is generated through the project's builders and settled 3 s standing under
the passive tensioner (``trackmj.track.mjcf.generate.settle``) for its ``home`` keyframe,
then run through ``TrackPlant`` on the ground foundation, as every run is. Checks:

* ``--static``: 1.5 s standing at the model file's preload; per upper-strand pin k its
  stretch |p_k − p_{k−1}| − pitch (pin centres) against T/K (T its tension): mean ratio and
  the largest deviation from the mean stretch in units of T/K;
* ``--comb``: idler contact force at 1.5 m/s, passive preload 12.5 kN (settle 1 s, ramp
  1 s, hold 1 s, record 8.3 s ≈ 2 revolutions): the lines at 1/4, 3/4, 5/4 and 7/4 of the
  measured link-passing frequency (where a 4-link period shows, the even quarters being the
  track's own), each as a Hann single-bin rms and as the rms within ±0.75 Hz, and their
  root-sum-square; the same lines of the lower run's tension and of the chassis' vertical
  acceleration, and that acceleration's 8-12 Hz band (the chassis' body mode);
* ``--cost``: bare ``TrackPlant.step`` µs per step at 1.5 m/s, candidates alternating in one
  process (best and median of ``--rounds`` blocks of 1000 steps);
* ``--hard``: hard start to 1.5 m/s from ``home``, preload 12 kN stepped to 15 kN at 3 s,
  8 s: MuJoCo warnings, derailment checks every 0.1 s, largest pin stretch.

Run: ``python benchmarks/bench_pin_compliance.py --static --comb --hard chains4 free
slides4`` and ``taskset -c 0 python benchmarks/bench_pin_compliance.py --cost chains4
slides4``.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable
from unittest.mock import patch

import mujoco
import numba
import numpy as np
from bench_structure import _component, idler_contact_N
from scipy.signal import periodogram

from trackmj.host import machine
from trackmj.machines.assembly import model_mjcf, resolve
from trackmj.ports import ForceLaw, TensionerElement
from trackmj.track.mechanics import ModelParams, load_model_params
from trackmj.track.mjcf import builders
from trackmj.track.mjcf.builders import build_mjcf
from trackmj.track.mjcf.generate import SETTLE_DURATION_S, settle
from trackmj.track.mjcf.layout import compute_layout
from trackmj.track.mjcf.names import link_name
from trackmj.track.mjcf.structure import pin_series_count as structure_series
from trackmj.track.mjcf.tree import find
from trackmj.track.plant import PassiveTensioner, TrackPlant, _pin_tensions

MACHINE = resolve(None)   # the default machine (LF1352)
SPEED_M_S = 1.5
COMB_PRELOAD_N = 12.5e3
QUARTERS = (1, 3, 5, 7)
BAND_HZ = 0.75
KIN_RELAXATION = 0.3
"""α of the ``+kin`` candidate's stretch update [-] per 1 ms step (0.1 measured the same)."""


def _params(structure: str, links: int) -> ModelParams:
    overrides: dict[str, object] = ({"track.structure": "free"} if structure == "free" else
                                    {"track.structure": structure, "track.chain_links": links})
    return load_model_params(MACHINE.mechanics, overrides=overrides)


def candidate_mjcf(candidate: str) -> tuple[str, ModelParams]:
    """MJCF text (with a settled ``home`` keyframe) and parameters of ``candidate``."""
    head, *options = candidate.split("+")
    structure = "free" if head == "free" else head.rstrip("0123456789")
    if structure not in ("free", "chains", "slides"):
        raise SystemExit(f"unknown candidate {candidate!r}")
    links = int(head[len(structure):] or 4) if structure != "free" else 4
    params = _params(structure, links)
    unknown = [o for o in options if o not in ("discrete", "kin")]
    if unknown or ("kin" in options and structure != "chains"):
        raise SystemExit(f"unknown candidate option {(unknown or options)[0]!r}")
    if not options:
        return model_mjcf(params, MACHINE), params
    if "kin" in options:                     # every connect carries one pin
        with patch.object(builders, "pin_series_count",
                          lambda p: dict.fromkeys(structure_series(p), 1)):
            root = ET.fromstring(build_mjcf(params, compute_layout(params)))
    else:
        root = ET.fromstring(build_mjcf(params, compute_layout(params)))
    if "discrete" in options:
        find(root, "option").set("integrator", "discrete")
    model = mujoco.MjModel.from_xml_string(ET.tostring(root, encoding="unicode"))
    data = settle(model, params, SETTLE_DURATION_S)
    key = ET.SubElement(ET.SubElement(root, "keyframe"), "key", name="home",
                        qpos=" ".join(f"{v:.6f}" for v in data.qpos),
                        ctrl=f"0 {params.tensioner.preload_N:.9g}")
    key.tail = "\n"
    return ET.tostring(root, encoding="unicode"), params


def build(candidate: str) -> TrackPlant:
    """The plant of ``candidate`` (module docstring) at its ``home`` keyframe."""
    text, params = candidate_mjcf(candidate)
    plant = TrackPlant(mujoco.MjModel.from_xml_string(text), params)
    if candidate.endswith("+kin"):
        _stretch_kinematically(plant)
    return plant


@numba.njit(cache=True)
def _kinematic_stretch(efc_force: np.ndarray, cfrc_int: np.ndarray, xmat: np.ndarray,
                       link_body: np.ndarray, connect_of_pin: np.ndarray, tension: np.ndarray,
                       ends: np.ndarray, weights: np.ndarray, stretch: np.ndarray,
                       offset: np.ndarray, unit: np.ndarray, body_pos: np.ndarray,
                       child: np.ndarray, relaxation: float, stiffness: float) -> None:
    """The ``+kin`` update after a step: the connects' tensions [N], each hinged pin's
    interpolated between its chain's two (``ends`` (h, 2) pin indices, ``weights`` (h, 2)),
    its stretch [m] relaxed towards max(T, 0)/K, and its child link moved along its pitch
    (``body_pos[child] = offset + unit·stretch``)."""
    _pin_tensions(efc_force, cfrc_int, xmat, link_body, connect_of_pin, tension)
    for j in range(len(child)):
        t = weights[j, 0] * tension[ends[j, 0]] + weights[j, 1] * tension[ends[j, 1]]
        stretch[j] += relaxation * (max(t, 0.0) / stiffness - stretch[j])
        for c in range(3):
            body_pos[child[j], c] = offset[j, c] + unit[j, c] * stretch[j]


def _stretch_kinematically(plant: TrackPlant) -> None:
    """Make ``plant.step`` the ``+kin`` candidate's: the step, then :func:`_kinematic_stretch`
    (its connect tensions read from the step's ``efc_force``; ``cfrc_int`` is not updated,
    the hinged pins' own entries are not used)."""
    m, d, n = plant.model, plant.data, plant.link_count
    link_body = np.array([m.body(link_name(k)).id for k in range(n)])
    connect_of_pin = np.full(n, -1, dtype=np.int64)
    connected = np.array([k for k in range(n) if m.body(link_name(k)).parentid == 0])
    connect_of_pin[connected] = np.arange(len(connected))
    hinged = np.array([k for k in range(n) if connect_of_pin[k] < 0])
    first = np.searchsorted(connected, hinged, side="right") - 1
    nxt = (first + 1) % len(connected)
    start = connected[first]
    end = np.where(nxt == 0, connected[0] + n, connected[nxt])
    share = (hinged - start) / (end - start)
    ends = np.stack([start, connected[nxt]], axis=1)
    weights = np.stack([1.0 - share, share], axis=1)
    child = link_body[hinged]
    offset = m.body_pos[child].copy()
    unit = offset / np.linalg.norm(offset, axis=1, keepdims=True)
    stretch, tension = np.zeros(len(hinged)), np.zeros(n)
    stiffness = plant.params.pin_joint.radial_stiffness_N_m
    body_pos, step = m.body_pos, plant.step

    def kinematic_step(element: TensionerElement,
                       on_substep: Callable[[], None] | None = None) -> ForceLaw:
        law = step(element, on_substep)
        _kinematic_stretch(d.efc_force, d.cfrc_int, d.xmat, link_body, connect_of_pin,
                           tension, ends, weights, stretch, offset, unit, body_pos, child,
                           KIN_RELAXATION, stiffness)
        return law

    plant.step = kinematic_step    # type: ignore[method-assign]


def pin_stretch_m(plant: TrackPlant) -> np.ndarray:
    """Stretch of every pin k [m]: |p_k − p_{k−1}| − pitch, shape (link_count,)."""
    pins = plant.pin_positions()
    return (np.linalg.norm(pins - np.roll(pins, 1, axis=0), axis=1)
            - plant.params.track.pitch_m)


def ramp(speed: float) -> Callable[[float], float]:
    """Track-speed command: standing 1 s, then a 1 s ramp to ``speed`` [m/s]."""
    return lambda t: speed * min(1.0, max(0.0, t - 1.0))


def static(candidate: str) -> str:
    plant = build(candidate)
    plant.run(PassiveTensioner.from_params(plant.params), 1.5, 0.0)
    upper = plant.upper_strand_pins()
    stretch = pin_stretch_m(plant)[upper]
    reference = plant.pin_tensions_N()[upper] / plant.params.pin_joint.radial_stiffness_N_m
    spread = float(np.abs(stretch - stretch.mean()).max() / reference.mean())
    return (f"{len(upper)} upper-strand pins at {reference.mean() * 1e6:.2f} um T/K: stretch "
            f"mean {stretch.mean() * 1e6:.2f} um (ratio {stretch.mean() / reference.mean():.3f}),"
            f" largest deviation {spread:.2f} T/K; warnings {plant.warning_count}")


def band_rms(x: np.ndarray, f_hz: float, dt: float, half_width_hz: float = BAND_HZ) -> float:
    """Rms of ``x`` within ±``half_width_hz`` of ``f_hz`` (Hann periodogram) [unit of x]."""
    f, psd = periodogram(x - x.mean(), fs=1.0 / dt, window="hann", scaling="density")
    band = (f >= f_hz - half_width_hz) & (f <= f_hz + half_width_hz)
    return float(math.sqrt(np.trapezoid(psd[band], f[band])))


def _odd_quarters(x: np.ndarray, f_link: float, dt: float) -> str:
    """The odd-quarter lines of ``x``: each within ±BAND_HZ and their root-sum-square."""
    bands = [band_rms(x, f_link * q / 4, dt) for q in QUARTERS]
    return f"{', '.join(f'{v:.3g}' for v in bands)} (rss {math.hypot(*bands):.3g})"


def comb(candidate: str) -> str:
    plant = build(candidate)
    element = PassiveTensioner.from_params(plant.params)
    element.preload_N = COMB_PRELOAD_N
    plant.run(element, 3.0, ramp(SPEED_M_S))
    steps, dt = 8300, 1e-3
    force, omega = np.empty(steps), np.empty(steps)
    lower, accel = np.empty(steps), np.empty(steps)
    geom, wrench = plant.model.geom("idler_wheel").id, np.zeros(6)
    for i in range(steps):
        plant.set_track_speed(SPEED_M_S)
        plant.step(element)
        force[i] = idler_contact_N(plant, geom, wrench)
        omega[i] = plant.sprocket_speed_rad_s
        lower[i] = plant.strand_tensions_N().lower_N
        accel[i] = plant.chassis_acc_z_m_s2
    # the peak near the sprocket's pitch-line link rate (bench_structure.check)
    guess = omega.mean() * plant.params.sprocket_pitch_radius_m / plant.params.track.pitch_m
    grid = guess * np.linspace(0.97, 1.01, 401)
    f_link = float(grid[np.argmax([_component(force, f, dt) for f in grid])])
    lines = [_component(force, f_link * q / 4, dt) for q in QUARTERS]
    return (f"link passing {f_link:.2f} Hz, {_component(force, f_link, dt):.0f} N; idler "
            f"force odd quarters single-bin {', '.join(f'{v:.1f}' for v in lines)} N (rss "
            f"{math.hypot(*lines):.1f}), within ±{BAND_HZ} Hz {_odd_quarters(force, f_link, dt)}"
            f" N; lower-run tension {_odd_quarters(lower, f_link, dt)} N; chassis vertical "
            f"acceleration {_odd_quarters(accel, f_link, dt)} m/s², 8-12 Hz "
            f"{band_rms(accel, 10.0, dt, 2.0):.3g} m/s²; warnings {plant.warning_count}")


def hard(candidate: str) -> str:
    plant = build(candidate)
    element = PassiveTensioner.from_params(plant.params)
    failed, largest = "", 0.0
    for _ in range(80):
        element.preload_N = 12e3 if plant.time_s < 3.0 else 15e3
        plant.run(element, 0.1, SPEED_M_S)
        if not np.isfinite(plant.data.qpos).all():
            failed = f"non-finite state at {plant.time_s:.1f} s"
            break
        status = plant.derailment()
        if status.any and not failed:
            failed = f"derailment check at {plant.time_s:.1f} s ({status})"
        largest = max(largest, float(np.abs(pin_stretch_m(plant)).max()))
    return (f"{failed or 'healthy'}; warnings {plant.warning_count}; largest pin stretch "
            f"{largest * 1e3:.3f} mm")


def cost(candidates: list[str], rounds: int) -> None:
    plants = {}
    for candidate in candidates:
        plant = build(candidate)
        element = PassiveTensioner.from_params(plant.params)
        plant.run(element, 2.5, ramp(SPEED_M_S))
        plants[candidate] = (plant, element)
    times: dict[str, list[float]] = {c: [] for c in candidates}
    for _ in range(rounds):
        for candidate, (plant, element) in plants.items():
            start = time.perf_counter()
            for _ in range(1000):
                plant.step(element)
            times[candidate].append((time.perf_counter() - start) * 1e3)
    first = min(times[candidates[0]])
    for candidate, (plant, _) in plants.items():
        t = times[candidate]
        print(f"{candidate}: best {min(t):.1f} us/step (median {statistics.median(t):.1f}), "
              f"{first / min(t):.3f}x the speed of {candidates[0]}; nv {plant.model.nv}, "
              f"nefc {plant.data.nefc}; warnings {plant.warning_count}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("candidates", nargs="+", metavar="CANDIDATE")
    for check in ("static", "comb", "hard", "cost"):
        parser.add_argument(f"--{check}", action="store_true")
    parser.add_argument("--rounds", type=int, default=5, help="cost: blocks per candidate")
    args = parser.parse_args()
    print(f"machine: {machine()}")
    for candidate in args.candidates:
        for check, run in (("static", static), ("comb", comb), ("hard", hard)):
            if getattr(args, check):
                print(f"{candidate} {check}: {run(candidate)}", flush=True)
    if args.cost:
        cost(args.candidates, args.rounds)


if __name__ == "__main__":
    main()
