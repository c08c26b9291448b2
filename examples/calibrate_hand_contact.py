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

Run:  python examples/calibrate_hand_contact.py [--samples 300] [--test 200] [--seed 1]
      python examples/calibrate_hand_contact.py --quick      (< 1 minute)
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

import jwarp
from jwarp.solvers.calibration import error_stats
from jwarp.solvers.calibration.campaign import simulate_campaign, uniform_configurations
from jwarp.solvers.calibration.files import make_measurement
from jwarp.solvers.calibration.result import model_frames
from jwarp.solvers.calibration.scenarios import (HAND_FINGERS, contact_sampler,
                                                 hand_contact_setup)

from calib_common import calibrate_row, noise_floor, print_table, verdict

# contact paper Table I (real DLR-Hand II): contact distance mean, std, max [mm]; task mean
PAPER = {"nominal": (6.07, 3.90, 17.70), "joint offsets": (1.04, 0.82, 5.13),
         "full DH": (0.72, 0.58, 3.69)}
THUMB_PAIRS = (("thumb", "index"), ("thumb", "middle"), ("thumb", "ring"))
FINGER_PAIRS = (("index", "middle"), ("middle", "ring"))
PAPER_TASK = {"nominal": 8.01, "joint offsets": 1.36, "full DH": 0.89}


def parse(argv: list[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=int, default=300, help="calibration rows (default 300)")
    ap.add_argument("--test", type=int, default=200, help="test rows (default 200)")
    ap.add_argument("--seed", type=int, default=1, help="seed of truth, samples and noise")
    ap.add_argument("--noise", type=float, default=0.5,
                    help="distance noise sigma [mm] (default 0.5)")
    ap.add_argument("--task", type=int, default=500,
                    help="uniform configurations of the task error (default 500)")
    ap.add_argument("--finger-pairs", action="store_true",
                    help="also measure index-middle and middle-ring contacts (all chains "
                         "pairwise connected, as the thesis' all-pairs calibration)")
    ap.add_argument("--starts", type=int, default=1, help="multi-start count per row")
    ap.add_argument("--max-nfev", type=int, default=200, help="solver evaluations per row")
    ap.add_argument("--quick", action="store_true",
                    help="smoke run: 120 calibration / 60 test rows (< 1 minute)")
    args = ap.parse_args(argv)
    if args.quick:
        args.samples, args.test, args.task = 120, 60, 200
    if args.samples < 1 or args.test < 1 or args.task < 1:
        ap.error("--samples, --test and --task must be >= 1")
    return args


def tip_positions(robot: jwarp.RobotModel, q: np.ndarray) -> np.ndarray:
    """(S, 3, 3) fingertip positions relative to the thumb tip [m] (eq. 2.46)."""
    F = model_frames(robot, q)
    x = np.stack([F[:, robot.frame_index(f"{f}_tip"), :3, 3] for f in HAND_FINGERS], axis=1)
    return x[:, 1:] - x[:, :1]


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    jwarp.robot("hand4")
    t_all = time.perf_counter()
    robot = jwarp.robot("hand4")
    pairs = THUMB_PAIRS + (FINGER_PAIRS if args.finger_pairs else ())
    setup = hand_contact_setup(noise=args.noise * 1e-3, pairs=pairs)
    sampler = contact_sampler(robot, setup)
    camp = simulate_campaign(robot, setup, args.samples + args.test, seed=args.seed,
                             kappa=None, sampler=sampler)
    t_sim = time.perf_counter() - t_all
    meas = make_measurement(robot, camp.setup)
    truth = make_measurement(camp.true_robot, camp.true_setup)
    train = camp.samples.select(slice(0, args.samples))
    test = camp.samples.select(slice(args.samples, args.samples + args.test))
    y_clean = truth.predict(model_frames(camp.true_robot, test.q), camp.true_params, test.meta)
    rng = np.random.default_rng(args.seed + 1000)
    q_task = uniform_configurations(robot, rng, args.task)
    tips_true = tip_positions(camp.true_robot, q_task)
    counts = np.bincount(camp.samples.meta["pair"], minlength=len(meas.pairs))
    print(f"hand4 fingertip contacts {', '.join('-'.join(p) for p in meas.pairs)} "
          f"({', '.join(map(str, counts))} samples): {args.samples} calibration / {args.test} "
          f"test rows, seed {args.seed}, noise {args.noise:g} mm; truth: DH errors +-5 mm / "
          f"+-5 deg; campaign simulated in {t_sim:.1f} s")
    floor = noise_floor(1, args.noise)
    print(f"a perfect model's mean test error on the measured rows = {floor:.3f} mm (scalar)")

    plan = [("nominal", None), ("joint offsets", ["theta"]),
            ("full DH", ["theta", "d", "r", "alpha"])]
    rows = []
    for label, free in plan:
        r = calibrate_row(label, robot, meas, train, test, y_clean, free or [], scale=1000.0,
                          n_starts=args.starts, seed=args.seed, max_nfev=args.max_nfev,
                          fit=free is not None)
        model = robot if r.result is None else r.result.robot
        d = np.linalg.norm(tip_positions(model, q_task) - tips_true, axis=-1)
        r.extra["task mm"] = {k: v * 1000.0 for k, v in error_stats(d).items()}
        rows.append(r)
        print(f"  {label}: {r.test['mean']:.3f} mm ({r.time_s:.1f} s)", file=sys.stderr,
              flush=True)
    print_table("contact paper Table I (simulated): contact distance errors [mm], task "
                "error [mm]", rows, "mm", PAPER, extra=["task mm"])
    print("paper task error mean [mm]: "
          + ", ".join(f"{k} {v:.2f}" for k, v in PAPER_TASK.items()))
    full = rows[-1]
    lim = 1.5 * args.noise
    print("\nacceptance (full DH: the truth is inside this model)")
    print(f"  mean test error vs measured distances {full.test['mean']:.3f} mm <= 1.5 sigma = "
          f"{lim:.3f} mm: {verdict(full.test['mean'] <= lim)}  (perfect model {floor:.3f} mm)")
    print(f"  mean test error vs noise-free distances {full.clean['mean']:.3f} mm <= 1.5 sigma: "
          f"{verdict(full.clean['mean'] <= lim)}")
    print(f"  nominal > joint offsets > full DH: "
          f"{verdict(rows[0].test['mean'] > rows[1].test['mean'] > full.test['mean'])}")
    print(f"\ntotal {time.perf_counter() - t_all:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
