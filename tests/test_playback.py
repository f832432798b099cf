"""Rerun playback: a short real run recorded to .rrd and read back through Rerun's own tools
(``python -m rerun rrd verify`` and the ``rerun.chunk.RrdReader`` Python API)."""

from __future__ import annotations

import gc
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest

from trackmj.machines.track_plant import load_plant
from trackmj.results.playback import (
    FRAME_PERIOD_S,
    RUN_RRD,
    SERIES,
    PlaybackRecorder,
    open_viewer,
    resolve_rrd,
    tension_colors,
)
from trackmj.results.store import COLUMN_UNITS, Result, make_table, run_metadata
from trackmj.track.plant import PassiveTensioner, TrackPlant

DURATION_S = 0.2
N_FRAMES = round(DURATION_S / FRAME_PERIOD_S)


def synthetic_result(n_steps: int) -> Result:
    """1 kHz contract table with simple known signals (t = 1 ms ... n ms)."""
    t = np.arange(1, n_steps + 1) * 1e-3
    cols = {name: np.zeros(n_steps) for name in COLUMN_UNITS}
    cols |= {"t_s": t, "tension_N": 12e3 + 1e3 * t, "tension_ref_N": np.full(n_steps, 12e3),
             "p_head_Pa": np.full(n_steps, 10e6), "p_rod_Pa": np.full(n_steps, 1e6),
             "p_supply_Pa": np.full(n_steps, 12e6),
             "valve_mode": (np.arange(n_steps) % 3 - 1).astype(float),
             "u": np.full(n_steps, 0.5), "e_supply_J": 100.0 * t}
    meta = run_metadata("W1", "tp", "nmpc", "ekf", 0, "test", machine="lf1352")
    return Result(make_table(cols, COLUMN_UNITS, meta))


@pytest.fixture(scope="module")
def plant() -> TrackPlant:
    return load_plant()


@pytest.fixture(scope="module")
def recording(plant: TrackPlant, tmp_path_factory: pytest.TempPathFactory) -> dict:
    """Record 0.2 s of the passive track (a frame every 20 ms) plus a synthetic result,
    batching 4 frames so the buffer is sent several times and once more at close."""
    out = tmp_path_factory.mktemp("playback") / RUN_RRD
    with PlaybackRecorder(plant, out, frames_per_batch=4) as rec:
        plant.run(PassiveTensioner.from_params(plant.params), DURATION_S,
                  on_step=rec.step_callback(FRAME_PERIOD_S))
        rec.log_timeseries(synthetic_result(round(DURATION_S * 1e3)))
        frames = rec.frame_count
    d, m = plant.data, plant.model
    poses = {name: (d.xpos[m.body(name).id].copy(), d.xquat[m.body(name).id].copy())
             for name in ("chassis", "sprocket", "road_wheel_3", "idler_carrier")}
    return {"path": out, "frames": frames, "pins": plant.pin_positions(),
            "tension": plant.pin_tensions_N(), "poses": poses}


def read_chunks(path: Path) -> dict[str, list[pa.RecordBatch]]:
    """Entity path -> record batches of its temporal chunks (Rerun's Python reader)."""
    from rerun.chunk import RrdReader

    chunks: dict[str, list[pa.RecordBatch]] = {}
    for chunk in RrdReader(path).stream():
        if not chunk.is_static:
            chunks.setdefault(chunk.entity_path, []).append(chunk.to_record_batch())
    return chunks


def sim_times_s(batches: list[pa.RecordBatch]) -> np.ndarray:
    ns = np.concatenate([b.column("sim").cast(pa.int64()).to_numpy() for b in batches])
    return np.sort(ns) * 1e-9


def test_recording_is_complete_and_verified_by_rerun(recording: dict) -> None:
    path = recording["path"]
    assert path.is_file() and path.stat().st_size > 0
    assert sorted(p.name for p in path.parent.iterdir()) == [RUN_RRD]  # no temp left
    assert recording["frames"] == N_FRAMES
    done = subprocess.run([sys.executable, "-m", "rerun", "rrd", "verify", str(path)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr


def test_entities_blueprint_and_static_terrain(recording: dict) -> None:
    from rerun.chunk import RrdReader

    reader = RrdReader(recording["path"])
    paths = set(reader.store().schema().entity_paths())
    wheels = ["sprocket", "idler", *(f"road_wheel_{k}" for k in range(1, 7)),
              "return_roller_1", "return_roller_2"]
    scene = {"/scene/terrain", "/scene/track/links", "/scene/track/pins",
             "/scene/wheels/sprocket/teeth", "/scene/chassis", "/scene/chassis/box",
             "/scene/idler_carrier", "/scene/idler_carrier/box", "/plots/pin_tension",
             *(f"/scene/wheels/{w}" for w in wheels)}
    plots = {"/" + s.entity for s in SERIES}
    assert scene | plots <= paths
    assert "/plots/tension/actual" in paths and "/plots/tension/reference" in paths
    assert len(reader.blueprints()) == 1
    temporal = read_chunks(recording["path"])
    assert "/scene/terrain" not in temporal  # logged once, static


def test_sim_timeline_spans_the_run(recording: dict) -> None:
    chunks = read_chunks(recording["path"])
    frames = np.arange(1, N_FRAMES + 1) * FRAME_PERIOD_S
    for entity in ("/scene/track/links", "/scene/track/pins", "/scene/wheels/sprocket",
                   "/scene/wheels/road_wheel_3", "/scene/chassis", "/plots/pin_tension"):
        np.testing.assert_allclose(sim_times_s(chunks[entity]), frames, atol=1e-9)
    n = round(DURATION_S * 1e3)
    for s in SERIES:
        np.testing.assert_allclose(sim_times_s(chunks["/" + s.entity]),
                                   np.arange(1, n + 1) * 1e-3, atol=1e-9)


def _last_row(batches: list[pa.RecordBatch], column: str) -> pa.Scalar:
    last = max(batches, key=lambda b: b.column("sim").cast(pa.int64()).to_numpy().max())
    order = np.argsort(last.column("sim").cast(pa.int64()).to_numpy())
    return last.column(column)[int(order[-1])]


def test_last_frame_matches_the_plant(recording: dict) -> None:
    chunks = read_chunks(recording["path"])
    points = _last_row(chunks["/scene/track/pins"], "Points3D:positions")
    xyz = np.array(points.as_py())
    np.testing.assert_allclose(xyz[:, [0, 2]], recording["pins"], atol=1e-6)
    np.testing.assert_allclose(xyz[:, 1], 0.0, atol=1e-9)
    bars = _last_row(chunks["/plots/pin_tension"], "BarChart:values").as_py()[0]
    assert bars["shape"] == [82]
    np.testing.assert_allclose(bars["buffer"], recording["tension"] * 1e-3, rtol=1e-12)
    links = _last_row(chunks["/scene/track/links"], "LineStrips3D:strips").as_py()
    assert [len(s) for s in links] == [83, 83, 83]  # rail + two shoe edges, closed


def test_body_poses_and_wheel_outlines(recording: dict, plant: TrackPlant) -> None:
    """Last-frame body transforms equal MuJoCo's poses; the static sprocket outline lies on
    its pitch circle in the body frame."""
    from rerun.chunk import RrdReader

    chunks = read_chunks(recording["path"])
    for body, (pos, wxyz) in recording["poses"].items():
        entity = f"/scene/{body}" if body in ("chassis", "idler_carrier") \
            else f"/scene/wheels/{body}"
        t = np.array(_last_row(chunks[entity], "Transform3D:translation").as_py()[0])
        q = np.array(_last_row(chunks[entity], "Transform3D:quaternion").as_py()[0])
        np.testing.assert_allclose(t, pos, atol=1e-6)
        np.testing.assert_allclose(q, wxyz[[1, 2, 3, 0]], atol=1e-6)
    static = [c for c in RrdReader(recording["path"]).stream()
              if c.is_static and c.entity_path == "/scene/wheels/sprocket"]
    faces = static[0].to_record_batch().column("LineStrips3D:strips")[0].as_py()
    assert len(faces) == 2
    xyz = np.array(faces[0])
    np.testing.assert_allclose(np.hypot(xyz[:, 0], xyz[:, 2]),
                               plant.params.sprocket_pitch_radius_m, rtol=1e-6)


def test_timeseries_values_in_display_units(recording: dict) -> None:
    chunks = read_chunks(recording["path"])
    tension = chunks["/plots/tension/actual"]
    values = np.concatenate([np.array(b.column("Scalars:scalars").to_pylist()).ravel()
                             for b in tension])
    t = sim_times_s(tension)
    np.testing.assert_allclose(np.sort(values), 12.0 + t, rtol=1e-12)  # kN, monotonic in t


def test_recording_named_after_the_run_and_valve_drawn_as_steps(recording: dict) -> None:
    from rerun.chunk import RrdReader

    static = {}
    for chunk in RrdReader(recording["path"]).stream():
        if chunk.is_static:
            for row in chunk.to_record_batch().to_pylist():
                static.setdefault(chunk.entity_path, {}).update(row)
    assert static["/__properties"]["RecordingInfo:name"] == ["W1 tp nmpc ekf seed 0"]
    assert static["/plots/valve/mode"]["SeriesLines:interpolation_mode"] != \
        static["/plots/valve/u"].get("SeriesLines:interpolation_mode")


def test_failure_during_recording_leaves_no_file(plant: TrackPlant, tmp_path: Path) -> None:
    target = tmp_path / RUN_RRD
    with pytest.raises(RuntimeError, match="boom"), PlaybackRecorder(plant, target) as rec:
        rec.log_frame(0.0)
        raise RuntimeError("boom")
    assert list(tmp_path.iterdir()) == []


def test_recorder_dropped_without_close_leaves_no_file(plant: TrackPlant,
                                                       tmp_path: Path) -> None:
    rec = PlaybackRecorder(plant, tmp_path / RUN_RRD)
    rec.log_frame(0.0)
    assert len(list(tmp_path.iterdir())) == 1  # the hidden temporary
    del rec
    gc.collect()
    assert list(tmp_path.iterdir()) == []


def test_recorder_argument_checks(plant: TrackPlant, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"\.rrd"):
        PlaybackRecorder(plant, tmp_path / "run.txt")
    with pytest.raises(ValueError, match="tension_range_N"):
        PlaybackRecorder(plant, tmp_path / "a.rrd", tension_range_N=(1.0, 1.0))
    rec = PlaybackRecorder(plant, tmp_path / "b.rrd")
    with pytest.raises(ValueError, match="multiple"):
        rec.step_callback(0.0205)
    assert rec.close() == tmp_path / "b.rrd"
    with pytest.raises(RuntimeError, match="closed"):
        rec.log_frame(1.0)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.rrd"]


def test_tension_colours_ramp_and_clip() -> None:
    rgb = tension_colors(np.array([-5e3, 0.0, 12.5e3, 25e3, 40e3]), (0.0, 25e3))
    assert rgb.dtype == np.uint8 and rgb.shape == (5, 3)
    assert (rgb[0] == rgb[1]).all() and (rgb[3] == rgb[4]).all()  # clipped
    assert rgb[1, 2] > rgb[1, 0] and rgb[3, 0] > rgb[3, 2]  # low blue, high red


def test_viewer_path_resolution(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="no such recording"):
        open_viewer(tmp_path / "missing.rrd")
    with pytest.raises(FileNotFoundError, match=f"no {RUN_RRD}"):
        resolve_rrd(tmp_path)
    other = tmp_path / "notes.txt"
    other.write_text("x")
    with pytest.raises(ValueError, match="not a Rerun recording"):
        resolve_rrd(other)
    (tmp_path / RUN_RRD).write_bytes(b"")
    assert resolve_rrd(tmp_path) == tmp_path / RUN_RRD
    assert resolve_rrd(tmp_path / RUN_RRD) == tmp_path / RUN_RRD
