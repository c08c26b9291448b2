"""Compatibility name for plugin authors: the measurement plugin contract lives in
:mod:`jwarp.measurement` (``Measurement``, ``ParamBlock``)."""

from jwarp.measurement import Measurement, ParamBlock

__all__ = ["Measurement", "ParamBlock"]
