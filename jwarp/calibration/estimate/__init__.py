"""Estimation: MAP calibration, parameters, robust losses, results and diagnostics
(thesis 2.3)."""
