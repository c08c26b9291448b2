"""CLI subcommands ``jwarp train ik|plan`` and ``jwarp eval ik|plan`` (hooked into
:mod:`jwarp.cli`): learned warm starts for the collision-free IK (thesis 3.4.4, 3.5.3) and
the motion planner (3.4.3, 3.5.2).

Examples::

    jwarp train ik --robot planar5 --world random --epochs 20 --out planar5.pt
    jwarp train ik --robot justin19 --frame right_tcp --world shelf --epochs 50 \\
        --steps-per-epoch 200 --batch 512 --device cuda --out justin19.pt --rerun curves.rrd
    jwarp train ik --robot justin19 --world shelf --epochs 80 --out justin19.pt --resume
    jwarp eval ik --robot planar5 --world random --model planar5.pt --model sup.pt
    jwarp eval ik --robot justin19 --world shelf --model justin19.pt --targets 200 --json
    jwarp ik --robot justin19 --frame right_tcp --target ... --warm-start justin19.pt

``train ik`` trains an IK network (:func:`jwarp.learn.train_ik.train_ik`; ``--supervised``:
the supervised baseline, :func:`~jwarp.learn.train_ik.train_ik_supervised`) with a
progress bar and one line per epoch (loss terms, hard-set size, validation cost and
feasibility, samples/s), writing the checkpoint ``--out`` after every epoch (atomically;
``--resume`` continues from it). ``--rerun FILE.rrd`` streams the per-epoch curves
(every number of the epoch line) to a rerun recording (timeline ``epoch``). Switches of
the ablation (Table 3.4): ``--no-twin``, ``--no-unit-vectors``, ``--no-boosting``;
``--n-bps N`` > 0 makes the network world-aware (basis point set of N points).

``train plan`` trains the motion-planning network (thesis 3.4.3;
:func:`jwarp.learn.train_plan.train_plan`) on random simplex worlds whose random (``--hard``:
only tasks the straight line does not solve) tasks are labelled by the planner's
multi-starts; switches ``--no-time-reversal``, ``--no-axis-symmetry``, ``--boosting``;
``--cleans N`` / ``--extend F`` add Algorithm 1's rounds (clean the labels with the
network + planner, add ``F`` x the set of new tasks the network does worst on).
``--data DB.sqlite`` trains on the labels of a path database instead
(:func:`jwarp.learn.train_plan.samples_from_db`; ``--val-fraction F`` of its worlds held
out, :func:`jwarp.learn.train_plan.split_by_world`). ``eval
plan`` prints the feasibility table (:func:`jwarp.learn.evaluate_plan.evaluate_plan`:
network alone, network + k planner iterations, random multi-starts 1 and best of N,
straight line) on unseen worlds. ``jwarp plan --warm-start MODEL.pt`` plans from the
network's paths.

    jwarp train plan --robot planar4 --n-worlds 8 --tasks-per-world 60 --hard --epochs 10 \
        --out plan4.pt
    jwarp train plan --robot planar4 --data p4.sqlite --val-fraction 0.1 --epochs 10 \
        --out plan4.pt
    jwarp eval plan --robot planar4 --model plan4.pt --hard --ks 0,10,50

``eval ik`` prints the Table 3.5 analogue (:func:`jwarp.learn.evaluate.evaluate_ik`) on
unseen targets (and, for random worlds, unseen worlds): the Random row always, then one
row per ``--model``; ``--ablation`` adds Table 3.4 (feasibility after 10 solver
iterations) of the models.

Every option is checked before any work (data generation, training): counts and numbers
in range, ``--device``, the output paths (``--out``, ``--rerun``: writable folder, not a
folder, not the same file), with ``--resume`` that ``--out`` exists, and the memory the
network needs to train (``--hidden``, ``--batch``; counted on torch's meta device) and
``train plan``'s labelling needs (``--tasks-per-world`` x ``--label-starts``); errors name
the option (``jwarp: error: --batch: ...``). A checkpoint (``--model``, ``--resume``) is
checked against its config before any weight is allocated. ``train plan --data DB
--skip-damaged`` leaves out damaged worlds and rows of the database (each named).
"""

from __future__ import annotations

import argparse
import math
import re
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.cli.common import (
    CLIError,
    check_device,
    check_option_memory,
    check_output,
    dumps,
    int_arg,
    quiet_warp,
    real_arg,
    rerun_recording,
    robot_option,
)

if TYPE_CHECKING:
    from jwarp.model import RobotModel

#: the test targets of ``eval ik`` without ``--mix`` (as in training by default)
DEFAULT_EVAL_MIX = (0.6, 0.2, 0.2, 0.0)

#: the options' names in the training options' errors
_TRAIN_OPTION_OF = {"mix": "--mix", "robot": "--robot", "frame": "--frame", "world": "--world",
                    "n_worlds": "--n-worlds", "n_targets": "--targets-per-world",
                    "n_val": "--val-targets", "n_bps": "--n-bps", "hidden": "--hidden",
                    "batch_size": "--batch", "epochs": "--epochs",
                    "steps_per_epoch": "--steps-per-epoch", "lr": "--lr", "device": "--device",
                    "seed": "--seed", "checkpoint": "--out", "resume": "--resume"}


def _frame(model: RobotModel, frame: str | None) -> str:
    """``--frame`` checked, or the robot's first end effector."""
    if frame is None:
        if not model.end_effectors:
            raise CLIError(f"--frame: robot '{model.name}' names no end effector; give --frame")
        return next(iter(model.end_effectors))
    try:
        model.frame_index(frame)
    except (ValueError, TypeError, KeyError) as e:
        raise CLIError(f"--frame: {' '.join(str(e).split()).removeprefix('frame: ')}") from None
    return frame


def _check_world_kind(model: RobotModel, kind: str) -> None:
    if kind == "shelf" and model.workspace_dim != 3:
        raise CLIError(f"--world: the shelf is a 3D scene; '{model.name}' is planar (use random "
                       f"or none)")


def _torch_device(name: str) -> None:
    """``--device`` for torch and Warp (checked before any work)."""
    try:
        import torch
    except ImportError as e:  # pragma: no cover - torch is a dependency of jwarp.learn
        raise CLIError(f"--device: the IK networks need torch ({e})") from None
    try:
        dev = torch.device(name)
    except (RuntimeError, ValueError) as e:
        raise CLIError(f"--device: {' '.join(str(e).split())}") from None
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise CLIError(f"--device: {name} requested but torch sees no CUDA device")
    if dev.type not in ("cpu", "cuda"):
        raise CLIError(f"--device: expected cpu or cuda[:N], got {name!r}")
    check_device(name)


def _option_error(e: Exception, mapping: dict, command: str) -> CLIError:
    msg = " ".join(str(e).split())
    m = re.match(r"^([a-z_]+): ", msg)
    if m and m.group(1) in mapping:
        return CLIError(f"{mapping[m.group(1)]}: {msg[m.end():]}")
    return CLIError(f"{command}: {msg}")


def _load_model(path: str, model: RobotModel, device: str = "cpu") -> Any:
    try:
        from jwarp.learn.checkpoint import load_checkpoint
    except ImportError as e:  # pragma: no cover
        raise CLIError(f"--model: the IK networks need torch ({e})") from None
    try:
        return load_checkpoint(path, robot=model, device=device)
    except (ValueError, TypeError, OSError, KeyError) as e:
        raise CLIError(f"--model: {' '.join(str(e).split()).removeprefix('checkpoint: ')}") \
            from None


def _worlds_per_batch(batch: int, n_worlds: int, kind: str) -> int:
    """Worlds per training batch: up to 4 (random worlds), dividing ``batch``."""
    if kind != "random":
        return 1
    for w in range(min(4, n_worlds), 0, -1):
        if batch % w == 0:
            return w
    return 1


# ------------------------------------------------------------------ commands
def cmd_train_ik(args: argparse.Namespace) -> int:
    model = robot_option(args.robot)
    frame = _frame(model, args.frame)
    _check_world_kind(model, args.world)
    _check_mix_world(args.mix, args.world)
    if args.world != "random" and args.n_worlds is not None:
        raise CLIError(f"--n-worlds: only meaningful with --world random (got --world "
                       f"{args.world})")
    if args.supervised and args.no_boosting:
        raise CLIError("--no-boosting: the supervised baseline never boosts; drop it")
    quiet_warp()
    _torch_device(args.device)
    check_output(args.out, "--out", inputs={"--rerun": args.rerun})
    if args.resume and not Path(args.out).is_file():
        raise CLIError(f"--resume: no checkpoint {args.out} to resume from (--out)")
    if args.rerun is not None:
        check_output(args.rerun, "--rerun", rerun=True, inputs={"--out": args.out})
        if Path(args.rerun).resolve() == Path(args.out).resolve():
            raise CLIError(f"--rerun: {args.rerun} is also --out; give another file")
    from jwarp.core.arrays import init_warp
    from jwarp.learn.train_ik import TrainIKOptions, train_ik, train_ik_supervised

    n_worlds = args.n_worlds if args.n_worlds is not None else 8
    fields = dict(robot=model.name, frame=frame, world=args.world, n_worlds=n_worlds,
                  n_targets=args.targets_per_world, n_val=args.val_targets, n_bps=args.n_bps,
                  hidden=args.hidden, twin=not args.no_twin,
                  unit_vectors=not args.no_unit_vectors, boosting=not args.no_boosting,
                  batch_size=args.batch, mix=args.mix,
                  worlds_per_batch=_worlds_per_batch(args.batch, n_worlds, args.world),
                  epochs=args.epochs, steps_per_epoch=args.steps_per_epoch, lr=args.lr,
                  device=args.device, seed=args.seed, checkpoint=args.out, resume=args.resume)
    if args.world != "random":
        fields["n_val_worlds"] = 1
    try:
        options = TrainIKOptions(**fields)
    except (ValueError, TypeError) as e:
        raise _option_error(e, _TRAIN_OPTION_OF, "train ik") from None
    _check_net_memory("ik", options, args)
    init_warp()
    curves = None
    if args.rerun is not None:
        from jwarp.viz.curves import TrainingCurves

        curves = rerun_recording(TrainingCurves, args.rerun)

    def callback(rec: Any, net: Any = None) -> None:
        if curves is not None and isinstance(rec, dict):
            curves.log(rec)

    run = train_ik_supervised if args.supervised else train_ik
    try:
        net, history = run(options, progress=not args.quiet, callback=callback)
        written = curves.close() if curves is not None else None
    except BaseException:
        if curves is not None:
            curves.abort()
        raise
    last = history[-1] if history else {}
    kind = "supervised" if args.supervised else "unsupervised"
    print(f"trained {kind} IK network for {model.name} {frame} ({args.world} worlds): epoch "
          f"{last.get('epoch', 0)}/{args.epochs}, validation feasibility "
          f"{100 * last.get('val_feasible', math.nan):.1f}% after "
          f"{options.val_iterations} solver iterations")
    if Path(args.out).is_file():
        print(f"wrote {args.out}; use with: jwarp ik --robot {model.name} --frame {frame} "
              f"--target ... --warm-start {args.out}")
    if written is not None:
        print(f"wrote {written}; view with: rerun {written}")
    return 0


def _eval_data(model: RobotModel, frame: str, kind: str, n_worlds: int, n_targets: int,
               seed: int, mix: tuple) -> tuple[list, list]:
    """Unseen test worlds and targets (seeds offset from training (seed + 100 i) and
    validation (seed + 100000))."""
    from jwarp.learn.ik_data import SCENE_TASKS, make_worlds, sample_targets

    worlds = make_worlds(model, kind, n_worlds, seed=seed + 200000)
    targets = [sample_targets(model, frame, n_targets, w, seed=seed * 7919 + 200000 + i,
                              mix=mix, tasks=SCENE_TASKS.get(kind))[0]
               for i, w in enumerate(worlds)]
    return worlds, targets


def _mix_arg(text: str) -> tuple:
    """argparse type of ``--mix``: 3 or 4 comma-separated fractions (CLIError naming it)."""
    from jwarp.learn.ik_data import check_mix

    try:
        mix = tuple(float(v) for v in text.split(","))
        check_mix(mix)
    except ValueError:
        raise CLIError(f"--mix: expected 3 or 4 comma-separated fractions >= 0 (uniform, near "
                       f"obstacles, border[, scene tasks]), got {text!r}") from None
    return mix


def _check_mix_world(mix: tuple, kind: str) -> None:
    from jwarp.learn.ik_data import SCENE_TASKS

    if len(mix) == 4 and mix[3] > 0 and kind not in SCENE_TASKS:
        raise CLIError(f"--mix: scene tasks need a world with a task distribution "
                       f"({', '.join(SCENE_TASKS)}), got --world {kind}")


def cmd_eval_ik(args: argparse.Namespace) -> int:
    model = robot_option(args.robot)
    quiet_warp()
    check_device(args.device)
    nets = [(p, _load_model(p, model)) for p in (args.model or [])]
    if args.ablation and not nets:
        raise CLIError("--ablation: needs at least one --model")
    frames = {str(n.config.frame) for _, n in nets}
    if args.frame is None and len(frames) == 1:
        frame = frames.pop()
    else:
        frame = _frame(model, args.frame)
    for p, n in nets:
        if model.frame_index(n.config.frame) != model.frame_index(frame):
            raise CLIError(f"--model: {p} predicts frame '{n.config.frame}', not {frame}")
    kind = args.world
    if kind is None:
        kinds = {str((n.meta.get("training") or {}).get("world", "")) for _, n in nets} - {""}
        kind = kinds.pop() if len(kinds) == 1 else ("shelf" if model.workspace_dim == 3
                                                      else "random")
    _check_world_kind(model, kind)
    for p, n in nets:
        if getattr(n.config, "n_bps", 0) and kind == "none":
            raise CLIError(f"--world: {p} is world-aware; evaluate it in worlds (random, shelf)")
    n_worlds = args.n_worlds if kind == "random" else 1
    from jwarp.learn.evaluate import (
        ablation_table,
        evaluate_ik,
        format_table_34,
        format_table_35,
    )

    mix = args.mix if args.mix is not None else DEFAULT_EVAL_MIX
    _check_mix_world(mix, kind)
    worlds, targets = _eval_data(model, frame, kind, n_worlds, args.targets, args.seed, mix)
    common = dict(iterations=args.iterations, seed=args.seed, device=args.device)
    rows = [evaluate_ik(model, frame, worlds, targets, n_random=args.random_starts,
                        name="Random", **common)]
    for p, n in nets:
        sup = bool((n.meta.get("training") or {}).get("supervised", False))
        name = f"{Path(p).stem} ({'supervised' if sup else 'unsupervised'})"
        rows.append(evaluate_ik(model, frame, worlds, targets, warm_start=n,
                                n_random=args.random_starts, name=name, **common))
    ablation = None
    if args.ablation:
        ablation = ablation_table(model, frame, worlds, targets,
                                  [(Path(p).stem, n) for p, n in nets],
                                  iterations=args.ablation_iterations, seed=args.seed,
                                  device=args.device)
    where = f"{kind} world{'s' if len(worlds) > 1 else ''}" if kind != "none" else "no world"
    if args.json:
        out = {"robot": model.name, "frame": frame, "world": kind, "n_worlds": len(worlds),
               "targets_per_world": args.targets, "models": [p for p, _ in nets],
               "table_3_5": rows}
        if ablation is not None:
            out["table_3_4"] = ablation
        print(dumps(_plain(out)))
    else:
        print(format_table_35(rows, f"Table 3.5 analogue: {model.name} {frame}, {where} "
                                    f"(unseen targets)"))
        if ablation is not None:
            print()
            print(format_table_34(ablation, f"Table 3.4 analogue: {model.name} {frame}, "
                                            f"{where}"))
    return 0


# ------------------------------------------------------------------ planning network
_TRAIN_PLAN_OPTION_OF = {"robot": "--robot", "n_bps": "--n-bps", "n_waypoints": "--waypoints",
                         "hidden": "--hidden", "n_blocks": "--blocks", "n_heads": "--heads",
                         "epochs": "--epochs", "steps_per_epoch": "--steps-per-epoch",
                         "batch_size": "--batch", "lr": "--lr", "device": "--device",
                         "seed": "--seed", "checkpoint": "--out", "n_substeps": "--substeps"}


def _plan_worlds(model: RobotModel, n: int, seed: int) -> list:
    from jwarp.world.feasibility import feasible_simplex_world

    return [feasible_simplex_world(model, seed=seed + 7 * i) for i in range(n)]


def _load_plan_model(path: str, model: RobotModel, option: str = "--model") -> Any:
    try:
        from jwarp.learn.checkpoint import load_plan_checkpoint
    except ImportError as e:  # pragma: no cover
        raise CLIError(f"{option}: the planning networks need torch ({e})") from None
    try:
        return load_plan_checkpoint(path, robot=model)
    except (ValueError, TypeError, OSError, KeyError) as e:
        raise CLIError(f"{option}: {' '.join(str(e).split()).removeprefix('checkpoint: ')}") \
            from None


def _plan_db_samples(args: argparse.Namespace, model: RobotModel) -> tuple[Any, Any]:
    """(train, val) of ``--data`` (split by world, ``--val-fraction``); one-line CLIErrors
    naming ``--data``, ``--waypoints`` or ``--val-fraction``."""
    from jwarp.learn.dataset import PathDB
    from jwarp.learn.train_plan import samples_from_db, split_by_world

    def clean(e: Exception) -> str:
        return " ".join(str(e).split()).removeprefix("database: ")

    try:
        db = PathDB(args.data, model)
    except ValueError as e:  # PathDBError: missing, not a database, another robot, corrupt
        raise CLIError(f"--data: {clean(e)}") from None
    try:
        skipped: list = []
        samples = samples_from_db(db, model, hard_only=not args.all_paths,
                                  n_waypoints=args.waypoints, skip_damaged=args.skip_damaged,
                                  skipped=skipped)
        for item in skipped:
            print(f"jwarp: warning: skipped {item['what']}", file=sys.stderr)
    except ValueError as e:
        msg = clean(e)
        if "is damaged" in msg:
            msg += " (--skip-damaged leaves damaged worlds and rows out)"
        if msg.startswith("n_waypoints: "):
            raise CLIError(f"--waypoints: {msg.removeprefix('n_waypoints: ')}") from None
        raise CLIError(f"--data: {msg}") from None
    finally:
        db.close()
    try:
        return split_by_world(samples, args.val_fraction, args.seed)
    except ValueError as e:
        raise CLIError(f"--val-fraction: {clean(e).removeprefix('val_fraction: ')}") from None


def _check_net_memory(kind: str, options: Any, args: argparse.Namespace) -> None:
    """Refuse a network (``--hidden``, ``--blocks``, ``--n-bps``) whose training memory
    (weights, gradients, Adam's moments; counted on torch's meta device) or whose batch
    (``--batch`` x ``--hidden`` activations) exceeds the available memory, before any
    data is made."""
    from jwarp.learn.checkpoint import network_bytes

    cls: type
    if kind == "ik":
        from jwarp.learn.ik_net import IKNet as cls
    else:
        from jwarp.learn.plan_net import PlanNet as cls
    config = options.net_config()
    need = network_bytes(cls, config, training=True)
    blocks = getattr(config, "n_blocks", 3)
    need += 4.0 * 2 * args.batch * args.hidden * (2 * blocks + 2)   # activations + grads
    option = "--hidden" if args.hidden * args.hidden > 64 * args.batch * 8 else "--batch"
    check_option_memory(need, f"training this network (hidden {args.hidden}, {blocks} blocks, "
                        f"batch {args.batch}: weights, gradients, optimizer state and "
                        f"activations)", option)


def _check_label_memory(model: RobotModel, args: argparse.Namespace) -> None:
    """Refuse ``--tasks-per-world`` x ``--label-starts`` x ``--waypoints`` whose labelling
    (one planner batch per world) cannot fit in memory (estimate of
    :func:`jwarp.cli.data.labeller_memory`)."""
    from types import SimpleNamespace

    from jwarp.cli.data import labeller_memory

    W = args.waypoints or 20
    n = max(args.tasks_per_world, args.val_tasks)
    need = labeller_memory(model, SimpleNamespace(n_waypoints=W, max_starts=args.label_starts,
                                                  n_substeps=None, dtype="float32"), n, 1)
    option = max((("--tasks-per-world", n / 50), ("--label-starts", args.label_starts / 16),
                  ("--waypoints", W / 20)), key=lambda t: t[1])[0]
    check_option_memory(need, f"labelling {n} tasks x {args.label_starts} multi-starts x {W} "
                        f"waypoints of '{model.name}'", option)


def cmd_train_plan(args: argparse.Namespace) -> int:
    model = robot_option(args.robot)
    if model.workspace_dim not in (2, 3):  # pragma: no cover - every robot is 2D or 3D
        raise CLIError(f"--robot: unsupported workspace dimension {model.workspace_dim}")
    quiet_warp()
    _torch_device(args.device)
    check_output(args.out, "--out")
    from jwarp.core.arrays import init_warp
    from jwarp.learn.train_plan import (
        TrainPlanOptions,
        improve,
        make_plan_data,
        train_plan,
    )

    if args.skip_damaged and args.data is None:
        raise CLIError("--skip-damaged: only with --data (a path database)")
    if args.data is None:  # the labelling's memory, before any world is made
        _check_label_memory(model, args)
    db_data = _plan_db_samples(args, model) if args.data is not None else None
    if args.waypoints is None:
        args.waypoints = db_data[0].paths.shape[1] if db_data is not None else 20
    try:
        options = TrainPlanOptions(robot=model.name, n_bps=args.n_bps, n_waypoints=args.waypoints,
                                   hidden=args.hidden, n_blocks=args.blocks, n_heads=args.heads,
                                   epochs=args.epochs, steps_per_epoch=args.steps_per_epoch,
                                   batch_size=args.batch, lr=args.lr,
                                   time_reversal=not args.no_time_reversal,
                                   axis_symmetry=not args.no_axis_symmetry,
                                   boosting=args.boosting, device=args.device, seed=args.seed,
                                   checkpoint=args.out)
        options.validate()
        from jwarp.learn.plan_net import axis_symmetries
        axis_symmetries(model)
    except (ValueError, TypeError) as e:
        raise _option_error(e, _TRAIN_PLAN_OPTION_OF, "train plan") from None
    _check_net_memory("plan", options, args)
    init_warp()
    if db_data is not None:
        data, val = db_data
        n_train_worlds, n_val_worlds = len(data.worlds), len(val.worlds)
    else:
        worlds = _plan_worlds(model, args.n_worlds, args.seed * 1000 + 1)
        val_worlds = _plan_worlds(model, args.val_worlds, args.seed * 1000 + 100001)
        common = dict(n_waypoints=args.waypoints, n_starts=args.label_starts,
                      iterations=args.label_iterations, hard=args.hard)
        data = make_plan_data(model, worlds, args.tasks_per_world, seed=args.seed, **common)
        val = make_plan_data(model, val_worlds, args.val_tasks, seed=args.seed + 1, **common)
        n_train_worlds, n_val_worlds = len(worlds), len(val_worlds)
    if not len(data):
        raise CLIError("train plan: the planner labelled no task feasibly (raise "
                       "--label-starts or --label-iterations)")
    if not args.quiet:
        src = f" from {args.data}" if args.data is not None else ""
        print(f"data{src}: {len(data)} training tasks in {n_train_worlds} worlds, {len(val)} "
              f"validation tasks in {n_val_worlds} unseen worlds")
    rounds = max(args.cleans, 1 if args.extend > 0 else 0)
    if rounds:
        _, data, log = improve(options, data, val if len(val) else None, rounds=rounds,
                                 n_cleans=args.cleans, extend_fraction=args.extend,
                                 progress=not args.quiet)
        mse = log[-1]["val_mse"]
    else:
        _, hist = train_plan(options, data, val if len(val) else None,
                               progress=not args.quiet)
        mse = hist[-1]["val_mse"]
    print(f"trained planning network for {model.name}: {len(data)} tasks, validation MSE "
          f"{mse:.5g}")
    print(f"wrote {args.out}; use with: jwarp plan --robot {model.name} --world ... --start ... "
          f"--goal ... --warm-start {args.out}")
    return 0


def cmd_eval_plan(args: argparse.Namespace) -> int:
    model = robot_option(args.robot)
    quiet_warp()
    check_device(args.device)
    try:
        ks = tuple(sorted({int(v) for v in args.ks.split(",")}))
        if not ks or ks[0] < 0:
            raise ValueError
    except ValueError:
        raise CLIError(f"--ks: expected comma-separated iteration counts >= 0, got "
                       f"{args.ks!r}") from None
    nets = [(p, _load_plan_model(p, model)) for p in (args.model or [])]
    from jwarp.learn.evaluate_plan import evaluate_plan, format_plan_table
    from jwarp.learn.train_plan import hard_tasks, sample_tasks

    W = nets[0][1].n_waypoints if nets else 20
    worlds = _plan_worlds(model, args.n_worlds, args.seed * 1000 + 200001)
    rng = np.random.default_rng(args.seed + 200000)
    S, G, I = [], [], []
    for i, w in enumerate(worlds):
        if args.hard:
            q0, q1 = hard_tasks(model, w, args.tasks, rng, n_waypoints=W)
        else:
            q0, q1 = sample_tasks(model, w, args.tasks, rng)
        S.append(q0)
        G.append(q1)
        I.append(np.full(len(q0), i))
    starts, goals, index = np.concatenate(S), np.concatenate(G), np.concatenate(I)
    if not len(starts):
        raise CLIError("--hard: no hard task found in the test worlds")
    rows = evaluate_plan(model, worlds, starts, goals, index,
                         nets=[(Path(p).stem, n) for p, n in nets], ks=ks,
                         n_random=args.random_starts, n_waypoints=W, seed=args.seed,
                         device=args.device)
    if args.json:
        print(dumps(_plain({"robot": model.name, "n_worlds": len(worlds), "tasks": len(starts),
                            "hard": args.hard, "ks": list(ks), "models": [p for p, _ in nets],
                            "rows": [{**r, "feasible": {str(k): v for k, v in
                                                        r["feasible"].items()}} for r in rows]})))
    else:
        print(format_plan_table(rows, f"{model.name}: {len(starts)} {'hard ' if args.hard else ''}"
                                      f"tasks in {len(worlds)} unseen random worlds"))
    return 0


def _plain(x: Any) -> Any:
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return None if not math.isfinite(float(x)) else float(x)
    if isinstance(x, np.integer):
        return int(x)
    return x


# ------------------------------------------------------------------ parser
def _optimizer_options(s: argparse.ArgumentParser, epochs_help: str, batch: int,
                       item: str) -> None:
    """--epochs (required), --steps-per-epoch, --batch (default ``batch`` ``item``s per
    step) and --lr of a training command."""
    s.add_argument("--epochs", type=int_arg("--epochs", 1, 10**6), required=True, metavar="N",
                   help=epochs_help)
    s.add_argument("--steps-per-epoch", type=int_arg("--steps-per-epoch", 1, 10**9),
                   default=100, metavar="N", help="optimizer steps per epoch (default 100)")
    s.add_argument("--batch", type=int_arg("--batch", 1, 10**7), default=batch, metavar="N",
                   help=f"{item} per step (default {batch})")
    s.add_argument("--lr", type=real_arg("--lr", 0.0, lo_open=True), default=1e-3,
                   help="learning rate, > 0 (default 1e-3)")


def add_subcommands(sub: Any) -> None:
    """Add ``train ik|plan`` and ``eval ik|plan`` to the ``jwarp`` subparsers."""
    from jwarp.cli.common import Parser

    train = sub.add_parser("train", help="train a learned warm start: train ik (IK network) "
                                         "| train plan (motion-planning network)")
    tsub = train.add_subparsers(dest="what", metavar="WHAT", parser_class=Parser)
    tsub.required = True
    s = tsub.add_parser("ik", help="train an IK network (learned warm starts of the IK solver)")
    s.add_argument("--robot", required=True, help="robot name or path to a robot .json")
    s.add_argument("--frame", default=None, help="end-effector frame (default: the robot's "
                                                 "first end effector)")
    s.add_argument("--world", default="random", choices=("random", "shelf", "none"),
                   help="training worlds: random simplex worlds, the shelf scene or none "
                        "(default random)")
    s.add_argument("--n-worlds", type=int_arg("--n-worlds", 1), default=None, metavar="N",
                   help="random training worlds (default 8)")
    s.add_argument("--targets-per-world", type=int_arg("--targets-per-world", 1), default=2000,
                   metavar="N", help="training targets per world (default 2000)")
    s.add_argument("--val-targets", type=int_arg("--val-targets", 1), default=128, metavar="N",
                   help="validation targets per validation world (default 128)")
    _optimizer_options(s, "epochs in all (counting resumed ones)", 256, "targets")
    s.add_argument("--hidden", type=int_arg("--hidden", 1, 1 << 16), default=128, metavar="N",
                   help="hidden width (default 128)")
    s.add_argument("--n-bps", type=int_arg("--n-bps", 0, 1 << 20), default=0, metavar="N",
                   help="basis points of the world encoding; 0: world-unaware (default 0)")
    s.add_argument("--mix", type=_mix_arg, default=(0.6, 0.2, 0.2, 0.0), metavar="U,N,B[,T]",
                   help="fractions of the training targets: uniform, near obstacles, workspace "
                        "border, scene tasks (the shelf's grasp poses; default 0.6,0.2,0.2,0)")
    s.add_argument("--no-twin", action="store_true", help="one head instead of twin heads")
    s.add_argument("--no-unit-vectors", action="store_true",
                   help="plain joint values instead of (sin, cos) unit vectors")
    s.add_argument("--no-boosting", action="store_true", help="no hard-sample boosting")
    s.add_argument("--supervised", action="store_true",
                   help="the supervised baseline (labels from the IK solver)")
    s.add_argument("--device", default="cpu",
                   help="torch device of the network and Warp device of the IK solver that "
                        "scores it (default cpu; e.g. cuda)")
    s.add_argument("--out", default="model.pt", metavar="MODEL.pt",
                   help="checkpoint, written after every epoch (default model.pt)")
    s.add_argument("--resume", action="store_true", help="continue from the checkpoint --out")
    s.add_argument("--rerun", default=None, metavar="FILE.rrd",
                   help="stream the training curves to a rerun recording")
    s.add_argument("--seed", type=int_arg("--seed", 0, 2**31 - 1), default=0,
                   help="random seed (data, initialisation; >= 0)")
    s.add_argument("--quiet", action="store_true", help="no progress bar or epoch lines")
    s.set_defaults(func=cmd_train_ik)

    s = tsub.add_parser("plan", help="train a motion-planning network (learned warm starts "
                                     "of the planner)")
    s.add_argument("--robot", required=True, help="robot name or path to a robot .json")
    s.add_argument("--n-worlds", type=int_arg("--n-worlds", 1, 10**6), default=8, metavar="N",
                   help="random training worlds (default 8)")
    s.add_argument("--tasks-per-world", type=int_arg("--tasks-per-world", 1, 10**7), default=50,
                   metavar="N", help="labelled tasks per training world (default 50)")
    s.add_argument("--val-worlds", type=int_arg("--val-worlds", 0, 10**6), default=2,
                   metavar="N", help="unseen validation worlds (default 2)")
    s.add_argument("--val-tasks", type=int_arg("--val-tasks", 1, 10**7), default=20,
                   metavar="N", help="tasks per validation world (default 20)")
    s.add_argument("--hard", action="store_true",
                   help="only tasks whose straight line the planner does not solve")
    s.add_argument("--label-starts", type=int_arg("--label-starts", 1, 10**5), default=16,
                   metavar="N", help="planner multi-starts per label (default 16)")
    s.add_argument("--label-iterations", type=int_arg("--label-iterations", 1, 10**6),
                   default=200, metavar="N", help="planner iterations per label (default 200)")
    s.add_argument("--waypoints", type=int_arg("--waypoints", 3, 10**4), default=None,
                   metavar="W", help="waypoints of the predicted paths (default 20; with "
                                     "--data: the database's, which it must match)")
    s.add_argument("--data", default=None, metavar="DB.sqlite",
                   help="train on the labels of a path database (jwarp data generate) instead "
                        "of generating tasks (--n-worlds, --tasks-per-world, --val-worlds, "
                        "--val-tasks, --hard, --label-* are then unused)")
    s.add_argument("--val-fraction", type=real_arg("--val-fraction", 0.0, 1.0, hi_open=True),
                   default=0.1, metavar="F",
                   help="with --data: fraction of its worlds held out for validation, unseen "
                        "in training (default 0.1; 0: no validation)")
    s.add_argument("--skip-damaged", action="store_true",
                   help="with --data: leave out worlds and path rows whose stored data is "
                        "damaged (each named on stderr) instead of stopping at the first")
    s.add_argument("--all-paths", action="store_true",
                   help="with --data: also the paths not flagged hard (default: hard only; "
                        "infeasible paths are always left out)")
    s.add_argument("--n-bps", type=int_arg("--n-bps", 0, 1 << 20), default=128, metavar="N",
                   help="basis points of the world encoding (default 128; 0: world-unaware)")
    s.add_argument("--hidden", type=int_arg("--hidden", 1, 1 << 16), default=256, metavar="N",
                   help="hidden width (default 256)")
    s.add_argument("--blocks", type=int_arg("--blocks", 1, 64), default=3, metavar="N",
                   help="dense blocks (default 3)")
    s.add_argument("--heads", type=int_arg("--heads", 1, 64), default=1, metavar="N",
                   help="paths per task (default 1)")
    _optimizer_options(s, "epochs (per round of --cleans/--extend)", 128, "samples")
    s.add_argument("--no-time-reversal", action="store_true",
                   help="no time-reversal augmentation")
    s.add_argument("--no-axis-symmetry", action="store_true",
                   help="no augmentation by the robot's axis symmetries")
    s.add_argument("--boosting", action="store_true",
                   help="oversample the tasks the network does worst on (Algorithm 1's boost)")
    s.add_argument("--cleans", type=int_arg("--cleans", 0, 1000), default=0, metavar="N",
                   help="rounds of label cleaning by network + planner (default 0)")
    s.add_argument("--extend", type=real_arg("--extend", 0.0, 10.0), default=0.0, metavar="F",
                   help="per round, add F x the set of new tasks the network does worst on "
                        "(default 0)")
    s.add_argument("--device", default="cpu",
                   help="torch device of the network (default cpu; e.g. cuda); the planner "
                        "that labels the tasks runs on the CPU")
    s.add_argument("--out", default="plan_model.pt", metavar="MODEL.pt",
                   help="checkpoint, written after every epoch (default plan_model.pt)")
    s.add_argument("--seed", type=int_arg("--seed", 0, 2**31 - 1), default=0,
                   help="random seed (worlds, tasks, initialisation; >= 0)")
    s.add_argument("--quiet", action="store_true", help="no epoch lines")
    s.set_defaults(func=cmd_train_plan)

    ev = sub.add_parser("eval", help="evaluate learned warm starts: eval ik (Tables 3.4/3.5) "
                                     "| eval plan (Fig. 3.24, Table 3.3)")
    esub = ev.add_subparsers(dest="what", metavar="WHAT", parser_class=Parser)
    esub.required = True
    s = esub.add_parser("ik", help="Table 3.5 analogue: random vs learned IK warm starts")
    s.add_argument("--robot", required=True, help="robot name or path to a robot .json")
    s.add_argument("--frame", default=None,
                   help="end-effector frame (default: the models', else the first end effector)")
    s.add_argument("--world", default=None, choices=("random", "shelf", "none"),
                   help="test worlds (default: the models' training worlds)")
    s.add_argument("--model", action="append", default=None, metavar="MODEL.pt",
                   help="a checkpoint of jwarp train ik (repeatable; one row each)")
    s.add_argument("--targets", type=int_arg("--targets", 1, 10**7), default=100, metavar="N",
                   help="unseen targets per world (default 100)")
    s.add_argument("--n-worlds", type=int_arg("--n-worlds", 1, 10**5), default=4, metavar="N",
                   help="unseen random worlds (--world random; default 4)")
    s.add_argument("--random-starts", type=int_arg("--random-starts", 1, 10**5), default=50,
                   metavar="N", help="random seeds tried one after the other: the cap of the "
                                     "multi-starts (default 50)")
    s.add_argument("--iterations", type=int_arg("--iterations", 0, 10**6), default=200,
                   metavar="N", help="solver iterations per seed (default 200)")
    s.add_argument("--mix", type=_mix_arg, default=None, metavar="U,N,B[,T]",
                   help="fractions of the test targets: uniform, near obstacles, workspace "
                        "border, scene tasks (default 0.6,0.2,0.2,0)")
    s.add_argument("--ablation", action="store_true",
                   help="also Table 3.4: feasibility of each model after --ablation-iterations")
    s.add_argument("--ablation-iterations", type=int_arg("--ablation-iterations", 0, 10**6),
                   default=10, metavar="N", help="solver iterations of --ablation (default 10)")
    s.add_argument("--seed", type=int_arg("--seed", 0, 2**31 - 1), default=0,
                   help="seed of the test worlds, targets and random seeds")
    s.add_argument("--device", default="cpu", help="Warp device of the solver (default cpu)")
    s.add_argument("--json", action="store_true", help="print JSON")
    s.set_defaults(func=cmd_eval_ik)

    s = esub.add_parser("plan", help="feasibility of learned vs random planner starts "
                                     "(thesis Fig. 3.24, Table 3.3)")
    s.add_argument("--robot", required=True, help="robot name or path to a robot .json")
    s.add_argument("--model", action="append", default=None, metavar="MODEL.pt",
                   help="a checkpoint of jwarp train plan (repeatable; one row each)")
    s.add_argument("--n-worlds", type=int_arg("--n-worlds", 1, 10**5), default=4, metavar="N",
                   help="unseen random worlds (default 4)")
    s.add_argument("--tasks", type=int_arg("--tasks", 1, 10**6), default=25, metavar="N",
                   help="tasks per world (default 25)")
    s.add_argument("--hard", action="store_true",
                   help="only tasks whose straight line the planner does not solve")
    s.add_argument("--ks", default="0,10,50", metavar="K,K,...",
                   help="planner iterations at which feasibility is counted (default 0,10,50)")
    s.add_argument("--random-starts", type=int_arg("--random-starts", 1, 10**4), default=10,
                   metavar="N", help="the random multi-starts of the best-of row (default 10)")
    s.add_argument("--seed", type=int_arg("--seed", 0, 2**31 - 1), default=0,
                   help="seed of the test worlds and tasks")
    s.add_argument("--device", default="cpu",
                   help="Warp device of the planner (default cpu; e.g. cuda:0)")
    s.add_argument("--json", action="store_true", help="print JSON")
    s.set_defaults(func=cmd_eval_plan)
