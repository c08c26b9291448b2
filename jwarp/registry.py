"""Plugin registry: pluggy hook specifications for robots and measurement functions.

Built-in robots live in :mod:`jwarp.plugins.robots`; external packages register a module
(or object) with ``@jwarp.hookimpl`` functions through the entry-point group ``jwarp``::

    # pyproject.toml of a plugin package
    [project.entry-points.jwarp]
    my_robots = "my_package.robots"

    # my_package/robots.py
    import jwarp
    @jwarp.hookimpl
    def jwarp_robots():
        return {"my_arm": lambda: jwarp.RobotModel.load(PATH)}

A robot factory is a callable returning a :class:`~jwarp.model.RobotModel` (or the model
itself, or a path to a robot JSON file). Two plugins offering one name is an error that
names both plugins.
"""

from __future__ import annotations

import os
from typing import Any, Callable

import pluggy

from jwarp.model import RobotModel

PROJECT = "jwarp"
hookspec = pluggy.HookspecMarker(PROJECT)
hookimpl = pluggy.HookimplMarker(PROJECT)

BUILTIN_ROBOT_MODULES = (
    "jwarp.plugins.robots.justin19",
    "jwarp.plugins.robots.arm7",
    "jwarp.plugins.robots.planar",
    "jwarp.plugins.robots.sphere2d",
    "jwarp.plugins.robots.hand4",
)
BUILTIN_MEASUREMENT_MODULES: tuple[str, ...] = (
    "jwarp.plugins.measurements.cartesian",
    "jwarp.plugins.measurements.image",
    "jwarp.plugins.measurements.contact",
    "jwarp.plugins.measurements.relative",
)


class PluginError(ValueError):
    """Plugins conflict or return something malformed."""


class JwarpSpec:
    """Hook specifications of jwarp."""

    @hookspec
    def jwarp_robots(self) -> dict[str, Callable[[], RobotModel] | RobotModel | str]:
        """Return ``{robot_name: factory}``; a factory returns a RobotModel (called lazily)."""

    @hookspec
    def jwarp_measurements(self) -> dict[str, Any]:
        """Return ``{measurement_name: factory}`` for measurement functions (may be empty)."""


_PM: pluggy.PluginManager | None = None
_ROBOT_CACHE: dict[str, RobotModel] = {}


def plugin_manager() -> pluggy.PluginManager:
    """The process-wide plugin manager (built-ins plus the ``jwarp`` entry points)."""
    global _PM
    if _PM is None:
        import importlib

        pm = pluggy.PluginManager(PROJECT)
        pm.add_hookspecs(JwarpSpec)
        for mod in BUILTIN_ROBOT_MODULES + BUILTIN_MEASUREMENT_MODULES:
            pm.register(importlib.import_module(mod), name=mod)
        if not os.environ.get("JWARP_NO_ENTRY_POINTS"):
            pm.load_setuptools_entrypoints(PROJECT)
        _PM = pm
    return _PM


def register_plugin(plugin: object, name: str | None = None) -> None:
    """Register a plugin object/module at run time (tests, notebooks)."""
    plugin_manager().register(plugin, name=name)
    _ROBOT_CACHE.clear()


def unregister_plugin(plugin: object) -> None:
    plugin_manager().unregister(plugin)
    _ROBOT_CACHE.clear()


def _collect(hook_name: str) -> dict[str, tuple[str, Any]]:
    pm = plugin_manager()
    found: dict[str, tuple[str, Any]] = {}
    for impl in getattr(pm.hook, hook_name).get_hookimpls():
        result = impl.function()
        if result is None:
            continue
        if not isinstance(result, dict):
            raise PluginError(f"plugin '{impl.plugin_name}': {hook_name}() must return a dict, "
                              f"got {type(result).__name__}")
        for key, factory in result.items():
            if key in found:
                raise PluginError(f"{hook_name}: name '{key}' is claimed by two plugins: "
                                  f"'{found[key][0]}' and '{impl.plugin_name}'")
            found[key] = (impl.plugin_name, factory)
    return found


def robots() -> list[str]:
    """Names of all registered robots, sorted."""
    return sorted(_collect("jwarp_robots"))


def robot(name: str | RobotModel) -> RobotModel:
    """The robot registered under ``name`` (a RobotModel passes through; a path to a
    ``.json`` robot file is loaded)."""
    if isinstance(name, RobotModel):
        return name
    if not isinstance(name, (str, os.PathLike)):
        raise TypeError(f"robot: expected a robot name, path or RobotModel, got {type(name).__name__}")
    name = os.fspath(name)
    if name in _ROBOT_CACHE:
        return _ROBOT_CACHE[name]
    table = _collect("jwarp_robots")
    if name not in table:
        if name.endswith(".json") and os.path.exists(name):
            return RobotModel.load(name)
        raise ValueError(f"robot: unknown robot '{name}'; registered: {', '.join(sorted(table))}")
    plugin, factory = table[name]
    if isinstance(factory, RobotModel):
        model = factory
    elif isinstance(factory, (str, os.PathLike)):
        model = RobotModel.load(factory)
    elif callable(factory):
        model = factory()
    else:
        raise PluginError(f"plugin '{plugin}': factory for robot '{name}' is not callable")
    if not isinstance(model, RobotModel):
        raise PluginError(f"plugin '{plugin}': robot '{name}' factory returned "
                          f"{type(model).__name__}, not RobotModel")
    _ROBOT_CACHE[name] = model
    return model


def measurements() -> list[str]:
    """Names of all registered measurement functions, sorted."""
    return sorted(_collect("jwarp_measurements"))


def measurement(name: str) -> Any:
    """The measurement class (factory) registered under ``name``, e.g. ``"cartesian"``;
    call it as ``cls(robot, setup_section)``."""
    if not isinstance(name, str):
        raise TypeError(f"measurement: expected a measurement name, got {type(name).__name__}")
    table = _collect("jwarp_measurements")
    if name not in table:
        raise ValueError(f"measurement: unknown measurement '{name}'; registered: "
                         f"{', '.join(sorted(table)) or '(none)'}")
    plugin, factory = table[name]
    if not callable(factory):
        raise PluginError(f"plugin '{plugin}': factory for measurement '{name}' is not callable")
    return factory
