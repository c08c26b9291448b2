"""Sensitivity of hand4 fingertip contacts vs the relative-position task (thesis 2.6.1,
Fig. 2.8): identifiable parameter counts per mode and the kernel-inclusion test (eq. 2.24).

Modes (all DH parameters theta, d, r, alpha of the fingers involved, 16 per finger):
``one pair`` thumb-index (32), ``three fingers`` thumb, index, middle with their three
pairs (48), ``all pairs`` the six pairs of the four fingers (64). The actual measurement is
the contact distance at configurations in contact on the nominal model (``--n`` per mode),
the task the fingertip positions relative to the thumb tip (eq. 2.46) at ``--n`` uniform
configurations. Jacobians unwhitened, at the nominal model.

Columns: identifiable counts by numerical rank (eigenvalue > 1e-12 x the largest; exact
kernels sit at ~1e-16) and by the thesis' absolute threshold 1e-6 (Fig. 2.8), the
kernel-inclusion verdict at each, the thesis' counts, and the count the hand's known
redundancies predict.

Known redundancies (checked): each finger's three parallel flexion axes leave 2
combinations of their ``d`` offsets unidentifiable (the thesis' 8 of 64), and hand4 has one
more, shared by both measurements: index, middle and ring bases have the palm's
orientation, so the translations the first DH row of every finger can make (r along the
base x, d along the base z) share one direction ``v = y_palm x y_thumb_base``: a common shift
of all fingertips along ``v`` changes no relative position and no distance (on the
DLR-Hand II only ring and middle share an orientation, so three different planes have no
common direction: the thesis counts 56 of 64, hand4 55). The example builds these vectors
in closed form and checks that they span the task's kernel exactly, and that the task's
kernel lies inside the contact kernel (distances cannot see what positions do not see).

The all-pairs inclusion failure at the thesis threshold (contacts 54 vs 55) is the
weakest contact direction, a rigid rotation of the whole hand about ``v``: distances do
not change under a rigid motion, and the first DH rows can make that rotation exactly only
when the finger bases lie in one plane normal to ``y_palm x v``; hand4's middle base sits
5 mm ahead of index and ring (x 0.095 vs 0.090 m), so the direction is identifiable, but
only through that 5 mm lever (eigenvalue ~1e-9 of the largest). The counterfactual row
moves the middle base to x = 0.090: the rotation becomes an exact contact kernel
direction and eq. 2.24 fails structurally. So the failure is the geometry of hand4 (a
near-symmetry), not a bug of the contact model.

Run:  python examples/sensitivity_hand4.py [--n 200] [--seed 0]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from calib_common import Check, report_checks

import jwarp
from jwarp.model import RobotModel
from jwarp.calibration.simulate.campaign import uniform_configurations
from jwarp.calibration.files import Setup, make_measurement
from jwarp.calibration.pool import draw_configurations
from jwarp.calibration.simulate.scenarios import HAND_FINGERS, hand_contact_setup
from jwarp.calibration.design.sensitivity import (kernel_basis, sensitivity, spectrum,
                                                  stacked_jacobian)

FREE = "theta,d,r,alpha"
THESIS_ATOL = 1e-6
#: thesis Fig. 2.8: (contact, relative) identifiable counts
THESIS = {"one pair": (26, 27), "three fingers": (42, 42), "all pairs": (56, 56)}


def modes() -> dict[str, tuple[str, ...]]:
    return {"one pair": ("thumb", "index"), "three fingers": ("thumb", "index", "middle"),
            "all pairs": HAND_FINGERS}


def pairs_of(fingers: tuple[str, ...]) -> tuple[tuple[str, str], ...]:
    return tuple((a, b) for i, a in enumerate(fingers) for b in fingers[i + 1:])


def known_kernel(robot: RobotModel, names: list[str], fingers: tuple[str, ...]) -> np.ndarray:
    """Closed-form kernel of the relative task (P, k): per finger the two parallel-axis
    d combinations, and the common translation along v (module docstring)."""
    cols = []
    idx = {n: i for i, n in enumerate(names)}
    for f in fingers:
        for a, b in (("proximal", "intermediate"), ("intermediate", "distal")):
            v = np.zeros(len(names))
            v[idx[f"{f}_{a}.d"]], v[idx[f"{f}_{b}.d"]] = 1.0, -1.0
            cols.append(v)
    F = jwarp.fk(robot, np.zeros(robot.n_dof), device="cpu", dtype="float64")
    R = {f: np.asarray(F[robot.frame_index(f"{f}_base"), :3, :3]) for f in fingers}
    ys = np.array([R[f][:, 1] for f in fingers])            # base y axes (plane normals)
    # a direction normal to every base y axis (exists when they span <= 2 dimensions)
    _, s, Vt = np.linalg.svd(ys)
    if s.size < 3 or s[-1] < 1e-9:
        v = Vt[-1]
        t = np.zeros(len(names))
        for f in fingers:
            t[idx[f"{f}_knuckle.r"]] = v @ R[f][:, 0]
            t[idx[f"{f}_knuckle.d"]] = v @ R[f][:, 2]
        cols.append(t)
    return np.array(cols).T


def span_equal(K: np.ndarray, E: np.ndarray, tol: float = 1e-6) -> bool:
    """span(K) == span(E) (orthonormal K; E any basis)."""
    if K.shape[1] != np.linalg.matrix_rank(E, tol=tol):
        return False
    Q = np.linalg.qr(E)[0]
    return bool(np.linalg.norm(Q - K @ (K.T @ Q)) < tol and np.linalg.norm(K - Q @ (Q.T @ K)) < tol)


def contained(Ksmall: np.ndarray, Kbig: np.ndarray, tol: float = 1e-6) -> bool:
    return bool(np.linalg.norm(Ksmall - Kbig @ (Kbig.T @ Ksmall)) < tol)


def rigid_residual(robot: RobotModel, d: np.ndarray, q: np.ndarray,
                   fingers: tuple[str, ...]) -> float:
    """How far the fingertip motion of the parameter direction ``d`` is from one rigid
    motion of the whole hand: the tips' first-order displacements dx (at configurations
    q) fitted by ``w x x + t`` (6 unknowns, least squares); returns |residual| / |dx|."""
    absolute = make_measurement(robot, Setup(plugin="relative", robot="hand4", section={
        "end_effectors": ["palm"] + [f"{f}_tip" for f in fingers]}))
    J, _ = stacked_jacobian(robot, absolute, q, FREE)
    dx = (J @ d).reshape(-1, 3)
    x = absolute.predict(jwarp.fk(robot, q, device="cpu", dtype="float64"),
                         absolute.params.nominal).reshape(-1, 3)
    A = np.zeros((len(x), 3, 6))
    A[:, 0, 1], A[:, 0, 2] = x[:, 2], -x[:, 1]         # w x x = -[x]x w
    A[:, 1, 0], A[:, 1, 2] = -x[:, 2], x[:, 0]
    A[:, 2, 0], A[:, 2, 1] = x[:, 1], -x[:, 0]
    A[:, :, 3:] = np.eye(3)
    A = A.reshape(-1, 6)
    sol = np.linalg.lstsq(A, dx.reshape(-1), rcond=None)[0]
    return float(np.linalg.norm(A @ sol - dx.reshape(-1)) / np.linalg.norm(dx))


def middle_base_at(robot: RobotModel, x: float) -> RobotModel:
    doc = robot.to_dict()
    for fr in doc["frames"]:
        if fr["name"] == "middle_base":
            fr["transform"][0][3] = x
    return RobotModel.from_dict(doc)


def run_mode(robot: RobotModel, fingers: tuple[str, ...], n: int, seed: int) -> dict:
    setup = hand_contact_setup(pairs=pairs_of(fingers))
    actual = make_measurement(robot, setup)
    task = make_measurement(robot, Setup(plugin="relative", robot="hand4", section={
        "end_effectors": [f"{f}_tip" for f in fingers]}))
    q, meta = draw_configurations(robot, setup, n, seed)
    qt = uniform_configurations(robot, np.random.default_rng(seed + 1), n)
    res = sensitivity(robot, actual, q, task, qt, FREE, meta_actual=meta)
    res6 = sensitivity(robot, actual, q, task, qt, FREE, meta_actual=meta, atol=THESIS_ATOL)
    Ja, na = stacked_jacobian(robot, actual, q, FREE, meta=meta)
    Jt, nt = stacked_jacobian(robot, task, qt, FREE)
    assert na == nt == res.names
    Ka, Kt = kernel_basis(Ja), kernel_basis(Jt)
    E = known_kernel(robot, nt, fingers)
    ev = spectrum(Ja).eigenvalues
    weakest = ev[res.actual.n_identifiable - 1] / ev[0]
    # the weakest identifiable contact direction vs the direction breaking the inclusion at
    # the thesis threshold
    _, _, Vt = np.linalg.svd(Ja, full_matrices=False)
    cos = max((abs(float(Vt[res.actual.n_identifiable - 1] @ d.vector)) for d in res6.breaking),
              default=float("nan"))
    rigid = rigid_residual(robot, res6.breaking[0].vector, qt, fingers) if res6.breaking \
        else float("nan")
    return {"res": res, "res6": res6, "rigid": rigid, "known": E.shape[1], "task_kernel_known": span_equal(Kt, E),
            "task_in_contact": contained(Kt, Ka), "weakest": weakest, "cos": cos, "P": len(nt)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=200,
                    help="configurations per measurement and mode (default 200; thesis 100)")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    if args.n < 1:
        ap.error("--n must be >= 1")
    robot = jwarp.robot("hand4")
    t0 = time.perf_counter()
    rows = {name: run_mode(robot, f, args.n, args.seed) for name, f in modes().items()}
    counter = middle_base_at(robot, 0.090)
    rows["all pairs, middle base x=0.090"] = run_mode(counter, HAND_FINGERS, args.n, args.seed)
    print(f"hand4 sensitivity: contacts (actual) vs fingertips relative to the thumb (task), "
          f"{args.n} configurations each, free {FREE}, seed {args.seed}")
    print(f"\n{'mode':<32}{'P':>4}{'known':>7} | {'rank (rtol 1e-12)':^26} | "
          f"{'thesis threshold 1e-6':^26} | {'thesis':>8}  {'weakest':>9}")
    print(f"{'':<32}{'':>4}{'':>7} | {'contact':>8}{'task':>6}{'eq.2.24':>12} | "
          f"{'contact':>8}{'task':>6}{'eq.2.24':>12} | {'c / t':>8}  {'contact':>9}")

    def verdict(r):
        return "holds" if r.kernel_included else f"fails({len(r.breaking)})"

    for name, d in rows.items():
        r, r6 = d["res"], d["res6"]
        th = THESIS.get(name)
        print(f"{name:<32}{d['P']:>4}{d['P'] - d['known']:>7} | {r.actual.n_identifiable:>8}"
              f"{r.task.n_identifiable:>6}{verdict(r):>12} | {r6.actual.n_identifiable:>8}"
              f"{r6.task.n_identifiable:>6}{verdict(r6):>12} | "
              f"{f'{th[0]}/{th[1]}' if th else '-':>8}  {d['weakest']:>9.1e}")
    print("\nknown = P - (2 parallel-axis d combinations per finger + 1 common translation "
          "along y_palm x y_thumb_base); weakest = smallest identifiable contact eigenvalue / "
          "largest")
    for name, d in rows.items():
        for k, b in enumerate(d["res"].breaking + d["res6"].breaking):
            top = ", ".join(f"{n} {w:+.2f}" for n, w in b.top[:5])
            print(f"breaking direction ({name}): {top}")
    d = rows["all pairs"]
    print(f"\nall pairs at the thesis threshold: the breaking direction is the weakest "
          f"identifiable contact eigenvector (|cos| = {d['cos']:.4f}), eigenvalue "
          f"{d['weakest']:.1e} of the largest: a near-symmetry of hand4's geometry (rigid "
          f"rotation of the hand, identifiable only through the middle base's 5 mm offset), "
          f"not a bug of the contact model; with the middle base moved in line it becomes "
          f"exact (last row)")

    checks = []
    one, three, allp = rows["one pair"], rows["three fingers"], rows["all pairs"]
    cf = rows["all pairs, middle base x=0.090"]
    checks.append(("one pair: contact 26, task 27 identifiable (as the thesis), eq. 2.24 "
                   "fails by one direction",
                   (one["res"].actual.n_identifiable, one["res"].task.n_identifiable,
                    len(one["res"].breaking)) == (26, 27, 1)))
    for name, d in (("three fingers", three), ("all pairs", allp)):
        checks.append((f"{name}: equal identifiable counts and eq. 2.24 holds",
                       d["res"].actual.n_identifiable == d["res"].task.n_identifiable
                       and d["res"].kernel_included))
    for name in modes():
        d = rows[name]
        checks.append((f"{name}: the task kernel is exactly the known redundancies "
                       f"({d['known']} directions) and lies in the contact kernel",
                       d["task_kernel_known"] and d["task_in_contact"]))
    checks.append(("all pairs: the weakest contact direction is weak (< 1e-6 of the largest) "
                   "but identifiable", allp["weakest"] < 1e-6))
    checks.append((f"all pairs: the direction breaking eq. 2.24 at the thesis threshold moves "
                   f"the fingertips nearly rigidly (residual of a rigid fit "
                   f"{allp['rigid']:.3f} < 0.05), in line exactly ({cf['rigid']:.1e} < 1e-6)",
                   allp["rigid"] < 0.05 and cf["rigid"] < 1e-6))
    checks.append(("counterfactual (middle base in line): the near-symmetry becomes exact, "
                   "contact = task - 1 and eq. 2.24 fails by one direction",
                   cf["res"].actual.n_identifiable == cf["res"].task.n_identifiable - 1
                   and len(cf["res"].breaking) == 1))
    return report_checks([Check(text, ok) for text, ok in checks], t0)


if __name__ == "__main__":
    sys.exit(main())
