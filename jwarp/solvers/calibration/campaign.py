"""Deprecated path: moved to :mod:`jwarp.calibration.simulate.campaign` (issue 28, packages by job); importable from
here for one release, with a DeprecationWarning."""

from jwarp.utils.deprecation import moved

__getattr__, __dir__ = moved(__name__, ('jwarp.calibration.simulate.campaign',))
