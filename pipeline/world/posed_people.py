"""People's boxes as their posed bodies fill them, frame by frame.

SUMO's pedestrian box (0.215 x 0.478 x 1.719 m, every person alike) is its walking model's footprint, not a body. A
person of a :class:`pipeline.world.people.PersonFamily` instead gets, in each row of the trajectory, the pose of its
gait at that time (:func:`pipeline.world.gait.gait_poses`) and the box of that pose's mesh at the person's own
stature (:func:`pipeline.world.people.person_statures`): size = the posed mesh's extent as modelled x stature /
MODEL_STATURE_M, and the centre where the mesh's centre lies when its pelvis is over the trajectory point and its feet
on the ground. Since a placed actor is its model's unit-box mesh mapped onto its box (:mod:`pipeline.world.actors`),
the mesh fills the box exactly in every frame: the 3D label, the 2D boxes, masks, depth and occlusion all come from
the posed body. Where a rain asks for it (the condition's ``rain.umbrellas``, 0 unless set) a share of the people
walk and stand under an open umbrella: their poses are the umbrella ones and their boxes enclose the umbrella too,
as nuScenes' annotators include what a pedestrian carries ("bags, umbrellas, tools") in the pedestrian's box. Other
actors of the body-sized classes (users' pedestrian models) keep SUMO's height and take their model's depth
(:meth:`pipeline.world.actors.ActorMeshes.body_lengths`). A bicycle (:class:`pipeline.world.two_wheelers.BicycleFamily`)
keeps its simulated box and gets the crank pose of the distance it rode (:func:`pipeline.world.gait.crank_poses`): its
rider pedals in phase with its speed.
"""

from __future__ import annotations

import numpy as np

from pipeline.core.geometry import Boxes3D
from pipeline.world.actors import ActorMeshes, Actors
from pipeline.world.gait import MODEL_STATURE_M, crank_poses, gait_poses
from pipeline.world.people import person_statures


def posed_boxes(meshes: ActorMeshes, actors: Actors, row_actor: np.ndarray, time_s: np.ndarray,
                speed_mps: np.ndarray, boxes: Boxes3D, seed: int, umbrellas: float = 0.0) -> tuple[Boxes3D, np.ndarray]:
    """The boxes and poses of R trajectory rows.

    Args:
        actors: the run's actors, one per track (their class, size and variant hold for the track).
        row_actor: (R,) int64 each row's actor (position in ``actors``).
        time_s, speed_mps: (R,) float64 each row's time and speed.
        boxes: (R) the rows' boxes as simulated (SUMO's: centre at half the box height above the ground).
        seed: the run seed (statures and umbrellas are drawn from it).
        umbrellas: the share of people who walk and stand under an open umbrella (the condition's rain; each person
            drawn once, :func:`umbrella_carriers`); ``meshes`` must then have the umbrella poses
            (:func:`pipeline.world.actors.umbrella_meshes`), or a ValueError says so.

    Returns:
        (R) boxes: people's posed, others' with the length of :meth:`ActorMeshes.body_lengths`; (R,) int64 pose
        (a person's gait pose, a bicycle's crank pose; 0 for the others).
    """
    row_actor = np.asarray(row_actor, np.int64)
    center, size, yaw = boxes.center.copy(), boxes.size.copy(), boxes.yaw_rad.copy()
    size[:, 0] = meshes.body_lengths(actors)[row_actor]
    pose = np.zeros(len(row_actor), np.int64)
    family = meshes.family_codes(actors)
    group = np.array([getattr(meshes.families[f], "group", "") for f in family], object)
    offset = (actors.variant.astype(np.float64) % 65536.0) / 65536.0  # each one's own phase
    development = np.array([getattr(meshes.families[f], "development_m", 0.0) for f in family])
    pedalled = np.flatnonzero(np.isin(row_actor, np.flatnonzero(development > 0)))
    if len(pedalled):  # a bicycle's cranks turn with the distance ridden; its box stays as simulated
        a = row_actor[pedalled]
        for d in np.unique(development[a]):
            at = pedalled[development[a] == d]
            phases = int(meshes.family_poses(family[row_actor[at[0]]]))
            pose[at] = crank_poses(actors.track_id[row_actor[at]], time_s[at], speed_mps[at], d, phases,
                                   offset[row_actor[at]])
    people = np.flatnonzero(group != "")
    rows = np.flatnonzero(np.isin(row_actor, people))
    if not len(rows):
        return Boxes3D(center, size, yaw), pose
    stature = np.zeros(len(actors))
    stature[people] = person_statures(group[people], actors.track_id[people], seed)
    a = row_actor[rows]
    carries = np.zeros(len(actors), bool)
    carries[people] = umbrella_carriers(actors.track_id[people], seed, umbrellas)
    bare = sorted({meshes.families[f].__name__ for f in family[people[carries[people]]]
                   if getattr(meshes.families[f], "umbrella", None) is None})
    if bare:
        raise ValueError(f"umbrellas {umbrellas}: the actor models of {', '.join(bare[:3])} have no umbrella poses "
                         "(pipeline.world.actors.umbrella_meshes has them)")
    pose[rows] = gait_poses(actors.track_id[a], time_s[rows], speed_mps[rows], stature[a], offset[a], carries[a])
    model = meshes.family_models(family[a], pose[rows])
    scale = stature[a] / MODEL_STATURE_M
    extent = np.array(meshes.model_extent, np.float64)[model] * scale[:, None]
    middle = (np.array(meshes.model_low, np.float64)[model] + 0.5 * np.array(meshes.model_extent)[model]) \
        * scale[:, None]  # the mesh's centre from the ground point under the pelvis, body frame
    c, s = np.cos(yaw[rows]), np.sin(yaw[rows])
    ground_z = center[rows, 2] - 0.5 * boxes.size[rows, 2]
    center[rows, 0] += c * middle[:, 0] - s * middle[:, 1]
    center[rows, 1] += s * middle[:, 0] + c * middle[:, 1]
    center[rows, 2] = ground_z + middle[:, 2]
    size[rows] = extent
    return Boxes3D(center, size, yaw), pose


def umbrella_carriers(track_id: np.ndarray, seed: int, share: float) -> np.ndarray:
    """(N,) bool: which of N people carry an open umbrella, each with probability ``share``, one draw per person
    from ``numpy.random.default_rng([seed, UMBRELLA_TAG, track id])`` (the same in every frame and shard)."""
    if share <= 0.0:
        return np.zeros(len(track_id), bool)
    return np.array([np.random.default_rng([int(seed), UMBRELLA_TAG, int(t)]).random() < share
                     for t in np.asarray(track_id).tolist()], bool)


UMBRELLA_TAG = 0x0B7E
