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
itself, or a path to a robot JSON file).

One broken plugin never disables the others: an entry point that fails to import or to
register, a hook that raises or returns something malformed, and a misspelled hook name
are each reported once as a one-line :class:`PluginWarning` (and listed by
:func:`plugin_problems` and ``jwarp robots``); the other robots and measurements work.
A robot whose factory raises, and a name claimed by two plugins, are errors
(:class:`PluginError`, naming the plugins) only when that name is asked for. Set the
environment variable ``JWARP_NO_ENTRY_POINTS=1`` to skip the entry points (built-ins only).
"""

from __future__ import annotations

import os
import types
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

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
#: environment variable: any non-empty value skips the ``jwarp`` entry points
NO_ENTRY_POINTS_ENV = "JWARP_NO_ENTRY_POINTS"
SKIP_HINT = f"set {NO_ENTRY_POINTS_ENV}=1 to skip the entry-point plugins"


class PluginError(ValueError):
    """Plugins conflict or return something malformed."""


class PluginWarning(UserWarning):
    """A plugin is broken (fails to load, raises, misspells a hook); the others still work."""


class JwarpSpec:
    """Hook specifications of jwarp."""

    @hookspec
    def jwarp_robots(self) -> dict[str, Callable[[], RobotModel] | RobotModel | str]:
        """Return ``{robot_name: factory}``; a factory returns a RobotModel (called lazily)."""

    @hookspec
    def jwarp_measurements(self) -> dict[str, Any]:
        """Return ``{measurement_name: factory}`` for measurement functions (may be empty)."""


HOOK_NAMES = ("jwarp_robots", "jwarp_measurements")
_WHAT = {"jwarp_robots": "robot", "jwarp_measurements": "measurement"}

_PM: pluggy.PluginManager | None = None
_ROBOT_CACHE: dict[str, RobotModel] = {}
#: plugin name -> how messages name it (entry points: entry point and distribution)
_ORIGIN: dict[str, str] = {}
#: plugin names that came from entry points (their messages say how to skip them)
_ENTRY_POINT_PLUGINS: set[str] = set()
#: problems found while loading the entry points (in order)
_LOAD_PROBLEMS: list[str] = []
#: every message already emitted as a PluginWarning (each is emitted once per process)
_WARNED: set[str] = set()


def _one_line(e: BaseException) -> str:
    """``Type: message`` of an exception on one line."""
    text = "; ".join(line.strip() for line in str(e).splitlines() if line.strip())
    return f"{type(e).__name__}: {text}" if text else type(e).__name__


def _who(plugin_name: str) -> str:
    return _ORIGIN.get(plugin_name, f"plugin '{plugin_name}'")


def _hint(plugin_names: Any) -> str:
    return f" ({SKIP_HINT})" if any(n in _ENTRY_POINT_PLUGINS for n in plugin_names) else ""


def _warn(message: str) -> None:
    """Emit ``message`` as a PluginWarning once per process, attributed to the first caller
    outside jwarp (so that Python's warning line points at the user's code)."""
    if message in _WARNED:
        return
    _WARNED.add(message)
    import sys

    package = os.path.dirname(os.path.abspath(__file__)) + os.sep
    level = 1
    frame: types.FrameType | None = sys._getframe(0)
    while frame is not None and os.path.abspath(frame.f_code.co_filename).startswith(package):
        level, frame = level + 1, frame.f_back
    warnings.warn(message, PluginWarning, stacklevel=level)


def _hook_problems(pm: pluggy.PluginManager, plugin: object, name: str) -> list[str]:
    """Misspelled or unmarked hooks of a registered plugin, and a plugin without hooks."""
    who = _who(name)
    known = ", ".join(HOOK_NAMES)
    problems = []
    callers = pm.get_hookcallers(plugin) or []
    for caller in callers:
        if caller.spec is None:
            impls = [i for i in caller.get_hookimpls() if i.plugin is plugin]
            if impls and all(i.optionalhook for i in impls):
                continue
            problems.append(f"{who}: hook '{caller.name}' is not a jwarp hook (known: {known}); "
                            f"misspelled? it is ignored")
    unmarked = []
    for hook in HOOK_NAMES:
        try:
            attr = getattr(plugin, hook, None)
        except Exception:  # noqa: BLE001 - a property of a plugin object that raises
            attr = None
        if callable(attr) and pm.parse_hookimpl_opts(plugin, hook) is None:
            unmarked.append(hook)
            problems.append(f"{who}: '{hook}' is not marked with @jwarp.hookimpl; it is ignored")
    if not any(c.spec is not None for c in callers) and not unmarked:
        problems.append(f"{who} defines no @jwarp.hookimpl hook ({known}); it provides nothing")
    return problems


def _load_entry_points(pm: pluggy.PluginManager) -> None:
    """Load and register every ``jwarp`` entry point, each on its own: one that fails is
    recorded in ``_LOAD_PROBLEMS`` and skipped (pluggy's loader stops at the first)."""
    from importlib.metadata import entry_points

    try:
        eps = list(entry_points(group=PROJECT))
    except Exception as e:  # noqa: BLE001 - broken metadata somewhere on sys.path
        _LOAD_PROBLEMS.append(f"could not list the '{PROJECT}' entry points: {_one_line(e)}; "
                              f"using the built-in plugins only")
        return
    for ep in eps:
        try:
            dist = ep.dist
            # no distribution (None): AttributeError, caught below
            dist_name = str(dist.metadata["Name"] or dist.name)  # type: ignore[union-attr]
            dist_text = f"{dist_name} {dist.version}"  # type: ignore[union-attr]
        except Exception:  # noqa: BLE001 - no or broken distribution metadata
            dist_name, dist_text = "?", "unknown"
        desc = f"entry point '{ep.name} = {ep.value}' (distribution {dist_text})"
        try:
            plugin = ep.load()
        except (Exception, SystemExit) as e:  # noqa: BLE001 - any failure of a plugin's import
            _LOAD_PROBLEMS.append(f"{desc} failed to load: {_one_line(e)}; skipped, the other "
                                  f"plugins still work ({SKIP_HINT})")
            continue
        if pm.is_registered(plugin):
            continue  # one module named by two entry points: registered once
        name = ep.name
        if pm.has_plugin(name) or pm.is_blocked(name):
            name = f"{dist_name}:{ep.name}"  # two distributions using one entry-point name
        _ORIGIN[name] = desc
        _ENTRY_POINT_PLUGINS.add(name)
        try:
            if pm.register(plugin, name=name) is None:
                raise PluginError(f"plugin name '{name}' is blocked")
        except Exception as e:  # noqa: BLE001 - e.g. pluggy.PluginValidationError
            _LOAD_PROBLEMS.append(f"{desc} could not be registered: {_one_line(e)}; skipped, "
                                  f"the other plugins still work ({SKIP_HINT})")
            continue
        _LOAD_PROBLEMS.extend(f"{p} ({SKIP_HINT})" for p in _hook_problems(pm, plugin, name))


def plugin_manager() -> pluggy.PluginManager:
    """The process-wide plugin manager (built-ins plus the ``jwarp`` entry points, unless
    ``JWARP_NO_ENTRY_POINTS`` is set). Entry points that fail are skipped and reported."""
    global _PM
    if _PM is None:
        import importlib

        pm = pluggy.PluginManager(PROJECT)
        pm.add_hookspecs(JwarpSpec)
        for mod in BUILTIN_ROBOT_MODULES + BUILTIN_MEASUREMENT_MODULES:
            pm.register(importlib.import_module(mod), name=mod)
        if not os.environ.get(NO_ENTRY_POINTS_ENV):
            _load_entry_points(pm)
        _PM = pm
        for message in _LOAD_PROBLEMS:
            _warn(message)
    return _PM


def register_plugin(plugin: object, name: str | None = None) -> None:
    """Register a plugin object/module at run time (tests, notebooks).

    Raises :class:`PluginError` (nothing registered) if the plugin is already registered,
    the name is taken, or a hook is misspelled, not marked ``@jwarp.hookimpl`` or has
    arguments the hook does not have."""
    if plugin is None:
        raise TypeError("plugin: expected a module or object with @jwarp.hookimpl functions, "
                        "got None")
    if name is not None and not isinstance(name, str):
        raise TypeError(f"name: expected a string or None, got {type(name).__name__}")
    pm = plugin_manager()
    try:
        registered = pm.register(plugin, name=name)
    except (ValueError, pluggy.PluginValidationError) as e:
        raise PluginError(f"register_plugin: {_one_line(e)}") from None
    if registered is None:
        raise PluginError(f"register_plugin: plugin name '{name}' is blocked")
    problems = _hook_problems(pm, plugin, registered)
    if problems:
        pm.unregister(plugin)
        raise PluginError(f"register_plugin: {'; '.join(problems)}")
    _ROBOT_CACHE.clear()


def unregister_plugin(plugin: object) -> None:
    """Remove a plugin registered by :func:`register_plugin` (the object or its name)."""
    pm = plugin_manager()
    if isinstance(plugin, str):
        if not pm.has_plugin(plugin):
            raise ValueError(f"unregister_plugin: no plugin named '{plugin}' is registered")
        pm.unregister(name=plugin)
    else:
        if not pm.is_registered(plugin):
            raise ValueError("unregister_plugin: this plugin is not registered")
        pm.unregister(plugin)
    _ROBOT_CACHE.clear()


@dataclass
class _Table:
    """What the plugins of one hook offer: ``found[name] = (plugin_name, factory)``; names
    claimed by several plugins are in ``conflicts`` (and not in ``found``)."""

    found: dict[str, tuple[str, Any]] = field(default_factory=dict)
    conflicts: dict[str, list[str]] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)


def _conflict_text(what: str, key: str, plugins: list[str]) -> str:
    count = "two" if len(plugins) == 2 else str(len(plugins))
    return f"{what} '{key}' is claimed by {count} plugins: {' and '.join(_who(p) for p in plugins)}"


def _collect(hook_name: str) -> _Table:
    """Call each plugin's hook on its own: one that raises or returns something malformed is
    reported (once) and skipped; the others still count."""
    pm = plugin_manager()
    what = _WHAT[hook_name]
    table = _Table()
    claims: dict[str, list[tuple[str, Any]]] = {}
    for impl in getattr(pm.hook, hook_name).get_hookimpls():
        who = _who(impl.plugin_name)
        hint = _hint([impl.plugin_name])
        if impl.hookwrapper or getattr(impl, "wrapper", False):
            table.problems.append(f"{who}: {hook_name} is a hook wrapper, which jwarp does not "
                                  f"support; it is ignored{hint}")
            continue
        try:
            result = impl.function()
        except Exception as e:  # noqa: BLE001 - a plugin's hook may fail in any way
            table.problems.append(f"{who}: {hook_name}() raised {_one_line(e)}; its {what}s "
                                  f"are skipped, the others still work{hint}")
            continue
        if result is None:
            continue
        if not isinstance(result, dict):
            table.problems.append(f"{who}: {hook_name}() returned {type(result).__name__}, "
                                  f"expected a dict {{name: factory}}; ignored{hint}")
            continue
        for key, factory in result.items():
            if not isinstance(key, str) or not key:
                table.problems.append(f"{who}: {hook_name}() returned the {what} name {key!r}; "
                                      f"names must be non-empty strings; ignored{hint}")
                continue
            claims.setdefault(key, []).append((impl.plugin_name, factory))
    for key, offers in claims.items():
        if len(offers) == 1:
            table.found[key] = offers[0]
        else:
            plugins = [p for p, _ in offers]
            table.conflicts[key] = plugins
            table.problems.append(f"{_conflict_text(what, key, plugins)}; asking for it is an "
                                  f"error until one is removed{_hint(plugins)}")
    for message in table.problems:
        _warn(message)
    return table


def plugin_problems() -> list[str]:
    """One-line messages of every plugin problem found so far: entry points that failed to
    load or register, misspelled or unmarked hooks, hooks that raise or return something
    malformed, names claimed by several plugins. Each is also emitted once as a
    :class:`PluginWarning`. Robot factories are not called here (they run lazily); a factory
    that raises is an error of :func:`robot` for that name only."""
    plugin_manager()
    problems = list(_LOAD_PROBLEMS)
    for hook in HOOK_NAMES:
        problems.extend(p for p in _collect(hook).problems if p not in problems)
    return problems


def _problems_note(table: _Table) -> str:
    n = len(_LOAD_PROBLEMS) + len(table.problems)
    return (f" ({n} plugin problem{'s' if n != 1 else ''}: see the warnings or "
            f"jwarp.plugins.registry.plugin_problems())") if n else ""


def robots() -> list[str]:
    """Names of all registered robots, sorted (names claimed by several plugins left out,
    reported as a :class:`PluginWarning`)."""
    return sorted(_collect("jwarp_robots").found)


def _looks_like_path(name: str) -> bool:
    seps = {"/", os.sep} | ({os.altsep} if os.altsep else set())
    return name.lower().endswith((".json", ".urdf", ".xml")) or any(s in name for s in seps)


def _load_file(path: str) -> RobotModel:
    """The robot of a file: a ``.urdf`` by :func:`jwarp.importers.robot.load_urdf`, a
    ``.xml`` whose root is ``<mujoco>`` by :func:`jwarp.importers.robot.load_mjcf`, else a
    robot JSON."""
    if path.lower().endswith(".urdf"):
        from jwarp.importers.robot import load_urdf

        return load_urdf(path).model
    from jwarp.importers.mjcf import is_mjcf

    if is_mjcf(path):   # .xml with a <mujoco> root (needs jwarp[mjcf])
        from jwarp.importers.robot import load_mjcf

        return load_mjcf(path).model
    return RobotModel.load(path)


def robot(name: str | os.PathLike | RobotModel) -> RobotModel:
    """The robot registered under ``name`` (a RobotModel passes through; a path to a robot
    file, a name ending in ``.json`` or ``.urdf`` or containing a ``/``, is loaded; a
    ``.urdf`` file is imported by :func:`jwarp.importers.robot.load_urdf`, a ``.xml`` file
    whose root is ``<mujoco>`` by :func:`jwarp.importers.robot.load_mjcf`). A name
    ``"example-robot-data:NAME"`` is a URDF of the example-robot-data package
    (:func:`jwarp.importers.robot.example_robot_urdf`: ``panda``, ``ur5``, ``xarm7``, ...),
    ``"robot_descriptions:NAME"`` one of the robot_descriptions package
    (:func:`~jwarp.importers.robot.robot_descriptions_path`); ValueError naming the package
    to install when it is missing (docs/urdf.md "Robots one name away")."""
    if isinstance(name, RobotModel):
        return name
    if not isinstance(name, (str, os.PathLike)):
        raise TypeError(f"robot: expected a robot name, path or RobotModel, "
                        f"got {type(name).__name__}")
    name = os.fspath(name)
    if not isinstance(name, str):
        raise TypeError("robot: expected a robot name, path or RobotModel, got a bytes path")
    if name in _ROBOT_CACHE:
        return _ROBOT_CACHE[name]
    table = _collect("jwarp_robots")
    if name in table.conflicts:
        plugins = table.conflicts[name]
        raise PluginError(f"robot: {_conflict_text('robot', name, plugins)}; remove one of "
                          f"them{_hint(plugins)}")
    if name not in table.found:
        if ":" in name:   # "example-robot-data:panda", "robot_descriptions:panda"
            from jwarp.importers.robot import package_robot_path

            try:
                path = package_robot_path(name)
            except ValueError as e:
                raise ValueError(f"robot: {e}") from None
            if path is not None:
                model = _load_file(path)
                _ROBOT_CACHE[name] = model
                return model
        if _looks_like_path(name):
            if os.path.exists(name):
                return _load_file(name)
            raise ValueError(f"robot: file not found: '{name}' (read as a path to a robot "
                             f"file; no robot is registered under that name either)")
        raise ValueError(f"robot: unknown robot '{name}'; registered: "
                         f"{', '.join(sorted(table.found)) or '(none)'}{_problems_note(table)}")
    plugin, factory = table.found[name]
    who = _who(plugin)
    if isinstance(factory, RobotModel):
        model = factory
    elif isinstance(factory, (str, os.PathLike)) or callable(factory):
        try:
            model = RobotModel.load(factory) if not callable(factory) else factory()
        except Exception as e:  # noqa: BLE001 - a plugin's factory may fail in any way
            raise PluginError(f"robot: {who}: the factory of robot '{name}' raised "
                              f"{_one_line(e)}{_hint([plugin])}") from e
    else:
        raise PluginError(f"robot: {who}: factory for robot '{name}' is not callable "
                          f"({type(factory).__name__}){_hint([plugin])}")
    if not isinstance(model, RobotModel):
        raise PluginError(f"robot: {who}: robot '{name}' factory returned "
                          f"{type(model).__name__}, not RobotModel{_hint([plugin])}")
    _ROBOT_CACHE[name] = model
    return model


def measurements() -> list[str]:
    """Names of all registered measurement functions, sorted (names claimed by several
    plugins left out, reported as a :class:`PluginWarning`)."""
    return sorted(_collect("jwarp_measurements").found)


def measurement(name: str) -> Any:
    """The measurement class (factory) registered under ``name``, e.g. ``"cartesian"``;
    call it as ``cls(robot, setup_section)``."""
    if not isinstance(name, str):
        raise TypeError(f"measurement: expected a measurement name, got {type(name).__name__}")
    table = _collect("jwarp_measurements")
    if name in table.conflicts:
        plugins = table.conflicts[name]
        raise PluginError(f"measurement: {_conflict_text('measurement', name, plugins)}; "
                          f"remove one of them{_hint(plugins)}")
    if name not in table.found:
        raise ValueError(f"measurement: unknown measurement '{name}'; registered: "
                         f"{', '.join(sorted(table.found)) or '(none)'}{_problems_note(table)}")
    plugin, factory = table.found[name]
    if not callable(factory):
        raise PluginError(f"measurement: {_who(plugin)}: factory for measurement '{name}' is not "
                          f"callable ({type(factory).__name__}){_hint([plugin])}")
    return factory
