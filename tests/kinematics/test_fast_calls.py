"""Small calls (reused workspaces, recorded launches) and ``out=`` of fk / jacobian /
fk_elastic: the same results as the general path, never aliased, clear errors."""

import gc
import threading

import numpy as np
import pytest
import warp as wp
from devices import requires_cuda
from reference import ref_fk, ref_jacobian_fd, sample_q

import jwarp
from jwarp import kinematics as K
from jwarp.kinematics import launch

torch = pytest.importorskip("torch")

BIG = 2000   # justin19 float64: 3.5 MB of frames, over SMALL_CALL_BYTES: the general path


@pytest.fixture(scope="module")
def justin():
    return jwarp.robot("justin19")


@pytest.fixture(scope="module")
def qs(justin):
    return sample_q(justin, BIG, seed=7)


def test_thresholds_put_one_configuration_on_the_small_path_and_big_ones_off(justin):
    row = justin.n_frames * 16 * 8
    assert row <= launch.SMALL_CALL_BYTES < BIG * row


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_small_fk_and_jacobian_equal_the_general_path(justin, qs, dtype):
    q = qs.astype(dtype)
    frames = K.fk(justin, q, device="cpu")          # general path (big)
    jac = K.jacobian(justin, q, "right_tcp", device="cpu")
    launch.clear_workspaces()
    for b in (0, 5, 17, BIG - 1):
        f1 = K.fk(justin, q[b], device="cpu")
        assert f1.shape == (27, 4, 4) and f1.dtype == dtype
        np.testing.assert_array_equal(f1, frames[b])
        j1 = K.jacobian(justin, q[b], "right_tcp", device="cpu")
        assert j1.shape == (6, 19) and j1.dtype == dtype
        np.testing.assert_array_equal(j1, jac[b])
    np.testing.assert_allclose(K.fk(justin, qs[3]), ref_fk(justin, qs[3:4])[0], atol=1e-9)


def test_repeated_calls_return_new_arrays(justin, qs):
    a = K.fk(justin, qs[0], device="cpu")
    keep = a.copy()
    b = K.fk(justin, qs[1], device="cpu")
    assert not np.shares_memory(a, b)
    np.testing.assert_array_equal(a, keep)           # not overwritten by the next call
    ja = K.jacobian(justin, qs[0], 13, device="cpu")
    jkeep = ja.copy()
    K.jacobian(justin, qs[1], 13, device="cpu")
    np.testing.assert_array_equal(ja, jkeep)
    a[...] = 0                                       # writing a result changes nothing else
    np.testing.assert_array_equal(K.fk(justin, qs[0], device="cpu"), keep)


def test_shape_and_dtype_changes_between_calls(justin, qs):
    ref = K.fk(justin, qs, device="cpu")
    for shape in [(19,), (1, 19), (3, 19), (2, 2, 19), (19,), (3, 19), (1, 1, 19)]:
        n = int(np.prod(shape[:-1]))
        out = K.fk(justin, qs[:n].reshape(shape), device="cpu")
        assert out.shape == shape[:-1] + (27, 4, 4)
        np.testing.assert_array_equal(out.reshape(-1, 27, 4, 4), ref[:n])
    f32 = K.fk(justin, qs[0], device="cpu", dtype=np.float32)   # float64 q, float32 compute
    assert f32.dtype == np.float32
    np.testing.assert_allclose(f32, ref[0], atol=1e-5)
    np.testing.assert_array_equal(K.fk(justin, qs[0], device="cpu"), ref[0])


def test_validation_unchanged_on_the_small_path(justin, qs):
    K.fk(justin, qs[0], device="cpu")                 # the workspace exists
    bad = qs[0].copy()
    bad[4] = np.nan
    with pytest.raises(ValueError, match=r"q: contains NaN or inf \(batch rows \[0\]\)"):
        K.fk(justin, bad, device="cpu")
    with pytest.raises(ValueError, match="q: contains NaN"):
        K.jacobian(justin, bad, "right_tcp", device="cpu")
    with pytest.raises(ValueError, match="q: values overflow float32"):
        K.fk(justin, np.full(19, 1e39), device="cpu", dtype=np.float32)
    with pytest.raises(ValueError, match=r"q: expected shape \(\.\.\., 19\)"):
        K.fk(justin, np.zeros(7), device="cpu")
    with pytest.raises(TypeError, match="dtype"):
        K.fk(justin, qs[0], dtype=np.int32)
    with pytest.raises(ValueError, match="unknown frame 'nose'"):
        K.jacobian(justin, qs[0], "nose", device="cpu")
    with pytest.raises(ValueError, match="point"):
        K.jacobian(justin, qs[0], 13, point=[1, 2], device="cpu")
    assert np.isnan(K.fk(justin, bad, device="cpu", validate=False)).any()
    # the failed calls left the workspace usable
    np.testing.assert_array_equal(K.fk(justin, qs[0], device="cpu"),
                                  K.fk(justin, qs[:BIG], device="cpu")[0])


def test_jacobian_point_changes_between_calls(justin, qs):
    for point in ([0.1, 0.0, 0.0], None, [0.0, 0.2, -0.1], [0.0, 0.2, -0.1], None):
        one = K.jacobian(justin, qs[2], "left_tcp", point=point, device="cpu")
        big = K.jacobian(justin, qs, "left_tcp", point=point, device="cpu")
        np.testing.assert_array_equal(one, big[2])


def test_torch_small_calls(justin, qs):
    t = torch.tensor(qs[0])
    out = K.fk(justin, t, device="cpu")
    assert isinstance(out, torch.Tensor) and out.dtype == torch.float64
    np.testing.assert_array_equal(out.numpy(), K.fk(justin, qs, device="cpu")[0])
    out2 = K.fk(justin, torch.tensor(qs[1]), device="cpu")
    assert not np.shares_memory(out.numpy(), out2.numpy())
    tg = torch.tensor(qs[:1], requires_grad=True)    # autograd path unchanged
    f = K.fk(justin, tg, device="cpu")
    f[:, 13, 0, 3].sum().backward()
    assert tg.grad is not None and tg.grad.shape == (1, 19)


def test_concurrent_small_calls_from_threads(justin, qs):
    ref = K.fk(justin, qs, device="cpu")
    errors = []

    def work(offset):
        try:
            for k in range(300):
                b = (offset + 7 * k) % BIG
                np.testing.assert_array_equal(K.fk(justin, qs[b], device="cpu"), ref[b])
        except Exception as e:  # noqa: BLE001
            errors.append(e)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(4)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert not errors


def test_workspace_cache_is_bounded(justin, qs):
    launch.clear_workspaces()
    for n in range(1, launch.SMALL_CALL_WORKSPACES + 10):
        K.fk(justin, qs[:n], device="cpu")
    assert launch.clear_workspaces() <= launch.SMALL_CALL_WORKSPACES


# ---------------------------------------------------------------------------- out=
def test_out_numpy_torch_warp_equal_the_fresh_result(justin, qs):
    ref = K.fk(justin, qs, device="cpu")
    out = np.empty((BIG, 27, 4, 4))
    assert K.fk(justin, qs, device="cpu", out=out) is out
    np.testing.assert_array_equal(out, ref)
    one = np.empty((27, 4, 4))
    assert K.fk(justin, qs[5], device="cpu", out=one) is one   # small path
    np.testing.assert_array_equal(one, ref[5])
    tout = torch.empty((BIG, 27, 4, 4), dtype=torch.float64)
    assert K.fk(justin, torch.tensor(qs), device="cpu", out=tout) is tout
    np.testing.assert_array_equal(tout.numpy(), ref)
    wq = wp.array(qs, dtype=wp.float64, device="cpu")
    wout = wp.empty((BIG, 27), dtype=wp.mat44d, device="cpu")
    assert K.fk(justin, wq, out=wout) is wout
    np.testing.assert_array_equal(wout.numpy(), ref)
    jref = K.jacobian(justin, qs, "right_tcp", device="cpu")
    jout = np.empty((BIG, 6, 19))
    assert K.jacobian(justin, qs, "right_tcp", device="cpu", out=jout) is jout
    np.testing.assert_array_equal(jout, jref)
    j1 = np.empty((6, 19))
    K.jacobian(justin, qs[9], "right_tcp", device="cpu", out=j1)
    np.testing.assert_array_equal(j1, jref[9])
    wj = wp.empty((BIG, 6, 19), dtype=wp.float64, device="cpu")
    assert K.jacobian(justin, wq, "right_tcp", out=wj) is wj
    np.testing.assert_array_equal(wj.numpy(), jref)


def test_out_with_dh_rows_and_elastic(justin, qs):
    dh = justin.dh_table + 0.01 * justin.is_dh[:, None]
    out = np.empty((50, 27, 4, 4))
    K.fk(justin, qs[:50], dh=dh, device="cpu", out=out)
    np.testing.assert_allclose(out, ref_fk(justin, qs[:50], dh=dh), atol=1e-9)
    el = K.fk_elastic(justin, qs[:50], 1e-4, device="cpu")
    eout = np.empty((50, 27, 4, 4))
    el2 = K.fk_elastic(justin, qs[:50], 1e-4, device="cpu", out=eout)
    assert el2.frames is eout
    np.testing.assert_array_equal(eout, el.frames)
    np.testing.assert_array_equal(el2.rho, el.rho)


@pytest.mark.parametrize("out,err,match", [
    (np.empty((3, 27, 4, 4)), ValueError, r"out: expected shape \(2, 27, 4, 4\), got \(3, 27, 4, 4\)"),
    (np.empty((2, 27, 4, 4), np.float32), TypeError, "out: dtype float32, expected float64"),
    (np.empty((2, 27, 4, 8))[..., ::2], ValueError, "out: must be C-contiguous"),
    ([[0.0]], TypeError, "out: expected a numpy array, torch tensor or Warp array, got list"),
    (torch.empty((2, 27, 4, 4), dtype=torch.float32), TypeError, "out: dtype torch.float32"),
    (torch.empty((2, 27, 4, 4), dtype=torch.float64, requires_grad=True), ValueError,
     "out: must not require grad"),
    (wp.empty((2, 27), dtype=wp.mat44f, device="cpu"), TypeError, "out: Warp array of 4x4 float32"),
    (wp.empty((2, 27, 4, 4), dtype=wp.float64, device="cpu"), TypeError, "out: Warp array of float64"),
    (wp.empty((2, 26), dtype=wp.mat44d, device="cpu"), ValueError, r"out: expected shape \(2, 27\)"),
])
def test_out_errors_name_out(justin, qs, out, err, match):
    with pytest.raises(err, match=match):
        K.fk(justin, qs[:2], device="cpu", out=out)


def test_out_read_only_and_other_errors(justin, qs):
    ro = np.empty((27, 4, 4))
    ro.flags.writeable = False
    with pytest.raises(ValueError, match="out: is read-only"):
        K.fk(justin, qs[0], device="cpu", out=ro)
    with pytest.raises(ValueError, match=r"out: expected shape \(6, 19\), got \(6, 18\)"):
        K.jacobian(justin, qs[0], 13, device="cpu", out=np.empty((6, 18)))
    with pytest.raises(ValueError, match="out: not supported when q requires grad"):
        K.fk(justin, torch.tensor(qs[:2], requires_grad=True), device="cpu",
             out=torch.empty((2, 27, 4, 4), dtype=torch.float64))
    with pytest.raises(ValueError, match=r"out: expected shape \(4, 27, 4, 4\)"):
        K.fk_elastic(justin, qs[:4], 1e-4, device="cpu", out=np.empty((5, 27, 4, 4)))


# ------------------------------------------------------------------- big results
def test_big_results_outlive_the_call(justin, qs):
    """Big CPU outputs live in numpy memory shared with a Warp array: the result (numpy,
    torch or Warp) keeps it alive."""
    ref = K.fk(justin, qs, device="cpu").copy()
    frames_t = K.fk(justin, torch.tensor(qs), device="cpu")
    frames_w = K.fk(justin, wp.array(qs, dtype=wp.float64, device="cpu"))
    jac = K.jacobian_dh(justin, qs[:200], "right_tcp", device="cpu")
    gc.collect()
    K.fk(justin, qs[::-1].copy(), device="cpu")        # reuses freed memory, if any
    np.testing.assert_array_equal(frames_t.numpy(), ref)
    np.testing.assert_array_equal(frames_w.numpy(), ref)
    assert jac.shape == (200, 6, 27, 5) and np.isfinite(jac).all()
    assert np.abs(jac[:, :, ~justin.is_dh.astype(bool)]).max() == 0   # zeros where off


@requires_cuda
def test_cuda_small_calls_and_out(justin, qs):
    ref = ref_fk(justin, qs)
    for b in (0, 1):
        np.testing.assert_allclose(K.fk(justin, qs[b], device="cuda"), ref[b], atol=1e-12)
    one = np.empty((27, 4, 4))
    K.fk(justin, qs[3], device="cuda", out=one)
    np.testing.assert_allclose(one, ref[3], atol=1e-12)
    big = np.empty((BIG, 27, 4, 4))
    K.fk(justin, qs, device="cuda", out=big)
    np.testing.assert_allclose(big, ref, atol=1e-12)
    np.testing.assert_allclose(K.fk(justin, qs, device="cuda"), ref, atol=1e-12)
    jref = ref_jacobian_fd(justin, qs[4:5], 13)[0]
    np.testing.assert_allclose(K.jacobian(justin, qs[4], 13, device="cuda"), jref, atol=1e-7)
    tq = torch.tensor(qs, device="cuda")
    tout = torch.empty((BIG, 27, 4, 4), dtype=torch.float64, device="cuda")
    assert K.fk(justin, tq, out=tout) is tout
    np.testing.assert_allclose(tout.cpu().numpy(), ref, atol=1e-12)
    with pytest.raises(ValueError, match="out: on device cpu"):
        K.fk(justin, tq, out=torch.empty((BIG, 27, 4, 4), dtype=torch.float64))


def test_first_touch_of_big_fresh_outputs_keeps_results(justin):
    """Outputs over FIRST_TOUCH_BYTES are faulted in on a second thread while the kernel
    writes them (content-preserving): the results equal those written into a reused out."""
    from jwarp.core import arrays

    q = sample_q(justin, 20_000, seed=11)                 # 69 MB of float64 frames
    assert q.shape[0] * 27 * 128 >= arrays.FIRST_TOUCH_BYTES
    out = np.empty((20_000, 27, 4, 4))
    K.fk(justin, q, device="cpu", out=out)
    for _ in range(2):
        np.testing.assert_array_equal(K.fk(justin, q, device="cpu"), out)
    jout = np.empty((20_000, 6, 19))
    K.jacobian(justin, q, "right_tcp", device="cpu", out=jout)
    np.testing.assert_array_equal(K.jacobian(justin, q, "right_tcp", device="cpu"), jout)
    q32 = q[:6000].astype(np.float32)                     # 19 MB of DH Jacobians
    jdh = K.jacobian_dh(justin, q32, "right_tcp", device="cpu")
    np.testing.assert_array_equal(jdh, np.concatenate(
        [K.jacobian_dh(justin, q32[i:i + 500], "right_tcp", device="cpu")
         for i in range(0, 6000, 500)]))
    arr = arrays.empty((arrays.FIRST_TOUCH_BYTES // 8,), wp.float64, wp.get_device("cpu"))
    done = arrays.first_touch(arr)
    if done is not None:      # Linux with more than one core
        done()
    assert arrays.first_touch(arrays.empty((10,), wp.float64, wp.get_device("cpu"))) is None


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_warp_small_calls_equal_the_general_path(justin, qs, dtype):
    """A small Warp CPU q takes the small path (issue 28: fk overhead): a new Warp array per
    call, of the general path's shape and dtype, bit-identical, never overwritten later."""
    launch.clear_workspaces()
    for shape in [(19,), (1, 19), (3, 19), (3, 1, 19)]:
        n = int(np.prod(shape[:-1]))
        x = qs[:n].astype(dtype).reshape(shape)
        general = wp.array(x, device="cpu", requires_grad=True)   # grad: the general path
        for device in (None, "cpu"):
            a = K.fk(justin, wp.array(x, device="cpu"), device=device)
            b = K.fk(justin, general, device=device)
            assert type(a) is wp.array and a.shape == b.shape and a.dtype == b.dtype
            np.testing.assert_array_equal(a.numpy(), b.numpy())
            j = K.jacobian(justin, wp.array(x, device="cpu"), "right_tcp", device=device)
            jg = K.jacobian(justin, general, "right_tcp", device=device)
            assert j.shape == jg.shape and j.dtype == jg.dtype
            np.testing.assert_array_equal(j.numpy(), jg.numpy())
    keep = [K.fk(justin, wp.array(qs[i:i + 1].astype(dtype), device="cpu")) for i in range(80)]
    assert len({k.ptr for k in keep}) == 80
    gc.collect()
    for i, k in enumerate(keep):
        np.testing.assert_array_equal(k.numpy(), K.fk(justin, qs[i:i + 1].astype(dtype)))
    np.testing.assert_array_equal(wp.clone(keep[3]).numpy(), keep[3].numpy())  # a kernel reads it
    assert launch.clear_workspaces() >= 1


def test_warp_small_calls_from_threads(justin, qs):
    """Threads on the Warp small path never share a result slot: every array keeps its own
    configuration's frames."""
    ref = K.fk(justin, qs[:200], device="cpu")
    bad = []

    def work(first):
        kept = [(i, K.fk(justin, wp.array(qs[i:i + 1], device="cpu"))) for i in
                range(first, 200, 4)]
        bad.extend(i for i, a in kept if not np.array_equal(a.numpy()[0], ref[i]))

    threads = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not bad


def test_host_wrap_copies_only_known_array_attributes(monkeypatch):
    """HostWrap makes result arrays from a template only while a wp.array's attributes are
    exactly the known ones (else it builds each with wp.array): both give the same array."""
    from jwarp.core.arrays import HostWrap

    fast = HostWrap((3, 4), np.float32, wp.float32)
    assert fast.state is not None   # this Warp: the fast path
    monkeypatch.setattr(HostWrap, "KNOWN_ATTRIBUTES", HostWrap.KNOWN_ATTRIBUTES - {"_is_read"})
    slow = HostWrap((3, 4), np.float32, wp.float32)
    assert slow.state is None       # an unknown attribute: every array built by Warp
    for h in (fast, slow):
        slot, ptr = h.take()
        slot[:] = np.arange(12, dtype=np.float32).reshape(3, 4)
        a = h.wrap(slot, ptr)
        assert type(a) is wp.array and a.ptr == ptr and a.shape == (3, 4)
        np.testing.assert_array_equal(a.numpy(), slot)
