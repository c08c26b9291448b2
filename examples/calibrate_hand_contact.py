"""hand4 from pairwise fingertip contacts: joint offsets only vs all DH parameters (thesis
2.6.1; Table I of the DLR-Hand II contact-calibration paper), on a simulated campaign.

The truth: hand4's nominal DH rows plus uniform errors (+-5 mm on d, r; +-5 deg on theta,
alpha of every DH frame, thesis 2.6.1); rigid (no compliances). Measurements: the signed
distance between the fingertip capsules of the thumb and each finger (scenario
``hand4/contact``). The sampler finds configurations in contact on the NOMINAL model (the
truth is unknown when a campaign is planned); the recorded value is the TRUE model's signed
distance there plus Gaussian noise (default 0.5 mm); ``--finger-pairs`` adds the
index-middle and middle-ring contacts - on the real hand the fingers touch
(distance 0) at configurations the nominal model gets wrong; here the configurations are
the nominal model's contacts and the distance is what the truth says: the same information.

Rows: nominal (no calibration), calibrated joint offsets (theta), calibrated full DH
(theta, d, r, alpha). Columns: test error of the distance [mm] against the measured rows
(mean, std, max), the mean against the truth's noise-free distances ("clean"), the mean on
the calibration rows, and the task error (eq. 2.46): the error [mm] of the fingertip
positions relative to the thumb tip on uniformly random configurations (calibrated vs
true model); the paper's numbers (real hand) for orientation.

Under the table: the acceptance checks (``check: ... PASS|FAIL``) of ``full DH`` (the truth
is inside this model): mean test error <= 1.5 sigma against the noise-free distances and
<= 1.5 x the perfect-model floor (calib_common.noise_floor) against the measured ones; and
nominal > joint offsets > full DH. Exit status 1 when any check fails, else 0.

Run:  python examples/calibrate_hand_contact.py [--samples 300] [--test 200] [--seed 1]
      python examples/calibrate_hand_contact.py --quick      (< 1 minute)
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

import jwarp
from jwarp.calibration.simulate.campaign import simulate_campaign, uniform_configurations
from jwarp.calibration.files import make_measurement
from jwarp.calibration.estimate.result import model_frames
from jwarp.calibration.simulate.scenarios import (HAND_FINGERS, contact_sampler,
                                                  hand_contact_setup)

from calib_common import (accuracy_checks, distance_stats_mm, example_parser, falls_check,
                          floor_line, parse_example, print_table, report_checks, run_rows,
                          split_campaign, start)

# contact paper Table I (real DLR-Hand II): contact distance mean, std, max [mm]; task mean
PAPER = {"nominal": (6.07, 3.90, 17.70), "joint offsets": (1.04, 0.82, 5.13),
         "full DH": (0.72, 0.58, 3.69)}
THUMB_PAIRS = (("thumb", "index"), ("thumb", "middle"), ("thumb", "ring"))
FINGER_PAIRS = (("index", "middle"), ("middle", "ring"))
PAPER_TASK = {"nominal": 8.01, "joint offsets": 1.36, "full DH": 0.89}


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    ap = example_parser(__doc__, noise=0.5, noise_help="distance noise sigma [mm]",
                        quick_help="120 calibration / 60 test rows (< 1 minute)")
    ap.add_argument("--task", type=int, default=500,
                    help="uniform configurations of the task error (default 500)")
    ap.add_argument("--finger-pairs", action="store_true",
                    help="also measure index-middle and middle-ring contacts (all chains "
                         "pairwise connected, as the thesis' all-pairs calibration)")
    return parse_example(ap, argv, {"samples": 120, "test": 60, "task": 200},
                         positive=("samples", "test", "task"))


def tip_positions(robot: jwarp.RobotModel, q: np.ndarray) -> np.ndarray:
    """(S, 3, 3) fingertip positions relative to the thumb tip [m] (eq. 2.46)."""
    F = model_frames(robot, q)
    x = np.stack([F[:, robot.frame_index(f"{f}_tip"), :3, 3] for f in HAND_FINGERS], axis=1)
    return x[:, 1:] - x[:, :1]


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    robot, t_all = start("hand4")
    pairs = THUMB_PAIRS + (FINGER_PAIRS if args.finger_pairs else ())
    setup = hand_contact_setup(noise=args.noise * 1e-3, pairs=pairs)
    sampler = contact_sampler(robot, setup)
    camp = simulate_campaign(robot, setup, args.samples + args.test, seed=args.seed,
                             length_error=0.005, angle_error=math.radians(5.0),  # thesis 2.6.1
                             kappa=None, sampler=sampler)
    t_sim = time.perf_counter() - t_all
    meas = make_measurement(robot, camp.setup)
    data = split_campaign(camp, args.samples, args.test)
    rng = np.random.default_rng(args.seed + 1000)
    q_task = uniform_configurations(robot, rng, args.task)
    tips_true = tip_positions(camp.true_robot, q_task)
    counts = np.bincount(camp.samples.meta["pair"], minlength=len(meas.pairs))
    print(f"hand4 fingertip contacts {', '.join('-'.join(p) for p in meas.pairs)} "
          f"({', '.join(map(str, counts))} samples): {args.samples} calibration / {args.test} "
          f"test rows, seed {args.seed}, noise {args.noise:g} mm; truth: DH errors +-5 mm / "
          f"+-5 deg; campaign simulated in {t_sim:.1f} s")
    print(floor_line(1, args.noise, "mm"))

    def task_mm(r):
        model = robot if r.result is None else r.result.robot
        return distance_stats_mm(tip_positions(model, q_task), tips_true)

    plan = [("nominal", None), ("joint offsets", ["theta"]),
            ("full DH", ["theta", "d", "r", "alpha"])]
    rows = run_rows(plan, robot, meas, data, args, "mm", scale=1000.0,
                    extra={"task mm": task_mm})
    print_table("contact paper Table I (simulated): contact distance errors [mm], task "
                "error [mm]", rows, "mm", PAPER, extra=["task mm"])
    print("paper task error mean [mm]: "
          + ", ".join(f"{k} {v:.2f}" for k, v in PAPER_TASK.items()))
    checks = [*accuracy_checks(rows[-1], 1, args.noise, "mm"),
              falls_check("nominal > joint offsets > full DH (test mean, mm)", rows)]
    return report_checks(checks, t_all, "acceptance of 'full DH' (the truth is inside this "
                                        "model)")


if __name__ == "__main__":
    sys.exit(main())
