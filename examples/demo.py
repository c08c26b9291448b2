"""End-to-end demo of jwarp on DLR Agile Justin (``justin19``).

1. load the robot from the plugin registry,
2. rigid and elastic forward kinematics (compliance 0.1 rad/kNm on the joint axis and the
   two lateral axes of every DH frame) for q = 0 and 4 seeded random configurations
   inside the joint limits (with 0 <= q1 + q2 <= 135 deg for the coupled torso),
3. a table of the elastic sag of both TCPs and the iterations of the equilibrium solve,
4. Jacobians of the right TCP,
5. a batched run (thousands of configurations per call),
6. elastic compensation in planning: a collision-free path and a collision-free IK
   solution on the elastic robot in a simplex world, each checked on the converged
   torque equilibrium,
7. a rerun recording with the frames and collision spheres (rigid and elastic).

Run:  python examples/demo.py [OUT.rrd] [--seed N]      (view: rerun demo_justin19.rrd)
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np
import warp as wp

import jwarp
from jwarp import kinematics

KAPPA = 0.1e-3  # 0.1 rad/kNm = 1e-4 rad/(N m), for [alpha, beta, theta] of every DH frame


def plan_on_the_elastic_robot(robot: jwarp.RobotModel, rng: np.random.Generator) -> None:
    """A path and an IK solution on the elastic robot (one torque update per iteration),
    checked on the converged equilibrium."""
    from jwarp.solvers import compensation
    from jwarp.world import path_feasibility
    from jwarp.world.io import parse_world_spec

    world = parse_world_spec("simplex:seed=1,feasible=200", jwarp.robot(robot))
    q = random_configurations(robot, 200, rng)
    q = q[path_feasibility.collision_free(robot, world, q, 0.0, kappa=KAPPA)][:2]  # elastic robot
    t0 = time.perf_counter()
    res = compensation.compensated_plan(jwarp.robot(robot), world, q[0], q[1], kappa=KAPPA, n_starts=8,
                                        iterations=100, step=0.2, stop_when_solved=False,
                                        fallback=None)
    dt = time.perf_counter() - t0
    ok = path_feasibility.path_feasible(jwarp.robot(robot), world, res.path[0], 4 * res.n_substeps, kappa=KAPPA)
    print(f"\nelastic plan in simplex:seed=1 (voxel {100 * world.voxel_size:.1f} cm): "
          f"feasible {bool(res.feasible[0])}, {int(res.n_feasible[0])} of 8 starts, "
          f"{int(res.iterations[0])} iterations, {dt:.2f} s; re-checked on the equilibrium "
          f"at 4x the substeps: {bool(ok)}")
    T = jwarp.fk(robot, q[1])[robot.frame_index("right_tcp")]
    t0 = time.perf_counter()
    sol = compensation.compensated_ik(jwarp.robot(robot), "right_tcp", T, kappa=KAPPA, world=world)
    dt = time.perf_counter() - t0
    pos, ang = compensation.equilibrium_pose_error(jwarp.robot(robot), "right_tcp", sol.q, T, KAPPA)
    print(f"elastic IK of right_tcp: feasible {bool(sol.feasible)}, {1e3 * dt:.1f} ms; on the "
          f"converged equilibrium the hand is {1e3 * float(pos):.3f} mm / "
          f"{1e3 * float(ang):.3f} mrad off the target")


def random_configurations(model: jwarp.RobotModel, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` configurations uniform in the joint limits that satisfy the linear limits
    (for justin19: 0 <= torso_tilt_1 + torso_tilt_2 <= 135 deg), by rejection."""
    lo, hi = model.joint_limits.T
    out = []
    while len(out) < n:
        q = rng.uniform(lo, hi)
        if all(lim.lower <= sum(c * q[j] for j, c in zip(lim.joints, lim.coefficients)) <= lim.upper
               for lim in model.linear_limits):
            out.append(q)
    return np.array(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", nargs="?", default="demo_justin19.rrd", help="rerun recording to write")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    if hasattr(wp, "LOG_WARNING"):  # keep Warp's greeting and module-load lines quiet
        wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)

    t_start = time.perf_counter()
    robot = jwarp.robot("justin19")
    print(robot.summary().splitlines()[0])
    rng = np.random.default_rng(args.seed)
    q = np.vstack([np.zeros(robot.n_dof), random_configurations(robot, 4, rng)])  # (5, 19) rad

    # rigid and elastic FK of all 27 frames: (5, 27, 4, 4), float64 on the CPU
    rigid = kinematics.fk(robot, q, device="cpu", dtype=np.float64)
    elastic = kinematics.fk_elastic(robot, q, KAPPA, lam=1.0, max_iter=20,
                                    device="cpu", dtype=np.float64)
    print(f"fk: q {q.shape} -> frames {rigid.shape}; fk_elastic -> frames "
          f"{elastic.frames.shape}, rho {elastic.rho.shape}")

    tcps = ("right_tcp", "left_tcp")
    idx = [robot.frame_index(t) for t in tcps]
    sag = 1e3 * np.linalg.norm(elastic.frames[:, idx][..., :3, 3] - rigid[:, idx][..., :3, 3],
                               axis=-1)  # (5, 2) [mm]
    print(f"\nelastic sag at kappa = {KAPPA * 1e3:g} rad/kNm (joint + lateral axes), "
          f"gravity {robot.gravity.tolist()} m/s^2")
    print(f"{'config':<8} {'torso q1+q2 [deg]':>17} {'right_tcp [mm]':>15} {'left_tcp [mm]':>14} "
          f"{'iterations':>11} {'converged':>10}")
    for k in range(len(q)):
        name = "q=0" if k == 0 else f"rand{k}"
        print(f"{name:<8} {np.rad2deg(q[k, 1] + q[k, 2]):>17.1f} {sag[k, 0]:>15.3f} "
              f"{sag[k, 1]:>14.3f} {int(elastic.iterations[k]):>11d} "
              f"{str(bool(elastic.converged[k])):>10}")

    # convergence of the fixed-point iteration at q = 0 (cf. thesis Fig. 2.12)
    ref = elastic.frames[0, idx[0], :3, 3]
    left = []
    for it in range(4):
        f_it = kinematics.fk_elastic(robot, q[:1], KAPPA, max_iter=it, device="cpu",
                                     dtype=np.float64).frames[0, idx[0], :3, 3]
        left.append(1e3 * np.linalg.norm(f_it - ref))
    print("right_tcp error after 0, 1, 2, 3 torque updates [mm]: "
          + ", ".join(f"{e:.4f}" for e in left))

    # Jacobians of the right TCP: geometric (6 x 19 per configuration) and w.r.t. DH rows
    J = kinematics.jacobian(robot, q, "right_tcp", device="cpu", dtype=np.float64)
    Jdh = kinematics.jacobian_dh(robot, q, "right_tcp", device="cpu", dtype=np.float64)
    print(f"\njacobian(right_tcp): {J.shape} [(config, [v; w], joint)], "
          f"jacobian_dh(right_tcp): {Jdh.shape} [(config, [v; w], frame, DH param)]")

    # batched: thousands of configurations per call
    qb = random_configurations(robot, 4096, rng).astype(np.float32)
    for label, fn in (("fk", lambda: kinematics.fk(robot, qb, device="cpu")),
                      ("fk_elastic", lambda: kinematics.fk_elastic(robot, qb, KAPPA, device="cpu"))):
        fn()  # warm-up (kernel compilation / load)
        t0 = time.perf_counter()
        out = fn()
        dt = time.perf_counter() - t0
        shape = (out.frames if hasattr(out, "frames") else out).shape
        print(f"batched {label:<10} float32 cpu: {qb.shape} -> {shape} in {1e3 * dt:.1f} ms")

    plan_on_the_elastic_robot(robot, rng)

    # rerun recording: frames, skeleton and collision spheres, rigid and elastic
    try:
        from jwarp.viz import save_robot_rrd

        path = save_robot_rrd(robot, q, args.out, elastic_kappa=KAPPA)
        print(f"\nwrote {path} ({len(q)} configurations, {robot.n_frames} frames, "
              f"{len(robot.spheres)} spheres); view with: rerun {path}")
    except ImportError as e:
        print(f"\nno recording written: {e}", file=sys.stderr)
    print(f"demo done in {time.perf_counter() - t_start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
