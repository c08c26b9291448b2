"""The CLI's one vocabulary of options (issue 27).

* ``--out FILE`` is the file (or folder) a command writes as its result, on every command
  that writes one (``show``, ``data export``, ``sensitivity``, ``design``, ``calibrate``,
  ``simulate-campaign``, ``sample-poses``, ``train ik|plan``, ``import-urdf``,
  ``import-mjcf``, ``export-urdf``, ``ik --targets``). Old spellings (``--save``,
  ``--npz``, ``--png``) are hidden aliases: they still work and print one line
  ``jwarp: warning: --save is deprecated; use --out`` on stderr.
* Secondary outputs are named by what they hold: ``--rerun FILE.rrd`` (a rerun recording,
  on every command that can write one), ``--params-out`` (``calibrate``'s parameters).
* ``--db FILE.sqlite`` names a path database: it is read as well as written (``data
  generate`` resumes into it; ``data info|export`` read it), so it keeps its own name.
* ``--device`` on every command whose work runs on a Warp or torch device.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

__all__ = ["add_out", "require_out", "DeprecatedAlias"]


class DeprecatedAlias(argparse.Action):
    """An old spelling of an option: stores into the new option's ``dest`` and prints
    one deprecation line on stderr (``jwarp: warning: OLD is deprecated; use NEW``)."""

    def __init__(self, option_strings: list[str], dest: str, new: str = "--out",
                 **kw: Any) -> None:
        self.new = new
        super().__init__(option_strings, dest, **kw)

    def __call__(self, parser: Any, namespace: Any, values: Any,
                 option_string: str | None = None) -> None:
        print(f"jwarp: warning: {option_string} is deprecated; use {self.new}",
              file=sys.stderr)
        setattr(namespace, self.dest, values)


def add_out(s: argparse.ArgumentParser, *old: str, required: bool = False,
            metavar: str = "FILE", help: str = "the file to write",
            default: Any = None) -> None:
    """Add ``--out`` (dest ``out``) to ``s`` and the hidden, deprecated aliases ``old``.

    With aliases, ``required`` is checked by :func:`require_out` after parsing (argparse
    would otherwise demand ``--out`` even when an alias gave the value)."""
    s.add_argument("--out", default=default, metavar=metavar,
                   required=required and not old, help=help)
    for o in old:
        s.add_argument(o, dest="out", action=DeprecatedAlias, metavar=metavar,
                       help=argparse.SUPPRESS)
    if required and old:
        s.set_defaults(_out_required=True)


def require_out(args: argparse.Namespace) -> str:
    """``args.out``; a CLIError ``--out: required`` when an output is required and was given
    neither as ``--out`` nor as an old spelling."""
    from jwarp.cli.common import CLIError

    if getattr(args, "out", None) is None and getattr(args, "_out_required", False):
        raise CLIError("--out: required (the file to write)")
    return args.out
