"""Compatibility name for plugin authors: the measurement plugin contract lives in
:mod:`jwarp.model.measurement` (``Measurement``, ``ParamBlock``)."""

from jwarp.model.measurement import Measurement, ParamBlock

__all__ = ["Measurement", "ParamBlock"]
