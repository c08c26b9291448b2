"""Eigenvalue spectra in rerun (``jwarp sensitivity --rerun``): bar charts of log10
eigenvalues."""

from __future__ import annotations

import numpy as np

from jwarp.viz.recording import Recording


class SpectraRecording(Recording):
    """A recording of named spectra."""

    def __init__(self, path: str, option: str = "path"):
        super().__init__(path, "jwarp-sensitivity", option=option)

    def save(self, spectra: list[tuple[str, np.ndarray]]) -> None:
        """Log the spectra as bar charts (log10 eigenvalues, zeros at -30) under
        ``sensitivity/<name>`` and close the recording (removed on any error)."""
        with self:
            for name, v in spectra:
                lv = np.log10(np.maximum(np.asarray(v, np.float64), 1e-30))
                self.rec.log(f"sensitivity/{name}", self.rr.BarChart(lv), static=True)
