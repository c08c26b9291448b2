"""After ``jwarp warmup``, the documented commands compile no kernel module (issue 39,
item 2), counted by the compile notice (one line per module compiled,
jwarp.core.kernel_cache).

A fresh process runs ``jwarp warmup --device cpu --robots planar4,arm7`` on the user's
kernel cache and lists the cache folders of the jwarp modules it loaded
(:func:`jwarp.core.kernel_cache.loaded_modules`). A new kernel cache then holds exactly
those folders (links) and Warp's own modules, nothing else of jwarp: what warmup would
have left in an empty cache. A second fresh process with that cache runs, as the docs
write them, every documented command on planar4 and arm7 that needs no file of its own:
``jwarp fk`` (README), the ``jwarp ik`` examples of docs/ik.md and README on arm7 (the
pose forms, --position-only, --free-axis, --initial, tolerances, the table_shelf scene,
with and without --voxel), ``jwarp free-config`` and ``jwarp plan`` on planar4 (README and
docs/scenes.md, the shortening's float64 checks and the RRT fallback included). Any jwarp
module warmup did not build would compile there: its notice line (which module, why) fails
the test. Left out: the commands on justin19 and imported robots (their warmup and fits
take minutes on 2 cores), and those reading a file the docs make first (targets.csv,
pose.txt; tests/test_docs_commands.py runs all of them, without this count)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import doc_commands as dc  # tests/doc_commands.py
import pytest
import warp as wp

ROBOTS = "planar4,arm7"
#: the documented commands run after warmup (FILE: the command's whole text)
KEYS = (
    "README.md: jwarp fk arm7 --q 0,30,0,-60,0,45,0 --deg",
    "docs/ik.md: jwarp ik --robot arm7 --frame right_tcp "
    "--target -0.7296,0.1664,0.8123,-0.1763,-1.238,-0.0875",
    "README.md: jwarp plan --robot planar4 --world block.npz --start 1.2,0,0,0 "
    "--goal=-1.2,0,0,0",
    "docs/scenes.md: jwarp plan --robot planar4 --world block.npz --start 1.2,0,0,0 "
    "--goal -1.2,0,0,0",
    # every other documented command on these two robots that needs no file of its own
    "docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target -0.7296,0.1664,0.8123 "
    "--quat -0.0825,-0.5792,-0.0409,0.8099",
    "docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target -0.7296,0.1664,0.8123 "
    "--rpy -0.2667,-1.2378,0.0895",
    "docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target-matrix \"0 0 -1 -0.73 0 1 0 "
    "0.17 1 0 0 0.81 0 0 0 1\"",
    "docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target -0.7296,0.1664,0.8123 "
    "--position-only",
    "docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target -0.7296,0.1664,0.8123,"
    "-0.1763,-1.238,-0.0875 --free-axis 0,0,1",
    "docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target -0.7296,0.1664,0.8123,"
    "-0.1763,-1.238,-0.0875 --initial 17,57,11,57,-23,29,6 --deg --starts 1",
    "docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target -0.7296,0.1664,0.8123,"
    "-0.1763,-1.238,-0.0875 --tol-pos 0.001 --tol-rot 0.01",
    "docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target -0.7296,0.1664,0.8123,"
    "-0.1763,-1.238,-0.0875 --scene examples/scenes/table_shelf.yaml",
    "docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target -0.7296,0.1664,0.8123,"
    "-0.1763,-1.238,-0.0875 --scene examples/scenes/table_shelf.yaml --voxel 0.02",
    "docs/ik.md: jwarp ik --robot arm7 --frame right_tcp --target 0.55,0.4,0.4 "
    "--position-only --scene examples/scenes/table_shelf.yaml",
    "README.md: jwarp ik --robot arm7 --frame right_tcp --target -0.7296,0.1664,0.8123 "
    "--quat -0.0825,-0.5792,-0.0409,0.8099 --scene examples/scenes/table_shelf.yaml",
    "README.md: jwarp free-config --robot planar4 --world simplex:seed=3 --n 2",
    "docs/scenes.md: jwarp plan --robot planar4 --world block.npz --start 1.2,0,0,0 "
    "--goal -1.2,0,0,0 --starts 2 --iterations 3",
)

WARMUP = f"""
from jwarp.cli.main import main
from jwarp.core.kernel_cache import loaded_modules
assert main(["warmup", "--device", "cpu", "--robots", "{ROBOTS}"]) == 0
print("LOADED", *loaded_modules())
"""

COMMANDS = """
import json, sys
from jwarp.cli.main import main
from jwarp.core.kernel_cache import compiled_modules, loaded_modules
for argv in json.loads(sys.argv[1]):
    code = main(argv)
    assert code in (0, 1), (argv, code)
print("COMPILED", *compiled_modules())
print("LOADED", *loaded_modules())
"""


def _argv(key: str) -> list[str]:
    """The command's argv after ``jwarp`` (a command whose text starts with the key's,
    the one equal to it where several do)."""
    file, prefix = key.split(": ", 1)
    found = [c for c in dc.all_commands() if c.file == file and c.text.startswith(prefix)]
    found = [c for c in found if c.text == prefix] or found
    assert found, f"{key!r}: no such command in the docs"
    return dc.words(found[0].text)[1:]


def _run(script: str, args: list[str], env: dict, cwd: Path) -> subprocess.CompletedProcess:
    r = subprocess.run([sys.executable, "-c", script, *args], env=env, cwd=cwd,
                       capture_output=True, text=True, timeout=1800)
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-4000:]
    return r


def _field(out: str, name: str) -> list[str]:
    line = [ln for ln in out.splitlines() if ln.startswith(name)][-1]
    return line.split()[1:]


def test_documented_commands_compile_nothing_after_warmup(tmp_path):
    import json

    from worlds import block_world_2d

    from jwarp.core.arrays import init_warp
    from jwarp.world import save_world

    init_warp()
    shared = Path(wp.config.kernel_cache_dir)
    env = {k: v for k, v in os.environ.items() if k != "WARP_CACHE_PATH"}
    env.update(JWARP_COMPILE_NOTICE="1", WARP_CACHE_PATH=str(shared.parent),
               PYTHONPATH=os.pathsep.join([str(dc.ROOT), str(dc.ROOT / "tests"),
                                           env.get("PYTHONPATH", "")]))
    if shared.name != wp.config.version:
        pytest.skip(f"the kernel cache {shared} is not <WARP_CACHE_PATH>/<warp version>")
    # 1. warmup on the user's cache (compiles what is missing there; fast when warm)
    r = _run(WARMUP, [], env, tmp_path)
    warm = _field(r.stdout, "LOADED")
    assert len(warm) > 50, r.stdout
    # 2. a cache holding what warmup built and Warp's own modules, no other jwarp module
    cache = tmp_path / "cache" / wp.config.version
    cache.mkdir(parents=True)
    for name in warm:
        assert (shared / name).is_dir(), name
        (cache / name).symlink_to(shared / name, target_is_directory=True)
    for d in shared.iterdir():
        if d.name.startswith("wp_warp.") and not (cache / d.name).exists():
            (cache / d.name).symlink_to(d, target_is_directory=True)
    # 3. the documented commands in a fresh process with that cache
    save_world(block_world_2d(), str(tmp_path / "block.npz"))
    (tmp_path / "examples").symlink_to(dc.ROOT / "examples", target_is_directory=True)
    argvs = [_argv(k) for k in KEYS]
    env["WARP_CACHE_PATH"] = str(cache.parent)
    r = _run(COMMANDS, [json.dumps(argvs)], env, tmp_path)
    notices = [ln for ln in r.stderr.splitlines() if ln.startswith("jwarp: compiling")]
    assert not notices, "\n".join(notices)
    assert _field(r.stdout, "COMPILED") == []
    used = _field(r.stdout, "LOADED")
    assert len(used) > 10 and set(used) <= set(warm), set(used) - set(warm)
