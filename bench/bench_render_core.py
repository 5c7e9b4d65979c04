"""Benchmark of the renderer core: one labelled frame = 800x600 camera (primary + shadow rays, images, GT)
plus one 64 x 1800 LiDAR sweep, against the bare Embree casts those need.

    .venv/bin/python bench/bench_render_core.py [--frames 20] [--actors 30] [--sim DIR] [--condition noon]
        [--threads 0] [--save FILE.png]

Without ``--sim`` the world is synthetic (tessellated ground, a road with markings, building blocks and
trees, ~35k triangles; 30 random actors, the ego following its lane). With ``--sim`` it is a simulated run:
the static world from DIR/roads (pipeline.world.static), actors and ego from DIR/trajectories.parquet.
Every frame rebuilds its actor geometry. Nothing is written to disk (``--save`` keeps the last image).
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import open3d as o3d

from pipeline.core.classes import ObjectClass, SemanticClass
from pipeline.core.config.sensors import CameraConfig, ImageSensorConfig, LidarConfig
from pipeline.core.geometry import Boxes3D, Transform
from pipeline.sensors.camera import Camera
from pipeline.sensors.conditions import get_condition
from pipeline.sensors.exposure import exposure_for
from pipeline.sensors.groundtruth import camera_labels, project_actors
from pipeline.sensors.lidar import Lidar, render_lidar
from pipeline.sensors.post import sensor_noise
from pipeline.sensors.render import render_camera
from pipeline.sensors.shading import shade, to_srgb8
from pipeline.world.actor_shapes import cuboid, wheel
from pipeline.world.actors import Actors, srgb8_to_linear
from pipeline.world.materials import material_index
from pipeline.world.mesh import Mesh
from pipeline.world.scene import FrameScene, StaticScene, make_rays

EGO_SPEED_MPS = 15.0
EXPOSURE = exposure_for(ImageSensorConfig(), 1 / 1000, 1.0)  # a daylight exposure's noise on the bare shading
DIMS = {"car": (4.5, 1.8, 1.5), "van": (5.0, 2.0, 2.2), "truck": (8.0, 2.5, 3.5), "bus": (12.0, 2.55, 3.2),
        "motorcycle": (2.2, 0.8, 1.5), "bicycle": (1.8, 0.6, 1.75), "pedestrian": (0.5, 0.6, 1.75)}


def synthetic_static(rng: np.random.Generator) -> list[Mesh]:
    n, size = 120, 300.0
    xs = np.linspace(-size, size, n + 1)
    gx, gy = np.meshgrid(xs, xs)
    verts = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, -0.05)])
    i, j = np.meshgrid(np.arange(n), np.arange(n))
    a = (j * (n + 1) + i).ravel()
    tris = np.concatenate([np.column_stack([a, a + 1, a + n + 2]), np.column_stack([a, a + n + 2, a + n + 1])])
    meshes = [Mesh(verts, tris, material_index("grass"), SemanticClass.TERRAIN)]
    road = cuboid((-size, -7.5, -0.1), (size, 7.5, 0.0), "asphalt")
    meshes.append(Mesh(*road, semantic=SemanticClass.ROAD))
    marks = [cuboid((x, y - 0.08, 0.0), (x + 3.0, y + 0.08, 0.01), "lane_paint") for x in np.arange(-size, size, 9.0)
             for y in (-3.75, 0.0, 3.75)]
    meshes.append(Mesh.concatenate([Mesh(*m, semantic=SemanticClass.LANE_MARKING) for m in marks]))
    blocks = []
    for x in np.arange(-size, size, 25.0):
        for side in (-1, 1):
            w, d, h = rng.uniform(12, 22), rng.uniform(8, 16), rng.uniform(6, 30)
            y0 = side * rng.uniform(14, 20)
            blocks.append(cuboid((x, min(y0, y0 + side * d), 0.0), (x + w, max(y0, y0 + side * d), h), "building"))
    meshes.append(Mesh.concatenate([Mesh(*b, semantic=SemanticClass.BUILDING) for b in blocks]))
    trees = [wheel(x, 4.0, 2.0, y - 2.0, y + 2.0, "foliage", n=8) for x in np.arange(-size, size, 12.0)
             for y in (-11.0, 11.0)]
    meshes.append(Mesh.concatenate([Mesh(*t, semantic=SemanticClass.VEGETATION) for t in trees]))
    return meshes


def random_actors(rng: np.random.Generator, n: int) -> tuple[Actors, np.ndarray]:
    classes = [list(ObjectClass)[i] for i in rng.choice(7, n, p=[0.55, 0.1, 0.1, 0.05, 0.08, 0.06, 0.06])]
    size = np.array([DIMS[c.value] for c in classes]) * rng.uniform(0.9, 1.1, (n, 1))
    lane = rng.choice([-5.6, -1.9, 1.9, 5.6], n)
    x = rng.uniform(-40.0, 150.0, n)
    yaw = np.where(lane > 0, np.pi, 0.0)
    speed = np.where(lane > 0, -1.0, 1.0) * rng.uniform(5, 25, n)
    # The ego's lane (y = -1.9): keep a gap ahead of it and follow at its speed, so no actor overlaps it.
    ego_lane = lane == -1.9
    x[ego_lane] = np.sort(rng.uniform(12.0, 150.0, ego_lane.sum()))
    speed[ego_lane] = EGO_SPEED_MPS
    boxes = Boxes3D(np.column_stack([x, lane, size[:, 2] / 2]), size, yaw)
    return Actors(np.arange(1, n + 1), classes, boxes, rng.uniform(0.05, 0.95, (n, 3)), rng.random(n) < 0.3), speed


def moved(actors: Actors, speed: np.ndarray, t: float) -> Actors:
    c = actors.boxes.center.copy()
    c[:, 0] += speed * t
    return Actors(actors.track_id, actors.object_class, Boxes3D(c, actors.boxes.size, actors.boxes.yaw_rad),
                  actors.color_rgb, actors.brake)


class BareCasts:
    """The Embree calls a frame needs, alone: same triangles, same rays, scenes built outside the timing."""

    def __init__(self, static_meshes: list[Mesh]) -> None:
        merged = Mesh.concatenate([m for m in static_meshes if len(m)])
        self.static = self._scene(merged.vertices, merged.triangles)
        self.cpu_s = 0.0  # CPU seconds of all the casts timed so far (every Embree thread)

    @staticmethod
    def _scene(vertices: np.ndarray, triangles: np.ndarray) -> o3d.t.geometry.RaycastingScene:
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.core.Tensor(vertices.astype(np.float32)), o3d.core.Tensor(triangles.astype(np.uint32)))
        scene.cast_rays(o3d.core.Tensor(np.array([[0, 0, 0, 1, 0, 0]], np.float32)))  # builds the BVH
        return scene

    def time(self, scene: FrameScene, rays: dict[str, np.ndarray]) -> dict[str, float]:
        """Seconds per kind of cast for one frame's rays (camera / lidar: static all + actors masked)."""
        actors = self._scene(scene.geometry.vertices, scene.geometry.triangles)
        t = {k: o3d.core.Tensor.from_numpy(np.ascontiguousarray(v)) for k, v in rays.items()}
        out = {}
        cpu = time.process_time()
        for name in ("camera", "lidar"):
            start = time.perf_counter()
            self.static.cast_rays(t[name])
            actors.cast_rays(t[name + "_actor"])
            out[name] = time.perf_counter() - start
        start = time.perf_counter()
        self.static.test_occlusions(t["shadow"])
        actors.test_occlusions(t["shadow"])
        out["shadow"] = time.perf_counter() - start
        self.cpu_s += time.process_time() - cpu
        return out


def frame_rays(camera, lidar, scene, ego, condition, crays, mask, hits) -> dict[str, np.ndarray]:
    """The rays of one frame: camera (+ actor-masked subset), shadow rays of sunlit hits, lidar (+ subset)."""
    lit = hits.hit & (hits.normal @ condition.sun_direction > 0) & condition.shadows & (condition.sun_elevation_deg > 0)
    p = crays[lit, :3] + crays[lit, 3:] * hits.t_m[lit, None] + hits.normal[lit] * 1e-3
    shadow = np.concatenate([p, np.broadcast_to(condition.sun_direction, p.shape)], axis=1).astype(np.float32)
    to_w = lidar.lidar_to_world(ego)
    lrays = make_rays(to_w.translation, lidar.directions, to_w.rotation)
    return {"camera": crays, "camera_actor": crays[mask], "shadow": shadow, "lidar": lrays,
            "lidar_actor": lrays[lidar.actor_ray_mask(scene, to_w)]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--actors", type=int, default=30)
    ap.add_argument("--threads", type=int, default=0, help="Embree threads per cast (0 = all cores)")
    ap.add_argument("--condition", default="noon", help="a preset of pipeline.sensors.conditions")
    ap.add_argument("--sim", type=Path, default=None, help="a simulate-stage output folder")
    ap.add_argument("--save", type=Path, default=None, help="write the last frame's RGB with boxes here")
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    if args.sim is not None:
        from pipeline.world.static import build_static_world

        static_meshes = build_static_world(args.sim / "roads", seed=0).meshes
        frames = sim_frames(args.sim, args.frames + 1)
    else:
        static_meshes = synthetic_static(rng)
        actors0, speed = random_actors(rng, args.actors)
        frames = [(moved(actors0, speed, 0.1 * f), Transform.from_xyz_rpy((EGO_SPEED_MPS * 0.1 * f, -1.9, 0.75)))
                  for f in range(args.frames + 1)]
    start = time.perf_counter()
    static = StaticScene(static_meshes)
    static.cast(np.array([[0, 0, 50, 0, 0, -1]], np.float32))  # Embree builds its BVH on the first cast
    build_s = time.perf_counter() - start
    camera = Camera(CameraConfig(name="front", mount={"xyz_m": (0.8, 0.0, 0.7)}))
    lidar = Lidar(LidarConfig(name="top", mount={"xyz_m": (0.0, 0.0, 1.0)}))
    condition = get_condition(args.condition)
    lidar_here = Lidar(condition.lidar(lidar))
    _ = camera.pixel_directions, lidar.directions, lidar_here.directions

    bare_caster = BareCasts(static_meshes)
    totals, stages, bare, ratios = [], defaultdict(float), defaultdict(float), []
    for f, (actors, ego) in enumerate(frames):
        t0 = time.perf_counter()
        scene = FrameScene(static, actors, threads=args.threads)
        t1 = time.perf_counter()
        frame = render_camera(scene, camera, ego, condition, np.random.default_rng(f))
        t2 = time.perf_counter()
        sweep = render_lidar(scene, lidar_here, ego, np.random.default_rng(f))
        t3 = time.perf_counter()
        if f == 0:
            continue  # warm-up
        totals.append(t3 - t0)
        stages["actor geometry + BVH"] += t1 - t0
        stages["camera (all)"] += t2 - t1
        stages["lidar (all)"] += t3 - t2
        # Instrumented camera pass: the same public steps as render_camera, timed one by one.
        c0 = time.perf_counter()
        cam_to_world = camera.camera_to_world(ego)
        amodal = project_actors(scene, camera, cam_to_world)
        mask = amodal.pixel_mask(camera.width, camera.height)
        crays = make_rays(cam_to_world.translation, camera.pixel_directions, cam_to_world.rotation)
        c1 = time.perf_counter()
        hits = scene.cast_rays(crays, actor_rays=mask)
        c2 = time.perf_counter()
        image = np.where(hits.instance_id > 0, hits.actor_index + 1, 0).astype(np.int32).reshape(camera.height, -1)
        camera_labels(scene, camera, cam_to_world, amodal, image)
        c3 = time.perf_counter()
        radiance = sensor_noise(condition.fog(shade(scene, crays, hits, condition), hits.t_m, hits.hit),
                                EXPOSURE, np.random.default_rng(f))
        c4 = time.perf_counter()
        to_srgb8(radiance)
        c5 = time.perf_counter()
        for name, dt in (("  cam: rays + amodal boxes + mask", c1 - c0),
                         ("  cam: primary cast -> Hits", c2 - c1),
                         ("  cam: labels (incl. alone casts)", c3 - c2),
                         ("  cam: shading (incl. shadow rays)", c4 - c3),
                         ("  cam: tone map", c5 - c4)):
            stages[name] += dt
        # Bare Embree casts of this frame's rays, right after it (same machine load).
        rays = frame_rays(camera, lidar, scene, ego, condition, crays, mask, hits)
        frame_bare = bare_caster.time(scene, rays)
        for name, dt in frame_bare.items():
            bare[name] += dt
        ratios.append(totals[-1] / sum(frame_bare.values()))
    n = len(totals)
    bare = {k: v / n for k, v in bare.items()}
    bare_total = sum(bare.values())
    mean = float(np.mean(totals))
    print(f"static world: {static.num_triangles} triangles, built in {build_s * 1e3:.0f} ms (once per run); "
          f"actors: {len(actors)} ({len(scene.geometry.triangles)} triangles); frames: {n}; "
          f"camera rays {len(crays)} (actor-masked {len(rays['camera_actor'])}), shadow rays {len(rays['shadow'])}, "
          f"lidar rays {len(rays['lidar'])}, lidar points {len(sweep)}, labels {len(frame.labels)}")
    print(f"{'stage':42s} {'ms/frame':>9s} {'share':>6s}")
    for name, s in stages.items():
        print(f"{name:42s} {s / n * 1e3:9.1f} {s / n / mean:6.0%}")
    print(f"{'TOTAL labelled frame':42s} {mean * 1e3:9.1f} {1:6.0%}")
    for name, s in bare.items():
        print(f"{'bare Embree: ' + name:42s} {s * 1e3:9.1f}")
    print(f"{'bare Embree: total':42s} {bare_total * 1e3:9.1f}")
    print(f"labelled frames/s: {1 / mean:.2f}   ratio total / bare casts: {mean / bare_total:.2f}x "
          f"(per-frame ratios: median {np.median(ratios):.2f}x, min {np.min(ratios):.2f}x, max {np.max(ratios):.2f}x)")
    if args.save is not None:
        save_preview(frame, args.save)


def sim_frames(sim: Path, count: int) -> list[tuple[Actors, Transform]]:
    """(actors, ego pose) of the first ``count`` recorded frames of a simulated run."""
    import pandas as pd

    traj = pd.read_parquet(sim / "trajectories.parquet")
    out = []
    for _, rows in list(traj.groupby("frame", sort=True))[:count]:
        ego = rows[rows.is_ego].iloc[0]
        others = rows[~rows.is_ego]
        boxes = Boxes3D(others[["x_m", "y_m", "z_m"]].to_numpy(),
                        others[["length_m", "width_m", "height_m"]].to_numpy(), others.yaw_rad.to_numpy())
        color = srgb8_to_linear(others[["color_r", "color_g", "color_b"]].to_numpy())
        actors = Actors(others.track_id.to_numpy(), others.cls.tolist(), boxes, color, others.braking.to_numpy())
        pose = Transform.from_xyz_rpy((ego.x_m, ego.y_m, ego.z_m), (0.0, 0.0, ego.yaw_rad))
        out.append((actors, pose))
    return out


def save_preview(frame, path: Path) -> None:
    """RGB with tight (green) and clipped amodal (red) boxes and occlusion/truncation text."""
    import cv2

    img = np.ascontiguousarray(frame.rgb[:, :, ::-1])
    lab = frame.labels
    for i in np.flatnonzero(lab.visible):
        x1, y1, x2, y2 = lab.box_amodal_clipped[i].astype(int)
        cv2.rectangle(img, (x1, y1), (x2 - 1, y2 - 1), (0, 0, 255), 1)
        x1, y1, x2, y2 = lab.box_tight[i].astype(int)
        cv2.rectangle(img, (x1, y1), (x2 - 1, y2 - 1), (0, 255, 0), 1)
        cv2.putText(img, f"{lab.track_id[i]} o{lab.occlusion[i]:.2f} t{lab.truncation[i]:.2f}", (x1, max(y1 - 3, 8)),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.3, (255, 255, 255), 1)
    cv2.imwrite(str(path), img)


if __name__ == "__main__":
    main()
