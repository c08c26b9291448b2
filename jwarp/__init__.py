"""jwarp: NVIDIA Warp kernels for accurate and fast robot motion.

The facade: kinematics (:func:`fk`, :func:`fk_elastic`, :func:`jacobian`,
:func:`jacobian_dh`), robots (:func:`robot`, :func:`robots`, :class:`RobotModel`), worlds
(:class:`World`), the solvers (:func:`plan`, :func:`ik`, :func:`calibrate`,
:class:`Planner`, :class:`IKSolver`) and :func:`warmup` (compile every kernel ahead of
time). Every name, and every subpackage (``jwarp.kinematics``, ``jwarp.solvers``, ...), is
imported on first use, so ``import jwarp`` costs no Warp, torch or scipy import (``jwarp
--help`` starts in a fraction of a second). The layers beneath are listed in README.md
("Architecture").
"""

from typing import Any

__version__ = "0.2.0"

#: facade names imported on first use: name -> module
LAZY = {
    "ElasticFK": "jwarp.kinematics.launch",
    "ElasticStep": "jwarp.kinematics.launch",
    "RobotModel": "jwarp.model",
    "RobotModelError": "jwarp.model",
    "elastic_step": "jwarp.kinematics.equilibrium",
    "fk": "jwarp.kinematics.fk",
    "fk_elastic": "jwarp.kinematics.equilibrium",
    "gravity_torques": "jwarp.kinematics.equilibrium",
    "hookimpl": "jwarp.plugins.registry",
    "jacobian": "jwarp.kinematics.jacobians",
    "jacobian_dh": "jwarp.kinematics.jacobians",
    "measurements": "jwarp.plugins.registry",
    "register_plugin": "jwarp.plugins.registry",
    "robot": "jwarp.plugins.registry",
    "robots": "jwarp.plugins.registry",
    "World": "jwarp.world.sdf",
    "plan": "jwarp.solvers.planning",
    "Planner": "jwarp.solvers.planning",
    "ik": "jwarp.solvers.ik",
    "IKSolver": "jwarp.solvers.ik",
    "calibrate": "jwarp.calibration.estimate.map",
    "warmup": "jwarp.cli.warmup",
}

#: subpackages and modules reachable as attributes (``import jwarp; jwarp.kinematics.fk``)
SUBMODULES = frozenset({
    "calibration", "cli", "core", "importers", "kernels", "kinematics", "learn", "model",
    "plugins", "solvers", "utils", "viz", "world",
})

#: the entry points (``__all__``, docs/api.md's first section); the other names of
#: :data:`LAZY` stay reachable here and are documented under their facade
#: (``jwarp.kinematics``, ``jwarp.model``): no name is listed by two facades
ENTRY_POINTS = ("IKSolver", "Planner", "RobotModel", "World", "calibrate", "fk", "hookimpl", "ik",
                "jacobian", "measurements", "plan", "register_plugin", "robot", "robots",
                "warmup")
__all__ = sorted(ENTRY_POINTS)


def __getattr__(name: str) -> Any:
    import importlib

    if name in LAZY:
        value = getattr(importlib.import_module(LAZY[name]), name)
        globals()[name] = value
        return value
    if name in SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")  # sets the attribute itself
    raise AttributeError(f"module 'jwarp' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(LAZY) | SUBMODULES)
