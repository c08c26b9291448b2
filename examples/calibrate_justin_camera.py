"""Agile Justin's head camera: markers on both hands and on a pole (thesis 2.6.3, Table 2.3),
calibrated with and without the camera intrinsics, on a simulated campaign.

The truth: justin19's nominal DH rows plus uniform errors (+-5 mm, +-5 deg, thesis 2.6.1)
and compliances kappa_theta, kappa_alpha in [0.5, 1.5] x 1e-4 rad/(N m); a 1280 x 960 px
camera on ``head_tcp`` (scenario ``justin19/image``: focal 612/607 px, centre (646, 474),
radial distortion xi = 0.03), a marker 5 cm off each TCP and three markers on a pole 1.1 m
in front of the robot, 1 px noise per coordinate. Every sample sees all five markers
(the scenario's sampler points the head at hands and pole; ``accept`` keeps samples with
every marker inside the image on the true robot).

The solver gets a rough setup: camera mount off by 0.2 m / 20 deg, markers by 1 cm, and
the *datasheet* intrinsics (focal 600, centre (640, 480), xi 0). Rows:

  c (camera, markers)      nominal robot, camera mount and markers fitted ("before")
  full, intrinsics fixed   + all DH groups and compliances, intrinsics at the datasheet
  full + intrinsics        + the intrinsics group (focal, centre, xi) free

Columns: pixel error per marker on the test rows against the measured pixels (mean, std,
max), the mean against the truth's noise-free pixels ("clean"), the mean on the calibration
rows, and the 3-D error [mm] of the two hand markers in the camera frame (calibrated robot,
mount and markers vs the truth, noise-free, on the test configurations) - the hand-eye
accuracy a grasp needs; paper Table 2.3 (real robot, 640 x 480 camera, no TOW) for
orientation.

Under the table: the acceptance checks (``check: ... PASS|FAIL``) of ``full + intrinsics``
(the truth is inside this model): mean test error <= 1.5 sigma against the noise-free pixels
and <= 1.5 x the perfect-model floor (calib_common.noise_floor) against the measured pixels;
and freeing the intrinsics lowers the test error. Exit status 1 when any check fails, else 0.

Run:  python examples/calibrate_justin_camera.py [--samples 300] [--test 200] [--seed 1]
      python examples/calibrate_justin_camera.py --quick      (< 1 minute)
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

import jwarp
from jwarp.model.geometry import pose_matrix
from jwarp.calibration.simulate.campaign import simulate_campaign
from jwarp.calibration.files import Setup, make_measurement
from jwarp.calibration.estimate.result import model_frames
from jwarp.calibration.simulate.scenarios import scenario

from calib_common import (Check, accuracy_checks, distance_stats_mm, example_parser,
                          floor_line, parse_example, print_table, report_checks, run_rows,
                          split_campaign, start)

ROBOT_GROUPS = ["theta", "d", "r", "alpha", "kappa_theta", "kappa_alpha"]
DATASHEET = {"focal": [600.0, 600.0], "center": [640.0, 480.0], "xi": 0.0}
# thesis Table 2.3, "Images" rows without TOW: px mean, std, max and mm mean, std, max
PAPER_PX = {"full, intrinsics fixed": (1.05, 0.59, 3.76), "full + intrinsics": (0.97, 0.53, 3.44)}
PAPER_MM = {"full, intrinsics fixed": (4.77, 2.29, 11.75), "full + intrinsics": (4.65, 2.27, 11.58)}


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    ap = example_parser(__doc__, noise=1.0, noise_help="pixel noise sigma [px]",
                        quick_help="80 calibration / 40 test rows (< 1 minute)")
    return parse_example(ap, argv, {"samples": 80, "test": 40})


def hand_points_camera(robot: jwarp.RobotModel, meas, p: np.ndarray, q: np.ndarray
                       ) -> np.ndarray:
    """(S, H, 3) positions [m] of the markers on robot frames in the camera frame, on the
    (elastic) model ``robot`` with measurement parameters ``p``."""
    F = model_frames(robot, q)
    names = meas.params.names
    i = names.index("camera_px")
    T = F[:, robot.frame_index(meas.setup["camera"]["frame"])] @ pose_matrix(p[i:i + 3],
                                                                             p[i + 3:i + 6])
    out = []
    for mk in meas.setup["markers"]:
        if mk["frame"] is None:
            continue
        j = names.index(f"marker_{mk['name']}_x")
        Fm = F[:, robot.frame_index(mk["frame"])]
        xw = Fm[:, :3, :3] @ p[j:j + 3] + Fm[:, :3, 3]
        out.append(np.einsum("sji,sj->si", T[:, :3, :3], xw - T[:, :3, 3]))
    return np.stack(out, axis=1)


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    robot, t_all = start("justin19")
    setup, sampler, accept = scenario("justin19", "image")
    setup.section["noise"] = args.noise
    camp = simulate_campaign(robot, setup, args.samples + args.test, seed=args.seed,
                             length_error=0.005, angle_error=math.radians(5.0),  # thesis 2.6.1
                             kappa=(0.5e-4, 1.5e-4), sampler=sampler, accept=accept)
    t_sim = time.perf_counter() - t_all
    rough = dict(camp.setup.section)
    rough["intrinsics"] = dict(rough["intrinsics"], **DATASHEET)
    meas = make_measurement(robot, Setup("image", rough, "justin19"))
    data = split_campaign(camp, args.samples, args.test)
    x_true = hand_points_camera(camp.true_robot, data.truth, camp.true_params, data.test.q)
    print(f"justin19 head camera (1280 x 960 px), markers on both hands + 3 on a pole: "
          f"{args.samples} calibration / {args.test} test rows (all markers visible), seed "
          f"{args.seed}, noise {args.noise:g} px; campaign simulated in {t_sim:.1f} s")
    u = camp.samples.y
    dist = np.linalg.norm(x_true, axis=-1)
    print(f"pixels used: u {u[:, 0::2].min():.0f}..{u[:, 0::2].max():.0f}, "
          f"v {u[:, 1::2].min():.0f}..{u[:, 1::2].max():.0f}; hand markers "
          f"{dist.min():.2f}..{dist.max():.2f} m from the camera")
    print(floor_line(2, args.noise, "px"))

    def hand_mm(r):
        x_cal = hand_points_camera(r.result.robot, meas, r.result.params, data.test.q)
        return distance_stats_mm(x_cal, x_true)

    plan = [("c (camera, markers)", ["camera", "markers"]),
            ("full, intrinsics fixed", ROBOT_GROUPS + ["camera", "markers"]),
            ("full + intrinsics", ROBOT_GROUPS + ["camera", "markers", "intrinsics"])]
    rows = run_rows(plan, robot, meas, data, args, "px", extra={"hand mm": hand_mm})
    print_table("Table 2.3 (simulated): test errors per marker [px], hand markers in the "
                "camera frame [mm]", rows, "px", PAPER_PX, extra=["hand mm"], paper_unit="px")
    print("paper Table 2.3 cartesian errors [mm] (mean, std, max; tracker, robot base): "
          + "; ".join(f"{k}: {v[0]:.2f}, {v[1]:.2f}, {v[2]:.2f}" for k, v in PAPER_MM.items()))
    full, fixed = rows[-1], rows[1]
    i = meas.params.names.index("intrinsics_fx")
    fmt = lambda v: ", ".join(f"{x:.4g}" for x in v)  # noqa: E731
    print(f"intrinsics fx, fy, cx, cy, xi: datasheet [{fmt(meas.params.nominal[i:i + 5])}], "
          f"calibrated [{fmt(full.result.params[i:i + 5])}], truth "
          f"[{fmt(camp.true_params[i:i + 5])}]")
    checks = [*accuracy_checks(full, 2, args.noise, "px"),
              Check(f"freeing the intrinsics lowers the test error: {fixed.test['mean']:.3f} "
                    f"-> {full.test['mean']:.3f} px", full.test["mean"] < fixed.test["mean"])]
    return report_checks(checks, t_all, "acceptance of 'full + intrinsics' (the truth is "
                         "inside this model)")


if __name__ == "__main__":
    sys.exit(main())
