"""Target formats of ``jwarp ik`` (:mod:`jwarp.cli.targets`): quaternions, roll-pitch-yaw,
rotation vectors and 4x4 matrices against scipy's Rotation (an independent reference),
round trips, the ROS conventions, and the errors (a CLIError naming the option)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from jwarp.cli.common import CLIError
from jwarp.cli.targets import (
    matrix_target,
    parse_target,
    quaternion_matrix,
    rotvec_matrix,
    rpy_matrix,
    target_pose,
    unit_axis,
)

ROT = Rotation.random(50, random_state=7)


def text(v) -> str:
    return ",".join(repr(float(x)) for x in np.ravel(v))


def test_quaternion_matches_scipy_xyzw_and_is_normalised():
    for r in ROT:
        q = r.as_quat()                      # scipy: scalar last, as ROS
        np.testing.assert_allclose(quaternion_matrix(text(q)), r.as_matrix(), atol=1e-12)
        # any positive or negative scale is the same rotation
        np.testing.assert_allclose(quaternion_matrix(text(-3.5 * q)), r.as_matrix(), atol=1e-12)
    # identity in ROS order is 0,0,0,1 (scalar last), not 1,0,0,0
    np.testing.assert_allclose(quaternion_matrix("0,0,0,1"), np.eye(3), atol=0)
    assert not np.allclose(quaternion_matrix("1,0,0,0"), np.eye(3))


def test_rpy_is_the_ros_convention():
    for r in ROT:
        rpy = r.as_euler("xyz")              # extrinsic x, y, z = Rz Ry Rx
        np.testing.assert_allclose(rpy_matrix(text(rpy)), r.as_matrix(), atol=1e-12)
    # closed form: yaw pi/2 turns x into y; roll pi/2 turns y into z; pitch pi/2 turns z into x
    np.testing.assert_allclose(rpy_matrix(f"0,0,{np.pi / 2}") @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(rpy_matrix(f"{np.pi / 2},0,0") @ [0, 1, 0], [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(rpy_matrix(f"0,{np.pi / 2},0") @ [0, 0, 1], [1, 0, 0], atol=1e-15)
    # the order: R = Rz(y) Ry(p) Rx(r), built from single-axis rotations
    r, p, y = 0.3, -0.7, 1.9
    ref = (Rotation.from_rotvec([0, 0, y]) * Rotation.from_rotvec([0, p, 0])
           * Rotation.from_rotvec([r, 0, 0])).as_matrix()
    np.testing.assert_allclose(rpy_matrix(f"{r},{p},{y}"), ref, atol=1e-12)


def test_rotation_vector_matches_scipy():
    for r in ROT:
        np.testing.assert_allclose(rotvec_matrix(r.as_rotvec()), r.as_matrix(), atol=1e-12)
    np.testing.assert_allclose(rotvec_matrix([0.0, 0.0, 0.0]), np.eye(3))


def test_round_trips():
    """matrix -> quaternion / rpy / rotation vector / 16 numbers -> the same pose."""
    rng = np.random.default_rng(3)
    for r in ROT[:20]:
        p = rng.uniform(-1, 1, 3)
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = r.as_matrix(), p
        Tq, rot = target_pose(text(p), quat=text(Rotation.from_matrix(T[:3, :3]).as_quat()))
        Tr, _ = target_pose(text(p), rpy=text(Rotation.from_matrix(T[:3, :3]).as_euler("xyz")))
        Tv, _ = target_pose(text(np.r_[p, Rotation.from_matrix(T[:3, :3]).as_rotvec()]))
        Tm, _ = target_pose(matrix=" ".join(repr(float(v)) for v in T.ravel()))
        assert rot
        for X in (Tq, Tr, Tv, Tm):
            np.testing.assert_allclose(X, T, atol=1e-12)
    # numpy's and JSON's prints of a matrix parse too
    np.testing.assert_allclose(matrix_target(str(T.tolist())), T, atol=1e-12)
    np.testing.assert_allclose(matrix_target(np.array2string(T, precision=17)), T, atol=1e-12)


def test_position_only_target_has_identity_rotation():
    T, rot = target_pose("0.1,-0.2,0.3")
    assert not rot
    np.testing.assert_array_equal(T, [[1, 0, 0, 0.1], [0, 1, 0, -0.2], [0, 0, 1, 0.3],
                                      [0, 0, 0, 1]])
    p, rv = parse_target("1,2,3,0,0,0.5")
    np.testing.assert_array_equal(p, [1, 2, 3])
    np.testing.assert_array_equal(rv, [0, 0, 0.5])


def test_matrix_file(tmp_path):
    T = np.eye(4)
    T[:3, :3] = ROT[0].as_matrix()
    T[:3, 3] = [0.4, 0.1, 0.9]
    f = tmp_path / "pose.txt"
    f.write_text("# a pose\n" + "\n".join(" ".join(repr(float(v)) for v in row) for row in T)
                 + "\n")
    np.testing.assert_allclose(matrix_target(str(f)), T, atol=1e-12)
    g = tmp_path / "pose.csv"
    g.write_text(",".join(repr(float(v)) for v in T.ravel()))
    np.testing.assert_allclose(matrix_target(str(g)), T, atol=1e-12)


def test_matrix_nearly_rigid_is_projected():
    """Within 1e-6 the rotation is accepted and replaced by the nearest rotation."""
    R = ROT[1].as_matrix() + 4e-7 * np.array([[1, 0, 0], [0, -1, 0], [0, 0, 0]])
    T = np.eye(4)
    T[:3, :3] = R
    out = matrix_target(" ".join(repr(float(v)) for v in T.ravel()))
    np.testing.assert_allclose(out[:3, :3] @ out[:3, :3].T, np.eye(3), atol=1e-14)
    np.testing.assert_allclose(out[:3, :3], ROT[1].as_matrix(), atol=1e-6)


def error(fn, *args, option, match=None, **kw):
    with pytest.raises(CLIError) as e:
        fn(*args, **kw)
    msg = str(e.value)
    assert msg.startswith(f"{option}: "), msg
    if match is not None:
        assert match in msg, msg
    return msg


def test_errors_name_the_option(tmp_path):
    error(quaternion_matrix, "0,0,0,0", option="--quat", match="zero norm")
    error(quaternion_matrix, "0,0,1", option="--quat", match="expected 4 numbers")
    error(quaternion_matrix, "0,0,a,1", option="--quat")
    error(quaternion_matrix, "0,0,nan,1", option="--quat", match="finite")
    error(rpy_matrix, "0,0", option="--rpy", match="expected 3 numbers")
    error(rpy_matrix, "0,inf,0", option="--rpy")
    error(parse_target, "1,2", option="--target", match="3 or 6")
    error(parse_target, "1,2,3,4", option="--target", match="3 or 6")
    error(parse_target, "1,2,1e300", option="--target", match="within")
    error(unit_axis, "0,0,0", option="--free-axis", match="zero length")
    error(unit_axis, "0,1", option="--free-axis")
    np.testing.assert_allclose(unit_axis("0,0,2"), [0, 0, 1])
    # not rigid: scaled rotation, reflection, last row, wrong count, missing file
    S = np.eye(4)
    S[0, 0] = 1.01
    error(matrix_target, " ".join(map(str, S.ravel())), option="--target-matrix",
          match="not orthonormal")
    M = np.eye(4)
    M[2, 2] = -1
    error(matrix_target, " ".join(map(str, M.ravel())), option="--target-matrix",
          match="reflection")
    L = np.eye(4)
    L[3, 0] = 0.5
    error(matrix_target, " ".join(map(str, L.ravel())), option="--target-matrix",
          match="last row")
    error(matrix_target, "1 0 0 0 0 1 0 0 0 0 1 0", option="--target-matrix",
          match="expected 16 numbers")
    error(matrix_target, str(tmp_path / "nope.txt"), option="--target-matrix",
          match="no such file")
    error(matrix_target, str(tmp_path), option="--target-matrix", match="folder")
    bad = tmp_path / "bad.txt"
    bad.write_text("1 0 0 x")
    error(matrix_target, str(bad), option="--target-matrix", match="other than numbers")
    # combinations: each error names both options
    msg = error(target_pose, "1,2,3,0,0,1", quat="0,0,0,1", option="--quat",
                match="6-number --target")
    error(target_pose, "1,2,3,0,0,1", rpy="0,0,1", option="--rpy", match="6-number --target")
    error(target_pose, "1,2,3", quat="0,0,0,1", rpy="0,0,1", option="--quat", match="--rpy")
    eye = " ".join(map(str, np.eye(4).ravel()))
    error(target_pose, "1,2,3", matrix=eye, option="--target-matrix", match="--target")
    error(target_pose, None, quat="0,0,0,1", matrix=eye, option="--target-matrix",
          match="--quat")
    error(target_pose, None, option="--target", match="--target-matrix")
    assert "--target" in msg


def test_matrix_and_prior_files_are_small_regular_files(tmp_path, capsys):
    """Reliability round 4, item 7: ``--target-matrix /dev/zero`` read without a size limit
    (3 GB in 8 s). A file read for a few numbers must be a regular file of at most
    MAX_SMALL_TEXT bytes; nothing past that is read."""
    import os
    import time

    from jwarp.cli.common import MAX_SMALL_TEXT, read_small_text

    t0 = time.perf_counter()
    if os.path.exists("/dev/zero"):
        error(matrix_target, "/dev/zero", option="--target-matrix",
              match="/dev/zero is a device, not a regular file")
    assert time.perf_counter() - t0 < 5.0
    big = tmp_path / "big.txt"
    big.write_text("0 " * (MAX_SMALL_TEXT // 2 + 1))
    error(matrix_target, str(big), option="--target-matrix", match="larger than")
    fifo = tmp_path / "fifo"
    if hasattr(os, "mkfifo"):
        os.mkfifo(fifo)      # opening it would block forever
        error(matrix_target, str(fifo), option="--target-matrix", match="pipe")
    with pytest.raises(CLIError, match="--prior: .* is a folder, not a regular file"):
        read_small_text(str(tmp_path), "--prior")
    (tmp_path / "ok.json").write_text('{"theta": 1e-3}')
    assert read_small_text(str(tmp_path / "ok.json"), "--prior") == '{"theta": 1e-3}'
