"""Experiment design: sensitivity, optimal design, task-oriented weighting, virtual
noise, pose sampling and ordering (thesis 2.3.2-2.4.3)."""

from jwarp.calibration.design.optimal import DesignOptions, DesignResult, design
from jwarp.calibration.design.poses import PoseOptions, PoseSampler, sample_poses
from jwarp.calibration.design.sensitivity import SensitivityResult, sensitivity
from jwarp.calibration.design.tour import Ordering, order_poses
from jwarp.calibration.design.tow import TowSpec, tow_covariance, tow_from_dict
from jwarp.calibration.design.virtual_noise import add_virtual_noise

__all__ = [
    "DesignOptions", "DesignResult", "Ordering", "PoseOptions", "PoseSampler",
    "SensitivityResult", "TowSpec", "add_virtual_noise", "design", "order_poses",
    "sample_poses", "sensitivity", "tow_covariance", "tow_from_dict",
]
