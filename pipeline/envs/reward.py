"""The reward: a weighted sum of documented terms (RewardWeights), returned with each term for ``info``."""

from __future__ import annotations

from pipeline.envs.options import RewardWeights


def reward_terms(weights: RewardWeights, *, progress_m: float, target_speed_mps: float, dt_s: float, jerk_mps3: float,
                 lateral_offset_m: float, half_lane_width_m: float, collided: bool, off_road: bool) -> dict[str, float]:
    """Each weighted term (see RewardWeights); the reward is their sum."""
    progress = min(max(progress_m, 0.0) / (target_speed_mps * dt_s), 1.0)
    lane = min((lateral_offset_m / max(half_lane_width_m, 1e-6)) ** 2, 1.0)
    return {
        "progress": weights.progress * progress,
        "comfort": -weights.comfort * min((jerk_mps3 / weights.jerk_ref_mps3) ** 2, 1.0),
        "lane_keeping": -weights.lane_keeping * lane,
        "collision": -weights.collision * float(collided),
        "off_road": -weights.off_road * float(off_road),
    }
