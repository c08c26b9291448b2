#!/usr/bin/env python
"""Time of a full elastic MAP calibration of justin19 on a simulated tracker campaign.

The truth is inside the model: nominal DH rows plus uniform errors (+-5 mm, +-5 deg on
theta, d, r, alpha of every DH frame), compliances kappa_theta and kappa_alpha drawn from
[0.5, 1.5] x 1e-4 rad/(N m), a tracker 3 m in front of the robot, markers 5 cm off each
TCP, Gaussian noise. The setup handed to the solver is rough: tracker pose off by
decimetres and tens of degrees, markers off by centimetres. Free: all DH groups (theta,
d, r, alpha, beta) + kappa_theta + kappa_alpha + tracker + markers (the paper's full
model, 3 minutes there).

    python benchmarks/bench_calibration.py                 # 300 train + 200 test samples
    python benchmarks/bench_calibration.py --samples 100 --test 100 --quick
    python benchmarks/bench_calibration.py --threads 1     # one CPU core (BLAS threads)
    python benchmarks/bench_calibration.py --case systematic   # the data the model cannot fit

Section ``systematic`` (issue 16's speed acceptance: <= 10 s on one CPU core): the truth is
*outside* the calibration model, as a real robot is (:func:`systematic_truth`): smaller DH
errors (+-1 mm, +-0.25 deg, on beta too), kappa_theta and kappa_alpha as above, *lateral*
compliance kappa_beta of the same size (not free in the full model), and joint transmission
errors: two harmonics of every joint angle, amplitude up to ``--harmonic`` rad, applied to
q before the forward kinematics (:func:`transmission_error`). The MAP fit then ends with a
residual far above the noise and takes several times the iterations of clean data.

Prints the machine, the wall time of the calibration (min and median over ``--repeats``
runs after an untimed warm-up run, through ``benchmarks/timing.py``: every run solves the
same problem from the same seed), iterations, function evaluations and the train/test
errors [mm] before (nominal robot, tracker and markers fitted) and after. ``--device`` is
accepted for symmetry with the other benchmarks; the calibration runs in float64 on the
CPU.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys


def _parse(argv: list[str] | None = None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=int, default=300, help="calibration samples (default 300)")
    ap.add_argument("--test", type=int, default=200, help="test samples (default 200)")
    ap.add_argument("--noise", type=float, default=1e-4, help="tracker noise sigma [m] (default 0.1 mm)")
    ap.add_argument("--free", default="theta,d,r,alpha,beta,kappa_theta,kappa_alpha,tracker,markers")
    ap.add_argument("--starts", type=int, default=1, help="multi-start count (default 1)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--threads", type=int, default=1,
                    help="BLAS/OpenMP threads (default 1: the one-core figure)")
    ap.add_argument("--device", default="cpu", help="accepted for symmetry; calibration is CPU float64")
    ap.add_argument("--repeats", type=int, default=None,
                    help="timed calibrations, min/median (default 3; --quick 2)")
    ap.add_argument("--quick", action="store_true", help="skip the 'before' calibration, 2 repeats")
    ap.add_argument("--case", choices=("clean", "systematic", "both"), default="both",
                    help="clean: truth inside the model; systematic: truth outside it "
                         "(lateral compliance, joint harmonics); default both")
    ap.add_argument("--harmonic", type=float, default=1e-3,
                    help="systematic case: largest joint transmission error amplitude [rad] "
                         "(default 1 mrad)")
    ap.add_argument("--cv", type=int, default=None, metavar="K",
                    help="also time K-fold cross-validation of the default grid (10 prior "
                         "scales) on the train rows of each case (issue 38: 5 folds x 10 "
                         "settings of 300 rows <= 2 min on 2 cores), once")
    ap.add_argument("--cv-workers", type=int, default=None, metavar="N",
                    help="processes of --cv (default: one per core)")
    ap.add_argument("--json", help="write the figures as JSON")
    return ap.parse_args(argv)


def systematic_truth(nominal, rng, *, length_error: float = 0.001,
                     angle_error: float = math.radians(0.25),
                     kappa: tuple[float, float] = (0.5e-4, 1.5e-4)):
    """A true justin19 the full calibration model cannot represent: DH errors on theta, d,
    r, alpha and beta (uniform +-``length_error`` [m] / +-``angle_error`` [rad]), joint
    and lateral compliances kappa_theta, kappa_alpha *and kappa_beta* drawn from ``kappa``
    [rad/(N m)] (kappa_beta is left out of the default free groups: unmodeled)."""
    from jwarp.calibration.estimate.params import perturb_robot

    return perturb_robot(nominal, rng, groups=("theta", "d", "r", "alpha", "beta"),
                         length_error=length_error, angle_error=angle_error, kappa=kappa,
                         kappa_groups=("kappa_theta", "kappa_alpha", "kappa_beta"))


def transmission_error(q, rng, amplitude: float, harmonics: int = 2):
    """Joint values the true robot reaches for commanded ``q`` (S, n_dof): q plus
    ``sum_k a_jk sin(k q_j + phi_jk)`` for k = 1..``harmonics`` with a_jk uniform in
    +-``amplitude`` [rad] and random phases (a gear's transmission error; unmodeled)."""
    import numpy as np

    n = q.shape[1]
    a = amplitude * rng.uniform(-1.0, 1.0, (harmonics, n))
    phase = rng.uniform(0.0, 2.0 * np.pi, (harmonics, n))
    return q + sum(a[k] * np.sin((k + 1) * q + phase[k]) for k in range(harmonics))


def main(argv: list[str] | None = None) -> int:
    args = _parse(argv)
    if args.repeats is None:
        args.repeats = 2 if args.quick else 3
    if args.repeats < 1:
        print(f"--repeats: expected >= 1, got {args.repeats}", file=sys.stderr)
        return 2
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ[var] = str(args.threads)
    import warnings

    import numpy as np

    # after the BLAS thread count: timing imports warp, which loads numpy
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import timing  # benchmarks/timing.py, beside this script

    import jwarp
    from jwarp.calibration import CalibrationWarning, calibrate, error_stats, errors
    from jwarp.calibration.estimate.params import perturb_robot
    from jwarp.calibration.estimate.result import model_frames
    from jwarp.plugins.measurements.cartesian import CartesianMeasurement

    if args.device not in ("cpu",) and not args.device.startswith("cuda"):
        print(f"--device: expected cpu or cuda, got {args.device!r}", file=sys.stderr)
        return 2
    if args.device != "cpu":
        print("note: the calibration solver runs in float64 on the CPU; --device ignored")
    rng = np.random.default_rng(args.seed)
    nominal = jwarp.robot("justin19")
    true_setup = {"plugin": "cartesian",
                  "tracker": {"position": [3.0, 0.2, 1.0], "rotvec": [0.0, 0.0, math.pi]},
                  "markers": [{"name": "right", "frame": "right_tcp", "position": [0.0, 0.02, 0.05]},
                              {"name": "left", "frame": "left_tcp", "position": [0.0, 0.02, 0.05]}],
                  "noise": args.noise}
    rough = json.loads(json.dumps(true_setup))
    rough["tracker"] = {"position": [2.7, 0.5, 1.2], "rotvec": [0.1, -0.1, math.pi - 0.35],
                        "sigma_position": 1.0, "sigma_rotation": 1.0}
    for mk in rough["markers"]:
        mk["position"] = [0.0, 0.0, 0.03]
        mk["sigma"] = 0.05
    meas = CartesianMeasurement(nominal, rough)
    lim = nominal.joint_limits
    N = args.samples + args.test
    tr, te = slice(0, args.samples), slice(args.samples, N)
    machine = timing.machine()
    doc: dict = {"machine": machine, "settings": vars(args)}

    def timed(q, y, free: str, **kw) -> tuple:
        """(result, caught CalibrationWarnings, Timing) of ``--repeats`` calibrations."""
        def call() -> tuple:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", CalibrationWarning)
                r = calibrate(nominal, meas, q[tr], y[tr], free=free, noise_sigma=args.noise, **kw)
            return r, caught
        (runs,) = timing.each_run([lambda _: call], args.repeats)
        return (*runs.results[0], runs.timing)

    def section(label: str, truth, q, q_true, noise_rng) -> dict:
        """Simulate y on ``truth`` at the joint values ``q_true`` reached for the commanded
        ``q`` (noise from ``noise_rng``), calibrate, print and return the figures."""
        m_true = CartesianMeasurement(truth, true_setup)
        y_clean = m_true.predict(model_frames(truth, q_true), m_true.params.nominal)
        y = y_clean + noise_rng.normal(0.0, args.noise, y_clean.shape)
        print(f"\n[{label}] justin19 simulated tracker campaign: {args.samples} train / "
              f"{args.test} test samples x 2 markers, noise {args.noise * 1e3:.2f} mm, free "
              f"{args.free}; {machine}; min/median of {args.repeats} runs")
        before = tb = None
        if not args.quick:
            b, _, tb = timed(q, y, "tracker,markers")
            before = {"train": error_stats(b.errors),
                      "test": error_stats(errors(nominal, meas, b.params, q[te], y[te]))}
            print(f"before (nominal robot, tracker + markers fitted in {tb.median:.2f} s): "
                  f"test mean {before['test']['mean'] * 1e3:.2f} mm, max "
                  f"{before['test']['max'] * 1e3:.2f} mm")
        res, caught, t = timed(q, y, args.free, n_starts=args.starts, seed=args.seed)
        elapsed = t.median
        after = {"train": error_stats(res.errors),
                 "test": error_stats(errors(res.robot, meas, res.params, q[te], y[te])),
                 "test_vs_truth": error_stats(errors(res.robot, meas, res.params, q[te],
                                                     y_clean[te]))}
        held = sum(int(r.get("held_at_bound", 0)) for r in res.starts)
        print(f"full calibration: {len(res.names)} free parameters, {elapsed:.2f} s wall "
              f"(median; min {t.best:.2f} s), {res.iterations} iterations, {res.nfev} "
              f"evaluations, success={res.success} ({res.message})")
        print(f"  {len(res.unidentifiable)} unidentifiable directions, {len(res.moved)} "
              f"parameters moved > 3 prior sigmas, {held} compliance(s) held at 0, "
              f"{len(caught)} CalibrationWarning(s)")
        print(f"{'errors [mm]':<26} {'mean':>8} {'std':>8} {'max':>8}")
        rows = []
        if before:
            rows += [("before train", before["train"]), ("before test", before["test"])]
        rows += [("after train", after["train"]), ("after test", after["test"]),
                 ("after test vs noise-free", after["test_vs_truth"])]
        for name, st in rows:
            print(f"{name:<26} {st['mean'] * 1e3:>8.3f} {st['std'] * 1e3:>8.3f} "
                  f"{st['max'] * 1e3:>8.3f}")
        cv_fig = None
        if args.cv:
            import time as _time

            from jwarp.calibration import CalibrationOptions, CVOptions, cross_validate

            t_cv = _time.perf_counter()
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", CalibrationWarning)
                cv = cross_validate(nominal, meas, q[tr], y[tr],
                                    CalibrationOptions(free=args.free, noise_sigma=args.noise),
                                    CVOptions(folds=args.cv, workers=args.cv_workers))
            wall_cv = _time.perf_counter() - t_cv
            print(f"cross-validation: {args.cv} folds x {len(cv.settings)} settings of "
                  f"{args.samples} rows: {wall_cv:.1f} s wall in {cv.workers} process(es); "
                  f"chosen {cv.chosen.name()} (CV mean {cv.errors[cv.best] * 1e3:.3f} mm)")
            cv_fig = {"time_s": wall_cv, "workers": cv.workers, **cv.to_dict(1e3, "mm")}
        return {"time_s": elapsed, "time_min_s": t.best, "runs": t.runs, "cv": cv_fig,
                "before_time_s": tb.figures() if tb else None,
                "iterations": res.iterations, "nfev": res.nfev, "held_at_bound": held,
                "n_params": len(res.names), "before": before, "after": after}

    n_noise = float(np.mean(np.linalg.norm(rng.normal(0, args.noise, (100000, 3)), axis=1)))
    if args.case in ("clean", "both"):
        truth = perturb_robot(nominal, rng, groups=("theta", "d", "r", "alpha"),
                              kappa=(0.5e-4, 1.5e-4), kappa_groups=("kappa_theta", "kappa_alpha"))
        q = rng.uniform(lim[:, 0], lim[:, 1], (N, nominal.n_dof))
        fig = section("clean", truth, q, q, rng)
        print(f"(mean norm of the 3D noise alone: {n_noise * 1e3:.3f} mm)")
        ok = fig["time_s"] < 30.0
        print(f"target < 30 s: {'met' if ok else 'MISSED'} ({fig['time_s']:.2f} s median)")
        doc.update(fig)  # the clean figures at the top level, as before
        doc["noise_norm_mean"] = n_noise
    if args.case in ("systematic", "both"):
        srng = np.random.default_rng(args.seed + 1000)
        truth = systematic_truth(nominal, srng)
        q = srng.uniform(lim[:, 0], lim[:, 1], (N, nominal.n_dof))
        fig = section(f"systematic: kappa_beta and joint harmonics <= {args.harmonic:g} rad "
                      f"in the truth only", truth, q, transmission_error(q, srng, args.harmonic),
                      srng)
        ok = fig["time_s"] <= 10.0
        print(f"target <= 10 s on one core: {'met' if ok else 'MISSED'} "
              f"({fig['time_s']:.2f} s median)")
        doc["systematic"] = fig
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(doc, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
