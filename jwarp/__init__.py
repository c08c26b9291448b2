"""jwarp: NVIDIA Warp kernels for accurate and fast robot motion."""

from jwarp.model import RobotModel, RobotModelError
from jwarp.registry import hookimpl, register_plugin, robot, robots

__version__ = "0.1.0"
__all__ = ["RobotModel", "RobotModelError", "hookimpl", "register_plugin", "robot", "robots"]
