"""The cheap ``render_mode="rgb_array"`` picture: a north-up top view around the ego, drawn from SUMO's live state.

Lanes are grey bands of their width; vehicles and persons are their boxes (the ego red, others blue, persons
yellow). World x (east) is to the right and y (north) up; the ego's box centre is the image centre.
"""

from __future__ import annotations

import cv2
import numpy as np

from pipeline.core.geometry import sumo_front_to_center

SIZE_PX = 400
M_PER_PX = 0.25  # 100 m x 100 m
_ROAD, _BACKGROUND, _EGO, _OTHER, _PERSON = (90, 90, 95), (60, 100, 50), (220, 40, 40), (60, 110, 230), (240, 210, 60)


class TopView:
    """Draws the top view; the lane shapes are read from SUMO once per simulation (:meth:`start`)."""

    def start(self, sumo) -> None:
        self.lanes = [(np.asarray(sumo.lane.getShape(lane), np.float64), sumo.lane.getWidth(lane))
                      for lane in sorted(sumo.lane.getIDList()) if not lane.startswith(":")]

    def draw(self, sumo, ego_id: str) -> np.ndarray:
        """(SIZE_PX, SIZE_PX, 3) uint8 RGB around ``ego_id``."""
        image = np.empty((SIZE_PX, SIZE_PX, 3), np.uint8)
        image[:] = _BACKGROUND
        centre = self._box(sumo.vehicle, ego_id)[0]
        reach = SIZE_PX * M_PER_PX
        for shape, width in self.lanes:
            near = np.abs(shape - centre).max(axis=1) < reach
            if near.any():
                cv2.polylines(image, [self._px(shape, centre)], False, _ROAD,
                              max(1, round(width / M_PER_PX)), cv2.LINE_AA)
        for domain, colour in ((sumo.vehicle, _OTHER), (sumo.person, _PERSON)):
            for actor in domain.getIDList():
                xy, corners = self._box(domain, actor)
                if np.abs(xy - centre).max() < reach:
                    cv2.fillPoly(image, [self._px(corners, centre)], _EGO if actor == ego_id else colour, cv2.LINE_AA)
        return image

    @staticmethod
    def _box(domain, actor: str) -> tuple[np.ndarray, np.ndarray]:
        """Box centre (2,) and corners (4, 2) in world metres."""
        front = np.array([domain.getPosition(actor)])
        length, width = domain.getLength(actor), domain.getWidth(actor)
        centre, yaw = sumo_front_to_center(front, np.array([domain.getAngle(actor)]), np.array([length]))
        c, s = np.cos(yaw[0]), np.sin(yaw[0])
        half = np.array([[1, 1], [1, -1], [-1, -1], [-1, 1]]) * [0.5 * length, 0.5 * width]
        corners = centre[0] + half @ np.array([[c, s], [-s, c]])
        return centre[0], corners

    @staticmethod
    def _px(points_m: np.ndarray, centre_m: np.ndarray) -> np.ndarray:
        d = (points_m - centre_m) / M_PER_PX
        return np.round(np.column_stack([SIZE_PX / 2 + d[:, 0], SIZE_PX / 2 - d[:, 1]])).astype(np.int32)
