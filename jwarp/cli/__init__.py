"""The ``jwarp`` command line: one module per command group, registered by explicit import
in :mod:`jwarp.cli.main` (kinematics: robots, info, fk, show; calibration: calibrate,
simulate-campaign; planning: plan, ik;
learning: train, eval; data: data generate | info | export)."""

from jwarp.cli.main import CLIError, build_parser, main

__all__ = ["CLIError", "build_parser", "main"]
