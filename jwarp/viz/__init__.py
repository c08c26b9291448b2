"""Streaming robots to rerun (https://rerun.io): frames, skeleton, collision bodies.

The package: :mod:`jwarp.viz.robot`."""

from jwarp.viz.robot import (SAMPLE_TIMELINE, TIMELINE, atomic_recording, log_robot,
                             object_meshes, open_recording, rerun_module, save_calibration_rrd,
                             save_robot_rrd, world_capsules, world_spheres)

__all__ = [
    "SAMPLE_TIMELINE", "TIMELINE", "atomic_recording", "log_robot", "object_meshes",
    "open_recording", "rerun_module", "save_calibration_rrd", "save_robot_rrd",
    "world_capsules", "world_spheres",
]
