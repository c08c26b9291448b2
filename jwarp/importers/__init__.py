"""Importers of robot descriptions from other formats into jwarp's robot schema.

* :mod:`jwarp.importers.urdf`: URDF (through ``yourdfpy``) -> a ``jwarp.robot`` document
  plus the links' collision geometry (:func:`~jwarp.importers.urdf.read_urdf`).
* :mod:`jwarp.importers.robot`: the same as a validated :class:`~jwarp.model.RobotModel`
  (:func:`~jwarp.importers.robot.load_urdf`, :class:`~jwarp.importers.robot.UrdfRobot`).

See docs/urdf.md.
"""
