"""DH rows the kernels read: one typed value, :class:`DHRows`, instead of ``rho`` + magic ints.

Every FK, Jacobian, elastic and collision kernel takes the same four row arguments
``(rho, rho_stride, rows_kind[, rho_layout])`` (see :mod:`jwarp.kernels.fk`). ``rho`` used to
mean five things (the nominal table, shared calibrated rows, rows per configuration, the
9-column compensation rows kept per waypoint, the elastic reference rows ``rho0``) and
``use_rho`` was a bare 0/1/2. Here they are one value with named kinds:

=====================  =======  ==============================================================
kind                   columns  rows
=====================  =======  ==============================================================
``NOMINAL``            5        the model's nominal table ``(1, n_frames, 5)``, stride 0; the
                                kernels take the precomputed nominal tables (fast path)
``DH``                 5        ``[d, theta, r, alpha, beta]``: shared ``(1, n_frames, 5)``
                                (stride 0) or one per configuration ``(N, n_frames, 5)``
                                (stride 1); calibrated or elastic rows, differentiable
``COMPENSATION``       9        ``[d, theta, r, alpha, beta, cos a, sin a, cos b, sin b]`` one
                                per waypoint ``(P * W, n_frames, 9)`` with the path
                                ``layout`` of :func:`jwarp.kernels.fk.waypoint_thread`
                                (:class:`jwarp.kinematics.compensation.CompensationRows`)
=====================  =======  ==============================================================

Make them with the constructors (:meth:`DHRows.nominal`, :meth:`DHRows.shared`,
:meth:`DHRows.per_config`, :meth:`DHRows.compensation`); every construction is validated.
A :class:`jwarp.core.device.DeviceModel` keeps its nominal rows (``model.nominal_rows``).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum
from typing import Any, cast

import warp as wp

from jwarp.core.types import DeviceLike
from jwarp.kernels.fk import ROWS_COMPENSATION, ROWS_DH, ROWS_NOMINAL

__all__ = ["RowsKind", "DHRows", "PER_CONFIG_LAYOUT", "COLUMNS"]


class RowsKind(IntEnum):
    """How a kernel reads its DH rows (the kernels' ``rows_kind`` argument)."""

    NOMINAL = ROWS_NOMINAL
    DH = ROWS_DH
    COMPENSATION = ROWS_COMPENSATION


#: columns of the rows of each kind
COLUMNS = {RowsKind.NOMINAL: 5, RowsKind.DH: 5, RowsKind.COMPENSATION: 9}
#: row layout of :func:`jwarp.kernels.fk.waypoint_thread` where thread b computes
#: configuration b at row b (or row 0 with stride 0)
PER_CONFIG_LAYOUT = (1, 1, 1, 0)


@dataclass(frozen=True, eq=False)
class DHRows:
    """DH rows for the kernels: ``kind``, the device ``array`` (rows, n_frames, columns),
    the batch ``stride`` (0: every configuration reads row 0; 1: its own row, or its
    waypoint's for compensation rows) and the path ``layout`` (S, n_sub, W, P or 0) of
    :func:`jwarp.kernels.fk.waypoint_thread` (``PER_CONFIG_LAYOUT`` except for compensation
    rows). Validated on construction (ValueError / TypeError)."""

    kind: RowsKind
    array: wp.array
    stride: int
    layout: tuple = PER_CONFIG_LAYOUT

    def __post_init__(self) -> None:
        try:
            kind = RowsKind(self.kind)
        except ValueError:
            raise ValueError(f"kind: expected a RowsKind (0, 1 or 2), got {self.kind!r}") from None
        object.__setattr__(self, "kind", kind)
        a = self.array
        if not isinstance(a, wp.array):
            raise TypeError(f"rho: expected a warp array, got {type(a).__name__}")
        if a.dtype not in (wp.float32, wp.float64):
            raise TypeError(f"rho: expected float32 or float64 rows, got "
                            f"{getattr(a.dtype, '__name__', a.dtype)}")
        cols = COLUMNS[kind]
        if a.ndim != 3 or a.shape[2] != cols or a.shape[0] < 1:
            raise ValueError(f"rho: {kind.name} rows need shape (rows >= 1, n_frames, {cols}), "
                             f"got {tuple(a.shape)}")
        if self.stride not in (0, 1) or isinstance(self.stride, bool):
            raise ValueError(f"stride: expected 0 (shared row) or 1 (a row per configuration), "
                             f"got {self.stride!r}")
        if kind == RowsKind.NOMINAL and (self.stride != 0 or a.shape[0] != 1):
            raise ValueError(f"rho: nominal rows are one shared (1, n_frames, 5) table with "
                             f"stride 0, got shape {tuple(a.shape)} and stride {self.stride}")
        lay = tuple(int(v) for v in self.layout)
        if len(lay) != 4 or min(lay) < 0 or min(lay[:3]) < 1:
            raise ValueError(f"layout: expected (S, n_sub, W, P or 0) with S, n_sub, W >= 1, "
                             f"got {self.layout!r}")
        S, n_sub, W, P = lay
        if (W - 1) * n_sub + 1 != S:
            raise ValueError(f"layout: S = {S} configurations per path does not match "
                             f"W = {W} waypoints of n_sub = {n_sub} substeps")
        if kind != RowsKind.COMPENSATION and lay != PER_CONFIG_LAYOUT:
            raise ValueError(f"layout: only compensation rows are kept per waypoint, got "
                             f"{self.layout!r} for {kind.name} rows")
        if P and a.shape[0] != P * W:
            raise ValueError(f"rho: layout of {P} paths of {W} waypoints needs {P * W} rows, "
                             f"got {a.shape[0]}")
        object.__setattr__(self, "layout", lay)

    # ------------------------------------------------------------ constructors
    @classmethod
    def nominal(cls, dh0: wp.array) -> DHRows:
        """The nominal rows: a model's ``(1, n_frames, 5)`` table (``DeviceModel.dh0_3d``)."""
        return cls(RowsKind.NOMINAL, dh0, 0)

    @classmethod
    def shared(cls, array: wp.array) -> DHRows:
        """One row table ``(n_frames, 5)`` or ``(1, n_frames, 5)`` for every configuration."""
        if isinstance(array, wp.array) and array.ndim == 2:
            array = array.reshape((1, *array.shape))
        if isinstance(array, wp.array) and array.ndim == 3 and array.shape[0] != 1:
            raise ValueError(f"rho: shared rows need shape (n_frames, 5) or (1, n_frames, 5), "
                             f"got {tuple(array.shape)}")
        return cls(RowsKind.DH, array, 0)

    @classmethod
    def per_config(cls, array: wp.array, n: int | None = None) -> DHRows:
        """A row table per configuration ``(N, n_frames, 5)`` (``n``: the expected N)."""
        r = cls(RowsKind.DH, array, 1)
        if n is not None and array.shape[0] != n:
            raise ValueError(f"rho: expected rows for {n} configurations, got {array.shape[0]}")
        return r

    @classmethod
    def compensation(cls, array: wp.array, layout: Any) -> DHRows:
        """Compensation rows ``(P * W, n_frames, 9)`` kept per waypoint, read through the
        path ``layout`` (S, n_sub, W, P or 0)."""
        return cls(RowsKind.COMPENSATION, array, 1, tuple(layout))

    # ------------------------------------------------------------ kernel arguments
    @property
    def args(self) -> tuple[wp.array, int, int]:
        """``(rho, rho_stride, rows_kind)`` in the kernels' argument order."""
        return self.array, self.stride, int(self.kind)

    @property
    def layout_vec(self) -> Any:
        """The layout as the kernels' ``rho_layout`` (``wp.vec4i``)."""
        v = self.__dict__.get("_layout_vec")
        if v is None:
            v = wp.vec4i(*self.layout)
            object.__setattr__(self, "_layout_vec", v)
        return v

    @property
    def n_frames(self) -> int:
        return int(self.array.shape[1])

    @property
    def count(self) -> int:
        """Number of row tables (1 when shared)."""
        return int(self.array.shape[0])

    @property
    def scalar(self) -> type:
        return self.array.dtype

    @property
    def device(self) -> wp.Device:
        return cast(wp.Device, self.array.device)

    @property
    def is_nominal(self) -> bool:
        return self.kind == RowsKind.NOMINAL

    def check(self, n_frames: int, n: int, scalar: type, device: DeviceLike) -> DHRows:
        """ValueError/TypeError unless these rows fit ``n`` configurations of a robot with
        ``n_frames`` frames computed in ``scalar`` on ``device``; returns self."""
        if self.n_frames != n_frames:
            raise ValueError(f"rho: rows for {self.n_frames} frames, the robot has {n_frames}")
        if self.scalar != scalar:
            raise TypeError(f"rho: {self.scalar.__name__} rows, the kernels compute in "
                            f"{scalar.__name__}")
        if str(self.device) != str(device):
            raise ValueError(f"rho: rows on {self.device}, the kernels on {device}")
        if self.kind == RowsKind.DH and self.stride == 1 and self.count != n:
            raise ValueError(f"rho: rows for {self.count} configurations, expected {n}")
        return self
