"""MAP calibration of (elastic) robots from measurement-plugin data (thesis 2.3.1, eq. 2.5).

Typical use::

    from jwarp.solvers.calibration import calibrate, errors, error_stats
    meas = jwarp.registry.measurement("cartesian")(robot, setup["measurement"])
    res = calibrate(robot, meas, q_train, y_train,
                    free="theta,d,r,alpha,kappa_theta,kappa_alpha,tracker,markers")
    res.robot.save("calibrated.json")
    error_stats(errors(res.robot, meas, res.params, q_test, y_test))
"""

from jwarp.solvers.calibration.map import (CalibrationProblem, ModelState, Progress, calibrate,
                                           calibrate_with)
from jwarp.solvers.calibration.options import CalibrationOptions
from jwarp.solvers.calibration.params import (DEFAULT_SIGMA, ROBOT_GROUPS, ParameterSpace,
                                              influencing_frames, influencing_masses,
                                              parse_groups, perturb_robot)
from jwarp.solvers.calibration.samples import check_samples
from jwarp.solvers.calibration.result import (CalibrationResult, CalibrationWarning, Direction,
                                              error_stats, errors, model_frames,
                                              observation_groups, predict)

__all__ = [
    "CalibrationOptions", "CalibrationProblem", "CalibrationResult", "CalibrationWarning", "DEFAULT_SIGMA", "Direction",
    "ParameterSpace", "Progress", "ROBOT_GROUPS", "calibrate", "calibrate_with", "check_samples", "error_stats",
    "errors", "influencing_frames", "influencing_masses", "ModelState", "model_frames", "observation_groups", "parse_groups",
    "perturb_robot", "predict",
]
