"""The compile notice and ``jwarp warmup`` (jwarp.core.kernel_cache, jwarp.cli.warmup).

Compilation is judged by Warp's own cache: a module's folder
``<kernel_cache_dir>/<module identifier>`` appears when Warp compiled it. The notice tests
run small fresh kernels in subprocesses (the notice is once per process), each kernel
made unique by a random constant so that its first launch must compile."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import uuid
from pathlib import Path

import numpy as np
import pytest
import warp as wp

import jwarp
from jwarp.cli import main
from jwarp.core.arrays import init_warp
from jwarp.core.kernel_cache import cache_dir

NOTICE = re.compile(r"^jwarp: compiling kernel module (?P<module>\S+) \((?P<kernels>[^)]*)\) "
                    r"for cpu: (?P<why>.+) \(kept in the kernel cache (?P<dir>\S+) for later "
                    r"runs\)$")

# a kernel whose function claims a module name (`jwarp.*` for jwarp's own kernels)
PROBE = r'''
import importlib.util, os, sys, tempfile
import numpy as np
import warp as wp
from jwarp.core.arrays import init_warp
from jwarp.core.kernel_cache import compiled_modules

init_warp()
src = """
import warp as wp
@wp.kernel(module="unique")
def probe_{tag}(a: wp.array(dtype=float)):
    i = wp.tid()
    a[i] = a[i] * 2.0 + {value}
"""
out = []
folder = tempfile.mkdtemp()
for tag, module, value in [a.split(":") for a in sys.argv[1:]]:
    path = os.path.join(folder, f"probe_{tag}.py")   # Warp reads a kernel's source file
    with open(path, "w") as f:
        f.write(src.format(tag=tag, value=value))
    spec = importlib.util.spec_from_file_location(module, path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[module] = mod
    spec.loader.exec_module(mod)
    k = getattr(mod, "probe_" + tag)
    a = wp.zeros(4, dtype=float, device="cpu")
    wp.launch(k, dim=4, inputs=[a], device="cpu")
    assert np.allclose(a.numpy(), float(value))
    out.append((k.module.get_module_identifier(), k.module.name))
print(wp.config.kernel_cache_dir)
print(",".join(i for i, _ in out))
print(",".join(compiled_modules()))
print(",".join(n for _, n in out))
'''


def run_probe(kernels: list[tuple[str, str, float]], cache: Path,
              notice: str = "1") -> tuple[str, str]:
    """Launch the probe kernels in a fresh process with the kernel cache in ``cache``
    (WARP_CACHE_PATH: the probes stay out of the user's cache)."""
    env = dict(os.environ, JWARP_COMPILE_NOTICE=notice, WARP_CACHE_PATH=str(cache))
    args = [f"{t}:{m}:{v!r}" for t, m, v in kernels]
    r = subprocess.run([sys.executable, "-c", PROBE, *args], env=env,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return r.stdout, r.stderr


def in_cache(cache: str | Path, module_name: str) -> bool:
    """Warp keeps a compiled module in ``<cache>/wp_<module name>_<hash>``."""
    return any(p.name.startswith(f"wp_{module_name}_") for p in Path(cache).iterdir())


def notice_lines(stderr: str) -> list[str]:
    return [ln for ln in stderr.splitlines() if ln.startswith("jwarp: compiling")]


def test_notice_names_each_module_only_when_jwarp_compiles(tmp_path):
    v1, v2, v3 = (float(int(uuid.uuid4().int % 10**6)) + 0.25 * i for i in range(3))
    tag = uuid.uuid4().hex[:8]
    # two fresh jwarp kernels and a fresh kernel of another package: a line for each of
    # jwarp's, naming the module, its kernel and why (first use), none for the other
    out, err = run_probe([(f"a{tag}", "jwarp.probe_a", v1), (f"b{tag}", "jwarp.probe_b", v2),
                          (f"c{tag}", "userpkg.probe", v3)], tmp_path)
    cache, _, compiled, names = out.splitlines()
    lines = notice_lines(err)
    assert len(lines) == 2, err
    for line, name, t in zip(lines, names.split(",")[:2], "ab"):
        m = NOTICE.match(line)
        assert m, line
        assert m.group("dir") == cache == str(tmp_path / wp.config.version)
        assert m.group("module") == name and f"probe_{t}{tag}" in m.group("kernels")
        assert m.group("why") == "first use", line
    for name in names.split(","):          # Warp did compile each: its folder is there now
        assert in_cache(cache, name)
    assert compiled.split(",") == names.split(",")[:2]   # jwarp's two, not the other one
    # the same kernels again: loaded from the cache, no line
    out, err = run_probe([(f"a{tag}", "jwarp.probe_a", v1), (f"b{tag}", "jwarp.probe_b", v2)],
                         tmp_path)
    assert notice_lines(err) == [] and out.splitlines()[2] == ""
    # a fresh jwarp kernel with the notice turned off: no line, still compiled
    out, err = run_probe([(f"d{tag}", "jwarp.probe_d", v3)], tmp_path, notice="0")
    assert notice_lines(err) == []
    assert in_cache(out.splitlines()[0], out.splitlines()[3])


def test_only_a_fresh_user_kernel_prints_nothing(tmp_path):
    v = float(int(uuid.uuid4().int % 10**6)) + 0.5
    out, err = run_probe([(f"u{uuid.uuid4().hex[:8]}", "userpkg.other", v)], tmp_path)
    assert notice_lines(err) == [] and out.splitlines()[2] == ""


def test_warmup_loads_what_a_launch_uses():
    """warmup(fk, float64, justin19) on the CPU: 4 kernel modules, each in Warp's cache
    folder afterwards; a later FK / Jacobian launch uses the variants warmup loaded (no new
    load of those modules in this process)."""
    from jwarp.cli.warmup import kernel_modules, warmup
    from jwarp.kernels import fk as fk_kernels

    init_warp()
    mods = kernel_modules(["fk"], ["float64"], ["justin19"])
    ks = fk_kernels.kernels(wp.float64)
    assert {id(m) for m in mods} == {id(k.module) for k in (ks.fk, ks.fk_components, ks.jacobian,
                                                             ks.jacobian_dh)}
    for m in mods:
        m.unload()                         # as in a fresh process (reloads from the cache)
    rep = warmup("cpu", ["justin19"], ["float64"], ["fk"], progress=False)
    assert (rep.modules, rep.device, rep.families, rep.dtypes, rep.robots) == (
        4, "cpu", ["fk"], ["float64"], ["justin19"])
    assert rep.cache_dir == wp.config.kernel_cache_dir == cache_dir()
    for m in mods:
        assert in_cache(rep.cache_dir, m.name)
    loaded = {id(m): dict(m.execs) for m in mods}
    assert all(len(v) == 1 for v in loaded.values())
    q = np.zeros((2, 19))
    jwarp.fk("justin19", q, device="cpu")
    jwarp.jacobian("justin19", q, "right_tcp", device="cpu")
    jwarp.jacobian_dh("justin19", q, "right_tcp", device="cpu")
    for m in mods:                         # the same executables: nothing loaded again
        assert dict(m.execs) == loaded[id(m)]


def test_warmup_cli(capsys):
    rc = main(["warmup", "--device", "cpu", "--robots", "justin19", "--families", "fk",
               "--dtype", "float64"])
    out = capsys.readouterr().out
    assert rc == 0
    assert re.search(r"^4 kernel modules on cpu: \d compiled, \d already cached", out, re.M)
    assert f"kernel cache: {wp.config.kernel_cache_dir}\n" in out
    for argv, option in [(["--families", "fk,nope"], "--families"), (["--dtype", "float16"], "--dtype"),
                         (["--robots", "no_such_robot"], "--robots"), (["--jobs", "0"], "--jobs"),
                         (["--device", "cuda:99"], "--device")]:
        assert main(["warmup", *argv]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err[-1].startswith(f"jwarp: error: {option}"), err


def test_help_imports_no_heavy_packages():
    """`jwarp --help` (and `import jwarp`) import no torch, rerun, trimesh, scipy, cv2 or
    Warp; their first use still works."""
    code = ("import sys, io, contextlib\n"
            "import jwarp\n"
            "from jwarp.cli import main\n"
            "with contextlib.redirect_stdout(io.StringIO()) as f:\n"
            "    rc = main(['--help'])\n"
            "assert rc == 0 and 'warmup' in f.getvalue()\n"
            "heavy = ['torch', 'rerun', 'trimesh', 'scipy', 'cv2', 'warp', 'pluggy']\n"
            "print(','.join(m for m in heavy if m in sys.modules))\n"
            "print(jwarp.fk.__module__, jwarp.kinematics.__name__, jwarp.Planner.__name__)\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    loaded, names = r.stdout.splitlines()
    assert loaded == ""
    assert names == "jwarp.kinematics.fk jwarp.kinematics Planner"


CACHE_PROBE = '''
from jwarp.cli.common import plugin_warnings_one_line
plugin_warnings_one_line()
from jwarp.core.arrays import init_warp
init_warp()
import warp as wp
print(wp.config.kernel_cache_dir)
'''


@pytest.mark.parametrize("bad", ["file", "unwritable"])
def test_unusable_cache_path_warns_naming_it_and_falls_back(tmp_path, bad):
    """Reliability round 4, item 9: a WARP_CACHE_PATH that is a file or an unwritable
    folder made every command fail with a bare OS error. Now: one warning naming the cache
    and the variable, and a temporary cache."""
    if bad == "file":
        path = tmp_path / "a_file"
        path.write_text("x")
    else:
        if hasattr(os, "geteuid") and os.geteuid() == 0:
            pytest.skip("root writes into any folder")
        path = tmp_path / "ro"
        path.mkdir()
        path.chmod(0o500)
    env = dict(os.environ, WARP_CACHE_PATH=str(path), PYTHONPATH=str(Path(jwarp.__file__).parents[1]))
    r = subprocess.run([sys.executable, "-c", CACHE_PROBE], env=env, capture_output=True,
                       text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("jwarp: warning:")]
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith(f"jwarp: warning: WARP_CACHE_PATH={path}: Warp's kernel cache ")
    assert "cannot be used" in lines[0] and "temporary cache" in lines[0]
    used = r.stdout.strip().splitlines()[-1]
    assert not used.startswith(str(path)) and Path(used).is_dir()
    import shutil
    shutil.rmtree(Path(used).parent, ignore_errors=True)


def test_compile_reason_first_use_specialisation_or_changed(tmp_path):
    """The notice's reason, from the cache's other folders: none of these kernels (first
    use), another variant of the kernels (new specialisation: another dtype, robot size or
    constant; jwarp builds one module per variant), the same module under another hash
    (changed: build options or Warp)."""
    from jwarp.core.kernel_cache import compile_reason

    key = "kernels__locals__segment_kernel"
    target = tmp_path / f"wp_{key}_0123abcd_89abcde"
    assert compile_reason(str(target)) == "first use"
    (tmp_path / f"wp_{key}_fedc4321_1234567").mkdir()   # the float32 variant, say
    (tmp_path / "wp_kernels__locals__prep_kernel_0123abcd_1111111").mkdir()  # another kernel
    why = compile_reason(str(target))
    assert why.startswith("new specialisation") and "1 other variant of" in why, why
    (tmp_path / f"wp_{key}_0123abcd_7654321").mkdir()   # this module, another hash
    assert compile_reason(str(target)).startswith("changed"), compile_reason(str(target))


def test_notice_says_new_specialisation(tmp_path):
    """The same jwarp kernel with another constant (a new variant, as a new dtype or robot
    size gives): its notice says new specialisation."""
    tag = uuid.uuid4().hex[:8]
    v = float(int(uuid.uuid4().int % 10**6))
    run_probe([(f"s{tag}", "jwarp.probe_s", v)], tmp_path)
    _, err = run_probe([(f"s{tag}", "jwarp.probe_s", v + 0.5)], tmp_path)
    lines = notice_lines(err)
    assert len(lines) == 1, err
    m = NOTICE.match(lines[0])
    assert m and m.group("why").startswith("new specialisation"), lines[0]
