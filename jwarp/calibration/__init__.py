"""Calibration of (elastic) robots from measurement-plugin data (thesis chapter 2):
:mod:`~jwarp.calibration.estimate` (MAP, eq. 2.5), :mod:`~jwarp.calibration.design`
(sensitivity, optimal design, poses) and :mod:`~jwarp.calibration.simulate` (campaigns).

Typical use::

    from jwarp.calibration import calibrate, errors, error_stats
    meas = jwarp.plugins.registry.measurement("cartesian")(robot, setup["measurement"])
    res = calibrate(robot, meas, q_train, y_train,
                    free="theta,d,r,alpha,kappa_theta,kappa_alpha,tracker,markers")
    res.robot.save("calibrated.json")
    error_stats(errors(res.robot, meas, res.params, q_test, y_test))

A campaign's files as ``jwarp calibrate`` calibrates them (rows, initial guess, CV, task
weighting, provenance): :func:`load_campaign` and :func:`calibrate_campaign`
(:mod:`~jwarp.calibration.campaign_run`).
"""

from jwarp.calibration.campaign_run import (
                                            CampaignCalibration,
                                            CampaignData,
                                            CampaignOptions,
                                            calibrate_campaign,
                                            load_campaign,
)
from jwarp.calibration.design.optimal import DesignOptions, DesignResult
from jwarp.calibration.design.poses import PoseOptions, sample_poses
from jwarp.calibration.design.sensitivity import SensitivityResult, sensitivity
from jwarp.calibration.design.tour import order_poses
from jwarp.calibration.estimate.cv import (
                                            CVOptions,
                                            CVResult,
                                            CVSetting,
                                            calibrate_cv,
                                            cross_validate,
)
from jwarp.calibration.estimate.map import (
                                            CalibrationProblem,
                                            ModelState,
                                            Progress,
                                            calibrate,
                                            calibrate_with,
)
from jwarp.calibration.estimate.options import CalibrationOptions
from jwarp.calibration.estimate.params import (
                                            DEFAULT_SIGMA,
                                            ROBOT_GROUPS,
                                            ParameterSpace,
                                            influencing_frames,
                                            influencing_masses,
                                            parse_groups,
                                            perturb_robot,
)
from jwarp.calibration.estimate.result import (
                                            CalibrationResult,
                                            CalibrationWarning,
                                            Direction,
                                            error_stats,
                                            errors,
                                            model_frames,
                                            observation_groups,
                                            predict,
)
from jwarp.calibration.estimate.samples import check_samples
from jwarp.calibration.simulate.campaign import Campaign, simulate_campaign
from jwarp.calibration.simulate.scenarios import scenario

__all__ = [
    "calibrate_campaign", "calibrate_cv", "calibrate_with", "CampaignCalibration",
    "CampaignData", "CampaignOptions", "CalibrationOptions", "cross_validate", "CVOptions",
    "CVResult", "CVSetting", "CalibrationProblem", "CalibrationResult",
    "CalibrationWarning", "Direction", "error_stats", "errors", "influencing_frames",
    "influencing_masses", "model_frames", "ModelState", "observation_groups",
    "load_campaign", "ParameterSpace", "perturb_robot", "predict", "Progress",
]
