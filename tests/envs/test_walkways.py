"""The map test of where a place stands for people (pipeline/envs/walkways.py): in closed form on a corner of lanes,
a sidewalk, a walking area and a crossing; against SUMO's own lane of every person in the real urban scenario; and
as the perceived "path" row uses it: people waiting on a corner beside the lane the ego turns into are not in its
way."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest

from pipeline.envs.features import is_crossing, path_row
from pipeline.envs.walkways import WALKWAY_MARGIN_M, Walkways, in_rings, in_strips, near_segments


def _lane(lane_id: str, kind: str, width: float, *points: tuple[float, float]) -> dict:
    xs, ys = zip(*points, strict=True)
    return {"lane_id": lane_id, "kind": kind, "width_m": width, "shape_x": np.array(xs), "shape_y": np.array(ys)}


# A street along y = 0 (driving lane 3.2 m wide, a parking lane and a 2.5 m sidewalk to its right, y < 0), ending
# at x = 50 in a junction: a walking area (the corner square x 50-55, y -6.3 to -1.3), a crossing over the street at
# x = 52 from that corner to the far side, and the ego's right turn (an internal lane) sweeping through the corner's
# edge down to y = -20.
CORNER = pd.DataFrame([
    _lane("street_2", "driving", 3.2, (0.0, 0.0), (50.0, 0.0)),
    _lane("street_1", "parking", 2.5, (0.0, -2.85), (50.0, -2.85)),
    _lane("street_0", "sidewalk", 2.5, (0.0, -5.35), (50.0, -5.35)),
    _lane(":J_w0_0", "walkingarea", 2.5, (50.0, -1.3), (55.0, -1.3), (55.0, -6.3), (50.0, -6.3)),
    _lane(":J_c0_0", "crossing", 3.0, (52.0, -1.3), (52.0, 8.0)),
    _lane(":J_0_0", "driving", 3.2, (50.0, 0.0), (54.0, -1.0), (56.5, -4.0), (57.5, -20.0)),
])


def test_in_strips_and_rings_in_closed_form():
    starts, ends = np.array([[0.0, 0.0]]), np.array([[10.0, 0.0]])
    points = np.array([[5.0, 0.99], [5.0, -1.01], [-0.01, 0.0], [10.0, 0.5], [10.01, 0.0]])
    assert in_strips(points, starts, ends, np.array([1.0])).tolist() == [True, False, False, True, False]
    square = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])
    triangle = np.array([[10.0, 0.0], [14.0, 0.0], [10.0, 4.0]])
    starts = np.concatenate([square, triangle])
    ends = np.concatenate([np.roll(square, -1, 0), np.roll(triangle, -1, 0)])
    owner = np.repeat([0, 1], [4, 3])
    points = np.array([[2.0, 2.0], [5.0, 2.0], [11.0, 1.0], [13.0, 3.0], [-1.0, 2.0]])
    assert in_rings(points, starts, ends, owner, 2).tolist() == [True, False, True, False, False]
    # Capsules: the rectangle's sides, and discs at the ends.
    starts, ends = np.array([[0.0, 0.0]]), np.array([[10.0, 0.0]])
    points = np.array([[5.0, 0.99], [5.0, 1.01], [-0.7, 0.7], [-0.8, 0.7], [10.6, -0.7], [10.0, 0.0]])
    assert near_segments(points, starts, ends, 1.0).tolist() == [True, False, True, False, True, True]


def test_lanes_and_crossings_are_road_walkways_and_the_kerb_s_far_side_are_not():
    walkways = Walkways(CORNER)
    m = WALKWAY_MARGIN_M
    cases = {
        (20.0, 0.0): True,  # the street's driving lane
        (20.0, -1.4): True,  # its edge, 1.45 m from the sidewalk
        (20.0, -2.85): False,  # the parking lane: not a lane the ego drives
        (20.0, -5.35): False,  # the sidewalk
        (20.0, -9.0): False,  # beyond the kerb
        (20.0, -1.55): True,  # its edge beside the parking lane
        (53.0, -3.0): False,  # the corner's walking area, off the turning lane
        (54.5, -2.0): False,  # the walking area where the turning lane's strip overlaps it
        (55.0 + 0.5 * m, -3.0): False,  # on the turning lane, within the margin of the walking area
        (56.6, -5.0): True,  # on the turning lane, beyond the margin
        (55.3, -1.0): False,  # on the turning lane, within the margin of the walking area's corner (diagonally)
        (52.0, 0.0): True,  # the crossing over the street
        (52.0, -1.3 + m + 0.05): True,  # the crossing, just beyond the walking area's margin
        (52.0, -1.2): False,  # the crossing's kerb band, within the walking area's margin: the walkway wins
    }
    got = walkways.on_road(np.array(list(cases)))
    assert got.tolist() == list(cases.values())
    assert walkways.on_road(np.zeros((0, 2))).shape == (0,)


def _urban(seed: int, steps: int):
    import libsumo

    import pipeline.envs  # noqa: F401  (registers the envs)
    from pipeline.envs.driver import ReferenceAgent

    env = gym.make("roadsynth/Urban-v0", time_limit_s=30.0)
    try:
        obs, _ = env.reset(seed=seed)
        agent = ReferenceAgent(env)
        agent.reset(obs)
        for step in range(steps):
            obs, _, terminated, truncated, _ = env.step(agent.act(obs))
            assert not (terminated or truncated)
            ids = sorted(libsumo.person.getIDList())
            yield step, env.unwrapped, obs, ids, np.array([libsumo.person.getPosition(p) for p in ids])
    finally:
        env.close()


def test_the_map_agrees_with_sumo_s_lane_of_every_person_in_the_city():
    """SUMO knows which lane each of the ~800 people of urban seed 1 is on; the map test, from their places alone,
    must say the same: a crossing is the road, a sidewalk, a walking area or a stop beside them is not. The kerb's
    band of a crossing (its first and last ``WALKWAY_MARGIN_M`` along it) counts as the walkway by design: SUMO's
    people waiting on a walking area stand up to 0.7 m inside the crossing there; those on the crossing's lane in the
    band are left out of the comparison, and counted."""
    import libsumo

    kinds, compared, in_band = set(), 0, 0
    for step, inner, _obs, ids, xy in _urban(seed=1, steps=100):
        if step % 3:
            continue
        lanes = [libsumo.person.getLaneID(p) or libsumo.person.getRoadID(p) for p in ids]
        band = np.array([is_crossing(lane) and not (WALKWAY_MARGIN_M <= libsumo.person.getLanePosition(p)
                                                     <= libsumo.lane.getLength(lane) - WALKWAY_MARGIN_M)
                         for p, lane in zip(ids, lanes, strict=True)])
        truth = np.array([is_crossing(lane) for lane in lanes])
        kinds |= {"crossing" if is_crossing(lane) else "walkingarea" if lane.startswith(":") else "edge"
                  for lane, b in zip(lanes, band, strict=True) if not b}
        got = inner.on_road(xy)
        wrong = [(p, lane, tuple(q)) for p, lane, q, g, t, b in zip(ids, lanes, xy, got, truth, band, strict=True)
                 if g != t and not b]
        assert not wrong, wrong[:5]
        compared += int((~band).sum())
        in_band += int(band.sum())
    assert kinds == {"crossing", "walkingarea", "edge"}  # every kind was asked about
    assert compared > 25_000 and in_band < 0.01 * compared


@pytest.mark.slow
def test_people_waiting_on_a_corner_beside_the_turn_are_not_in_the_perceived_path():
    """Urban seed 1's ego waits at a red light while people wait on the corner beside the lane it will turn into,
    within the path's corridor: from their places alone (as perception estimates them, here exact), without the map
    test the path row holds one of them nearly all the time where the ground truth holds nobody; with it, never,
    and where both hold someone they hold the same place."""
    steps, blind_false, map_false, both = 0, 0, 0, 0
    for _step, inner, obs, _ids, xy in _urban(seed=1, steps=100):
        half = 0.5 * inner.ego_width_m()
        blind = path_row(inner.path_xy(), xy, np.zeros_like(xy), 0.0, half)
        mapped = path_row(inner.path_xy(), xy, np.zeros_like(xy), 0.0, half, on_road=inner.on_road(xy))
        truth = obs["path"]
        steps += 1
        blind_false += bool(blind[0] and not truth[0])
        map_false += bool(mapped[0] and not truth[0])
        if mapped[0] and truth[0]:
            both += 1
            assert mapped[1:] == pytest.approx(truth[1:], abs=1e-3)
    assert steps == 100
    assert blind_false > 80
    assert map_false == 0
