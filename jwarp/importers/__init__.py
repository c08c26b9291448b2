"""Robot description formats in and out of jwarp (host side, numpy).

* :mod:`jwarp.importers.urdf`: URDF (through ``yourdfpy``) -> a ``jwarp.robot`` document
  plus the links' collision geometry (:func:`~jwarp.importers.urdf.read_urdf`).
* :mod:`jwarp.importers.robot`: the same as a validated :class:`~jwarp.model.RobotModel`
  (:func:`~jwarp.importers.robot.load_urdf`, :class:`~jwarp.importers.robot.UrdfRobot`).
* :mod:`jwarp.importers.urdf_export`: a jwarp robot -> URDF (+ a side file for what URDF
  cannot hold).
* :mod:`jwarp.importers.spheres`: collision spheres fitted to meshes and primitives.

See docs/urdf.md and docs/urdf_export.md.
"""
