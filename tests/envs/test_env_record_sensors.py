"""record=DIR, sensors=[...] and render_mode on a small real highway (no mocks): an agent's episode becomes a
simulated run that `render` and `export` read unchanged, and the env's sensor frames are the render stage's."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest
from gymnasium.utils.env_checker import check_env
from pycocotools.coco import COCO

import pipeline.envs  # noqa: F401  (registers the envs)
from pipeline.core.config import ConditionConfig, RigConfig, load_config
from pipeline.core.config.resolve import resolve_scenario
from pipeline.core.record import DatasetRecord, label_columns
from pipeline.envs import RoadsynthEnv
from pipeline.envs.sensors import RADAR_FIELDS
from pipeline.envs.topview import SIZE_PX
from pipeline.stages.cli import main as cli_main
from pipeline.stages.render import render
from pipeline.stages.simulate import simulate
from pipeline.traffic.simulation import active_sumo_owner

pytestmark = pytest.mark.slow

SMALL = {"vehicles": 60, "warmup_s": 20.0, "time_limit_s": 2.0}
STEPS = 20  # the time limit in steps of 0.1 s
AGENT_ACTION = np.array([0.3, 0.05], np.float32)  # a little faster, drifting left: not what SUMO would drive

TINY_RIG = """
name: tiny
cameras:
  - name: front
    width_px: 80
    height_px: 60
    hfov_deg: 90.0
    samples_per_pixel: 1
    quality: fast
    mount: {xyz_m: [0.6, 0.0, 0.65], rpy_rad: [0.0, 0.0, 0.0]}
lidars:
  - name: top
    channels: 8
    upper_fov_deg: 2.0
    lower_fov_deg: -24.9
    horizontal_resolution_deg: 2.0
    range_m: 80.0
    rotation_hz: 10.0
    attenuation_per_m: 0.004
    range_noise_std_m: 0.02
    dropout: 0.02
    mount: {xyz_m: [0.0, 0.0, 1.05], rpy_rad: [0.0, 0.0, 0.0]}
"""


@pytest.fixture(scope="module")
def tiny_rig(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("rig") / "tiny.yaml"
    path.write_text(TINY_RIG)
    return path


@pytest.fixture(scope="module")
def episode(tmp_path_factory):
    """An agent's episode with the default rig's camera, LiDAR and radar, recorded: (record root, observations,
    infos)."""
    root = tmp_path_factory.mktemp("episodes")
    env = gym.make("roadsynth/Highway-v0", **SMALL, sensors=["camera", "lidar", "radar"], record=root)
    observations, infos = [], []
    try:
        obs, info = env.reset(seed=5)
        observations.append(obs)
        infos.append(info)
        for _ in range(STEPS):
            obs, _, terminated, truncated, info = env.step(AGENT_ACTION)
            observations.append(obs)
            infos.append(info)
            if terminated or truncated:
                break
    finally:
        env.close()
    return root, observations, infos


def test_recorded_episode_has_simulates_layout(episode, tmp_path):
    root, observations, infos = episode
    run = root / "episode-0000"
    assert infos[-1]["record_dir"] == str(run) and infos[-1]["reason"] == "time_limit"
    assert len(observations) == STEPS + 1
    config, _ = resolve_scenario("highway", vehicles=SMALL["vehicles"], warmup_s=SMALL["warmup_s"], duration_s=2.0)
    simulate(config, 5, tmp_path / "sim", progress=False)
    files = sorted(str(p.relative_to(run)) for p in run.rglob("*") if p.is_file())
    assert files == sorted(str(p.relative_to(tmp_path / "sim")) for p in (tmp_path / "sim").rglob("*") if p.is_file())
    recorded = pd.read_parquet(run / "trajectories.parquet")
    simulated = pd.read_parquet(tmp_path / "sim" / "trajectories.parquet")
    assert recorded.dtypes.equals(simulated.dtypes)
    assert recorded["frame"].unique().tolist() == list(range(STEPS + 1))
    assert (recorded.groupby("frame")["is_ego"].sum() == 1).all()
    ego_rec = recorded[recorded["is_ego"]].set_index("frame")
    ego_sim = simulated[simulated["is_ego"]].set_index("frame")
    # The same ego at the same start; then the agent drives it, not SUMO.
    assert ego_rec["actor_id"].iloc[0] == ego_sim["actor_id"].iloc[0] == infos[0]["ego_id"]
    np.testing.assert_allclose(ego_rec.loc[0, ["x_m", "y_m"]].to_numpy(float),
                               ego_sim.loc[0, ["x_m", "y_m"]].to_numpy(float), atol=1e-9)
    # simulate's 2 s are frames 0-19; the episode's 20 steps add frame 20.
    assert ego_sim.index.tolist() == list(range(STEPS))
    assert not np.allclose(ego_rec.loc[1:STEPS - 1, ["x_m", "y_m"]].to_numpy(float),
                           ego_sim.loc[1:, ["x_m", "y_m"]].to_numpy(float), atol=0.05)
    meta = json.loads((run / "meta.json").read_text())
    assert meta["seed"] == 5 and meta["config"]["env"]["episode_end"] == "time_limit"
    assert json.loads((run / "stats.json").read_text())["frames"] == STEPS + 1


def test_recorded_episode_renders_and_exports_and_matches_the_env_sensors(episode, tmp_path):
    root, observations, infos = episode
    rig = load_config(RigConfig, "default", "rigs")[0]
    noon = load_config(ConditionConfig, "noon", "conditions")[0]
    record_dir = tmp_path / "record"
    render(root / "episode-0000", noon, rig, record_dir, frames=2, workers=1, progress=False)
    record = DatasetRecord(record_dir)
    frames = record.frames["frame"].tolist()
    assert frames == [0, STEPS]
    labels = record.labels
    for frame in frames:
        # The env rendered this frame with the render stage's code: the same pixels, points and labels.
        obs, truth = observations[frame], infos[frame]["sensors"]
        assert obs["camera"].shape == (600, 800, 3) and obs["camera"].dtype == np.uint8
        np.testing.assert_array_equal(obs["camera"], record.rgb("front", frame))
        np.testing.assert_array_equal(truth["camera_instance_id"], record.instance("front", frame))
        np.testing.assert_array_equal(truth["camera_semantic"], record.semantic("front", frame))
        points = record.points("top", frame)
        mask = obs["lidar_mask"].astype(bool)
        assert mask.sum() == len(points)
        got = np.sort(obs["lidar"][mask], axis=0)
        want = np.sort(points[["x_m", "y_m", "z_m", "intensity"]].to_numpy(np.float32), axis=0)
        np.testing.assert_array_equal(got, want)
        assert not obs["lidar"][~mask].any()
        detections = record.radar_detections("front_radar", frame)
        radar_mask = obs["radar_mask"].astype(bool)
        assert radar_mask.sum() == len(detections) > 0
        np.testing.assert_array_equal(obs["radar"][radar_mask], detections[list(RADAR_FIELDS)].to_numpy(np.float32))
        np.testing.assert_array_equal(truth["radar_instance_id"][radar_mask], detections["instance_id"].to_numpy())
        assert not obs["radar"][~radar_mask].any()
        env_labels = truth["labels"].to_pandas().astype(label_columns(radars=True))
        env_labels = env_labels.sort_values(["sensor", "track_id"]).reset_index(drop=True)
        rec_labels = labels[labels["frame"] == frame].sort_values(["sensor", "track_id"]).reset_index(drop=True)
        pd.testing.assert_frame_equal(env_labels[list(rec_labels.columns)], rec_labels, check_dtype=False)

    coco_dir = tmp_path / "coco"
    assert cli_main(["export", "--dataset", str(record_dir), "--format", "coco", "--out", str(coco_dir),
                     "--no-progress"]) == 0
    annotations = next(coco_dir.glob("annotations*.json"))
    coco = COCO(str(annotations))
    assert len(coco.getImgIds()) == 2
    visible = labels[(labels["sensor_type"] == "camera") & labels["visible"]]
    assert len(visible) > 0
    assert len(coco.getAnnIds()) == len(visible)


def test_sensor_envs_pass_check_env_and_repeat_with_the_seed(tiny_rig):
    env = gym.make("roadsynth/Highway-v0", **SMALL, sensors=["camera", "lidar"], rig=tiny_rig,
                   render_mode="rgb_array")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            check_env(env.unwrapped)
        first, _ = env.reset(seed=9)
        image = env.render()
        obs, *_ = env.step(AGENT_ACTION)
        again, _ = env.reset(seed=9)
        obs_again, *_ = env.step(AGENT_ACTION)
    finally:
        env.close()
    assert active_sumo_owner() is None
    assert first["camera"].shape == (60, 80, 3) and first["lidar"].shape == (8 * 180, 4)
    np.testing.assert_array_equal(image, first["camera"])  # the camera is the picture when it is a sensor
    for key in ("camera", "lidar", "lidar_mask"):
        np.testing.assert_array_equal(first[key], again[key])
        np.testing.assert_array_equal(obs[key], obs_again[key])
    assert first["lidar_mask"].sum() > 0


def test_default_rig_spaces():
    env = gym.make("roadsynth/Highway-v0", **SMALL, sensors=["lidar", "camera"])
    try:
        space = env.observation_space
        assert space["camera"].shape == (600, 800, 3) and space["camera"].dtype == np.uint8
        assert space["lidar"].shape == (64 * 1800, 4) and space["lidar_mask"].n == 64 * 1800
        assert "radar" not in space.spaces
    finally:
        env.close()
    env = gym.make("roadsynth/Highway-v0", **SMALL, sensors=["radar"])
    try:
        space = env.observation_space
        assert space["radar"].shape == (250, len(RADAR_FIELDS)) and space["radar_mask"].n == 250
    finally:
        env.close()


def test_top_view_is_centred_on_the_ego():
    env = gym.make("roadsynth/Highway-v0", **SMALL, render_mode="rgb_array")
    try:
        env.reset(seed=2)
        image = env.render()
    finally:
        env.close()
    assert image.shape == (SIZE_PX, SIZE_PX, 3) and image.dtype == np.uint8
    np.testing.assert_array_equal(image[SIZE_PX // 2, SIZE_PX // 2], (220, 40, 40))  # the ego's colour


def test_unfinished_episodes_are_recorded_at_reset_and_close(tmp_path):
    env = gym.make("roadsynth/Highway-v0", **SMALL, record=tmp_path)
    try:
        env.reset(seed=4)
        for _ in range(3):
            env.step(AGENT_ACTION)
        env.reset(seed=4)
        env.step(AGENT_ACTION)
    finally:
        env.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["episode-0000", "episode-0001"]
    for name, frames in (("episode-0000", 4), ("episode-0001", 2)):
        stats = json.loads((tmp_path / name / "stats.json").read_text())
        assert stats["frames"] == frames and stats["episode_end"] is None


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"sensors": ["camera", "sonar"]}, "sensors must name each of camera, lidar, radar"),
    ({"sensors": ["camera", "camera"]}, "at most once"),
    ({"render_mode": "ansi"}, "render_mode must be None or 'rgb_array'"),
])
def test_bad_sensor_options_are_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        RoadsynthEnv("highway", **SMALL, **kwargs)


def test_a_rig_without_the_asked_sensor_is_refused(tmp_path):
    rig = tmp_path / "camera_only.yaml"
    rig.write_text(TINY_RIG.split("lidars:")[0])
    with pytest.raises(ValueError, match=r"camera_only\.yaml: sensors asks for a lidar, but the rig has none"):
        gym.make("roadsynth/Highway-v0", **SMALL, sensors=["lidar"], rig=rig)
    with pytest.raises(ValueError, match=r"camera_only\.yaml: sensors asks for a radar, but the rig has none"):
        gym.make("roadsynth/Highway-v0", **SMALL, sensors=["radar"], rig=rig)
