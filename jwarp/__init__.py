"""jwarp: NVIDIA Warp kernels for accurate and fast robot motion."""

from jwarp.kinematics import (
    ElasticFK,
    ElasticStep,
    elastic_step,
    fk,
    fk_elastic,
    gravity_torques,
    jacobian,
    jacobian_dh,
)
from jwarp.model import RobotModel, RobotModelError
from jwarp.registry import hookimpl, measurements, register_plugin, robot, robots

__version__ = "0.1.0"
__all__ = [
    "ElasticFK", "ElasticStep", "RobotModel", "RobotModelError", "elastic_step", "fk",
    "fk_elastic", "gravity_torques", "hookimpl", "jacobian", "jacobian_dh", "measurements",
    "register_plugin", "robot", "robots",
]
