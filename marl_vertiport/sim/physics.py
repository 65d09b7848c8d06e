"""Rigid-body flight physics of the vehicles inside the vertiport airspace, in pybullet.

One DIRECT client per env (``physicsClientId`` on every call). Each vehicle is a box-shaped
rigid body. The flight controller is speed-commanded: at the start of every decision step the
commanded velocity is set on the bodies that move; gravity is taken as cancelled by thrust.
Gusts are external forces held over the step. One ``stepSimulation`` call advances the
``flight_seconds_per_step`` of a step in ``ceil(flight_seconds_per_step * physics_rate_hz)``
engine substeps, so the engine updates every body at ``>= physics_rate_hz``.

Cost in proportion: a vehicle that is parked or hovering is a static body (mass 0, nothing to
integrate); a vehicle outside the airspace has its collisions switched off and is moved by the
core's kinematic model, not by the engine; when no body moves the engine is not stepped.
"""

from __future__ import annotations

import math
import os
import time
import warnings

import numpy as np


def _import_pybullet_quietly():
    """pybullet prints its build time from C on import (on stderr in the 3.2.7 wheel); keep it
    out of the user's output: both standard streams point to ``os.devnull`` while it loads.
    An import error is still raised as an exception."""
    import sys

    sys.stdout.flush()
    sys.stderr.flush()
    try:
        saved = [os.dup(1), os.dup(2)]
    except OSError:  # no usable standard file descriptors
        import pybullet

        return pybullet
    try:
        with open(os.devnull, "w") as devnull:
            os.dup2(devnull.fileno(), 1)
            os.dup2(devnull.fileno(), 2)
            import pybullet

            _flush_c_stdio()  # the banner may sit in C's stdio buffer until flushed
    finally:
        for fd, copy in zip((1, 2), saved):
            os.dup2(copy, fd)
            os.close(copy)
    return pybullet


def _flush_c_stdio() -> None:
    try:
        import ctypes

        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):  # no C library handle on this platform
        pass


p = _import_pybullet_quietly()

#: Body colours (RGBA) used for rendering, cycled over the fleet.
VEHICLE_COLOURS = (
    (0.90, 0.30, 0.20, 1), (0.20, 0.50, 0.90, 1), (0.95, 0.75, 0.10, 1), (0.55, 0.30, 0.80, 1),
    (0.10, 0.70, 0.60, 1), (0.95, 0.45, 0.70, 1), (0.45, 0.45, 0.45, 1), (0.60, 0.80, 0.20, 1),
)

#: Projection of ``camera_image``: field of view (degrees), near and far clip planes (m).
CAMERA_FOV_DEG, CAMERA_NEAR_M, CAMERA_FAR_M = 50.0, 0.5, 400.0

#: Orientation of a level vehicle (the identity quaternion).
_UPRIGHT = (0.0, 0.0, 0.0, 1.0)
_PARKED_FAR_Z_M = -50.0  # where bodies of vehicles outside the airspace wait (below ground)


class FlightPhysics:
    """The pybullet world of one env.

    Args:
        n_vehicles: number of vehicle bodies.
        flight_seconds_per_step: physical seconds simulated per :meth:`step`.
        physics_rate_hz: minimum engine update rate.
        vehicle_size_m, vehicle_height_m, vehicle_mass_kg: body geometry and mass.
        gui: open pybullet's GUI instead of a headless DIRECT client.
    """

    def __init__(
        self,
        n_vehicles: int,
        flight_seconds_per_step: float,
        physics_rate_hz: float,
        vehicle_size_m: float,
        vehicle_height_m: float,
        vehicle_mass_kg: float,
        gui: bool = False,
    ) -> None:
        self._args = (n_vehicles, flight_seconds_per_step, physics_rate_hz, vehicle_size_m,
                      vehicle_height_m, vehicle_mass_kg, gui)
        self.dt_s = float(flight_seconds_per_step)
        self.substeps = max(1, math.ceil(self.dt_s * physics_rate_hz - 1e-9))
        self.mass_kg = float(vehicle_mass_kg)
        s, h = vehicle_size_m, vehicle_height_m
        self._inertia = [self.mass_kg / 12 * (s * s + h * h)] * 2 + [self.mass_kg / 12 * 2 * s * s]
        self.gui = gui
        self.client = p.connect(p.GUI if gui else p.DIRECT)
        if self.client < 0:
            raise RuntimeError("pybullet could not open a physics client")
        cid = self.client
        p.setGravity(0.0, 0.0, 0.0, physicsClientId=cid)
        p.setPhysicsEngineParameter(
            fixedTimeStep=self.dt_s, numSubSteps=self.substeps, physicsClientId=cid
        )
        half = [vehicle_size_m / 2.0, vehicle_size_m / 2.0, vehicle_height_m / 2.0]
        shape = p.createCollisionShape(p.GEOM_BOX, halfExtents=half, physicsClientId=cid)
        self.bodies: list[int] = []
        for i in range(n_vehicles):
            visual = p.createVisualShape(
                p.GEOM_BOX, halfExtents=half, rgbaColor=VEHICLE_COLOURS[i % len(VEHICLE_COLOURS)],
                physicsClientId=cid,
            )
            body = p.createMultiBody(
                baseMass=0.0, baseCollisionShapeIndex=shape, baseVisualShapeIndex=visual,
                basePosition=[0.0, 0.0, _PARKED_FAR_Z_M - 5.0 * i], physicsClientId=cid,
            )
            p.changeDynamics(body, -1, linearDamping=0.0, angularDamping=0.0,
                             restitution=0.2, physicsClientId=cid)
            self.bodies.append(body)
        self._body_to_vehicle = {b: i for i, b in enumerate(self.bodies)}
        self._dynamic = np.zeros(n_vehicles, dtype=bool)
        self._colliding = np.ones(n_vehicles, dtype=bool)
        self._scenery_built = False
        #: Wall-clock seconds spent in the engine's calls since the benchmark last zeroed it:
        #: stepping (with its velocity and force commands and position reads), contact queries,
        #: body mode changes and the position reads of snapshots.
        self.engine_seconds = 0.0
        #: Number of ``step`` calls that advanced the engine (steps in which bodies moved).
        self.engine_steps = 0

    # ------------------------------------------------------------------ copies
    def __getstate__(self) -> dict:
        """A pybullet client cannot be shared or pickled: a copy (pickle, deepcopy, supersuit's
        vector envs) records the construction arguments and each body's mode and pose, and opens
        its own headless client when it is restored."""
        return {"args": self._args, "bodies": self.body_states(), "engine_seconds": self.engine_seconds}

    def __setstate__(self, state: dict) -> None:
        args = list(state["args"])
        args[-1] = False  # a copy never opens a second GUI window
        self.__init__(*args)
        self.set_body_states(state["bodies"])
        self.engine_seconds = state["engine_seconds"]

    def body_states(self) -> list[tuple[str, tuple[float, float, float]]]:
        """Each body's mode (``"dynamic"``, ``"static"`` or ``"absent"``) and position. Every
        body is level between steps (:meth:`step` rights a body a contact tipped), so the
        position is its whole pose."""
        cid = self.client
        modes = ["dynamic" if d else "static" if c else "absent"
                 for d, c in zip(self._dynamic, self._colliding)]
        start = time.perf_counter()
        states = [(m, p.getBasePositionAndOrientation(b, physicsClientId=cid)[0])
                  for m, b in zip(modes, self.bodies)]
        self.engine_seconds += time.perf_counter() - start
        return states

    def set_body_states(self, states: list[tuple[str, tuple[float, float, float]]]) -> None:
        """Put every body in the mode and at the position of :meth:`body_states`, then drop the
        engine's cached contacts, so that a restored world steps exactly as the one it was
        taken from."""
        if len(states) != len(self.bodies):
            raise ValueError(f"{len(states)} body states for {len(self.bodies)} vehicle bodies")
        for i, (mode, pos) in enumerate(states):
            if mode == "absent":
                self.make_absent(i)
            elif mode == "dynamic":
                self.make_dynamic(i, np.asarray(pos, dtype=float))
            else:
                self.make_static(i, np.asarray(pos, dtype=float))
        self.forget_contacts()

    def forget_contacts(self) -> None:
        """Drop the engine's cached contacts between bodies. Contact manifolds persist in its
        pair cache and warm-start its solver, so a world put back into an earlier state (a
        restore, a new day) would otherwise step with traces of the contacts it had; taking
        each body out of collision and back removes them."""
        start = time.perf_counter()
        cid = self.client
        for i, b in enumerate(self.bodies):
            if self._colliding[i]:
                p.setCollisionFilterGroupMask(b, -1, 0, 0, physicsClientId=cid)
                p.setCollisionFilterGroupMask(b, -1, 1, 1, physicsClientId=cid)
        self.engine_seconds += time.perf_counter() - start

    # ------------------------------------------------------------------ body modes
    def make_static(self, i: int, pos: np.ndarray) -> None:
        """Fix vehicle ``i`` at ``pos`` (parked, hovering, or grounded): no integration cost."""
        start = time.perf_counter()
        cid, b = self.client, self.bodies[i]
        if self._dynamic[i]:
            p.changeDynamics(b, -1, mass=0.0, physicsClientId=cid)
            self._dynamic[i] = False
        if not self._colliding[i]:
            p.setCollisionFilterGroupMask(b, -1, 1, 1, physicsClientId=cid)
            self._colliding[i] = True
        p.resetBasePositionAndOrientation(b, pos.tolist(), _UPRIGHT, physicsClientId=cid)
        self.engine_seconds += time.perf_counter() - start

    def make_dynamic(self, i: int, pos: np.ndarray | None = None) -> None:
        """Let the engine move vehicle ``i`` (in flight inside the airspace)."""
        start = time.perf_counter()
        cid, b = self.client, self.bodies[i]
        if not self._colliding[i]:
            p.setCollisionFilterGroupMask(b, -1, 1, 1, physicsClientId=cid)
            self._colliding[i] = True
        if pos is not None:
            p.resetBasePositionAndOrientation(b, pos.tolist(), _UPRIGHT, physicsClientId=cid)
        if not self._dynamic[i]:
            p.changeDynamics(b, -1, mass=self.mass_kg, localInertiaDiagonal=self._inertia,
                             physicsClientId=cid)
            self._dynamic[i] = True
        self.engine_seconds += time.perf_counter() - start

    def make_absent(self, i: int) -> None:
        """Take vehicle ``i`` out of the engine (outside the airspace): no contacts, no cost."""
        start = time.perf_counter()
        cid, b = self.client, self.bodies[i]
        if self._dynamic[i]:
            p.changeDynamics(b, -1, mass=0.0, physicsClientId=cid)
            self._dynamic[i] = False
        if self._colliding[i]:
            p.setCollisionFilterGroupMask(b, -1, 0, 0, physicsClientId=cid)
            self._colliding[i] = False
        p.resetBasePositionAndOrientation(
            b, [0.0, 0.0, _PARKED_FAR_Z_M - 5.0 * i], _UPRIGHT, physicsClientId=cid
        )
        self.engine_seconds += time.perf_counter() - start

    @property
    def any_dynamic(self) -> bool:
        return bool(self._dynamic.any())

    # ------------------------------------------------------------------ stepping
    def step(self, vehicles: list[int], velocity_mps: list[tuple[float, float, float]],
             keep: list[float] | None = None) -> list[tuple[float, float, float]]:
        """Advance one decision step.

        A gust is a constant force held over the step. With the engine's semi-implicit Euler
        over ``n`` substeps, a constant acceleration ``a`` adds ``a dt^2 (n + 1) / (2 n)`` to
        the displacement of a step of length ``dt``; the force is sized so that the step's
        displacement is exactly ``keep`` times the commanded one.

        Args:
            vehicles: the ``M`` vehicles that are dynamic this step.
            velocity_mps: their commanded velocities at the start of the step.
            keep: per vehicle, the fraction of the step's displacement a gust leaves
                (1 no gust, 0 stopped, negative reversed), or ``None`` for no gusts.

        Returns:
            The ``M`` positions at the end of the step, as measured by the engine.
        """
        start = time.perf_counter()
        cid = self.client
        bodies = self.bodies
        zero = (0.0, 0.0, 0.0)
        for i, vel in zip(vehicles, velocity_mps):
            p.resetBaseVelocity(bodies[i], vel, zero, physicsClientId=cid)
        if keep is not None:
            gain = self.mass_kg * 2.0 * self.substeps / ((self.substeps + 1) * self.dt_s)
            for i, vel, f in zip(vehicles, velocity_mps, keep):
                if f != 1.0:
                    b = bodies[i]
                    pos, _ = p.getBasePositionAndOrientation(b, physicsClientId=cid)
                    g = -(1.0 - f) * gain
                    p.applyExternalForce(b, -1, (g * vel[0], g * vel[1], g * vel[2]), pos,
                                         p.WORLD_FRAME, physicsClientId=cid)
        p.stepSimulation(physicsClientId=cid)
        positions = []
        for i in vehicles:
            pos, orn = p.getBasePositionAndOrientation(bodies[i], physicsClientId=cid)
            if orn != _UPRIGHT:
                # A contact tipped the box; a speed-commanded vehicle flies level again at once.
                # (An orientation would also be state that no snapshot restores exactly: the
                # engine keeps a rotation matrix, a snapshot a quaternion.)
                p.resetBasePositionAndOrientation(bodies[i], pos, _UPRIGHT, physicsClientId=cid)
            positions.append(pos)
        self.engine_seconds += time.perf_counter() - start
        self.engine_steps += 1
        return positions

    def contact_pairs(self) -> list[tuple[int, int]]:
        """Vehicle pairs ``(i, j)``, ``i < j``, in contact at the end of the last step."""
        pairs = set()
        lookup = self._body_to_vehicle
        start = time.perf_counter()
        contacts = p.getContactPoints(physicsClientId=self.client)
        self.engine_seconds += time.perf_counter() - start
        for c in contacts:
            a, b = lookup.get(c[1]), lookup.get(c[2])
            if a is not None and b is not None and a != b:
                pairs.add((min(a, b), max(a, b)))
        return sorted(pairs)

    # ------------------------------------------------------------------ rendering
    def build_scenery(self, node_xy_m: np.ndarray, node_type: np.ndarray, node_z_m: np.ndarray,
                      airspace_radius_m: float) -> None:
        """Visual-only bodies (no collision, no cost in stepping): ground, ports, hover spots."""
        if self._scenery_built:
            return
        cid = self.client
        extent = airspace_radius_m * 1.1
        ground = p.createVisualShape(p.GEOM_BOX, halfExtents=[extent, extent, 0.01],
                                     rgbaColor=(0.80, 0.84, 0.80, 1), physicsClientId=cid)
        p.createMultiBody(0.0, -1, ground, basePosition=[0, 0, -0.02], physicsClientId=cid)
        colours = {0: (0.25, 0.25, 0.30, 1), 1: (0.10, 0.65, 0.25, 1), 2: (1.0, 0.85, 0.2, 0.5)}
        for xy, kind, z in zip(node_xy_m, node_type, node_z_m):
            if kind == 2:
                shape = p.createVisualShape(p.GEOM_SPHERE, radius=0.35, rgbaColor=colours[2],
                                            physicsClientId=cid)
                p.createMultiBody(0.0, -1, shape, basePosition=[xy[0], xy[1], float(z) - 0.6],
                                  physicsClientId=cid)
                pole = p.createVisualShape(p.GEOM_CYLINDER, radius=0.06, length=float(z),
                                           rgbaColor=(0.6, 0.6, 0.5, 1), physicsClientId=cid)
                p.createMultiBody(0.0, -1, pole, basePosition=[xy[0], xy[1], float(z) / 2 - 0.6],
                                  physicsClientId=cid)
            else:
                shape = p.createVisualShape(p.GEOM_CYLINDER, radius=1.6, length=0.04,
                                            rgbaColor=colours[int(kind)], physicsClientId=cid)
                p.createMultiBody(0.0, -1, shape, basePosition=[xy[0], xy[1], 0.0],
                                  physicsClientId=cid)
        ring_shape = p.createVisualShape(p.GEOM_CYLINDER, radius=0.15, length=0.05,
                                         rgbaColor=(0.3, 0.3, 0.9, 1), physicsClientId=cid)
        for ang in np.linspace(0, 2 * np.pi, 48, endpoint=False):
            p.createMultiBody(0.0, -1, ring_shape, basePosition=[
                airspace_radius_m * np.cos(ang), airspace_radius_m * np.sin(ang), 0.0],
                physicsClientId=cid)
        self._scenery_built = True

    def camera_image(self, width: int, height: int, target_m: tuple[float, float, float],
                     distance_m: float, yaw_deg: float = 30.0, pitch_deg: float = -55.0) -> np.ndarray:
        """Headless TinyRenderer image, shape ``(height, width, 3)`` uint8."""
        cid = self.client
        view = p.computeViewMatrixFromYawPitchRoll(target_m, distance_m, yaw_deg, pitch_deg, 0, 2,
                                                   physicsClientId=cid)
        proj = p.computeProjectionMatrixFOV(CAMERA_FOV_DEG, width / height, CAMERA_NEAR_M,
                                            CAMERA_FAR_M, physicsClientId=cid)
        _, _, rgba, _, _ = p.getCameraImage(width, height, view, proj,
                                            renderer=p.ER_TINY_RENDERER, physicsClientId=cid)
        return np.asarray(rgba, dtype=np.uint8).reshape(height, width, 4)[:, :, :3].copy()

    def close(self) -> None:
        if self.client is not None and self.client >= 0:
            try:
                p.disconnect(physicsClientId=self.client)
            except p.error:  # already disconnected (e.g. the GUI window was closed)
                pass
            self.client = -1

    def __del__(self) -> None:  # pragma: no cover - best effort at interpreter shutdown
        try:
            self.close()
        except Exception:
            pass


def display_available() -> bool:
    """Whether a GUI window can be opened (an X display is set)."""
    if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"):
        return True
    if os.name == "nt":
        return True
    warnings.warn("render_mode='human' needs a display; no window is opened (no DISPLAY set)",
                  stacklevel=3)
    return False
