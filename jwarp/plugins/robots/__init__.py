"""Built-in robots, one module each with its JSON description beside it."""

from __future__ import annotations

from pathlib import Path

from jwarp.model import RobotModel

HERE = Path(__file__).parent


def load_builtin(filename: str) -> RobotModel:
    """Load a robot description shipped in this folder."""
    return RobotModel.load(HERE / filename)
