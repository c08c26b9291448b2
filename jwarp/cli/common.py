"""Shared pieces of the command line: the error type, the argument parser class, option
value types that check ranges, joint-value and compliance parsing, the ``--robot`` loader,
output-path and device checks, the ``--rerun`` recording, JSON printing. See :mod:`jwarp.cli.main` for the error policy."""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.core.types import DTypeLike

if TYPE_CHECKING:
    from jwarp.model import RobotModel

#: default compliance of ``fk --elastic`` for a robot without its own kappa [rad/(N m)]
DEFAULT_KAPPA = 1e-4
#: default most torque updates of ``--elastic`` (stops earlier once converged)
DEFAULT_MAX_ITER = 50


class CLIError(Exception):
    """A usage or input error: reported as ``jwarp: error: ...``, exit status 2."""

    def __init__(self, message: str, usage: str = ""):
        super().__init__(message)
        self.usage = usage


class Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # type: ignore[override]
        # "argument --lam: invalid float value: 'x'" -> "--lam: invalid float value: 'x'"
        message = re.sub(r"^argument ([^:\s]+?)(?:/[^:\s]+)?: ", r"\1: ", message)
        raise CLIError(message, usage=self.format_usage())


# ------------------------------------------------------------------ option types
def int_arg(option: str, lo: int, hi: int | None = None) -> Callable[[str], int]:
    """An argparse ``type`` for an integer option in [lo, hi] (hi None: no upper bound);
    anything else is a :class:`CLIError` naming ``option`` (one line, no usage)."""
    def parse(text: str) -> int:
        try:
            v = int(text.strip())
        except ValueError:
            v = None
        if v is None or v < lo or (hi is not None and v > hi):
            rng = f">= {lo}" if hi is None else f"in [{lo}, {hi}]"
            raise CLIError(f"{option}: expected an integer {rng}, got {text!r}")
        return v

    parse.__name__ = "integer"  # argparse names the type in some messages
    return parse


def real_arg(option: str, lo: float = -math.inf, hi: float = math.inf, *,
             lo_open: bool = False, hi_open: bool = False,
             unit: str = "") -> Callable[[str], float]:
    """An argparse ``type`` for a finite real option in the interval from ``lo`` to ``hi``
    (``lo_open``/``hi_open``: excluding the bound); NaN, inf or out of range is a
    :class:`CLIError` naming ``option``."""
    if math.isinf(lo) and math.isinf(hi):
        what = "a finite number"
    elif math.isinf(hi):
        what = f"a number {'>' if lo_open else '>='} {lo:g}"
    elif math.isinf(lo):
        what = f"a number {'<' if hi_open else '<='} {hi:g}"
    else:
        what = f"a number in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"

    def parse(text: str) -> float:
        try:
            v = float(text.strip())
        except ValueError:
            v = math.nan
        above = v > lo if lo_open else v >= lo
        below = v < hi if hi_open else v <= hi
        if not (math.isfinite(v) and above and below):
            raise CLIError(f"{option}: expected {what}{unit}, got {text!r}")
        return v

    parse.__name__ = "number"
    return parse


def check_dtype_range(values: Any, dtype: DTypeLike, option: str) -> None:
    """CLIError naming ``option`` if finite ``values`` overflow the computing ``dtype``
    (1e39 is finite in float64, inf in float32)."""
    a = np.asarray(values, np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        ok = bool(np.all(np.isfinite(a.astype(dtype))))
    if not ok:
        raise CLIError(f"{option}: values overflow {np.dtype(dtype).name} (largest magnitude "
                       f"{float(np.finfo(dtype).max):.3g}); use --dtype float64")


def check_option_memory(need: float, what: str, option: str) -> None:
    """:func:`jwarp.utils.memory.check_memory` of ``need`` bytes for ``what``, before any work;
    too much is a CLIError naming ``option`` (the one to lower)."""
    from jwarp.utils.memory import check_memory

    try:
        check_memory(need, what, f"lower {option}")
    except MemoryError as e:
        raise CLIError(f"{option}: {e}") from None


def check_device(name: str, option: str = "--device") -> None:
    """CLIError naming ``option`` unless Warp has the device ``name`` (checked before any
    work; e.g. ``cuda:0`` on a machine without a GPU)."""
    from jwarp.core.arrays import resolve_device

    try:
        resolve_device(name)
    except (ValueError, TypeError, RuntimeError) as e:
        msg = " ".join(str(e).split())
        raise CLIError(f"{option}: {msg.removeprefix('device: ')}") from None


#: every existing file named on the command line being run ((option or argument, path),
#: several per option where a list or KEY=FILE items name several), set by
#: :func:`set_command_files`: no output may be one of them
_COMMAND_FILES: list[tuple[str, str]] = []


def _files_in(value: Any) -> list[str]:
    """The existing files a parsed value names: itself, or the ``FILE`` of its
    comma-separated ``KEY=FILE`` items (``--fix tracker=first.json``)."""
    if not isinstance(value, (str, os.PathLike)) or not str(value):
        return []
    text = os.fspath(value)
    names = [text]
    if isinstance(text, str) and "=" in text:
        names += [item.partition("=")[2].strip() for item in text.split(",") if "=" in item]
    return [n for n in names if n and os.path.isfile(n)]


def set_command_files(args: Any) -> None:
    """Record the existing files among the parsed arguments (string values that name a
    file, string items of list values, and the ``FILE`` of ``KEY=FILE`` items) as the
    command's inputs: :func:`check_output` and :func:`input_named` refuse any of them as an
    output (whatever option names it), so no command overwrites a file it reads."""
    _COMMAND_FILES.clear()
    for key, value in vars(args).items():
        if key == "func":
            continue
        values = value if isinstance(value, (list, tuple)) else [value]
        for v in values:
            for f in _files_in(v):
                _COMMAND_FILES.append((f"--{key.replace('_', '-')}", f))


def input_named(path: str, option: str, inputs: dict[str, str | None] | None = None
                ) -> str | None:
    """The option (or argument) of an existing input file that ``path`` (the output of
    ``option``) is: one of ``inputs`` ({option: path}) first, else one of the command's
    other files (:func:`set_command_files`); None if it is none of them."""
    others = [(k, v) for k, v in _COMMAND_FILES if k != option]
    for opt, src in [*(inputs or {}).items(), *others]:  # the caller's names first
        if src and os.path.isfile(src) and os.path.realpath(src) == os.path.realpath(path):
            return opt
    return None


#: the most bytes read from a text file that holds a few numbers (``--target-matrix FILE``,
#: ``--prior FILE.json``)
MAX_SMALL_TEXT = 1 << 20


def read_small_text(path: str, option: str, max_bytes: int = MAX_SMALL_TEXT) -> str:
    """The UTF-8 text of a small input file (a few numbers) named by ``option``: CLIError
    naming the option for anything but a regular file (a folder, ``/dev/zero``, a pipe),
    a file larger than ``max_bytes`` (never read past that), an unreadable or non-UTF-8
    file."""
    import stat

    try:
        st = os.stat(path)
    except OSError as e:
        raise CLIError(f"{option}: cannot read {path}: {e.strerror or e}") from None
    if not stat.S_ISREG(st.st_mode):
        what = ("a folder" if stat.S_ISDIR(st.st_mode) else "a device" if
                stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else "a pipe or socket"
                if stat.S_ISFIFO(st.st_mode) or stat.S_ISSOCK(st.st_mode) else "not a file")
        raise CLIError(f"{option}: {path} is {what}, not a regular file")
    too_big = (f"{option}: {path} is larger than {max_bytes} bytes; expected a small text "
               f"file of a few numbers")
    if st.st_size > max_bytes:
        raise CLIError(too_big)
    try:
        with open(path, "rb") as fh:
            raw = fh.read(max_bytes + 1)
    except OSError as e:
        raise CLIError(f"{option}: cannot read {path}: {e.strerror or e}") from None
    if len(raw) > max_bytes:  # it grew since the stat
        raise CLIError(too_big)
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise CLIError(f"{option}: {path} is not UTF-8 text (byte 0x{raw[e.start]:02x} at "
                       f"offset {e.start})") from None


def check_output(path: str, option: str, rerun: bool = False,
                 inputs: dict[str, str | None] | None = None) -> None:
    """Check an output path before any work: CLIError naming ``option`` if it is empty, a
    folder, in a missing or unwritable folder (a temporary file is made there and removed:
    :class:`jwarp.utils.atomic.AtomicFile`), one of the existing input files ``inputs``
    ({option: path}) or of the command's other files (:func:`set_command_files`), or, with
    ``rerun``, if rerun-sdk is missing."""
    from jwarp.utils.atomic import AtomicFile

    if not path or not path.strip():
        raise CLIError(f"{option}: empty file name")
    opt = input_named(path, option, inputs)
    if opt is not None:
        raise CLIError(f"{option}: {path} is also {opt}; give another file")
    if rerun:
        from jwarp.viz import rerun_module

        try:
            rerun_module()
        except ImportError as e:
            raise CLIError(f"{option}: {e}") from None
    try:
        AtomicFile(path, option=option).discard()
    except ValueError as e:
        raise CLIError(str(e)) from None


def rerun_recording(cls: type, path: str, *args: Any) -> Any:
    """``cls(path, *args, option="--rerun")`` (a :class:`jwarp.viz.recording.Recording`
    or a subclass): an unwritable path is a :class:`CLIError` naming ``--rerun``."""
    try:
        return cls(path, *args, option="--rerun")
    except ValueError as e:
        raise CLIError(str(e)) from None


# ------------------------------------------------------------------ parsing helpers
def load_robot(name: str):
    """A registered robot, a robot JSON, or a URDF file (also one of a description
    package: ``example-robot-data:NAME``, ``robot_descriptions:NAME``) with its collision
    model (spheres fitted to the links' collision geometry and sampled self-collision
    pairs, cached: :func:`jwarp.world.spherize.spherized_robot`)."""
    from jwarp.importers.robot import package_robot_path
    from jwarp.plugins.registry import robot

    path = package_robot_path(name)  # example-robot-data:NAME, robot_descriptions:NAME
    if path is not None and path.lower().endswith(".urdf"):
        name = path
    if isinstance(name, str) and name.lower().endswith(".urdf"):
        from jwarp.world.spherize import spherized_robot

        return spherized_robot(name, progress=None)[0]  # a bar on a terminal
    return robot(name)


def robot_option(name: str, option: str = "--robot") -> Any:
    """The robot of ``--robot`` (:func:`load_robot`); its errors as a :class:`CLIError`
    naming ``option``."""
    try:
        return load_robot(name)
    except (ValueError, TypeError, OSError, KeyError) as e:
        msg = " ".join(str(e).split())
        for prefix in ("robot: ", "path: "):
            msg = msg.removeprefix(prefix)
        raise CLIError(f"{option}: {msg}") from None


def parse_q(text: str, model: RobotModel, deg: bool = False, option: str = "--q") -> np.ndarray:
    """Parse ``v1,v2,...`` or ``zeros`` into (n_dof,) joint values [rad or m]."""
    text = text.strip()
    n = model.n_dof
    if text.lower() in ("zeros", "zero", "0"):
        return np.zeros(n)
    parts = [p.strip() for p in text.split(",")]
    if parts and parts[-1] == "":
        parts = parts[:-1]  # tolerate a trailing comma
    values = []
    for k, p in enumerate(parts):
        try:
            v = float(p)
        except ValueError:
            raise CLIError(f"{option}: value {k + 1} ({p!r}) is not a number") from None
        if not math.isfinite(v):
            raise CLIError(f"{option}: value {k + 1} is {p}; joint values must be finite")
        values.append(v)
    if len(values) != n:
        raise CLIError(f"{option}: robot '{model.name}' has {n} joints "
                       f"({', '.join(model.joint_names)}), got {len(values)} values")
    q = np.array(values, np.float64)
    if deg:
        revolute = np.array([j.type == "revolute" for j in model.joints])
        q = np.where(revolute, np.deg2rad(q), q)
    return q


def parse_kappa(text: str | None, model: RobotModel) -> tuple[Any, str]:
    """The kappa for fk_elastic and where it came from ('--kappa', 'robot' or 'default')."""
    if text is not None:
        parts = [p.strip() for p in text.split(",") if p.strip()]
        try:
            vals = [float(p) for p in parts]
        except ValueError:
            raise CLIError(f"--kappa: expected a number or 3 numbers [alpha,beta,theta] "
                           f"in rad/(N m), got {text!r}") from None
        if len(vals) not in (1, 3):
            raise CLIError(f"--kappa: expected 1 or 3 values [alpha,beta,theta], got {len(vals)}")
        if not all(math.isfinite(v) and v >= 0 for v in vals):
            raise CLIError(f"--kappa: compliances must be finite and >= 0, got {text!r}")
        return (vals[0] if len(vals) == 1 else vals), "--kappa"
    if np.any(model.kappa):
        return None, "robot"
    return DEFAULT_KAPPA, "default"


NEGATIVE_VALUE = re.compile(r"^-(\d|\.\d|inf|nan)", re.IGNORECASE)


def value_options(parser: argparse.ArgumentParser) -> set[str]:
    """The option strings (``--q``, ``--lam``, ...) of ``parser`` and its subcommands that
    take a value."""
    found: set[str] = set()
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                found |= value_options(sub)
        elif action.option_strings and action.nargs != 0:
            found.update(action.option_strings)
    return found


def fix_negative_values(argv: list[str], options: set[str] | None = None) -> list[str]:
    """Let ``--q -0.5,0,...`` mean ``--q=-0.5,0,...`` (argparse would take it for an
    option), for every option in ``options`` (default: the joint value options) and
    values that start like a negative number, ``-inf`` or ``-nan``."""
    if options is None:
        options = {"--q", "--kappa", "--start", "--goal", "--target"}
    out: list[str] = []
    i = 0
    while i < len(argv):
        a = argv[i]
        if a in options and i + 1 < len(argv) and NEGATIVE_VALUE.match(argv[i + 1]):
            out.append(f"{a}={argv[i + 1]}")
            i += 2
            continue
        out.append(a)
        i += 1
    return out


def quiet_warp() -> None:
    """Keep Warp's greeting and module-load messages off stdout (JSON output)."""
    import warp as wp

    if hasattr(wp.config, "quiet"):
        wp.config.quiet = True
    if hasattr(wp, "LOG_WARNING") and hasattr(wp.config, "log_level"):
        wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)


def warn_limits(model: RobotModel, q: np.ndarray) -> None:
    for j, (lo, hi) in enumerate(model.joint_limits):
        if not lo - 1e-12 <= q[j] <= hi + 1e-12:
            print(f"jwarp: warning: {model.joint_names[j]} = {q[j]:+.6g} outside its limits "
                  f"[{lo:+.6g}, {hi:+.6g}]", file=sys.stderr)
    for lim in model.linear_limits:
        v = sum(c * q[j] for j, c in zip(lim.joints, lim.coefficients))
        if not lim.lower - 1e-12 <= v <= lim.upper + 1e-12:
            terms = " + ".join(f"{c:g}*{model.joint_names[j]}"
                               for j, c in zip(lim.joints, lim.coefficients))
            print(f"jwarp: warning: {terms} = {v:+.6g} outside [{lim.lower:+.6g}, "
                  f"{lim.upper:+.6g}]", file=sys.stderr)
    from jwarp.model.valid_range import outside_message

    rng = outside_message(model, q, "q")   # a calibrated robot used outside its poses' range
    if rng is not None:
        print(f"jwarp: warning: {rng}", file=sys.stderr)


def dumps(obj: Any, indent: int = 0) -> str:
    """JSON with one line per object key and lists of numbers kept on one line."""
    pad = " " * (indent + 1)
    if isinstance(obj, dict) and obj:
        items = [f"{pad}{json.dumps(str(k))}: {dumps(v, indent + 1)}" for k, v in obj.items()]
        return "{\n" + ",\n".join(items) + "\n" + " " * indent + "}"
    if isinstance(obj, list) and any(isinstance(v, (dict, list)) for v in obj):
        items = [pad + dumps(v, indent + 1) for v in obj]
        return "[\n" + ",\n".join(items) + "\n" + " " * indent + "]"
    return json.dumps(obj)


def elastic_options(args: argparse.Namespace) -> None:
    """Reject elastic options without --elastic; fill in their defaults."""
    if not args.elastic:
        for opt, val in (("--kappa", args.kappa), ("--lam", args.lam),
                         ("--max-iter", args.max_iter)):
            if val is not None:
                raise CLIError(f"{opt}: only meaningful with --elastic")
    args.lam = 1.0 if args.lam is None else args.lam
    args.max_iter = DEFAULT_MAX_ITER if args.max_iter is None else args.max_iter


def dtype_of(name: str) -> Any:
    return {"float64": np.float64, "float32": np.float32}[name]




def plugin_warnings_one_line() -> None:
    """Show :class:`~jwarp.plugins.registry.PluginWarning`,
    :class:`~jwarp.core.kernel_cache.KernelCacheWarning` and
    :class:`~jwarp.utils.roots.OutsideFolderWarning` as one ``jwarp: warning: ...`` line on
    stderr (a broken plugin, an unusable kernel cache, a file outside its document's folder
    is reported, never a traceback); other warnings as before."""
    import warnings

    show = warnings.showwarning
    if getattr(show, "_jwarp_plugin_lines", False):
        return

    def showwarning(message, category, filename, lineno, file=None, line=None):  # noqa: ANN001
        from jwarp.core.kernel_cache import KernelCacheWarning
        from jwarp.plugins.registry import PluginWarning
        from jwarp.utils.roots import OutsideFolderWarning

        if isinstance(category, type) and issubclass(category, (
                PluginWarning, KernelCacheWarning, OutsideFolderWarning)):
            print(f"jwarp: warning: {message}", file=sys.stderr if file is None else file)
        else:
            show(message, category, filename, lineno, file, line)

    showwarning._jwarp_plugin_lines = True  # type: ignore[attr-defined]
    warnings.showwarning = showwarning
