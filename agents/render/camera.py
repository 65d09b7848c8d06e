"""The camera: pybullet's view and projection, and a camera placed so the airspace fits."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from marl_vertiport.sim.core import VertiportSim
from marl_vertiport.sim.physics import CAMERA_FAR_M, CAMERA_FOV_DEG, CAMERA_NEAR_M


DEFAULT_YAW_DEG, DEFAULT_PITCH_DEG = 0.0, -65.0  # +x to the right, +y away from the viewer


# ====================================================================== camera
def _gl_matrix(values: Any) -> np.ndarray:
    """pybullet's 16 floats (column-major, OpenGL) as a row-major 4x4 array."""
    return np.asarray(values, dtype=float).reshape(4, 4).T


@dataclass(frozen=True)
class Camera:
    """A TinyRenderer camera and the projection of world points to its pixels."""

    width: int
    height: int
    target_m: tuple[float, float, float]
    distance_m: float
    yaw_deg: float
    pitch_deg: float

    @property
    def matrix(self) -> np.ndarray:
        """Projection @ view, 4x4, as ``computeViewMatrixFromYawPitchRoll`` and
        ``computeProjectionMatrixFOV`` build them (they are pure functions of their inputs)."""
        import pybullet as p

        view = p.computeViewMatrixFromYawPitchRoll(list(self.target_m), self.distance_m,
                                                   self.yaw_deg, self.pitch_deg, 0, 2)
        proj = p.computeProjectionMatrixFOV(CAMERA_FOV_DEG, self.width / self.height,
                                            CAMERA_NEAR_M, CAMERA_FAR_M)
        return _gl_matrix(proj) @ _gl_matrix(view)

    def project(self, points_m: np.ndarray, matrix: np.ndarray | None = None) -> np.ndarray:
        """Pixel coordinates ``(N, 2)`` (x right, y down) of world points ``(N, 3)``; NaN for
        points behind the camera."""
        pts = np.atleast_2d(np.asarray(points_m, dtype=float))
        m = self.matrix if matrix is None else matrix
        clip = np.concatenate([pts, np.ones((len(pts), 1))], axis=1) @ m.T
        w = clip[:, 3]
        with np.errstate(divide="ignore", invalid="ignore"):
            ndc = clip[:, :2] / w[:, None]
        ndc[w <= 1e-9] = np.nan
        return np.stack([(ndc[:, 0] + 1.0) * 0.5 * self.width,
                         (1.0 - ndc[:, 1]) * 0.5 * self.height], axis=1)

    def image(self, sim: VertiportSim) -> np.ndarray:
        """The raw RGB frame, ``(height, width, 3)`` uint8."""
        from marl_vertiport.render import draw_scenery

        draw_scenery(sim)
        return sim.physics.camera_image(self.width, self.height, self.target_m, self.distance_m,
                                        self.yaw_deg, self.pitch_deg)


def fit_camera(sim: VertiportSim, width: int, height: int, yaw_deg: float = DEFAULT_YAW_DEG,
               pitch_deg: float = DEFAULT_PITCH_DEG, margin: float = 0.04) -> Camera:
    """The closest camera at ``yaw``/``pitch`` whose view holds the whole airspace: its ground
    ring and the ring at the transit altitude, inside ``margin`` of each edge. The target is
    moved so the airspace sits in the middle of the picture."""
    lay, fl = sim.layout, sim.cfg.flight
    r = lay.airspace_radius_m * 1.03
    ang = np.linspace(0.0, 2.0 * np.pi, 72, endpoint=False)
    ring = np.stack([r * np.cos(ang), r * np.sin(ang), np.zeros_like(ang)], axis=1)
    top = ring.copy()
    top[:, 2] = fl.transit_altitude_m
    pts = np.concatenate([ring, top])
    target = (0.0, 0.0, 0.0)

    def fits(dist: float, tgt: tuple[float, float, float]) -> bool:
        px = Camera(width, height, tgt, dist, yaw_deg, pitch_deg).project(pts)
        if np.isnan(px).any():
            return False
        return bool(px[:, 0].min() >= margin * width and px[:, 0].max() <= (1 - margin) * width
                    and px[:, 1].min() >= margin * height
                    and px[:, 1].max() <= (1 - margin) * height)

    for _ in range(3):  # fit the distance, then re-centre the picture on the airspace
        lo, hi = 1.0, 2000.0
        for _ in range(40):
            mid = math.sqrt(lo * hi)
            lo, hi = (lo, mid) if fits(mid, target) else (mid, hi)
        cam = Camera(width, height, target, hi, yaw_deg, pitch_deg)
        px = cam.project(pts)
        centre = np.array([(px[:, 0].min() + px[:, 0].max()) / 2, (px[:, 1].min() + px[:, 1].max()) / 2])
        off = centre - np.array([width / 2, height / 2])
        if np.abs(off).max() < 1.0:
            break
        # Move the target on the ground plane by the offset, measured in metres near the centre.
        o = cam.project(np.array([[target[0], target[1], 0.0], [target[0] + 1, target[1], 0.0],
                                  [target[0], target[1] + 1, 0.0]]))
        jac = np.stack([o[1] - o[0], o[2] - o[0]], axis=1)  # pixels per metre of x and y
        try:
            dxy = np.linalg.solve(jac, off)
        except np.linalg.LinAlgError:
            break
        target = (target[0] + float(dxy[0]), target[1] + float(dxy[1]), 0.0)
    return Camera(width, height, target, hi, yaw_deg, pitch_deg)

