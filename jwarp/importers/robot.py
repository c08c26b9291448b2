"""URDF -> :class:`~jwarp.model.RobotModel` with the links' collision geometry.

:func:`load_urdf` is what ``jwarp.robot("x.urdf")`` and ``jwarp import-urdf`` use (docs/urdf.md); :func:`load_mjcf` the same for MuJoCo's MJCF
(``jwarp.robot("x.xml")``, ``jwarp import-mjcf``).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from jwarp.importers.urdf import CollisionGeometry, UrdfImport, UrdfOptions, read_urdf
from jwarp.model import RobotModel, RobotModelError


@dataclass
class UrdfRobot:
    """An imported URDF: the ``model``, the collision ``geometries`` of its links (frames of
    the same names), and the raw import (``source``: document, link and joint frames)."""

    model: RobotModel
    geometries: list[CollisionGeometry]
    source: UrdfImport

    def geometries_of(self, link: str) -> list[CollisionGeometry]:
        """The collision geometry of one link (ValueError for an unknown link)."""
        if link not in self.source.link_frames:
            raise ValueError(f"link: unknown link '{link}'; known: "
                             f"{', '.join(self.source.link_frames)}")
        return [g for g in self.geometries if g.link == link]


def _imported(path: str | os.PathLike, imp: Any) -> UrdfRobot:
    """The validated model of an import's document, with its geometry and source."""
    try:
        model = RobotModel.from_dict(imp.document)
    except RobotModelError as e:
        raise RobotModelError(f"{os.fspath(path)}: imported robot is invalid: {e}") from None
    return UrdfRobot(model=model, geometries=imp.geometries, source=imp)


def load_urdf(path: str | os.PathLike, *, end_effectors: Mapping[str, str] | None = None,
              package_dirs: Sequence[str | os.PathLike] = (), **options: Any) -> UrdfRobot:
    """Import a URDF file. ``end_effectors``, ``package_dirs`` and ``options`` are the fields
    of :class:`~jwarp.importers.urdf.UrdfOptions`. ValueError naming the file and the
    element for a malformed URDF."""
    try:
        opt = UrdfOptions(end_effectors=end_effectors, package_dirs=package_dirs, **options)
    except TypeError as e:
        raise TypeError(f"load_urdf: {e}") from None
    imp = read_urdf(path, opt)
    return _imported(path, imp)


def load_mjcf(path: str | os.PathLike, *, end_effectors: Mapping[str, str] | None = None,
              **options: Any) -> UrdfRobot:
    """Import a MuJoCo MJCF file (needs the ``mujoco`` package: ``pip install jwarp[mjcf]``).
    ``end_effectors`` and ``options`` are the fields of
    :class:`~jwarp.importers.mjcf.MjcfOptions`; the result's ``geometries`` are the bodies'
    collision geoms (mesh geoms carry MuJoCo's compiled mesh in ``mesh``). ValueError naming
    the file and the element for a malformed or unsupported file (docs/urdf.md, MJCF)."""
    from jwarp.importers.mjcf import MjcfOptions, read_mjcf

    try:
        opt = MjcfOptions(end_effectors=end_effectors, **options)
    except TypeError as e:
        raise TypeError(f"load_mjcf: {e}") from None
    imp = read_mjcf(path, opt)
    return _imported(path, imp)


#: short names of example-robot-data's robots whose URDF is not ``<name>.urdf`` (the names
#: of its own ``example_robot_data.load``); any other name is a URDF's file name without
#: ``.urdf`` (``xarm7``, ``z1``, ``baxter``, ``tiago_dual``) or a ``<name>_description``
#: folder holding one URDF
EXAMPLE_ROBOT_ALIASES = {
    "ur3": "ur_description/urdf/ur3_robot.urdf",
    "ur5": "ur_description/urdf/ur5_robot.urdf",
    "ur10": "ur_description/urdf/ur10_robot.urdf",
    "talos": "talos_data/robots/talos_reduced.urdf",
    "talos_full": "talos_data/robots/talos_full_v2.urdf",
    "talos_arm": "talos_data/robots/talos_left_arm.urdf",
    "anymal": "anymal_b_simple_description/robots/anymal.urdf",
    "anymal_c": "anymal_c_simple_description/urdf/anymal.urdf",
    "anymal_kinova": "anymal_b_simple_description/robots/anymal-kinova.urdf",
    "hyq": "hyq_description/robots/hyq_no_sensors.urdf",
    "icub": "icub_description/robots/icub_reduced.urdf",
    "icub_full": "icub_description/robots/icub.urdf",
    "romeo": "romeo_description/urdf/romeo_small.urdf",
    "g1": "g1_description/urdf/g1_29dof_rev_1_0.urdf",
    "allegro_right_hand": "allegro_hand_description/urdf/allegro_right_hand.urdf",
    "allegro_left_hand": "allegro_hand_description/urdf/allegro_left_hand.urdf",
    "asr_twodof": "asr_twodof_description/urdf/TwoDofs.urdf",
}
#: name prefixes of :func:`package_robot_path` (``jwarp.robot("PREFIX:NAME")``)
PACKAGE_PREFIXES = ("example-robot-data", "robot_descriptions")


def _example_robots_folder() -> Any:
    from importlib import metadata
    from pathlib import Path

    try:
        dist = metadata.distribution("example-robot-data")
    except metadata.PackageNotFoundError:
        raise ValueError("example-robot-data: not installed (pip install example-robot-data, "
                         "or jwarp's test extra)") from None
    return Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))


def _example_urdfs(folder: Any) -> dict[str, list[str]]:
    """``{file name without .urdf: [relative paths]}`` of every URDF of the folder."""
    found: dict[str, list[str]] = {}
    for f in sorted(folder.rglob("*.urdf")):
        found.setdefault(f.stem, []).append(f.relative_to(folder).as_posix())
    return found


def example_robot_names() -> list[str]:
    """The short names :func:`example_robot_urdf` takes (``"panda"``, ``"ur5"``, ...),
    sorted: :data:`EXAMPLE_ROBOT_ALIASES` and the file names of the installed package's
    URDFs that name one file. ValueError when example-robot-data is not installed."""
    folder = _example_robots_folder()
    unique = {k for k, v in _example_urdfs(folder).items() if len(v) == 1}
    aliases = {k for k, v in EXAMPLE_ROBOT_ALIASES.items() if (folder / v).is_file()}
    return sorted(unique | aliases)


def example_robot_urdf(name: str) -> str:
    """The path of a URDF shipped by the ``example-robot-data`` package (a test extra of
    jwarp; its wheel ships the robots folder, no Python module, so ``import
    example_robot_data`` fails): a short name (``"panda"``, ``"ur5"``, ``"xarm7"``, ...;
    :func:`example_robot_names`) or a path under its robots folder
    (``"panda_description/urdf/panda.urdf"``). ValueError naming the package and the
    known names when it is not installed or has no such robot."""
    folder = _example_robots_folder()
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"example-robot-data: expected a robot name, got {name!r}")
    name = name.strip()
    rel = EXAMPLE_ROBOT_ALIASES.get(name)
    if rel is None and ("/" in name or name.endswith(".urdf")):
        rel = name
    if rel is None:
        urdfs = _example_urdfs(folder)
        hits = urdfs.get(name) or urdfs.get(name.removesuffix(".urdf"), [])
        if not hits:  # a <name>_description (or <name>) folder holding one URDF
            for d in (f"{name}_description/", f"{name}/"):
                hits = [p for ps in urdfs.values() for p in ps if p.startswith(d)]
                if hits:
                    break
        if len(hits) > 1:
            raise ValueError(f"example-robot-data: '{name}' names {len(hits)} URDFs "
                             f"({', '.join(hits)}); give one of them")
        if not hits:
            raise ValueError(f"example-robot-data: no robot '{name}'; known: "
                             f"{', '.join(example_robot_names())} (or a path under {folder})")
        rel = hits[0]
    path = folder / rel
    if not path.is_file():
        raise ValueError(f"example-robot-data: no file '{rel}' under {folder}")
    return str(path)


def robot_descriptions_path(name: str) -> str:
    """The URDF (else MJCF) path of a description of the ``robot_descriptions`` package:
    ``robot_descriptions.<name>.URDF_PATH`` (``name`` with or without the
    ``_description`` suffix: ``"panda"`` is ``panda_description``; ``"panda_mj"`` is
    ``panda_mj_description``, an MJCF). Importing a description downloads its repository
    once (robot_descriptions' own cache; network needed). ValueError naming the package
    when it is not installed or has no such description."""
    import importlib

    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"robot_descriptions: expected a description name, got {name!r}")
    name = name.strip()
    try:
        importlib.import_module("robot_descriptions")
    except ImportError:
        raise ValueError("robot_descriptions: not installed (pip install robot_descriptions); "
                         "or use example-robot-data:NAME (pip install example-robot-data)") \
            from None
    module = None
    tried = [name] if name.endswith("_description") else [f"{name}_description", name]
    for mod in tried:
        try:
            module = importlib.import_module(f"robot_descriptions.{mod}")
            break
        except ModuleNotFoundError as e:
            if e.name not in (f"robot_descriptions.{mod}", mod):
                raise ValueError(f"robot_descriptions: {mod}: {' '.join(str(e).split())}") from None
        except Exception as e:  # noqa: BLE001 - a failed download, in any form
            raise ValueError(f"robot_descriptions: {mod}: {' '.join(str(e).split())}") from None
    if module is None:
        raise ValueError(f"robot_descriptions: no description "
                         f"{' or '.join(repr(t) for t in tried)} (its names end in "
                         f"_description, e.g. panda_description)")
    for attr in ("URDF_PATH", "MJCF_PATH"):
        path = getattr(module, attr, None)
        if path:
            return str(path)
    raise ValueError(f"robot_descriptions: {module.__name__} has neither URDF_PATH nor "
                     f"MJCF_PATH")


def package_robot_path(name: str) -> str | None:
    """The robot file of a name ``"example-robot-data:NAME"`` (:func:`example_robot_urdf`)
    or ``"robot_descriptions:NAME"`` (:func:`robot_descriptions_path`); None for a name
    without one of these prefixes (:data:`PACKAGE_PREFIXES`)."""
    if not isinstance(name, str):
        return None
    prefix, colon, rest = name.partition(":")
    if not colon or prefix not in PACKAGE_PREFIXES:
        return None
    if prefix == "example-robot-data":
        return example_robot_urdf(rest)
    return robot_descriptions_path(rest)
