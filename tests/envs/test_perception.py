"""Perception in the loop (pipeline/envs/perception.py): LiDAR ranging of detector boxes in closed form, and the
PerceivedFeatures wrapper on a real highway env with a detector that reports the frame's ground-truth boxes."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import pipeline.envs  # noqa: F401  (registers the envs)
from pipeline.core.config import RigConfig, load_config
from pipeline.core.geometry import Transform
from pipeline.detect.infer import Detections as ImageDetections
from pipeline.envs.perception import PerceivedFeatures, Perception, centre_from_surface
from pipeline.stages.rig import build_sensors

SMALL_RIG = """
name: small
cameras:
  - name: front
    width_px: 320
    height_px: 240
    hfov_deg: 60.0
    samples_per_pixel: 1
    quality: fast
    mount: {xyz_m: [0.6, 0.0, 0.65], rpy_rad: [0.0, 0.0, 0.0]}
lidars:
  - name: top
    channels: 32
    upper_fov_deg: 2.0
    lower_fov_deg: -24.9
    horizontal_resolution_deg: 0.4
    range_m: 120.0
    rotation_hz: 10.0
    attenuation_per_m: 0.004
    range_noise_std_m: 0.02
    dropout: 0.0
    mount: {xyz_m: [0.0, 0.0, 1.05], rpy_rad: [0.0, 0.0, 0.0]}
"""


class FixedBoxes:
    """A detector that reports the same boxes for every image."""

    def __init__(self, boxes, scores, categories) -> None:
        self.out = ImageDetections(np.array(boxes, float).reshape(-1, 4), np.array(scores, float),
                                   np.array(categories, np.int64))

    def predict(self, rgbs):
        return [self.out for _ in rgbs]


@pytest.fixture(scope="module")
def rig_path(tmp_path_factory):
    path = tmp_path_factory.mktemp("rig") / "small.yaml"
    path.write_text(SMALL_RIG)
    return path


def test_surface_to_centre_in_closed_form():
    assert centre_from_surface(np.array([[30.0, 40.0]]), np.array([10.0])) == pytest.approx(np.array([[33.0, 44.0]]))


def test_a_box_is_ranged_by_the_median_of_the_lidar_points_inside_it(rig_path):
    rig = load_config(RigConfig, rig_path, "rigs")[0]
    cameras, lidars = build_sensors(rig)
    camera, lidar = cameras[0], lidars[0]
    # a patch of points 20 m ahead and 1 m to the left of the ego's centre, 0.5-1.5 m above the road
    ys, zs = np.meshgrid(np.linspace(0.6, 1.4, 9), np.linspace(0.5, 1.5, 5))
    patch_ego = np.column_stack([np.full(ys.size, 20.0), ys.ravel(), zs.ravel()])
    uv, _ = camera.project(camera.camera_to_world(Transform.identity()).inverse().apply(patch_ego))
    (x1, y1), (x2, y2) = uv.min(axis=0) - 1, uv.max(axis=0) + 1
    far_ego = np.array([[60.0, -10.0, 1.0]])  # a point seen elsewhere in the image
    points_lidar = lidar.mount.inverse().apply(np.vstack([patch_ego, far_ego])).astype(np.float32)
    mask = np.ones(len(points_lidar), np.int8)
    detector = FixedBoxes([[x1, y1, x2, y2], [0, 0, 5, 5], [x1, y1, x2, y2], [np.nan, 0, 1, 1]],
                          [0.6, 0.9, 0.99, 0.8], [3, 6, 1, 3])  # a car, an empty bus box, a person, a broken box
    perception = Perception(detector, camera, lidar.mount)
    frame = perception(np.zeros((240, 320, 3), np.uint8), points_lidar, mask)
    assert frame.category_ids.tolist() == [6, 3]  # by score; the person and the NaN box dropped, and counted
    assert perception.dropped == 2
    assert frame.points.tolist() == [0, len(patch_ego)]
    assert np.isnan(frame.position_m[0]).all()
    assert frame.position_m[1] == pytest.approx([20.0, 1.0], abs=1e-6)
    assert frame.range_m[1] == pytest.approx(math.hypot(20.0, 1.0), abs=1e-6)
    assert frame.bearing_rad[1] == pytest.approx(math.atan2(1.0, 20.0), abs=1e-9)


def test_a_range_gate_from_the_box_height_keeps_fog_echoes_out(rig_path):
    """The droplets' echoes a few metres ahead (the LiDAR in fog) that project into a car's box do not range it: only
    points at 0.4-2.5 x f_y H / h deep count (H = 1.5 m for a car); without the gate their median wins; a box cut by
    the image's bottom edge keeps the near points; a box as tall as a near object's is ranged by the echoes, one as
    short as a far object's is left unranged by the car's points."""
    rig = load_config(RigConfig, rig_path, "rigs")[0]
    cameras, lidars = build_sensors(rig)
    camera, lidar = cameras[0], lidars[0]
    ys, zs = np.meshgrid(np.linspace(0.6, 1.4, 9), np.linspace(0.5, 1.5, 5))
    car = np.column_stack([np.full(ys.size, 20.0), ys.ravel(), zs.ravel()])  # 45 points, 20 m ahead
    to_cam = camera.camera_to_world(Transform.identity()).inverse()
    eye = camera.camera_to_world(Transform.identity()).apply(np.zeros((1, 3)))[0]
    share = np.random.default_rng(3).uniform(0.15, 0.25, 60)[:, None]
    echoes = eye + share * (car[np.arange(60) % len(car)] - eye)  # on the car's rays, 3-5 m ahead
    uv, _ = camera.project(to_cam.apply(car))
    (x1, y1), (x2, y2) = uv.min(axis=0) - 1, uv.max(axis=0) + 1
    h = y2 - y1
    points = lidar.mount.inverse().apply(np.vstack([car, echoes])).astype(np.float32)
    mask = np.ones(len(points), np.int8)
    image = np.zeros((240, 320, 3), np.uint8)

    def ranged(box, gate=(0.4, 2.5), category=3):
        perception = Perception(FixedBoxes([box], [0.9], [category]), camera, lidar.mount, range_gate=gate)
        return perception(image, points, mask)

    frame = ranged([x1, y1, x2, y2])
    assert frame.points.tolist() == [len(car)]
    assert frame.position_m[0] == pytest.approx([20.0, 1.0], abs=1e-6)
    near, far = Perception(FixedBoxes([], [], []), camera, lidar.mount).gates(np.array([[x1, y1, x2, y2]]),
                                                                               np.array([3]))
    assert near[0] == pytest.approx(0.4 * camera.fy * 1.5 / h) and far[0] == pytest.approx(2.5 * camera.fy * 1.5 / h)
    ungated = ranged([x1, y1, x2, y2], gate=None)
    assert ungated.points.tolist() == [len(car) + len(echoes)] and ungated.position_m[0, 0] < 6.0
    # Boxes cut by the image's top or bottom edge keep the near points; their far limit is the formula's.
    near, far = Perception(FixedBoxes([], [], []), camera, lidar.mount).gates(
        np.array([[x1, 0.0, x2, 40.0], [x1, 200.0, x2, 240.0], [x1, 100.0, x2, 140.0]]), np.array([3, 8, 3]))
    assert near.tolist() == [0.0, 0.0, pytest.approx(0.4 * camera.fy * 1.5 / 40.0)]
    assert far == pytest.approx(2.5 * camera.fy * np.array([1.5, 3.0, 1.5]) / 40.0)
    tall = ranged([x1, y1 - 5 * h, x2, y2])  # six times as tall: a depth of ~5 m, the car beyond 2.5 x that
    assert tall.points.tolist() == [len(echoes)] and tall.position_m[0, 0] < 6.0
    short = ranged([x1, y1, x2, y1 + 0.25 * h])  # a quarter as tall: ~120 m deep, the car nearer than 0.4 x that
    assert short.points.tolist() == [0] and np.isnan(short.position_m).all()
    with pytest.raises(ValueError, match="range_gate"):
        Perception(FixedBoxes([], [], []), camera, lidar.mount, range_gate=(2.0, 1.0))


def test_road_returns_range_no_box(rig_path):
    """Ground removal: a flat box on the road 18 m ahead (a weak detection on a marking) holds only road returns
    (0.75 m below the ego frame's origin, the centre of a 1.5 m tall ego) and is left unranged; a car's box that
    also holds the road in front of it is ranged by the car alone (its median moves from the road's to the car's);
    without a ground height nothing is removed."""
    rig = load_config(RigConfig, rig_path, "rigs")[0]
    cameras, lidars = build_sensors(rig)
    camera, lidar = cameras[0], lidars[0]
    to_cam = camera.camera_to_world(Transform.identity()).inverse()
    ground = -0.75
    xs, ys = np.meshgrid(np.linspace(14.0, 22.0, 17), np.linspace(-1.0, 1.0, 9))
    road = np.column_stack([xs.ravel(), ys.ravel(), np.full(xs.size, ground + 0.02)])  # 153 returns
    ys, zs = np.meshgrid(np.linspace(-0.8, 0.8, 5), np.linspace(ground + 0.4, ground + 1.4, 5))
    car = np.column_stack([np.full(ys.size, 30.0), ys.ravel(), zs.ravel()])  # 25 returns on its back, 30 m ahead

    def box(points):
        uv, _ = camera.project(to_cam.apply(points))
        return [*(uv.min(axis=0) - 1), *(uv.max(axis=0) + 1)]

    marking, vehicle = box(road), box(np.vstack([car, road[road[:, 0] > 19.0]]))
    points = lidar.mount.inverse().apply(np.vstack([road, car])).astype(np.float32)
    mask = np.ones(len(points), np.int8)
    image = np.zeros((240, 320, 3), np.uint8)
    detector = FixedBoxes([marking, vehicle], [0.9, 0.8], [3, 3])
    removed = Perception(detector, camera, lidar.mount, range_gate=None, ground_z_m=ground)(image, points, mask)
    assert removed.points.tolist() == [0, len(car)]
    assert np.isnan(removed.position_m[0]).all()
    assert removed.position_m[1] == pytest.approx([30.0, 0.0], abs=1e-6)
    kept = Perception(detector, camera, lidar.mount, range_gate=None)(image, points, mask)
    assert kept.points[0] == len(road) and kept.position_m[0, 0] == pytest.approx(18.0, abs=0.5)
    assert kept.points[1] > 2 * len(car) and kept.position_m[1, 0] < 23.0  # the road outnumbers the car there
    with pytest.raises(ValueError, match="ground_clearance_m"):
        Perception(detector, camera, lidar.mount, ground_z_m=ground, ground_clearance_m=-0.3)


class GroundTruthBoxes:
    """A detector that sees exactly the frame's labelled vehicles (tight boxes of >= 50 visible pixels)."""

    def __init__(self, env) -> None:
        self.env = env

    def predict(self, rgbs):
        labels = self.env.unwrapped._truth["labels"].to_pandas()
        cam = labels[(labels.sensor == "front") & labels.visible & (labels.visible_px >= 50)]
        return [ImageDetections(cam[["x1", "y1", "x2", "y2"]].to_numpy(float), np.ones(len(cam)),
                                cam.category_id.to_numpy(np.int64))]


def _episode(rig_path, seed: int = 2, steps: int = 25):
    env = gym.make("roadsynth/Highway-v0", vehicles=100, warmup_s=30.0, time_limit_s=3.0,
                   sensors=["camera", "lidar"], rig=rig_path)
    wrapped = PerceivedFeatures(env, GroundTruthBoxes(env))
    try:
        obs, info = wrapped.reset(seed=seed)
        out = [(obs, info)]
        for _ in range(steps):
            obs, _, terminated, truncated, info = wrapped.step(np.zeros(2, np.float32))
            out.append((obs, info))
            if terminated or truncated:
                break
        return wrapped.observation_space, out
    finally:
        wrapped.close()


@pytest.mark.slow
def test_perceived_features_track_what_the_camera_sees(rig_path):
    space, steps = _episode(rig_path)
    obs, info = steps[-1]
    assert space.contains(obs)
    gt, perceived = info["ground_truth"]["neighbours"], obs["neighbours"]
    seen = [k for k in range(3) if perceived[k, 0]]  # leaders: the front camera sees only ahead
    assert seen, "no leader was tracked"
    for k in seen:
        assert gt[k, 0] == 1.0
        assert perceived[k, 1] == pytest.approx(gt[k, 1], abs=1.5)  # ds, centre to centre
        assert perceived[k, 2] == pytest.approx(gt[k, 2], abs=0.8)  # dd
        assert perceived[k, 3] == pytest.approx(gt[k, 3], abs=1.5)  # dv
    assert not perceived[3:, 0].any()  # followers are behind the camera
    assert obs["detections_mask"].sum() >= len(seen)
    ranged = obs["detection_ranged"].astype(bool)
    assert (obs["detection_range_m"][ranged] > 0).all() and (obs["detection_range_m"][~ranged] == 0).all()


@pytest.mark.slow
def test_a_perceived_episode_repeats_with_its_seed(rig_path):
    first = _episode(rig_path, steps=8)[1]
    second = _episode(rig_path, steps=8)[1]
    for (a, _), (b, _) in zip(first, second, strict=True):
        assert np.array_equal(a["neighbours"], b["neighbours"])
        assert np.array_equal(a["detections"], b["detections"])


class MissingFrames(GroundTruthBoxes):
    """The labelled vehicles' boxes, except on the frames (by call, reset's first) in ``missed``: none."""

    def __init__(self, env, missed) -> None:
        super().__init__(env)
        self.missed, self.calls = set(missed), 0

    def predict(self, rgbs):
        self.calls += 1
        if self.calls - 1 in self.missed:
            return [ImageDetections(np.zeros((0, 4)), np.zeros(0), np.zeros(0, np.int64))]
        return super().predict(rgbs)


@pytest.mark.slow
def test_a_leader_the_detector_misses_for_a_frame_coasts_in_view_and_not_out_of_it(rig_path):
    """A confirmed track missed for up to coast_in_view frames stays in its slot, predicted, while its centre lies in
    the camera's image (the detector missed it); a track predicted beside or behind the ego, or missed longer, is
    not reported."""
    from pipeline.envs.features import NEIGHBOUR_SLOTS
    from pipeline.envs.tracker import EgoPose, Track

    leader = NEIGHBOUR_SLOTS.index("leader")
    slots = {}
    for coast in (0, 2):
        env = gym.make("roadsynth/Highway-v0", vehicles=100, warmup_s=30.0, time_limit_s=3.0,
                       sensors=["camera", "lidar"], rig=rig_path)
        wrapped = PerceivedFeatures(env, MissingFrames(env, missed={6}), coast_in_view=coast)
        try:
            obs, _ = wrapped.reset(seed=3)  # a leader 56 m ahead
            seen = [obs["neighbours"][leader].copy()]
            for _ in range(7):
                obs, *_ = wrapped.step(np.zeros(2, np.float32))
                seen.append(obs["neighbours"][leader].copy())
            slots[coast] = seen
            if coast:
                inner = env.unwrapped
                pose = EgoPose.moving(*inner.ego_pose(), float(obs["ego"][0]))
                places = [(30.0, 0.0, 1), (30.0, 0.0, 2), (30.0, 0.0, 3), (0.0, 6.0, 1), (-20.0, 0.0, 1),
                          (30.0, 0.0, 0)]  # ego frame, misses
                fixed = pose.to_fixed(np.array([p[:2] for p in places]))
                wrapped.tracker.tracks = [Track(k + 1, np.array([*fixed[k], 0.0, 0.0]), np.eye(4), np.zeros(4), 3,
                                                np.array([4.5, 1.8]), 5, misses, True)
                                          for k, (_, _, misses) in enumerate(places)]
                assert [t.track_id for t in wrapped._coasting_in_view(pose)] == [1, 2]
        finally:
            wrapped.close()
    assert all(slot[0] == 1.0 for slot in slots[2][2:6])  # the leader, confirmed at the third frame
    assert slots[0][6][0] == 0.0  # missed on frame 6: not reported without coasting
    assert slots[2][6][0] == 1.0  # coasting in view
    assert slots[2][6][1] == pytest.approx(slots[2][5][1] + 0.1 * slots[2][5][3], abs=0.05)  # ds moved by dv dt
    assert slots[0][7][0] == slots[2][7][0] == 1.0  # the track takes its leader back
    assert np.array_equal(slots[0][:6], slots[2][:6])
    with pytest.raises(ValueError, match="coast_in_view"):
        PerceivedFeatures(env, FixedBoxes([], [], []), coast_in_view=-1)


def test_an_env_without_camera_and_lidar_is_refused():
    env = gym.make("roadsynth/Highway-v0", vehicles=20, warmup_s=5.0)
    try:
        with pytest.raises(ValueError, match="camera"):
            PerceivedFeatures(env, FixedBoxes([], [], []))
    finally:
        env.close()


@pytest.mark.slow
def test_perception_as_an_env_option_in_a_two_process_vector_env(rig_path, tmp_path):
    """gym.make(..., perception=MODEL.onnx) in each of two processes: same seeds, same perceived observations as in
    this process."""
    from tests.detect.test_onnx_heads import constant_model, yolox_output

    model = tmp_path / "car.onnx"
    constant_model(model, yolox_output())
    kwargs = {"vehicles": 60, "warmup_s": 20.0, "time_limit_s": 1.0, "rig": str(rig_path), "perception": str(model)}
    vec = gym.vector.AsyncVectorEnv([lambda: gym.make("roadsynth/Highway-v0", **kwargs)] * 2)
    try:
        obs, _ = vec.reset(seed=[4, 5])
        for _ in range(3):
            obs, *_ = vec.step(np.zeros((2, 2), np.float32))
    finally:
        vec.close()
    single = gym.make("roadsynth/Highway-v0", **kwargs)
    try:
        assert any(isinstance(e, PerceivedFeatures) for e in _chain(single))
        one, _ = single.reset(seed=5)
        for _ in range(3):
            one, *_ = single.step(np.zeros(2, np.float32))
    finally:
        single.close()
    assert np.array_equal(obs["detections"][1], one["detections"])
    assert np.array_equal(obs["neighbours"][1], one["neighbours"])
    assert obs["detections_mask"][1].sum() == 1  # the constant model's one car


def _chain(env):
    while hasattr(env, "env"):
        yield env
        env = env.env


@pytest.mark.slow
def test_parked_cars_beside_the_ego_s_lane_fill_no_lane_slot(small_default_rig):
    """Urban seed 1's ego drives in the rightmost lane, parked cars in the parking lane beside it (no class may drive
    there; SUMO has no lane for the ground truth's right slots). Seen exactly (the labelled vehicles' boxes) they are
    tracked in the band of a right lane on nearly every step; the perceived right slots stay empty, as the ground
    truth's do: the map says there is no lane to the right."""
    from pipeline.envs.driver import ReferenceAgent
    from pipeline.envs.features import NEIGHBOUR_SLOTS
    from pipeline.envs.tracker import EgoPose, lane_frame_tracks, track_neighbour_rows

    env = gym.make("roadsynth/Urban-v0", time_limit_s=30.0, sensors=["camera", "lidar"], rig=small_default_rig)
    wrapped = PerceivedFeatures(env, GroundTruthBoxes(env))
    inner, right = env.unwrapped, NEIGHBOUR_SLOTS.index("right_leader")
    try:
        obs, info = wrapped.reset(seed=1)
        agent = ReferenceAgent(wrapped)
        agent.reset(obs)
        in_the_band = 0
        for _ in range(20):
            obs, _, terminated, truncated, info = wrapped.step(agent.act(obs))
            assert not (terminated or truncated)
            assert not inner.lane_drivable(round(float(obs["ego"][2])) - 1)
            speed = float(obs["ego"][0])
            reported = [t for t in wrapped.tracker.tracks if t.confirmed and t.misses == 0]
            rows = track_neighbour_rows(lane_frame_tracks(reported, EgoPose.moving(*inner.ego_pose(), speed),
                                                          float(obs["ego"][4]), speed),
                                        float(obs["ego"][3]), inner.lane_width_m(), 100.0)
            in_the_band += bool(rows[right, 0])
            assert obs["neighbours"][right, 0] == 0.0 and info["ground_truth"]["neighbours"][right, 0] == 0.0
        assert in_the_band >= 15
    finally:
        wrapped.close()
