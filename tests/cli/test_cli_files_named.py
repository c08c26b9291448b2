"""Reliability round 3, item 10: files named in errors with what is wrong with them (a
non-UTF-8 robot JSON gave a bare codec error, a 0-byte database "does not exist", a
non-MJCF .xml "not valid JSON")."""

from __future__ import annotations

import pytest
from cli_helpers import run

import jwarp


def test_non_utf8_robot_json_names_the_file(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_bytes(b'{"name": "\xff\xfe"}')
    with pytest.raises(ValueError, match=r"bad.json: not a UTF-8 text file \(byte 10"):
        jwarp.robot(str(bad))


def test_xml_that_is_not_mjcf_says_so(tmp_path):
    xml = tmp_path / "arm.xml"
    xml.write_text("<robot/>")
    with pytest.raises(ValueError, match=r"arm.xml: an .xml robot must be MJCF"):
        jwarp.robot(str(xml))


def test_empty_database_is_called_empty(capsys, tmp_path):
    db = tmp_path / "paths.sqlite"
    db.write_bytes(b"")
    code, out, err = run(capsys, ["data", "info", str(db)])
    assert code == 2 and "is empty (0 bytes)" in err and "does not exist" not in err
