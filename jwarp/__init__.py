"""jwarp: NVIDIA Warp kernels for accurate and fast robot motion.

The facade: kinematics (:func:`fk`, :func:`fk_elastic`, :func:`jacobian`,
:func:`jacobian_dh`), robots (:func:`robot`, :func:`robots`, :class:`RobotModel`), worlds
(:class:`World`), and the solvers (:func:`plan`, :func:`ik`, :func:`calibrate`,
:class:`Planner`, :class:`IKSolver`). The solvers and worlds are imported on first use, so
``import jwarp`` stays light. The layers beneath are listed in README.md ("Architecture").
"""

from typing import Any

from jwarp.kinematics.equilibrium import elastic_step, fk_elastic, gravity_torques
from jwarp.kinematics.fk import fk
from jwarp.kinematics.jacobians import jacobian, jacobian_dh
from jwarp.kinematics.launch import ElasticFK, ElasticStep
from jwarp.model import RobotModel, RobotModelError
from jwarp.registry import hookimpl, measurements, register_plugin, robot, robots

__version__ = "0.1.0"

#: facade names imported on first use: name -> module
LAZY = {
    "World": "jwarp.world.sdf",
    "plan": "jwarp.solvers.planner",
    "Planner": "jwarp.solvers.planner",
    "ik": "jwarp.solvers.ik",
    "IKSolver": "jwarp.solvers.ik",
    "calibrate": "jwarp.solvers.calibration.map",
}

__all__ = [
    "ElasticFK", "ElasticStep", "RobotModel", "RobotModelError", "elastic_step", "fk",
    "fk_elastic", "gravity_torques", "hookimpl", "jacobian", "jacobian_dh", "measurements",
    "register_plugin", "robot", "robots", *LAZY,
]


def __getattr__(name: str) -> Any:
    if name in LAZY:
        import importlib

        value = getattr(importlib.import_module(LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'jwarp' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(LAZY))
