"""URDF -> :class:`~jwarp.model.RobotModel` with the links' collision geometry.

:func:`load_urdf` is what ``RobotModel.from_urdf``, ``jwarp.robot("x.urdf")`` and
``jwarp import-urdf`` use (docs/urdf.md); :func:`load_mjcf` the same for MuJoCo's MJCF
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


def example_robot_urdf(relative: str) -> str:
    """The path of a URDF shipped by the ``example-robot-data`` package (a test extra of
    jwarp; its wheel ships the robots folder, no Python module), e.g.
    ``"panda_description/urdf/panda.urdf"``. ValueError naming the package or the file
    when it is not installed or has no such file."""
    from importlib import metadata
    from pathlib import Path

    try:
        dist = metadata.distribution("example-robot-data")
    except metadata.PackageNotFoundError:
        raise ValueError("example-robot-data: not installed (pip install example-robot-data, "
                         "or jwarp's test extra)") from None
    folder = Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots"))
    path = folder / relative
    if not path.is_file():
        raise ValueError(f"example-robot-data: no file '{relative}' under {folder}")
    return str(path)
