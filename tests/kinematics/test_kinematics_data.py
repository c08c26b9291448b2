"""KinematicsData(model, batch) with forward_kinematics / frame_jacobian: the numpy
reference, bit-identical to jwarp.fk / jwarp.jacobian, the same buffers returned by every
call (no allocation, no new launch), clear errors naming the argument."""

import dataclasses

import numpy as np
import pytest
import warp as wp
from devices import cuda_available
from reference import ref_fk, ref_jacobian_fd, sample_q

import jwarp
from jwarp.core.device import put_model
from jwarp.kinematics import (
    KinematicsData,
    forward_kinematics,
    frame_dh_jacobian,
    frame_jacobian,
    launch,
)

ROBOTS = ["planar5", "arm7", "justin19"]
DTYPES = [np.float64, np.float32]
TCP = {"planar5": "tcp", "arm7": "right_tcp", "justin19": "right_tcp"}
B = 9


def tol(dtype):
    return 1e-9 if dtype == np.float64 else 2e-5


def frames_np(a: wp.array) -> np.ndarray:
    """A host copy (B, n_frames, 4, 4) of frames (on the CPU, .numpy() is a view of the
    buffer, which the next call overwrites)."""
    return np.array(a.numpy()).reshape(a.shape[0], a.shape[1], 4, 4)


def host(a: wp.array) -> np.ndarray:
    """A host copy of a Warp array (not a view of a reused buffer)."""
    return np.array(a.numpy())


def forbid_new_launches_and_arrays(mp: pytest.MonkeyPatch) -> None:
    """Make any wp.launch (argument packing) or new Warp array raise."""
    def boom(*a, **k):
        raise AssertionError("allocated or launched anew")
    for name in ("launch", "empty", "zeros", "clone", "empty_like", "zeros_like"):
        mp.setattr(wp, name, boom)
    mp.setattr(wp.array, "__init__", boom)


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("name", ROBOTS)
def test_forward_kinematics_equals_reference_and_fk(device, name, dtype):
    robot = jwarp.robot(name)
    m = put_model(robot, device, dtype)
    d = KinematicsData(m, B)
    q = sample_q(robot, B, seed=1).astype(dtype)
    frames = forward_kinematics(m, d, q)
    assert frames is d.frames
    assert frames.shape == (B, robot.n_frames) and frames.device == wp.get_device(device)
    got = frames_np(frames)
    assert got.dtype == dtype
    np.testing.assert_allclose(got, ref_fk(robot, q.astype(np.float64)), atol=tol(dtype), rtol=0)
    # bit-identical to the public fk: the small-call path (numpy) and the general path (Warp)
    np.testing.assert_array_equal(got, jwarp.fk(robot, q, device=device))
    wq = wp.array(q, dtype=m.scalar, device=device)
    np.testing.assert_array_equal(got, frames_np(jwarp.fk(robot, wq)))
    # the check can fail: another q gives other frames
    q2 = q.copy()
    q2[:, 0] += 0.3
    assert np.abs(frames_np(forward_kinematics(m, d, q2)) - got).max() > 1e-3


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("name", ROBOTS)
def test_frame_jacobian_equals_reference_and_jacobian(device, name, dtype):
    robot = jwarp.robot(name)
    m = put_model(robot, device, dtype)
    d = KinematicsData(m, B)
    q = sample_q(robot, B, seed=2).astype(dtype)
    tcp = TCP[name]
    fi = robot.frame_index(tcp)
    jac = frame_jacobian(m, d, tcp, q)
    assert jac is d.jacobian and jac.shape == (B, 6, robot.n_dof)
    got = host(jac)
    fd = ref_jacobian_fd(robot, q.astype(np.float64), fi)
    np.testing.assert_allclose(got, fd, atol=1e-6 if dtype == np.float64 else 5e-5)
    np.testing.assert_array_equal(got, jwarp.jacobian(robot, q, tcp, device=device))
    # by index, at a point, and back at the origin: one recorded launch, point set in place
    point = [0.05, -0.02, 0.1]
    jp = host(frame_jacobian(m, d, fi, q, point=point))
    np.testing.assert_array_equal(jp, jwarp.jacobian(robot, q, fi, point=point, device=device))
    assert np.abs(jp - got)[:, :3].max() > 1e-4      # the point moved the linear rows
    np.testing.assert_array_equal(frame_jacobian(m, d, tcp, q).numpy(), got)
    # another frame of the same data
    other = 3
    np.testing.assert_array_equal(frame_jacobian(m, d, other, q).numpy(),
                                  jwarp.jacobian(robot, q, other, device=device))
    np.testing.assert_array_equal(frame_jacobian(m, d, tcp, q).numpy(), got)


def _perturbed_rows(robot, seed):
    """(B, n_frames, 5) DH rows: the nominal ones plus up to 1 cm / 0.02 rad per entry."""
    rng = np.random.default_rng(seed)
    return robot.dh_table[None] + rng.uniform(-0.01, 0.01, (B, robot.n_frames, 5)) \
        * robot.is_dh[None, :, None]


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("name", ["arm7", "justin19"])
def test_dh_rows_equal_fk_and_jacobian_dh(device, name, dtype):
    """forward_kinematics(dh=) and frame_dh_jacobian equal jwarp.fk(dh=) and
    jwarp.jacobian_dh bit for bit (rows shared or per configuration, numpy or Warp), and the
    DH Jacobian equals central differences of the FK."""
    robot = jwarp.robot(name)
    m = put_model(robot, device, dtype)
    d = KinematicsData(m, B)
    q = sample_q(robot, B, seed=4).astype(dtype)
    rows = _perturbed_rows(robot, 5)
    got = frames_np(forward_kinematics(m, d, q, dh=rows))
    np.testing.assert_array_equal(got, jwarp.fk(robot, q, dh=rows, device=device))
    assert np.abs(got - frames_np(forward_kinematics(m, d, q))).max() > 1e-4  # rows matter
    shared = robot.dh_table + 0.003
    wrows = wp.array(shared.astype(dtype), dtype=m.scalar, device=device)
    np.testing.assert_array_equal(frames_np(forward_kinematics(m, d, q, dh=wrows)),
                                  jwarp.fk(robot, q, dh=shared, device=device))
    tcp = TCP[name]
    jd = frame_dh_jacobian(m, d, tcp, q, dh=rows)
    assert jd is d.jacobian_dh and jd.shape == (B, 6, robot.n_frames, 5)
    got_j = host(jd)
    np.testing.assert_array_equal(got_j, jwarp.jacobian_dh(robot, q, tcp, dh=rows,
                                                           device=device))
    point = [0.02, 0.0, -0.05]
    np.testing.assert_array_equal(
        host(frame_dh_jacobian(m, d, tcp, q, point=point, dh=rows)),
        jwarp.jacobian_dh(robot, q, tcp, point=point, dh=rows, device=device))
    if dtype == np.float64:   # position rows against central differences of the rows
        fi, h = robot.frame_index(tcp), 1e-6
        for f, c in ((int(np.nonzero(robot.is_dh)[0][1]), 0), (fi - 1, 1), (fi - 2, 3)):
            if not robot.is_dh[f]:
                continue
            up, dn = rows.copy(), rows.copy()
            up[:, f, c] += h
            dn[:, f, c] -= h
            fd = (frames_np(forward_kinematics(m, d, q, dh=up))[:, fi, :3, 3]
                  - frames_np(forward_kinematics(m, d, q, dh=dn))[:, fi, :3, 3]) / (2 * h)
            np.testing.assert_allclose(got_j[:, :3, f, c], fd, atol=1e-7)


def test_bad_dh_names_dh(device):
    robot = jwarp.robot("arm7")
    m = put_model(robot, device, np.float64)
    d = KinematicsData(m, 3)
    q = sample_q(robot, 3, seed=1)
    n = robot.n_frames
    with pytest.raises(ValueError, match=r"dh: expected shape"):
        forward_kinematics(m, d, q, dh=np.zeros((n, 4)))
    with pytest.raises(ValueError, match=r"dh: expected shape"):
        frame_dh_jacobian(m, d, "right_tcp", q, dh=np.zeros((2, n, 5)))
    bad = robot.dh_table.copy()
    bad[1, 0] = np.nan
    with pytest.raises(ValueError, match="dh"):
        forward_kinematics(m, d, q, dh=bad)
    with pytest.raises(TypeError, match=r"dh: Warp array of float32"):
        forward_kinematics(m, d, q, dh=wp.zeros((n, 5), dtype=wp.float32, device=device))
    with pytest.raises(TypeError, match="dh"):
        forward_kinematics(m, d, q, dh="rows")
    with pytest.raises(ValueError, match="right_hand"):
        frame_dh_jacobian(m, d, "right_hand", q)
    nan_w = wp.array(bad, dtype=wp.float64, device=device)
    with pytest.raises(ValueError, match="dh"):
        frame_dh_jacobian(m, d, "right_tcp", q, dh=nan_w)
    frame_dh_jacobian(m, d, "right_tcp", q, dh=nan_w, validate=False)  # not checked: runs


def test_second_call_returns_the_same_buffer_with_new_values(device):
    robot = jwarp.robot("justin19")
    m = put_model(robot, device, np.float64)
    d = KinematicsData(m, 4)
    q1, q2 = sample_q(robot, 4, seed=3), sample_q(robot, 4, seed=4)
    f1 = forward_kinematics(m, d, q1)
    keep = frames_np(f1).copy()
    j1 = frame_jacobian(m, d, "left_tcp", q1)
    jkeep = host(j1)
    ptr_f, ptr_j = f1.ptr, j1.ptr
    with pytest.MonkeyPatch.context() as mp:   # the recorded launches only, same arrays
        forbid_new_launches_and_arrays(mp)
        f2 = forward_kinematics(m, d, q2)
        j2 = frame_jacobian(m, d, "left_tcp", q2)
        jp = frame_jacobian(m, d, "left_tcp", q2, point=[0.0, 0.1, 0.0])
    assert f2 is f1 and j2 is j1 and jp is j1
    assert f2.ptr == ptr_f and j2.ptr == ptr_j
    f2h = frames_np(f2)
    np.testing.assert_allclose(f2h, ref_fk(robot, q2), atol=1e-9)
    np.testing.assert_array_equal(   # j2 is jp: the buffer holds the last Jacobian
        host(j2), jwarp.jacobian(robot, q2, "left_tcp", point=[0.0, 0.1, 0.0], device=device))
    assert np.abs(f2h - keep).max() > 1e-3 and np.abs(j2.numpy() - jkeep).max() > 1e-3


def test_q_from_a_warp_array_or_already_in_d_q(device):
    robot = jwarp.robot("arm7")
    m = put_model(robot, device, np.float32)
    d = KinematicsData(m, 5)
    q = sample_q(robot, 5, seed=5).astype(np.float32)
    ref = jwarp.fk(robot, q, device=device)
    np.testing.assert_array_equal(frames_np(forward_kinematics(m, d, wp.array(q, device=device))), ref)
    d.q.assign(sample_q(robot, 5, seed=6).astype(np.float32))
    d.q.assign(q)                         # filled in place, q=None uses it
    np.testing.assert_array_equal(frames_np(forward_kinematics(m, d)), ref)
    np.testing.assert_array_equal(frames_np(forward_kinematics(m, d, d.q)), ref)
    np.testing.assert_array_equal(frame_jacobian(m, d, "tcp").numpy(),
                                  jwarp.jacobian(robot, q, "tcp", device=device))
    # float64 numpy q into a float32 model: cast like jwarp.fk(..., dtype=float32)
    q64 = sample_q(robot, 5, seed=7)
    np.testing.assert_array_equal(frames_np(forward_kinematics(m, d, q64)),
                                  jwarp.fk(robot, q64, device=device, dtype=np.float32))
    # a list works as numpy does
    np.testing.assert_array_equal(frames_np(forward_kinematics(m, d, q.tolist())), ref)


def test_cuda_numpy_calls_back_to_back_keep_their_q():
    """Numpy q on CUDA goes through a pinned staging buffer copied asynchronously: a second
    call must not overwrite it before the first copy has read it."""
    if not cuda_available():
        pytest.skip("no CUDA device")
    robot = jwarp.robot("justin19")
    m = put_model(robot, "cuda:0", np.float64)
    d = KinematicsData(m, 256)
    qs = [sample_q(robot, 256, seed=s) for s in range(6)]
    kept = []
    for q in qs:                          # no host sync in between
        kept.append(wp.clone(forward_kinematics(m, d, q)))
    for q, f in zip(qs, kept):
        np.testing.assert_allclose(frames_np(f), ref_fk(robot, q), atol=1e-9)


@pytest.mark.parametrize("batch,err,match", [
    (0, ValueError, r"batch: expected >= 1 configurations, got 0"),
    (-3, ValueError, "batch: expected >= 1"),
    (2.5, TypeError, "batch: expected an integer"),
    (True, TypeError, "batch: expected an integer"),
    ("4", TypeError, "batch: expected an integer"),
])
def test_bad_batch_names_batch(batch, err, match):
    m = put_model(jwarp.robot("planar5"), "cpu", np.float64)
    with pytest.raises(err, match=match):
        KinematicsData(m, batch)


@pytest.mark.parametrize("model", ["justin19", None, 3, "RobotModel"])
def test_bad_model_names_model(model):
    if model == "RobotModel":
        model = jwarp.robot("justin19")
    with pytest.raises(TypeError, match="model: expected a DeviceModel"):
        KinematicsData(model, 4)


def test_bad_q_names_q_and_leaves_frames_alone(device):
    robot = jwarp.robot("justin19")
    m = put_model(robot, device, np.float32)
    d = KinematicsData(m, 3)
    q = sample_q(robot, 3, seed=8).astype(np.float32)
    good = frames_np(forward_kinematics(m, d, q)).copy()
    with pytest.raises(ValueError, match=r"q: expected shape \(3, 19\) .*got \(3, 18\)"):
        forward_kinematics(m, d, q[:, :18])
    with pytest.raises(ValueError, match=r"q: expected shape \(3, 19\) .*got \(19,\)"):
        forward_kinematics(m, d, q[0])
    with pytest.raises(ValueError, match=r"q: expected shape \(3, 19\) .*got \(2, 19\)"):
        frame_jacobian(m, d, "right_tcp", q[:2])
    bad = q.copy()
    bad[1, 4] = np.nan
    with pytest.raises(ValueError, match=r"q: contains NaN or inf \(batch rows \[1\]\)"):
        forward_kinematics(m, d, bad)
    with pytest.raises(ValueError, match=r"q: contains NaN or inf \(batch rows \[1\]\)"):
        frame_jacobian(m, d, "right_tcp", bad)
    with pytest.raises(ValueError, match=r"q: values overflow float32 .*\(batch rows \[2\]\)"):
        big = q.astype(np.float64)
        big[2, 0] = 1e39
        forward_kinematics(m, d, big)
    with pytest.raises(ValueError, match="q: contains NaN"):
        forward_kinematics(m, d, wp.array(bad, device=device))
    with pytest.raises(ValueError, match="q: contains NaN"):
        d.q.assign(bad)
        forward_kinematics(m, d)          # d.q as filled is checked too
    with pytest.raises(TypeError, match="q: Warp array of float64, expected float32"):
        forward_kinematics(m, d, wp.array(q.astype(np.float64), device=device))
    with pytest.raises(ValueError, match=r"q: expected shape \(3, 19\)"):
        forward_kinematics(m, d, wp.array(q[:2], device=device))
    with pytest.raises(TypeError, match="q: expected numbers, got booleans"):
        forward_kinematics(m, d, np.zeros((3, 19), bool))
    other = "cpu" if device != "cpu" else ("cuda:0" if cuda_available() else None)
    if other is not None:
        with pytest.raises(ValueError, match=f"q: Warp array on {other}"):
            forward_kinematics(m, d, wp.array(q, device=other))
    np.testing.assert_array_equal(frames_np(d.frames), good)   # no failed call wrote frames
    assert np.isnan(frames_np(forward_kinematics(m, d, bad, validate=False))[1]).any()
    np.testing.assert_array_equal(frames_np(forward_kinematics(m, d, q)), good)   # still usable


def test_bad_frame_point_and_mismatched_data(device):
    robot = jwarp.robot("justin19")
    m = put_model(robot, device, np.float64)
    d = KinematicsData(m, 2)
    q = sample_q(robot, 2, seed=9)
    with pytest.raises(ValueError, match="frame: unknown frame 'nose'"):
        frame_jacobian(m, d, "nose", q)
    with pytest.raises(ValueError, match="frame: frame index 27 out of range"):
        frame_jacobian(m, d, 27, q)
    with pytest.raises(ValueError, match="point: expected 3 finite numbers"):
        frame_jacobian(m, d, "right_tcp", q, point=[1.0, 2.0])
    with pytest.raises(ValueError, match="point: expected 3 finite numbers"):
        frame_jacobian(m, d, "right_tcp", q, point=[1.0, np.inf, 0.0])
    m32 = put_model(robot, device, np.float32)
    with pytest.raises(ValueError, match=f"d: made for robot 'justin19' on {device} in float64"):
        forward_kinematics(m32, d, q)
    with pytest.raises(ValueError, match="d: made for robot 'justin19'"):
        forward_kinematics(put_model(jwarp.robot("arm7"), device, np.float64), d, q)
    with pytest.raises(TypeError, match="d: expected a KinematicsData"):
        forward_kinematics(m, m, q)
    with pytest.raises(TypeError, match="m: expected a DeviceModel"):
        forward_kinematics("justin19", d, q)
    np.testing.assert_allclose(frames_np(forward_kinematics(m, d, q)), ref_fk(robot, q), atol=1e-9)


def test_equal_model_rebuilt_is_accepted(device):
    """A DeviceModel of the same content, device and dtype (not the same object, as after
    the model cache dropped it) serves the data's launches."""
    robot = jwarp.robot("planar5")
    m = put_model(robot, device, np.float64)
    d = KinematicsData(m, 3)
    twin = dataclasses.replace(m)
    assert twin is not m
    q = sample_q(robot, 3, seed=10)
    np.testing.assert_array_equal(frames_np(forward_kinematics(twin, d, q)),
                                  jwarp.fk(robot, q, device=device))


def test_small_calls_run_on_a_kinematics_data(device):
    """The small-call workspace of jwarp.fk / jwarp.jacobian holds one KinematicsData per
    (tables, batch size) serving FK and the Jacobians of every frame, bit-identical to the
    general path."""
    robot = jwarp.robot("justin19")
    q = sample_q(robot, 3, seed=11)
    launch.clear_workspaces()
    f = jwarp.fk(robot, q, device=device)
    ws = launch.workspace(put_model(robot, device, np.float64), 3)
    assert isinstance(ws.data, KinematicsData) and ws.data.batch == 3
    np.testing.assert_array_equal(frames_np(ws.data.frames), f)
    assert launch.clear_workspaces() == 1
    wq = wp.array(q, dtype=wp.float64, device=device)         # the general path
    for frame, point in [("right_tcp", None), ("left_tcp", None), ("right_tcp", [0.1, 0, 0]),
                         ("left_tcp", [0.0, 0.2, -0.1]), ("right_tcp", None), (5, None)]:
        np.testing.assert_array_equal(jwarp.jacobian(robot, q, frame, point=point, device=device),
                                      jwarp.jacobian(robot, wq, frame, point=point).numpy())
        np.testing.assert_array_equal(jwarp.fk(robot, q, device=device), f)
    assert launch.clear_workspaces() == 1     # one workspace for fk and every frame


def test_repr():
    d = KinematicsData(put_model(jwarp.robot("arm7"), "cpu", np.float32), 2)
    assert repr(d) == "KinematicsData(robot='arm7', batch=2, device='cpu', dtype=float32)"
