"""Command line interface: the parser and :func:`main`. Command groups, one module each,
registered by explicit import: :mod:`jwarp.cli.kinematics` (``robots | info | fk | show``),
:mod:`jwarp.cli.calibration` (``calibrate | simulate-campaign``), :mod:`jwarp.cli.planning`
(``plan | ik | free-config``), :mod:`jwarp.cli.learning` (``train ik | train plan | eval ik |
eval plan``), :mod:`jwarp.cli.data`
(``data generate | info | export``), :mod:`jwarp.cli.poses` (``sample-poses``),
:mod:`jwarp.cli.design` (``sensitivity | design``), :mod:`jwarp.cli.urdf` (``import-urdf``),
:mod:`jwarp.cli.urdf_export` (``export-urdf``), :mod:`jwarp.cli.mjcf` (``import-mjcf``),
:mod:`jwarp.cli.warmup` (``warmup``: compile every kernel ahead of time).

Examples and the joint-value syntax: :mod:`jwarp.cli.kinematics`. A value starting with a
minus sign may follow any option directly (``--q -0.5,0,...``, ``-inf``, ``-nan``).

Errors and exit status (:func:`main`):

* 0 success; 1 ``plan``/``ik`` found no feasible path/solution; 2 any error; 130
  interrupted (Ctrl-C: ``jwarp: interrupted``, no traceback, no partial output file).
* An error is ONE line ``jwarp: error: <option>: <what is wrong>`` on stderr (argparse's
  own usage errors, e.g. a missing required option, print the usage lines before it).
  Option values are checked before any work: numbers must be finite and in range
  (``--lam`` in (0, 1], counts >= 1, ``--max-iter`` >= 0, ...), sizes are checked against
  an estimate of the memory they need (:mod:`jwarp.utils.memory`; the error gives the figure),
  ``--device`` must exist, and every output path (``--out``, ``--rerun``) must be
  writable (its folder exists, it is not a folder) before the computation starts. Files
  are written atomically (:class:`jwarp.utils.atomic.AtomicFile`): an error or interrupt leaves
  no temporary file and the old file as it was.
* Exceptions reach :func:`main` as one line: :class:`CLIError`, ValueError, TypeError,
  OSError (files), ``zipfile.BadZipFile`` are input errors and print their message;
  OverflowError prints ``numeric overflow: ...``, MemoryError (and Warp's RuntimeError
  "Failed to allocate ...") ``out of memory: ...``. Any other exception (KeyError,
  IndexError, other RuntimeErrors, ...) is unexpected, possibly a bug: it prints
  ``jwarp: error: <Type>: <message> (run with JWARP_DEBUG=1 for the traceback)``, also with
  status 2. With the environment variable ``JWARP_DEBUG=1`` every exception other than
  CLIError (and --help/--version's exit) is raised with its traceback.
"""

from __future__ import annotations

import argparse
import os
import sys
import zipfile
from collections.abc import Sequence

from jwarp.cli import (
    calibration,
    data,
    design,
    kinematics,
    learning,
    mjcf,
    planning,
    poses,
    urdf,
    urdf_export,
    warmup,
)
from jwarp.cli.common import (
    CLIError,
    Parser,
    fix_negative_values,
    plugin_warnings_one_line,
    set_command_files,
    value_options,
)


def build_parser() -> argparse.ArgumentParser:
    from jwarp import __version__

    p = Parser(prog="jwarp", description="jwarp: fast batched (elastic) robot kinematics "
                "on NVIDIA Warp. Units: m, rad, N m.")
    p.add_argument("--version", action="version", version=f"jwarp {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)
    sub.required = True

    for group in (kinematics, calibration, planning, learning, data, poses, design, urdf,
                  urdf_export, mjcf, warmup):
        group.add_subcommands(sub)
    return p


#: exceptions that report a bad input, file or resource: their message is the error line
INPUT_ERRORS = (ValueError, TypeError, OSError, OverflowError, zipfile.BadZipFile)


def _one_line(e: BaseException) -> str:
    return " ".join(str(e).split())


def _debug() -> bool:
    return os.environ.get("JWARP_DEBUG", "").strip() not in ("", "0")


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; returns the exit status: 0 ok, 1 ``plan``/``ik`` not feasible, 2 any
    error (one line ``jwarp: error: ...`` on stderr), 130 interrupted. See the module
    docstring for which exceptions count as input errors and ``JWARP_DEBUG=1``."""
    argv = list(sys.argv[1:] if argv is None else argv)
    plugin_warnings_one_line()
    try:
        parser = build_parser()
        args = parser.parse_args(fix_negative_values(argv, value_options(parser)))
        set_command_files(args)  # no output may overwrite a file the command reads
        return args.func(args)
    except CLIError as e:
        if e.usage:
            sys.stderr.write(e.usage)
        print(f"jwarp: error: {_one_line(e)}", file=sys.stderr)
        return 2
    except SystemExit as e:  # --help / --version
        return e.code if isinstance(e.code, int) else (0 if e.code is None else 2)
    except BrokenPipeError:  # pragma: no cover - e.g. `jwarp fk ... | head`
        try:
            sys.stdout = open(os.devnull, "w")  # noqa: SIM115 (for the rest of the process)
        except OSError:
            pass
        return 0
    except KeyboardInterrupt:
        if _debug():
            raise
        print("jwarp: interrupted", file=sys.stderr)
        return 130
    except INPUT_ERRORS as e:
        # jwarp's own validation errors (unknown robot, bad kappa, unreadable file, ...)
        if _debug():
            raise
        what = "numeric overflow: " if isinstance(e, OverflowError) else ""
        print(f"jwarp: error: {what}{_one_line(e) or type(e).__name__}", file=sys.stderr)
        return 2
    except (MemoryError, RuntimeError) as e:
        if _debug():
            raise
        msg = _one_line(e)
        if isinstance(e, MemoryError) or "allocate" in msg.lower():  # Warp: "Failed to allocate"
            print(f"jwarp: error: out of memory{': ' + msg if msg else ''}", file=sys.stderr)
        else:
            print(f"jwarp: error: {type(e).__name__}: {msg} (run with JWARP_DEBUG=1 for the "
                  f"traceback)", file=sys.stderr)
        return 2
    except Exception as e:  # unexpected: possibly a bug; one line, the traceback on request
        if _debug():
            raise
        print(f"jwarp: error: {type(e).__name__}: {_one_line(e)} (run with JWARP_DEBUG=1 for "
              f"the traceback)", file=sys.stderr)
        return 2
