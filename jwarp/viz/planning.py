"""Planning runs in rerun: the world, the robot's configurations and end-effector traces
per iteration (``jwarp plan --rerun``; timelines ``iteration`` and the caller's)."""

from __future__ import annotations

from typing import TYPE_CHECKING, cast

import numpy as np

from jwarp.viz.recording import Recording
from jwarp.viz.robot import log_robot, object_meshes, world_spheres

if TYPE_CHECKING:
    from jwarp.model import RobotModel
    from jwarp.world.sdf import World


class PlanRecording(Recording):
    """The recording of a planning run (``jwarp plan --rerun``): the world (exact objects
    as meshes, occupied voxels as boxes) once, then configurations and end-effector traces
    per iteration. ``model`` the robot, ``world`` a :class:`jwarp.world.World` or None."""

    def __init__(self, path: str, model: RobotModel, world: World, option: str = "path"):
        super().__init__(path, "jwarp-planning", option=option)
        self.model = model
        if world is not None:
            try:
                self._log_world(world)
            except BaseException:
                self.abort()
                raise

    def _log_world(self, world: World) -> None:
        for oid, v, f in object_meshes(world):   # exact objects as meshes
            self.rec.log(f"world/objects/{oid}", self.rr.Mesh3D(
                vertex_positions=v, triangle_indices=f,
                vertex_colors=[(90, 90, 90, 160)] * len(v)), static=True)
        if not world.has_grid:
            return
        # has_grid: the SDF, its limits and voxel size are set
        sdf, limits = cast(np.ndarray, world.sdf), cast(np.ndarray, world.limits)
        h = cast(float, world.voxel_size)
        occ = world.occupancy if world.occupancy is not None else sdf < 0
        idx = np.argwhere(occ)
        pts = np.zeros((len(idx), 3))
        pts[:, :world.dim] = limits[:, 0] + h * idx
        half = np.full((len(idx), 3), 0.5 * h)
        if world.dim == 2:
            half[:, 2] = 0.005
        self.rec.log("world/occupied", self.rr.Boxes3D(centers=pts, half_sizes=half,
                                                       colors=[(90, 90, 90, 160)] * len(pts)),
                     static=True)

    def log_configs(self, timeline: str, step: int, q: np.ndarray, name: str = "robot") -> None:
        """Spheres (and skeleton of the first configuration) of q (K, n_dof) at one step."""
        from jwarp.core.device import host_frames

        self.rec.set_time(timeline, sequence=step)
        frames = host_frames(self.model, q)  # host FK: any --device, no Warp CPU backend needed
        log_robot(self.rec, self.model, frames[0], path=name, spheres=False)
        cs, rs = zip(*(world_spheres(self.model, f) for f in frames))
        self.rec.log(f"{name}/spheres", self.rr.Points3D(np.concatenate(cs), radii=np.concatenate(rs),
                                                         colors=[(80, 140, 220, 60)]))

    def log_traces(self, step: int, paths: np.ndarray) -> None:
        """End-effector (last frame) trace of every path (P, W, n_dof) at one iteration."""
        from jwarp.core.device import host_frames

        P, W, n = paths.shape
        fi = next(iter(self.model.end_effectors.values()), self.model.n_frames - 1)
        frames = host_frames(self.model, paths.reshape(-1, n))
        tcp = frames[:, fi, :3, 3].reshape(P, W, 3)
        self.rec.set_time("iteration", sequence=step)
        self.rec.log("paths/end_effector", self.rr.LineStrips3D(list(tcp), radii=0.004))
