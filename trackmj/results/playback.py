"""Rerun playback of a run: the animated 3D track scene and the time-series panels in one ``.rrd``.

Coordinates: the scene is MuJoCo's world frame in metres (x forward, y lateral, z up), logged
under ``scene`` with ``RIGHT_HAND_Z_UP`` view coordinates. Time: timeline ``sim``, a duration
in seconds of simulated time. Values are SI everywhere; only the plots show display units
(kN, MPa, kJ, mm), which their series names state.

Entity paths
------------
Scene (:meth:`PlaybackRecorder.log_frame`, one row per frame; ``scene/terrain`` static):

- ``scene/terrain``: ground profile (flat plane or the ``terrain`` heightfield) at the two
  shoe edges, y = ±width/2;
- ``scene/track/links``: the rail line through the pins (y = 0) and the two shoe edges;
- ``scene/track/pins``: pin points coloured by pin tension (blue low → red high);
- ``scene/wheels/<body>`` for sprocket, idler, road_wheel_1..6, return_roller_1..2: the
  body pose (``Transform3D``, one row per frame) and, static in the body frame, the outline
  of its visual cylinder at both faces (the sprocket's is its pitch circle);
  ``scene/wheels/sprocket/teeth``: the tooth segments (show the sprocket's rotation);
- ``scene/chassis``, ``scene/idler_carrier``: body pose per frame, box static in ``.../box``;
- ``plots/pin_tension``: bar chart of the pin tensions [kN] by pin index 0..81.

Time series (:meth:`PlaybackRecorder.log_timeseries`, columnar): see :data:`SERIES`.

The recording is written to a hidden temporary file beside the target and renamed into
place by :meth:`PlaybackRecorder.close`; :meth:`PlaybackRecorder.discard` (or leaving the
``with`` block by an exception) deletes it, so a ``.rrd`` on disk is always complete.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import weakref
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType

import mujoco
import numpy as np
import pyarrow as pa
import rerun as rr
import rerun.blueprint as rrb
from rerun.components import TensorDataBatch

from trackmj.io import install
from trackmj.ports import COUPLING_STEP_S
from trackmj.results.store import Result
from trackmj.track.mjcf.names import link_name
from trackmj.track.plant import TrackPlant

APPLICATION_ID = "trackmj"
TIMELINE = "sim"
RUN_RRD = "run.rrd"
"""File name of the recording inside a run directory."""

FRAME_PERIOD_S = 0.02
"""Default scene frame period [s] (50 frames per simulated second)."""

CIRCLE_SEGMENTS = 48
WHEEL_BODIES = ("sprocket", "idler", "road_wheel_", "return_roller_")
"""Bodies whose visual cylinders are drawn as outlines (prefixes end with ``_``)."""

EYE_DISTANCE_PER_LENGTH = 0.92
EYE_HEIGHT_PER_LENGTH = 0.26
"""Eye offset from the scene centre per metre of scene length (−y, +z) of the 3D view."""
HOME_SCENE_BOUNDS_M = (np.array([-1.30, -0.80, 0.0]), np.array([1.60, 0.10, 1.0]))
"""Scene box of the packaged track at home [m] (the framing when no plant is given)."""

# blue -> cyan -> green -> yellow -> red, for pin tension colours
_RAMP = np.array([[40, 60, 220], [0, 190, 230], [40, 200, 60], [240, 210, 0], [230, 30, 30]],
                 dtype=float)


@dataclass(frozen=True)
class Series:
    """One plotted column: ``values_display = values_SI · scale`` on ``entity``."""

    entity: str
    column: str
    scale: float
    name: str
    color: tuple[int, int, int]
    step: bool = False
    """Discrete signal: drawn as steps (held until the next sample)."""


SERIES: tuple[Series, ...] = (
    Series("plots/tension/actual", "tension_N", 1e-3, "F_ten [kN]", (30, 90, 200)),
    Series("plots/tension/reference", "tension_ref_N", 1e-3, "reference [kN]", (200, 60, 40)),
    Series("plots/pressure/head", "p_head_Pa", 1e-6, "head [MPa]", (200, 60, 40)),
    Series("plots/pressure/rod", "p_rod_Pa", 1e-6, "rod [MPa]", (30, 90, 200)),
    Series("plots/pressure/supply", "p_supply_Pa", 1e-6, "supply [MPa]", (90, 90, 90)),
    Series("plots/valve/mode", "valve_mode", 1.0, "valve mode [-1 release, 0 hold, +1 press]",
           (120, 60, 160), step=True),
    Series("plots/valve/u", "u", 1.0, "u [-]", (40, 150, 70)),
    Series("plots/energy/supply", "e_supply_J", 1e-3, "supply energy [kJ]", (200, 60, 40)),
    Series("plots/energy/p_work", "p_work_J", 1e-3, "∫Σp·A·v dt [kJ]", (30, 90, 200)),
    Series("plots/energy/mech_work", "mech_work_J", 1e-3, "∫F·v dt [kJ]", (40, 150, 70)),
    Series("plots/stroke/stroke", "stroke_m", 1e3, "stroke [mm]", (30, 90, 200)),
    Series("plots/chassis/acc_z", "chassis_acc_z_m_s2", 1.0, "chassis a_z [m/s²]",
           (90, 90, 90)),
)
"""Time-series panels: entity path, timeseries column (SI), display scale, label, colour."""


def tension_colors(tension_N: np.ndarray, range_N: tuple[float, float]) -> np.ndarray:
    """RGB colours (n, 3) uint8 of tensions [N] on a blue→red ramp over ``range_N``
    (values outside are clipped, so compression shows as the low end)."""
    lo, hi = range_N
    pos = np.clip((np.asarray(tension_N, dtype=float) - lo) / (hi - lo), 0.0, 1.0)
    pos *= len(_RAMP) - 1
    grid = np.arange(len(_RAMP))
    rgb = np.column_stack([np.interp(pos, grid, _RAMP[:, c]) for c in range(3)])
    return rgb.astype(np.uint8)


def _tensor_rows(values: np.ndarray) -> pa.Array:
    """Rerun ``TensorData`` Arrow array with one 1-D float64 tensor per row of ``values``
    (n, m), built column-wise (``rr.BarChart`` converts one tensor per call, ~0.4 ms)."""
    n, m = values.shape
    dtype = TensorDataBatch(np.zeros(1)).as_arrow_array().type
    shape = pa.ListArray.from_arrays(pa.array(np.arange(n + 1, dtype=np.int32)),
                                     pa.array(np.full(n, m, dtype=np.uint64)),
                                     type=dtype.field("shape").type)
    names = pa.nulls(n, type=dtype.field("names").type)
    union = dtype.field("buffer").type
    f64 = [f.name for f in union].index("F64")
    children = [pa.nulls(0, type=f.type) for f in union]
    children[f64] = pa.ListArray.from_arrays(
        pa.array(np.arange(0, n * m + 1, m, dtype=np.int32)),
        pa.array(np.ascontiguousarray(values, dtype=float).ravel()), type=union[f64].type)
    buffer = pa.Array.from_buffers(
        type=union, length=n,
        buffers=[None, pa.py_buffer(np.full(n, union.type_codes[f64], dtype=np.int8)),
                 pa.py_buffer(np.arange(n, dtype=np.int32))],
        children=children)
    return pa.StructArray.from_arrays([shape, names, buffer], fields=list(dtype))


class PlaybackRecorder:
    """Writes one run's Rerun recording (3D scene + plots + blueprint) to ``path``.

    Usage::

        with PlaybackRecorder(plant, out_dir / "run.rrd") as rec:
            plant.run(element, duration_s, on_step=rec.step_callback())
            rec.log_timeseries(result)
        # rec.path now exists; an exception inside the block leaves no file, nor does a
        # recorder that is dropped without close()

    Each recorder has its own ``rr.RecordingStream`` (never the global one), so several can
    coexist in one process. The plant supplies the geometry (model geoms) and, at every
    :meth:`log_frame`, the state to draw.

    tension_range_N: pin tension [N] mapped to the ends of the colour ramp.
    frames_per_batch: scene frames buffered before they are sent column-wise.
    """

    def __init__(self, plant: TrackPlant, path: str | Path, *,
                 tension_range_N: tuple[float, float] = (0.0, 25e3),
                 frames_per_batch: int = 50) -> None:
        lo, hi = tension_range_N
        if not hi > lo:
            raise ValueError(f"tension_range_N must be increasing, got {tension_range_N}")
        if frames_per_batch < 1:
            raise ValueError(f"frames_per_batch must be >= 1, got {frames_per_batch}")
        self.path = Path(path)
        if self.path.suffix != ".rrd":
            raise ValueError(f"{self.path}: a Rerun recording needs the .rrd suffix")
        self.plant = plant
        self.tension_range_N = (float(lo), float(hi))
        self._closed = False
        self._frames = 0
        self._geometry(plant)
        self._t = np.empty(frames_per_batch)
        self._pins = np.empty((frames_per_batch, len(self._pin_geoms), 3))
        self._body_pos = np.empty((frames_per_batch, len(self._bodies), 3))
        self._body_quat = np.empty((frames_per_batch, len(self._bodies), 4))
        self._tension = np.empty((frames_per_batch, plant.link_count))
        self._buffered = 0
        self.path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=self.path.parent, prefix=f".{self.path.name}.",
                                   suffix=".tmp")
        os.close(fd)
        self._tmp = Path(tmp)
        # a recorder dropped without close() (e.g. an exception in the caller's loop) leaves
        # no partial file: the temporary is removed when the recorder is collected
        weakref.finalize(self, self._tmp.unlink, missing_ok=True)
        try:
            self.stream = rr.RecordingStream(APPLICATION_ID)
            self.stream.set_log_tick_enabled(False)
            self.stream.set_log_time_enabled(False)
            self.stream.save(self._tmp, default_blueprint=self.blueprint(self.scene_bounds()))
            self._log_static()
        except BaseException:
            self._tmp.unlink(missing_ok=True)
            raise

    # ------------------------------------------------------------------ geometry
    def _geometry(self, plant: TrackPlant) -> None:
        """Rigid bodies drawn per frame and their constant shapes in the body frames.

        Each body in ``self._bodies`` gets a ``Transform3D`` per frame (its world pose) and
        static shapes at its entity: wheels their visual-cylinder outline at both faces
        (``scene/wheels/<body>``), the sprocket its teeth (``.../teeth``), chassis and idler
        carrier their visual box (``.../box``).
        """
        m = plant.model
        self.half_width_m = 0.5 * plant.params.track.link_width_m
        self._pin_geoms = np.array([m.geom(link_name(k) + "_pin").id
                                    for k in range(plant.link_count)])
        wheels = [i for i in range(m.ngeom)
                  if m.geom_type[i] == mujoco.mjtGeom.mjGEOM_CYLINDER
                  and any(m.body(m.geom_bodyid[i]).name == b
                          or (b.endswith("_") and m.body(m.geom_bodyid[i]).name.startswith(b))
                          for b in WHEEL_BODIES)]
        self.entities = {"scene/chassis": m.body("chassis").id,
                         "scene/idler_carrier": m.body("idler_carrier").id}
        self.entities |= {f"scene/wheels/{m.body(m.geom_bodyid[g]).name}": int(m.geom_bodyid[g])
                          for g in wheels}
        self._bodies = np.array(list(self.entities.values()))
        ang = np.linspace(0.0, 2.0 * np.pi, CIRCLE_SEGMENTS + 1)
        self._outlines: dict[str, np.ndarray] = {}
        for g in wheels:
            r, half = m.geom_size[g, :2]
            rot = np.empty(9)
            mujoco.mju_quat2Mat(rot, m.geom_quat[g])
            faces = [np.column_stack([r * np.cos(ang), r * np.sin(ang), np.full_like(ang, z)])
                     for z in (-half, half)]  # cylinder axis = geom z
            name = f"scene/wheels/{m.body(m.geom_bodyid[g]).name}"
            self._outlines[name] = np.stack(faces) @ rot.reshape(3, 3).T + m.geom_pos[g]
        teeth = [i for i in range(m.ngeom) if m.geom(i).name.startswith("sprocket_tooth_")]
        axes = np.empty((len(teeth), 9))
        for row, g in zip(axes, teeth, strict=True):
            mujoco.mju_quat2Mat(row, m.geom_quat[g])
        half_axis = axes.reshape(-1, 3, 3)[:, :, 2] * m.geom_size[teeth, 1][:, None]
        self._teeth = np.stack([m.geom_pos[teeth] - half_axis, m.geom_pos[teeth] + half_axis],
                               axis=1)
        self.tooth_radius_m = float(m.geom_size[teeth[0], 0])
        self._boxes = {"scene/chassis": m.geom("chassis_body").id,
                       "scene/idler_carrier": m.geom("idler_carrier_visual").id}
        self._ground = m.geom("ground").id

    def terrain_profile(self) -> np.ndarray:
        """Ground line (n, 2) of world (x, z) [m]: the plane's extent at its height, or the
        ``terrain`` heightfield's first row (the profile is constant across y)."""
        m, d = self.plant.model, self.plant.data
        g = self._ground
        cx, cz = d.geom_xpos[g, 0], d.geom_xpos[g, 2]
        if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_HFIELD:
            h = m.geom_dataid[g]
            ncol, adr = m.hfield_ncol[h], m.hfield_adr[h]
            size = m.hfield_size[h]
            x = cx + np.linspace(-size[0], size[0], ncol)
            z = cz + size[2] * m.hfield_data[adr:adr + ncol]
            return np.column_stack([x, z])
        half = m.geom_size[g, 0]
        return np.array([[cx - half, cz], [cx + half, cz]])

    # ------------------------------------------------------------------ layout
    def scene_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """World box (low, high) [m], shape (3,) each, around the pins and the chassis and
        idler-carrier boxes in the plant's current state (what the 3D view must show)."""
        m, d = self.plant.model, self.plant.data
        points = [d.geom_xpos[self._pin_geoms]]
        for g in self._boxes.values():
            corners = np.array(np.meshgrid(*[[-1.0, 1.0]] * 3)).reshape(3, -1).T
            points.append(d.geom_xpos[g] + (corners * m.geom_size[g]) @ d.geom_xmat[g]
                          .reshape(3, 3).T)
        cloud = np.concatenate(points)
        return cloud.min(axis=0), cloud.max(axis=0)

    @staticmethod
    def framing(low: np.ndarray, high: np.ndarray) -> tuple[list[float], list[float]]:
        """Eye position and look target [m] that frame the world box (low, high) in the 3D
        view: from the −y side, slightly above, far enough that the box's length fills
        about two thirds of a landscape view (checked on screenshots of the viewer)."""
        low, high = np.asarray(low, dtype=float), np.asarray(high, dtype=float)
        center = 0.5 * (low + high)
        length = float(high[0] - low[0])
        eye = center + length * np.array([0.0, -EYE_DISTANCE_PER_LENGTH,
                                          EYE_HEIGHT_PER_LENGTH])
        return eye.tolist(), center.tolist()

    @staticmethod
    def blueprint(bounds: tuple[np.ndarray, np.ndarray] | None = None) -> rrb.Blueprint:
        """Viewer layout: the 3D scene (framed on ``bounds``, default: the packaged track
        at home) over the pin-tension bar chart on the left, the time-series panels stacked
        on the right."""
        def plot(origin: str, name: str) -> rrb.TimeSeriesView:
            return rrb.TimeSeriesView(origin=origin, name=name,
                                      plot_legend=rrb.PlotLegend(visible=True))

        position, target = PlaybackRecorder.framing(*(bounds or HOME_SCENE_BOUNDS_M))
        scene = rrb.Spatial3DView(
            origin="scene", name="Track",
            eye_controls=rrb.EyeControls3D(position=position, look_target=target,
                                           eye_up=[0.0, 0.0, 1.0],
                                           tracking_entity="scene/chassis"))
        # the grid brings the y tick labels [kN]; the legend would only repeat the entity
        bars = rrb.BarChartView(origin="plots/pin_tension",
                                name="Pin tension [kN] (y) by pin index 0..81 (x)",
                                plot_legend=rrb.PlotLegend(visible=False),
                                background=rrb.archetypes.PlotBackground(show_grid=True))
        return rrb.Blueprint(
            rrb.Horizontal(
                rrb.Vertical(scene, bars, row_shares=[2.0, 1.0]),
                rrb.Vertical(
                    plot("plots/tension", "Tension [kN]"),
                    plot("plots/pressure", "Pressures [MPa]"),
                    plot("plots/valve", "Valve mode and u"),
                    plot("plots/energy", "Energy [kJ]"),
                    rrb.Tabs(plot("plots/stroke", "Stroke [mm]"),
                             plot("plots/chassis", "Chassis a_z [m/s²]"))),
                column_shares=[3.0, 2.0]),
            collapse_panels=True)

    def _log_static(self) -> None:
        """Coordinates, terrain, body shapes, and the per-frame entities' constant parts."""
        s, hw, m = self.stream, self.half_width_m, self.plant.model
        s.log("scene", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        ground = self.terrain_profile()
        edges = [np.column_stack([ground[:, 0], np.full(len(ground), y), ground[:, 1]])
                 for y in (-hw, hw)]
        s.log("scene/terrain", rr.LineStrips3D(edges, colors=[(110, 130, 90)], radii=0.004),
              static=True)
        rail = self.plant.params.track.rail_radius_m
        s.log("scene/track/links",
              rr.LineStrips3D.from_fields(radii=[rail, 0.003, 0.003],
                                          colors=[(70, 70, 75), (120, 120, 125),
                                                  (120, 120, 125)]), static=True)
        s.log("scene/track/pins",
              rr.Points3D.from_fields(radii=self.plant.params.track.pin_radius_m), static=True)
        for entity, outline in self._outlines.items():
            s.log(entity, rr.LineStrips3D(outline, radii=0.006, colors=[(60, 60, 60)],
                                          labels=entity.rsplit("/", 1)[1], show_labels=False),
                  static=True)
        s.log("scene/wheels/sprocket/teeth",
              rr.LineStrips3D(self._teeth, radii=self.tooth_radius_m, colors=[(40, 40, 40)]),
              static=True)
        for (entity, g), color in zip(self._boxes.items(), [(230, 150, 25), (75, 75, 200)],
                                      strict=True):
            s.log(f"{entity}/box",
                  rr.Boxes3D(centers=m.geom_pos[g], half_sizes=m.geom_size[g],
                             quaternions=[m.geom_quat[g][[1, 2, 3, 0]]], colors=[color],
                             fill_mode="MajorWireframe"), static=True)

    # ------------------------------------------------------------------ per frame
    def log_frame(self, t_s: float) -> None:
        """Record the plant's current state as the scene at simulated time ``t_s`` [s].

        The state (pin positions, body poses, pin tensions) is copied into a buffer that is
        sent column-wise every ``frames_per_batch`` frames and at :meth:`close`.
        """
        self._check_open()
        d, i = self.plant.data, self._buffered
        self._t[i] = t_s
        self._pins[i] = d.geom_xpos[self._pin_geoms]
        self._body_pos[i] = d.xpos[self._bodies]
        self._body_quat[i] = d.xquat[self._bodies]
        self._tension[i] = self.plant.pin_tensions_N()
        self._buffered += 1
        self._frames += 1
        if self._buffered == len(self._t):
            self._send_frames()

    def _send_frames(self) -> None:
        """Send the buffered frames as columns on the ``sim`` timeline and empty the buffer."""
        k = self._buffered
        if k == 0:
            return
        self._buffered = 0
        s = self.stream
        times = [rr.TimeColumn(TIMELINE, duration=self._t[:k].copy())]
        pins = self._pins[:k]
        loop = np.concatenate([pins, pins[:, :1]], axis=1)
        shift = np.array([0.0, self.half_width_m, 0.0])
        strips = np.stack([loop, loop - shift, loop + shift], axis=1)
        # rerun converts float64 points to its float32 strips; its type stub names float32 only
        s.send_columns("scene/track/links", indexes=times, columns=rr.LineStrips3D.columns(
            strips=strips.reshape(-1, *loop.shape[1:]),  # pyright: ignore[reportArgumentType]
        ).partition(np.full(k, 3)))
        tension = self._tension[:k]
        s.send_columns("scene/track/pins", indexes=times, columns=rr.Points3D.columns(
            positions=pins.reshape(-1, 3),
            colors=tension_colors(tension.ravel(), self.tension_range_N),
        ).partition(np.full(k, tension.shape[1])))
        s.send_columns("plots/pin_tension", indexes=times, columns=[rr.ComponentColumn(
            rr.BarChart.descriptor_values(), TensorDataBatch(_tensor_rows(tension * 1e-3)))])
        xyzw = self._body_quat[:k][:, :, [1, 2, 3, 0]]
        for j, entity in enumerate(self.entities):
            s.send_columns(entity, indexes=times, columns=rr.Transform3D.columns(
                translation=self._body_pos[:k, j], quaternion=xyzw[:, j]))

    def step_callback(self, period_s: float = FRAME_PERIOD_S) -> Callable[[TrackPlant], None]:
        """``on_step`` callback for :meth:`TrackPlant.run` logging a frame every
        ``period_s`` [s] of simulated time (a whole number of 1 ms steps)."""
        every = round(period_s / COUPLING_STEP_S)
        if every < 1 or abs(every * COUPLING_STEP_S - period_s) > 1e-9:
            raise ValueError(f"frame period {period_s} s must be a multiple of "
                             f"{COUPLING_STEP_S} s")

        def on_step(plant: TrackPlant) -> None:
            if round(plant.time_s / COUPLING_STEP_S) % every == 0:
                self.log_frame(plant.time_s)

        return on_step

    @property
    def frame_count(self) -> int:
        """Scene frames logged so far."""
        return self._frames

    # ------------------------------------------------------------------ time series
    def log_timeseries(self, result: Result) -> None:
        """Send the result's time-series columns (:data:`SERIES`) on the ``sim`` timeline
        (``t_s`` [s]) in one columnar batch per series, with display names and colours; the
        recording is named after the run (scenario, architecture, controller, seed)."""
        self._check_open()
        table = result.timeseries
        missing = [c for c in ("t_s", *(sr.column for sr in SERIES))
                   if c not in table.column_names]
        if missing:
            raise ValueError(f"result timeseries lacks column(s) {missing}")
        meta = result.metadata
        self.stream.send_recording_name(
            " ".join(meta.get(k, "?") for k in ("scenario", "architecture", "controller",
                                                 "estimator")) + f" seed {meta.get('seed', '?')}")
        times = rr.TimeColumn(TIMELINE, duration=table.column("t_s").to_numpy())
        for sr in SERIES:
            values = table.column(sr.column).to_numpy().astype(float) * sr.scale
            style = rr.SeriesLines(names=sr.name, colors=[sr.color],
                                   interpolation_mode="StepAfter" if sr.step else None)
            self.stream.log(sr.entity, style, static=True)
            self.stream.send_columns(sr.entity, indexes=[times],
                                     columns=rr.Scalars.columns(scalars=values))

    # ------------------------------------------------------------------ lifetime
    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError(f"{self.path}: recorder already closed")

    def close(self) -> Path:
        """Flush, finish the file and move it to :attr:`path` (atomic rename); returns it."""
        self._check_open()
        self._closed = True
        try:
            self._send_frames()
            self.stream.flush()
        except BaseException:
            self._closed = False
            self.discard()
            raise
        self.stream.disconnect()
        install(self._tmp, self.path)
        return self.path

    def discard(self) -> None:
        """Stop recording and delete the partial file; :attr:`path` is left untouched."""
        if self._closed:
            return
        self._closed = True
        try:
            self.stream.disconnect()
        finally:
            self._tmp.unlink(missing_ok=True)

    def __enter__(self) -> PlaybackRecorder:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if exc_type is None:
            if not self._closed:
                self.close()
        else:
            self.discard()


def resolve_rrd(path: str | Path) -> Path:
    """The recording to open: ``path`` itself if it is a ``.rrd`` file, or ``path/run.rrd``
    for a run directory. FileNotFoundError / ValueError with the reason otherwise."""
    p = Path(path)
    if p.is_dir():
        rrd = p / RUN_RRD
        if not rrd.is_file():
            raise FileNotFoundError(f"{p}: run directory has no {RUN_RRD} "
                                    "(run with --rrd to record one)")
        return rrd
    if not p.exists():
        raise FileNotFoundError(f"{p}: no such recording or run directory")
    if p.suffix != ".rrd":
        raise ValueError(f"{p}: not a Rerun recording (expected a .rrd file or a run "
                         "directory)")
    return p


def open_viewer(path: str | Path) -> subprocess.Popen[bytes]:
    """Open the Rerun viewer on a ``.rrd`` file or a run directory holding ``run.rrd``;
    returns the viewer process (needs a display)."""
    rrd = resolve_rrd(path)
    return subprocess.Popen([sys.executable, "-m", "rerun", str(rrd)])
