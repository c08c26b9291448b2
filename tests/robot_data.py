"""Files of the test extra's robot packages (tests import this module by name)."""

from __future__ import annotations

from importlib import metadata
from pathlib import Path

import pytest


def erd(relative: str) -> str:
    """A file of example-robot-data's robots folder (skip where not installed)."""
    try:
        dist = metadata.distribution("example-robot-data")
    except metadata.PackageNotFoundError:
        pytest.skip("example-robot-data is not installed")
    path = Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots")) / relative
    if not path.is_file():
        pytest.skip(f"example-robot-data has no {relative}")
    return str(path)
