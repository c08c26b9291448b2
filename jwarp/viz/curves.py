"""Training curves in rerun (``jwarp train ik --rerun``)."""

from __future__ import annotations

import math

from jwarp.viz.recording import Recording


class TrainingCurves(Recording):
    """Training curves in a rerun recording (``jwarp train ik --rerun``): every number of
    an epoch record under ``train/<key>`` on the timeline ``epoch``."""

    def __init__(self, path: str, option: str = "path"):
        super().__init__(path, "jwarp-train-ik", option=option)

    def log(self, rec: dict) -> None:
        """Log one epoch record (``epoch`` and numbers; other values are skipped)."""
        self.rec.set_time("epoch", sequence=int(rec.get("epoch", 0)))
        for k, v in rec.items():
            if k == "epoch" or isinstance(v, bool) or not isinstance(v, (int, float)):
                continue
            if math.isfinite(float(v)):
                self.rec.log(f"train/{k}", self.rr.Scalars(float(v)))
