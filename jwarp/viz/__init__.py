"""rerun (https://rerun.io) recordings: robots (frames, skeleton, collision bodies),
calibration samples, planning runs, training curves and spectra.

``rerun`` is imported on first use, so these modules import on machines without
rerun-sdk. Modules: :mod:`~jwarp.viz.robot` (robots, worlds, calibration samples),
:mod:`~jwarp.viz.recording` (a recording renamed into place at the end),
:mod:`~jwarp.viz.planning`, :mod:`~jwarp.viz.curves`, :mod:`~jwarp.viz.spectra`."""

from jwarp.viz.curves import TrainingCurves
from jwarp.viz.planning import PlanRecording
from jwarp.viz.recording import (
                             Recording,
                             atomic_recording,
                             open_recording,
                             rerun_module,
)
from jwarp.viz.robot import (
                             SAMPLE_TIMELINE,
                             TIMELINE,
                             log_robot,
                             object_meshes,
                             save_calibration_rrd,
                             save_robot_rrd,
                             world_capsules,
                             world_spheres,
)
from jwarp.viz.spectra import SpectraRecording

__all__ = [
    "PlanRecording", "Recording", "SpectraRecording", "TrainingCurves", "log_robot",
    "object_meshes", "open_recording", "save_calibration_rrd", "save_robot_rrd",
    "world_capsules", "world_spheres",
]
