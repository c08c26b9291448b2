"""Reliability round 4, item 12: sentences of the docs that said the opposite of what the
code does. Each test reads the sentence and checks the behaviour it describes."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import trimesh

ROOT = Path(__file__).resolve().parents[1]


def _text(name: str) -> str:
    return " ".join((ROOT / "docs" / name).read_text(encoding="utf-8").split())


def test_scenes_md_says_an_open_mesh_is_an_error_only_for_a_grid(tmp_path):
    from jwarp.world import exact_world
    from jwarp.world.scene_file import SceneOptions, scene_from_dict, scene_world

    text = _text("scenes.md")
    assert "an open (not watertight) mesh;" not in text          # listed as an error
    assert "an open (not watertight) mesh only where a grid is sampled" in text
    trimesh.creation.box().slice_plane([0, 0, 0], [0, 0, 1]).export(tmp_path / "cup.stl")
    cup = scene_from_dict({"objects": [{"id": "cup", "type": "mesh", "file": "cup.stl",
                                        "pose": {"position": [0, 0, 0]}}]}, base_dir=tmp_path)
    assert len(exact_world(cup).shapes) == 1                      # an exact world takes it
    with pytest.raises(ValueError, match="not watertight"):
        scene_world(cup, SceneOptions(voxel_size=0.1))            # a grid does not


def test_origin_with_compliances_is_not_called_an_error():
    """The origin group on a compliant robot is supported (issue 29; its behaviour:
    tests/calibration/test_calibration_origin.py, the elastic columns against central
    differences); docs/urdf_export.md and the params docstring called it an error."""
    from jwarp.calibration.estimate import params

    section = _text("urdf_export.md").split("## The `origin` calibration group")[1]
    assert "is an error naming the group" not in section
    assert "Compliant robots too" in section
    doc = " ".join((params.__doc__ or "").split())
    assert "rigid problems only" not in doc and "also on a compliant robot" in doc


def test_urdf_md_quotes_the_no_spheres_warning_import_mjcf_prints(tmp_path, capsys):
    pytest.importorskip("mujoco")
    from jwarp.cli import main

    quoted = re.search(r"prints `(jwarp: warning: --no-spheres [^`]*)`", _text("urdf.md"))
    assert quoted, "docs/urdf.md does not quote import-mjcf's --no-spheres warning"
    model = tmp_path / "m.xml"
    model.write_text("<mujoco model='m'><worldbody><body name='b'><joint name='j' "
                     "type='hinge' range='-1 1'/><geom type='sphere' size='0.05'/></body>"
                     "</worldbody></mujoco>")
    assert main(["import-mjcf", str(model), "--out", str(tmp_path / "m.json"),
                 "--no-spheres"]) == 0
    assert quoted.group(1) in capsys.readouterr().err
