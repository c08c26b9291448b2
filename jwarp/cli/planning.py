"""CLI subcommands ``jwarp plan``, ``jwarp ik`` and ``jwarp free-config`` (hooked into
:mod:`jwarp.cli`).

Examples::

    jwarp plan --robot planar4 --world simplex:seed=3 --start 1.2,0,0,0 --goal -1.2,0,0,0
    jwarp plan --robot justin19 --world world.npz --start ... --goal ... --starts 16 \\
        --rerun plan.rrd --json
    jwarp plan --robot panda.urdf --scene examples/scenes/table_shelf.yaml --voxel 0.02 \\
        --start moveit --goal moveit
    jwarp ik --robot justin19 --frame right_tcp --target 0.6,-0.25,0.8,0,1.5708,0 --json
    jwarp ik --robot justin19 --frame right_tcp --target ... --world shelf.npz \
        --warm-start model.pt [--starts 4]
    jwarp free-config --robot planar4 --world simplex:seed=3 --n 2 --seed 0

``ik`` targets (:mod:`jwarp.cli.targets`): ``--target X,Y,Z[,RX,RY,RZ]`` (rotation vector),
``--target X,Y,Z`` with ``--quat QX,QY,QZ,QW`` (ROS order, normalised) or ``--rpy R,P,Y``
[rad, also with ``--deg``] (R = Rz(Y) Ry(P) Rx(R)), or ``--target-matrix`` (a 4x4 rigid
transform: 16 numbers or a file); ``--position-only`` or ``--free-axis X,Y,Z`` (the rotation
about that end-effector axis is free; ``jwarp.ik(orientation=..., free_axis=...)``);
``--tol-pos M``/``--tol-rot RAD``; ``--initial Q`` (joint values, ``--deg`` honoured, within
the limits) is the first of the ``--starts`` seeds; ``--targets FILE --out RESULTS``
solves a file of targets in one batch (:func:`cmd_ik_batch`, docs/ik.md "Many targets");
``--scene`` as for ``plan`` (exact objects, or a grid with ``--voxel``/``--extent``). An infeasible answer prints ``why:``
(JSON ``reason``): :func:`jwarp.solvers.ik.explain.explain_ik` (limits, pose error against
the tolerances, colliding pairs).

``free-config`` prints collision-free configurations (within the joint limits, clear of
the world and of the robot itself by ``--margin``) with the joint names, and each as a
``--start`` value to copy. ``ik`` and ``plan`` print the joint names beside every
configuration (``--json``: ``joint_names``); ``plan --json``'s ``costs_explained`` says how
``costs.total`` is made of ``costs.collision`` and ``costs.length``.

``--warm-start MODEL.pt`` (``ik``) starts the solver from a trained IK network's
prediction (a ``jwarp train ik`` checkpoint for this robot and frame; twin heads: 2 seeds)
followed by ``--starts`` random seeds (default 0 with a warm start, 16 without).

``--warm-start MODEL.pt`` (``plan``) starts the planner from a trained motion-planning
network's paths (a ``jwarp train plan`` checkpoint for this robot; its waypoints) followed
by multi-starts up to ``--starts`` (default: the network's paths only).

``--scene FILE.yaml`` (``plan``, instead of ``--world``): a jwarp scene file or a MoveIt
planning scene (docs/scenes.md), its SDF sampled at ``--voxel V`` [m] (default: the file's
``grid.voxel``, else 0.02) over ``--extent x0,x1,y0,y1,z0,z1`` [m] (default: the obstacles'
bounding box padded by max(0.2 m, largest robot sphere radius + ``--margin`` + a voxel)).
Frame ids: ``world``, ``base`` and the robot's fixed frames, all the robot's base frame.

``--start``/``--goal`` are joint values v1,v2,... [rad, m for prismatic] (``--deg``: revolute
ones in degrees), or ``moveit`` (the ``--scene`` file's ``robot_state.joint_state`` /
goal ``joint_constraints``) or ``moveit:FILE`` (another planning scene or MotionPlanRequest
YAML): joints matched by name (unknown names are an error; a goal's unconstrained joints
keep the start's values); ``--target`` is x,y,z [m] and a rotation vector rx,ry,rz [rad] of the
frame in the robot's base frame. JSON output holds the path (or q), feasibility, costs,
iterations and wall time. ``--rerun FILE.rrd`` writes a recording: the world's occupied
voxels, the robot's spheres and the path (end-effector traces) at every logged iteration.

Budgets (``plan``, docs/scenes.md "Budgets and fallback"): the planner stops as soon as a
start is feasible (``--stop-when-solved``, the default; ``--no-stop-when-solved`` optimises
every start until it is feasible or out of iterations), after ``--iterations`` or after
``--time-limit S`` seconds (default: none). ``--fallback rrt`` (default) gives an unsolved
problem an RRT-Connect path as the seed of one more optimisation (after the iterations or
half the time limit); ``--fallback none`` does not. ``--shorten N`` (default 1 on the CPU, 4 on CUDA; 0: off) pulls
the solved path straight in N rounds of shortcuts proven by the exact check (with
``--stop-when-solved``), the rounds after the first check within ``--shorten-budget`` (their
check evaluations at most 0.5 of the optimisation's collision evaluations; ``none``: no
budget).
The output prints the path's length cost against the straight line's (and before the
shortening). The output says why the planner
stopped (``stop_reason``: solved, time_limit, iterations, all_done) and which stage solved
the problem (``stage``: optimizer, fallback, none).

Before any work (world generation included) every option is checked: finite numbers in
range, integer counts (``--starts`` >= 1, ``--waypoints`` >= 2, ``--substeps`` >= 1,
``--iterations`` in [0, 1e9], ``--seed`` >= 0), ``--device``, ``--frame``, the batch size
against an estimate of its memory (``--starts`` x ``--waypoints`` x ``--substeps``), the
``--world`` spec (its grid against its memory) and the ``--rerun`` path (writable folder,
not a folder); an error names the option (``jwarp: error: --starts: ...``). The recording
is written to a temporary file and renamed at the end; an error or Ctrl-C removes it.
"""

from __future__ import annotations

import argparse
import math
import re
from typing import TYPE_CHECKING, Any

import numpy as np

from jwarp.cli.common import (
    CLIError,
    check_device,
    check_option_memory,
    check_output,
    dtype_of,
    dumps,
    int_arg,
    parse_q,
    quiet_warp,
    real_arg,
    rerun_recording,
    robot_option,
)
from jwarp.cli.targets import MAX_TARGET  # noqa: F401  (the largest --target value, here before)
from jwarp.cli.vocabulary import add_out
from jwarp.core.types import ArrayLike

if TYPE_CHECKING:
    from jwarp.model import RobotModel
    from jwarp.world.sdf import World

#: log every this many iterations to rerun
RERUN_EVERY = 5
#: the most --iterations (a bound that keeps every counter in range)
MAX_ITERATIONS = 10**9
#: host memory per configuration whose frames are computed in one batch, per frame,
#: collision sphere and joint [bytes]: float64 4x4 frames, sphere centres and their
#: temporaries (measured: about 1.5 to 2 times 128 / 40 / 32 B; IK per start, the planner
#: per sampled point of its substep sizing)
_CONFIG_BYTES = (2 * 128, 2 * 40, 2 * 32)
#: ``--elastic`` of each command
ELASTIC_HELP = {
    "plan": "plan on the elastic model (one torque update per iteration)",
    "ik": "solve on the elastic model (one torque update per iteration; a solution counts "
          "once the torque equilibrium has converged, its pose and collisions are those of "
          "the deflected robot)"}
#: the planner samples each segment this many times to size --substeps (when not given)
_SIZING_SAMPLES = 16


def config_bytes(model: RobotModel) -> int:
    f, s, j = _CONFIG_BYTES
    return f * model.n_frames + s * len(model.spheres) + j * model.n_dof


def _world(spec: str | None, model: RobotModel, args: argparse.Namespace | None = None,
           scene: Any = None) -> Any:
    if scene is not None:
        return _scene_world(scene, model, args)
    if args is not None and getattr(args, "voxel", None) is not None:
        raise CLIError("--voxel: only with --scene (a simplex world takes voxel= in --world)")
    if args is not None and getattr(args, "extent", None) is not None:
        raise CLIError("--extent: only with --scene")
    if spec is None:
        return None
    from jwarp.world.io import parse_world_spec

    try:
        return parse_world_spec(spec, robot=model)
    except (ValueError, TypeError, OSError, MemoryError, OverflowError) as e:
        msg = " ".join(str(e).split())
        for prefix in ("world: ", "path: "):
            msg = msg.removeprefix(prefix)
        raise CLIError(f"--world: {msg}") from None



def _load_scene(args: argparse.Namespace, model: RobotModel) -> Any:
    """The :class:`~jwarp.world.scene_file.Scene` of ``--scene`` (None without), its
    frame ids: ``world``, ``base`` and the robot's fixed frames (all the robot's base)."""
    if getattr(args, "scene", None) is None:
        return None
    from jwarp.world.scene_file import load_scene, robot_frames

    try:
        return load_scene(args.scene, frames=robot_frames(model))
    except (ValueError, TypeError, OSError) as e:
        raise CLIError(f"--scene: {' '.join(str(e).split()).removeprefix('scene: ')}") from None


def _scene_world(scene: Any, model: RobotModel, args: argparse.Namespace) -> Any:
    """The World of ``--scene`` at ``--voxel`` over ``--extent`` (default: the obstacles'
    bounding box padded by at least DEFAULT_PAD and by the largest robot sphere radius
    + ``--margin`` + one voxel, so nothing outside the grid can touch the robot)."""
    from jwarp.world.collision import check_world
    from jwarp.world.scene_file import (
        DEFAULT_PAD,
        DEFAULT_VOXEL,
        SceneOptions,
        exact_world,
        scene_world,
    )

    if args.voxel is None and args.extent is None:  # no grid asked for: the exact objects
        try:
            world = exact_world(scene)
            check_world(model, world)
        except (ValueError, TypeError) as e:
            raise CLIError(f"--scene: {' '.join(str(e).split()).removeprefix('scene: ')}") \
                from None
        return world
    h = args.voxel if args.voxel is not None else scene.grid.get("voxel", DEFAULT_VOXEL)
    r = max((s.radius for s in model.spheres), default=0.0)
    pad = max(scene.grid.get("pad", DEFAULT_PAD), r + args.margin + float(h))
    limits = None
    if args.extent is not None:
        limits = np.array(args.extent).reshape(3, 2)
    try:
        world = scene_world(scene, SceneOptions(voxel_size=args.voxel, limits=limits, pad=pad))
        check_world(model, world)
    except (ValueError, TypeError, MemoryError) as e:
        raise CLIError(f"--scene: {' '.join(str(e).split()).removeprefix('scene: ')}") from None
    return world


def _extent(text: str) -> list[float]:
    """``--extent x0,x1,y0,y1,z0,z1`` [m]."""
    try:
        v = [float(p) for p in text.split(",")]
    except ValueError:
        v = []
    if len(v) != 6 or not all(math.isfinite(x) for x in v) or not all(
            v[2 * d] < v[2 * d + 1] for d in range(3)):
        raise CLIError(f"--extent: expected x0,x1,y0,y1,z0,z1 [m] with x0 < x1 etc., got {text!r}")
    return v


def _joint_option(text: str, option: str, model: RobotModel, args: argparse.Namespace, scene: Any,
                  fallback: np.ndarray | None = None) -> np.ndarray:
    """``--start``/``--goal``: joint values v1,v2,... (or zeros), or ``moveit`` (the
    ``--scene`` file's robot state / goal joint constraints) or ``moveit:FILE`` (a
    planning scene or MotionPlanRequest YAML). MoveIt values are in rad/m, matched to the
    robot's joints by name; a goal's unconstrained joints keep the start's values."""
    head, colon, path = text.strip().partition(":")
    if head.lower() != "moveit":
        return parse_q(text, model, args.deg, option=option)
    from jwarp.world.moveit import joint_vector
    from jwarp.world.scene_file import load_scene, robot_frames

    if colon and path.strip():
        try:
            src = load_scene(path.strip(), frames=robot_frames(model))
        except (ValueError, TypeError, OSError) as e:
            raise CLIError(f"{option}: {' '.join(str(e).split()).removeprefix('scene: ')}") from None
    elif scene is not None:
        src = scene
    else:
        raise CLIError(f"{option}: 'moveit' reads the --scene file; give --scene or moveit:FILE")
    what = "robot state (robot_state or start_state)" if option == "--start" else \
        "goal joint constraints"
    values = src.start if option == "--start" else src.goal
    if values is None:
        raise CLIError(f"{option}: {src.source} has no {what}")
    try:
        return joint_vector(model, values, f"{src.source} {what}", fallback)
    except ValueError as e:
        raise CLIError(f"{option}: {' '.join(str(e).split())}") from None


#: names in the solvers' errors -> the CLI options they come from
_OPTION_OF = {"start": "--start", "goal": "--goal", "target": "--target", "frame": "--frame",
              "n_starts": "--starts", "n_waypoints": "--waypoints", "n_substeps": "--substeps",
              "iterations": "--iterations", "max_iterations": "--iterations", "step": "--step",
              "margin": "--margin", "seed": "--seed", "kappa": "--kappa", "device": "--device",
              "world": "--world", "warm_start": "--warm-start",
              "n_random_with_warm_start": "--starts", "time_limit": "--time-limit",
              "fallback": "--fallback", "endpoint_margin": "--endpoint-margin",
              "self_margin": "--self-margin", "robot": "--robot", "initial": "--initial",
              "seeds": "--initial",
              "tol_pos": "--tol-pos", "tol_rot": "--tol-rot", "free_axis": "--free-axis",
              "orientation": "--position-only"}


def _solver_error(command: str, e: Exception) -> CLIError:
    """One line naming the option the solver's error is about (``start[0]: ...`` ->
    ``--start: ...``), else the command (``plan: ...``)."""
    msg = " ".join(str(e).split()).replace("allow_no_collision=True", "--no-collision")
    m = re.match(r"^([a-z_]+)(\[\d+\])?: ", msg)
    if m and m.group(1) in _OPTION_OF:
        return CLIError(f"{_OPTION_OF[m.group(1)]}: {msg[m.end():]}")
    return CLIError(f"{command}: {msg}")


def _check_plan_size(args: argparse.Namespace, model: RobotModel) -> None:
    """Refuse --starts x --waypoints x --substeps that cannot fit in memory (estimate)."""
    P, W = args.starts, args.waypoints
    sub = args.substeps if args.substeps is not None else _SIZING_SAMPLES
    S = (W - 1) * sub + 1
    item = np.dtype(dtype_of(args.dtype)).itemsize
    n, F, Sph = model.n_dof, model.n_frames, len(model.spheres)
    per_sub = item * (3 * n + 52 * F + 3 * Sph + 4) + 24 * n   # solver buffers + host checks
    need = float(P) * S * per_sub + 48.0 * P * W * n
    if args.substeps is None:  # the sizing of the substeps samples 16 points per segment
        need += float(P) * ((W - 1) * _SIZING_SAMPLES + 1) * config_bytes(model)
    ratios = {"--starts": P / 8, "--waypoints": W / 20,
              "--substeps": (args.substeps or 0) / 8}
    option = max(ratios, key=ratios.get)
    subs = f"{args.substeps} substeps" if args.substeps is not None else "sized substeps"
    check_option_memory(need, f"{P} starts x {W} waypoints x {subs} of '{model.name}'", option)


def _fallback(text: str) -> str | None:
    """``--fallback rrt|none``."""
    v = text.strip().lower()
    if v not in ("rrt", "none"):
        raise CLIError(f"--fallback: expected 'rrt' or 'none', got {text!r}")
    return None if v == "none" else v


def _shorten_budget(text: str) -> float | None:
    """``--shorten-budget SHARE|none``: a share > 0 of the optimisation's work, or none."""
    if text.strip().lower() == "none":
        return None
    return real_arg("--shorten-budget", 0.0, lo_open=True)(text)


def _weights() -> Any:
    """The weights of U_path the CLI plans with (the planner's default PathWeights)."""
    from jwarp.solvers.planning import PathWeights

    return PathWeights()


def _costs_explained() -> dict:
    """``costs_explained`` of ``plan --json``: the weights and how ``costs.total`` is made
    of ``costs.collision`` and ``costs.length`` (why total < length: the length enters
    with its weight 0.01)."""
    w = _weights()
    return {"weights": {"world": w.world, "self": w.self, "length": w.length},
            "explained": (f"total is U_path (thesis eq. 3.16) = collision + {w.length:g} x "
                          f"length. collision: the world ({w.world:g} x) and self-collision "
                          f"({w.self:g} x) costs summed over the path's substeps (positive "
                          f"within the cost's smoothing distance eps of an obstacle, so a "
                          f"feasible path can have collision > 0); length: U_l (eq. 3.5), the joint-space "
                          f"length cost, unweighted, 1 for the straight line and > 1 for "
                          f"any detour. So total < length whenever collision < "
                          f"{1 - w.length:g} x length")}


def _exact_endpoints(path: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> np.ndarray:
    """``path`` (W, n_dof) float64 with its first and last waypoints replaced by the
    float64 start and goal the planner held fixed (a float32 plan rounds them)."""
    path = np.array(path, np.float64)
    if len(path) >= 2 and np.allclose(path[0], q0, atol=1e-5) and \
            np.allclose(path[-1], q1, atol=1e-5):
        path[0], path[-1] = q0, q1
    return path


def _length_line(res: Any) -> str:
    """The text output's line of the length ratio: U_l (1 for the straight line) and,
    where :attr:`PlanOptions.shorten` shortened the path, what it was before."""
    line = f"length: {res.length_cost[0]:.3g} x the straight line's length cost"
    before = res.length_before
    if before is not None and np.isfinite(before[0]) and before[0] > res.length_cost[0]:
        line += (f" (shortened from {before[0]:.3g} x in {res.timings.get('shorten', 0.0):.3f} "
                 f"s)")
    return line


def _name_width(model: RobotModel) -> int:
    return max((len(n) for n in model.joint_names), default=5)


def _config_table(model: RobotModel, qs: np.ndarray) -> str:
    """Configurations (K, n_dof) as a table: one row per joint (its name), one column per
    configuration (waypoint k)."""
    w = _name_width(model)
    lines = [f"  {'joint':<{w}} " + " ".join(f"{'#' + str(k):>9}" for k in range(len(qs)))]
    for j, name in enumerate(model.joint_names):
        lines.append(f"  {name:<{w}} " + " ".join(f"{q[j]:+9.5f}" for q in qs))
    return "\n".join(lines)


#: what each stage of PlanResult.stage means, for the text output
_STAGE_TEXT = {"straight": "solved by the straight line, proven before any optimisation",
               "optimizer": "solved by the multi-start optimisation",
               "fallback": "solved by the fallback: an RRT-Connect path, then optimised",
               "none": "not solved"}


def _check_frame(model: RobotModel, frame: str) -> None:
    try:
        model.frame_index(frame)
    except (ValueError, TypeError, KeyError) as e:
        msg = " ".join(str(e).split()).removeprefix("frame: ")
        raise CLIError(f"--frame: {msg}") from None


def _kappa(args: argparse.Namespace, model: RobotModel) -> Any:
    if not args.elastic:
        if args.kappa is not None:
            raise CLIError("--kappa: only meaningful with --elastic")
        return None
    from jwarp.cli.common import parse_kappa

    kappa, _ = parse_kappa(args.kappa, model)
    return model.kappa if kappa is None else kappa


# ------------------------------------------------------------------ commands
def cmd_plan(args: argparse.Namespace) -> int:
    model = robot_option(args.robot)
    scene = _load_scene(args, model)
    q0 = _joint_option(args.start, "--start", model, args, scene)
    q1 = _joint_option(args.goal, "--goal", model, args, scene, fallback=q0)
    kappa = _kappa(args, model)
    net = _plan_warm_start(args.warm_start, model)
    if net is not None:
        if args.waypoints is not None and args.waypoints != net.n_waypoints:
            raise CLIError(f"--waypoints: the network of --warm-start predicts "
                           f"{net.n_waypoints} waypoints; drop --waypoints or give "
                           f"{net.n_waypoints}")
        args.waypoints = net.n_waypoints
        if args.starts is None:
            args.starts = net.n_heads
    if args.starts is None:  # the API's default: 8 on the CPU, 32 on a CUDA device
        from jwarp.core.arrays import resolve_device
        from jwarp.solvers.planning.options import PlanOptions, n_starts_for

        args.starts = n_starts_for(PlanOptions(), str(resolve_device(args.device)))
    if args.waypoints is None:
        args.waypoints = 20
    _check_plan_size(args, model)
    quiet_warp()
    check_device(args.device)
    if args.rerun is not None:  # before the world and the plan: no work lost on a bad path
        check_output(args.rerun, "--rerun", rerun=True,
                     inputs={"--world": args.world, "--scene": args.scene,
                             "--robot": args.robot, "--warm-start": args.warm_start})
    world = _world(args.world, model, args, scene)
    from jwarp.solvers.planning import Planner, PlanOptions, plan
    from jwarp.viz.planning import PlanRecording

    rec = (rerun_recording(PlanRecording, args.rerun, model, world)
           if args.rerun is not None else None)
    callback = None
    if rec is not None:
        def callback(it: int, paths: np.ndarray) -> None:
            if it % RERUN_EVERY == 0:
                rec.log_traces(it, paths)
                rec.log_configs("iteration", it, paths[0], name="start0")
    try:
        budget = dict(stop_when_solved=args.stop_when_solved, time_limit=args.time_limit,
                      fallback=args.fallback, endpoint_margin=args.endpoint_margin,
                      self_margin=args.self_margin, allow_no_collision=args.no_collision,
                      shorten=args.shorten, shorten_budget=args.shorten_budget)
        if net is not None:
            opts = PlanOptions(n_starts=args.starts, iterations=args.iterations,
                               n_waypoints=args.waypoints, n_substeps=args.substeps,
                               step=args.step, margin=args.margin, seed=args.seed, kappa=kappa,
                               callback=callback, **budget)
            res = Planner(model, world, 1, opts, device=args.device, dtype=dtype_of(args.dtype),
                          warm_start=net).plan(q0, q1)
        else:
            res = plan(model, world, q0, q1, n_starts=args.starts, iterations=args.iterations,
                       n_waypoints=args.waypoints, n_substeps=args.substeps, step=args.step,
                       margin=args.margin, seed=args.seed, kappa=kappa, device=args.device,
                       dtype=dtype_of(args.dtype), callback=callback, **budget)
        if rec is not None:
            for k, q in enumerate(res.path[0]):
                rec.log_configs("waypoint", k, q[None], name="result")
            written = rec.close()
    except (ValueError, TypeError) as e:
        if rec is not None:
            rec.abort()
        raise _solver_error("plan", e) from None
    except BaseException:
        if rec is not None:
            rec.abort()
        raise
    out = {"robot": model.name, "world": args.world if args.scene is None else args.scene,
           "joint_names": list(model.joint_names), "start": q0.tolist(), "goal": q1.tolist(),
           "dtype": args.dtype, "elastic": kappa is not None, **res.to_dict(0)}
    path = _exact_endpoints(np.asarray(res.path[0], np.float64), q0, q1)
    out["path"] = path.tolist()
    out["costs_explained"] = _costs_explained()  # beside "costs", which stays numbers
    if args.json:
        print(dumps(out))
    else:
        state = "feasible" if res.feasible[0] else "NOT feasible"
        print(f"robot {model.name}: path of {args.waypoints} waypoints is {state} "
              f"({res.n_feasible[0]} of {res.all_feasible.shape[1]} starts feasible)")
        if not res.feasible[0] and res.reasons is not None:
            print(f"why: {res.reasons[0]}")
        print(f"costs: total {res.cost[0]:.6g} = collision {res.collision_cost[0]:.6g} + "
              f"{_weights().length:g} x length {res.length_cost[0]:.6g}; iterations "
              f"{res.iterations[0]}; {res.n_substeps} substeps per segment; wall time "
              f"{res.wall_time:.3f} s")
        if res.feasible[0]:
            print(_length_line(res))
        stage = str(res.stage[0])
        print(f"stopped: {res.stop_reason}; stage: {stage} ({_STAGE_TEXT.get(stage, stage)})")
        print(f"path [rad/m] ({args.dtype}; start and goal as given):")
        print(_config_table(model, path))
    if rec is not None and not args.json:
        print(f"wrote {written}; view with: rerun {written}")
    return 0 if res.feasible[0] else 1


def _plan_warm_start(path: str | None, model: RobotModel) -> Any:
    """The planning network of ``plan --warm-start`` (errors name ``--warm-start``)."""
    if path is None:
        return None
    try:
        from jwarp.learn.checkpoint import load_plan_checkpoint
    except ImportError as e:  # torch missing
        raise CLIError(f"--warm-start: the planning networks need torch ({e})") from None
    try:
        return load_plan_checkpoint(path, robot=model, device="cpu")
    except (ValueError, TypeError, OSError, KeyError) as e:
        msg = " ".join(str(e).split()).removeprefix("checkpoint: ")
        raise CLIError(f"--warm-start: {msg}") from None


def _warm_start(path: str | None, model: RobotModel, frame: str, device: str) -> Any:
    """The IK network of ``--warm-start`` (errors name ``--warm-start``): a checkpoint for
    ``model`` predicting ``frame``."""
    if path is None:
        return None
    try:
        from jwarp.learn.checkpoint import load_checkpoint
    except ImportError as e:  # torch missing
        raise CLIError(f"--warm-start: the IK networks need torch ({e})") from None
    try:
        net = load_checkpoint(path, robot=model, device="cpu")
    except (ValueError, TypeError, OSError, KeyError) as e:
        msg = " ".join(str(e).split()).removeprefix("checkpoint: ")
        raise CLIError(f"--warm-start: {msg}") from None
    cfg = getattr(net, "config", None)
    net_frame = getattr(cfg, "frame", None)
    if net_frame is not None and model.frame_index(net_frame) != model.frame_index(frame):
        raise CLIError(f"--warm-start: the network predicts frame '{net_frame}' of "
                       f"'{model.name}', not --frame {frame}")
    return net


def _orientation(args: argparse.Namespace, has_rotation: bool) -> tuple[str, np.ndarray | None]:
    """``--position-only`` / ``--free-axis`` -> (orientation mode, free axis (3,) or None)."""
    from jwarp.cli.targets import unit_axis

    if args.position_only:
        if has_rotation:
            given = ("--targets" if getattr(args, "targets", None) is not None else
                     "--target-matrix" if args.target_matrix is not None else
                     "--quat" if args.quat is not None else "--rpy" if args.rpy is not None
                     else "a 6-number --target")
            raise CLIError(f"--position-only: not allowed with {given} (an orientation that "
                           f"would be ignored); give --target X,Y,Z")
        return "none", None
    if args.free_axis is not None:
        return "axis", unit_axis(args.free_axis, "--free-axis")
    return "full", None


def _initial(args: argparse.Namespace, model: RobotModel) -> np.ndarray | None:
    """``--initial Q`` (n_dof,) [rad/m] within the joint limits (errors name --initial)."""
    if args.initial is None:
        return None
    from jwarp.core.limits import describe_violation, within_limits

    q = parse_q(args.initial, model, args.deg, option="--initial")
    if not bool(within_limits(model, q)):
        raise CLIError(f"--initial: outside the joint limits of '{model.name}': "
                       f"{describe_violation(model, q)}")
    return q


def _ik_seeds(args: argparse.Namespace, model: RobotModel, q_init: np.ndarray, T: np.ndarray,
              world: World, net: Any) -> np.ndarray:
    """The seeds (S, n_dof) of ``--initial``: q_init first, then the warm start's and
    ``--starts`` random ones (with --warm-start), else ``--starts`` - 1 random ones, drawn
    as :func:`jwarp.solvers.ik.ik` draws its own (``--seed``)."""
    from jwarp.core.limits import sample_within_limits

    rng = np.random.default_rng(args.seed)
    if net is not None:
        from jwarp.solvers.ik import warm_start_seeds

        rest = warm_start_seeds(model, net, T[None], world, args.starts, rng,
                                name="--warm-start")[0]
    else:
        rest = sample_within_limits(model, args.starts - 1, rng)
    return np.concatenate([q_init[None], rest])


def _ik_keywords(args: argparse.Namespace, world: World, kappa: ArrayLike, orientation: str,
                 free_axis: Any) -> dict:
    """The keywords of ``jwarp.ik`` that ``ik`` and ``ik --targets`` take from the
    command line (tolerances only where given, the orientation only where not full)."""
    extra: dict = {k: v for k, v in (("tol_pos", args.tol_pos), ("tol_rot", args.tol_rot))
                   if v is not None}
    if orientation != "full":
        extra["orientation"] = orientation
        if free_axis is not None:
            extra["free_axis"] = free_axis
    return dict(world=world, margin=args.margin, iterations=args.iterations, seed=args.seed,
                kappa=kappa, device=args.device, dtype=dtype_of(args.dtype),
                allow_no_collision=args.no_collision, **extra)


def cmd_ik(args: argparse.Namespace) -> int:
    from jwarp.cli.targets import target_pose

    if args.targets is not None:
        return cmd_ik_batch(args)
    if args.out is not None:
        raise CLIError("--out: only with --targets (the results of a batch of targets)")
    model = robot_option(args.robot)
    _check_frame(model, args.frame)
    T, has_rotation = target_pose(args.target, args.quat, args.rpy, args.target_matrix)
    orientation, free_axis = _orientation(args, has_rotation)
    scene = _load_scene(args, model)
    q_init = _initial(args, model)
    kappa = _kappa(args, model)
    if args.starts is None:  # random seeds: 16, or none beside a warm start
        args.starts = 0 if args.warm_start is not None else 16
    elif args.starts < 1 and args.warm_start is None:
        raise CLIError(f"--starts: expected an integer >= 1, got '{args.starts}'")
    heads = 2 if args.warm_start is not None else 0  # a twin network's seeds
    check_option_memory(float(args.starts + heads + 1) * config_bytes(model),
                        f"{args.starts} starts of '{model.name}'", "--starts")
    quiet_warp()
    check_device(args.device)
    if args.rerun is not None:  # before the world and the solve: no work lost on a bad path
        check_output(args.rerun, "--rerun", rerun=True,
                     inputs={"--world": args.world, "--scene": args.scene, "--robot": args.robot,
                             "--warm-start": args.warm_start,
                             "--target-matrix": args.target_matrix})
    net = _warm_start(args.warm_start, model, args.frame, args.device)
    world = _world(args.world, model, args, scene)
    from jwarp.solvers.ik import ik

    try:
        common = _ik_keywords(args, world, kappa, orientation, free_axis)
        if q_init is not None:
            seeds = _ik_seeds(args, model, q_init, T, world, net)
            res = ik(model, args.frame, T, seeds=seeds, **common)
        elif net is not None:
            res = ik(model, args.frame, T, warm_start=net,
                     n_random_with_warm_start=args.starts, **common)
        else:
            res = ik(model, args.frame, T, n_starts=args.starts, **common)
        written = None
        if args.rerun is not None:
            from jwarp.viz.planning import PlanRecording

            rec = rerun_recording(PlanRecording, args.rerun, model, world)
            try:
                for k, q in enumerate(res.all_q):
                    rec.log_configs("start", k, q[None], name="solution")
                rec.rec.log("target", rec.rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]),
                            rec.rr.TransformAxes3D(0.1), static=True)
                written = rec.close()
            except BaseException:
                rec.abort()
                raise
    except (ValueError, TypeError) as e:
        raise _solver_error("ik", e) from None
    tol_pos = args.tol_pos if args.tol_pos is not None else _ik_default("tol_pos")
    tol_rot = args.tol_rot if args.tol_rot is not None else _ik_default("tol_rot")
    reason = None
    if not res.feasible:
        from jwarp.solvers.ik.explain import explain_ik

        reason = explain_ik(model, args.frame, np.asarray(res.q, np.float64), T, world=world,
                            margin=args.margin, tol_pos=tol_pos, tol_rot=tol_rot,
                            orientation=orientation,
                            free_axis=free_axis if free_axis is not None else (0.0, 0.0, 1.0),
                            kappa=kappa)
        if reason == "feasible":  # the float64 re-check passes: a solver-side rounding
            reason = (f"the solver's check failed, but a float64 re-check of the answer "
                      f"passes (limits, pose within tol_pos {tol_pos:g} m / tol_rot "
                      f"{tol_rot:g} rad, collisions with margin {args.margin:g} m)"
                      + ("; --dtype float32 rounds: try --dtype float64"
                         if args.dtype == "float32" else ""))
    out = {"robot": model.name, "frame": args.frame, "target": T.tolist(),
           "world": args.world if args.scene is None else args.scene,
           "joint_names": list(model.joint_names), "elastic": kappa is not None,
           "orientation": orientation,
           "free_axis": None if free_axis is None else free_axis.tolist(),
           "tol_pos_m": tol_pos, "tol_rot_rad": tol_rot,
           "initial": None if q_init is None else q_init.tolist(),
           **res.to_dict(0)}
    out["reason"] = reason if reason is not None else "feasible"
    if net is not None:
        out["warm_start"] = args.warm_start
    if args.json:
        print(dumps(out))
    else:
        state = "feasible" if res.feasible else "NOT feasible"
        mode = ""
        if orientation == "none":
            mode = " (position only)"
        elif orientation == "axis":
            mode = f" (free rotation about {','.join(f'{v:.4g}' for v in free_axis)})"
        print(f"robot {model.name}: IK of {args.frame}{mode} is {state} "
              f"({int(res.n_feasible)} of {res.all_q.shape[0]} starts); position error "
              f"{float(res.pos_err):.3g} m, rotation error {float(res.rot_err):.3g} rad "
              f"(tolerances {tol_pos:g} m, {tol_rot:g} rad); iterations "
              f"{int(res.iterations)}; wall time {res.wall_time:.4f} s")
        if reason is not None:
            print(f"why: {reason}")
        print("q [rad/m]:")
        for name, v in zip(model.joint_names, np.asarray(res.q, np.float64)):
            print(f"  {name:<{_name_width(model)}} {v:+.6f}")
        if written:
            print(f"wrote {written}; view with: rerun {written}")
    return 0 if res.feasible else 1


#: the file types of ``ik --targets ... --out FILE``
IK_OUT_TYPES = (".csv", ".npy")


def cmd_ik_batch(args: argparse.Namespace) -> int:
    """``jwarp ik --targets FILE --out RESULTS``: every target of the file in one batch
    (:func:`jwarp.solvers.ik.ik`); the results (q, status, errors per row) written
    atomically, the solve rate printed (docs/ik.md "Many targets")."""
    import time

    from jwarp.cli.targets import TARGET_LAYOUTS, read_targets

    t0 = time.perf_counter()
    for opt, val in (("--target", args.target), ("--quat", args.quat), ("--rpy", args.rpy),
                     ("--target-matrix", args.target_matrix), ("--initial", args.initial),
                     ("--rerun", args.rerun)):
        if val is not None:
            raise CLIError(f"--targets: not allowed with {opt} (the file holds the targets)")
    if args.out is None:
        raise CLIError("--out: required with --targets (the results file, .csv or .npy)")
    if not args.out.lower().endswith(IK_OUT_TYPES):
        raise CLIError(f"--out: expected a .csv or .npy file for the results, got {args.out!r}")
    model = robot_option(args.robot)
    _check_frame(model, args.frame)
    check_output(args.out, "--out", inputs={"--targets": args.targets, "--robot": args.robot,
                                            "--scene": args.scene, "--world": args.world,
                                            "--warm-start": args.warm_start})
    T, layout = read_targets(args.targets)
    if args.position_only and layout != "position":
        raise CLIError(f"--position-only: not allowed with --targets holding orientations "
                       f"({','.join(TARGET_LAYOUTS[layout][3:6])}...); give x,y,z columns")
    orientation, free_axis = _orientation(args, layout != "position")
    scene = _load_scene(args, model)
    kappa = _kappa(args, model)
    if args.starts is None:
        args.starts = 0 if args.warm_start is not None else 16
    elif args.starts < 1 and args.warm_start is None:
        raise CLIError(f"--starts: expected an integer >= 1, got '{args.starts}'")
    heads = 2 if args.warm_start is not None else 0
    check_option_memory(float(len(T)) * (args.starts + heads + 1) * config_bytes(model),
                        f"{len(T)} targets x {args.starts} starts of '{model.name}'",
                        "--targets")
    quiet_warp()
    check_device(args.device)
    net = _warm_start(args.warm_start, model, args.frame, args.device)
    world = _world(args.world, model, args, scene)
    from jwarp.solvers.ik import ik

    try:
        common = _ik_keywords(args, world, kappa, orientation, free_axis)
        if net is not None:
            res = ik(model, args.frame, T, warm_start=net,
                     n_random_with_warm_start=args.starts, **common)
        else:
            res = ik(model, args.frame, T, n_starts=args.starts, **common)
    except (ValueError, TypeError) as e:
        raise _solver_error("ik", e) from None
    written = write_ik_results(args.out, model, res)
    n, solved = len(T), int(np.sum(res.feasible))
    tol_pos = args.tol_pos if args.tol_pos is not None else _ik_default("tol_pos")
    tol_rot = args.tol_rot if args.tol_rot is not None else _ik_default("tol_rot")
    total = time.perf_counter() - t0
    if args.json:
        print(dumps({"robot": model.name, "frame": args.frame, "targets": args.targets,
                     "layout": layout, "n_targets": n, "solved": solved,
                     "solve_rate": solved / n, "orientation": orientation,
                     "tol_pos_m": tol_pos, "tol_rot_rad": tol_rot,
                     "solve_time_s": float(res.wall_time), "wall_time_s": total,
                     "out": str(written), "joint_names": list(model.joint_names)}))
    else:
        print(f"robot {model.name}: IK of {args.frame} for {n} target{'s' if n != 1 else ''} "
              f"of {args.targets} ({layout}): solved {solved} of {n} ({100.0 * solved / n:.1f} "
              f"%) within {tol_pos:g} m, {tol_rot:g} rad; solve {res.wall_time:.2f} s, total "
              f"{total:.2f} s")
        print(f"wrote {written} (one row per target: q, status, pos_err_m, rot_err_rad)")
    return 0 if solved == n else 1


def ik_result_columns(model: RobotModel) -> list[str]:
    """The columns of ``ik --targets``'s results: the joint names [rad/m], ``status``
    (CSV: solved|failed; .npy: 1|0), ``pos_err_m``, ``rot_err_rad``."""
    return [*model.joint_names, "status", "pos_err_m", "rot_err_rad"]


def write_ik_results(path: str, model: RobotModel, res: Any) -> str:
    """Write the batch IK results ``res`` (an :class:`~jwarp.solvers.ik.IKResult` of N
    targets) to ``path`` atomically (:class:`jwarp.utils.atomic.AtomicFile`): ``.npy`` a
    float64 array (N, n_dof + 3) [q, status 1|0, pos_err_m, rot_err_rad], else CSV with a
    header line of :func:`ik_result_columns`. Returns the path."""
    from jwarp.utils.atomic import AtomicFile

    q = np.asarray(res.q, np.float64).reshape(-1, model.n_dof)
    ok = np.asarray(res.feasible, bool).reshape(-1)
    pos = np.asarray(res.pos_err, np.float64).reshape(-1)
    rot = np.asarray(res.rot_err, np.float64).reshape(-1)
    try:
        with AtomicFile(path, option="--out") as f:
            if path.lower().endswith(".npy"):
                with open(f.tmp, "wb") as fh:
                    np.save(fh, np.column_stack([q, ok.astype(np.float64), pos, rot]))
            else:
                lines = [",".join(ik_result_columns(model))]
                lines += [",".join([*(repr(float(v)) for v in q[i]),
                                    "solved" if ok[i] else "failed", repr(float(pos[i])),
                                    repr(float(rot[i]))]) for i in range(len(q))]
                with open(f.tmp, "w", encoding="utf-8") as fh:
                    fh.write("\n".join(lines) + "\n")
    except ValueError as e:
        raise CLIError(str(e)) from None
    return path


def _ik_default(name: str) -> float:
    """The default of :func:`jwarp.solvers.ik.ik`'s option ``name`` (its tolerances): the
    :class:`~jwarp.solvers.ik.IKOptions` field's."""
    import dataclasses

    from jwarp.solvers.ik import IKOptions

    return float({f.name: f.default for f in dataclasses.fields(IKOptions)}[name])


#: configurations drawn per batch by ``free-config``
FREE_CONFIG_BATCH = 256


def cmd_free_config(args: argparse.Namespace) -> int:
    """``jwarp free-config``: collision-free configurations (joint limits, the world, self
    collision; :func:`jwarp.world.collision.is_collision_free`) drawn uniformly within the
    joint limits (:func:`jwarp.world.feasibility.random_configurations`), for a ``--start``
    or ``--goal`` that is not in collision."""
    model = robot_option(args.robot)
    quiet_warp()
    check_device(args.device)
    check_option_memory(float(FREE_CONFIG_BATCH) * config_bytes(model),
                        f"{FREE_CONFIG_BATCH} configurations of '{model.name}'", "--robot")
    world = _world(args.world, model)
    kappa = _kappa(args, model)
    from jwarp.world.feasibility import random_configurations
    from jwarp.world.path_feasibility import ELASTIC_CHECK, collision_free, elastic_equilibrium

    if not model.spheres and not args.no_collision:
        raise CLIError(f"--robot: '{model.name}' has no collision spheres, so nothing can be "
                       f"checked (give --no-collision for configurations within the joint "
                       f"limits only)")
    found: list[np.ndarray] = []
    tried = 0
    batch = 0
    while len(found) < args.n and tried < args.tries:
        k = min(FREE_CONFIG_BATCH, args.tries - tried)
        q = random_configurations(model, k, seed=[args.seed, batch])
        batch += 1
        tried += k
        if model.spheres:
            try:
                # the one check of plan/ik (the deflected robot with --kappa: a
                # configuration whose equilibrium does not converge is not free)
                ok = collision_free(model, world, q, args.margin, kappa=kappa,
                                    device=args.device, self_margin=args.margin)
                if kappa is not None and not ok.any() and not elastic_equilibrium(
                        model, q, kappa, device=args.device)[1].any():
                    c = ELASTIC_CHECK
                    raise CLIError(f"--kappa: the elastic equilibrium converges at none of "
                                   f"{len(q)} random configurations ({c['max_iter']} torque "
                                   f"updates, lam {c['lam']:g}, to {c['tol']:g} rad), so "
                                   f"no collision can be checked; lower --kappa")
            except (ValueError, TypeError) as e:
                raise _solver_error("free-config", e) from None
        else:
            ok = np.ones(len(q), bool)
        found += list(q[ok][:args.n - len(found)])
    if not found:
        raise CLIError(f"--tries: none of {tried} random configurations of '{model.name}' is "
                       f"collision-free in --world {args.world} (margin {args.margin:g} m); "
                       f"raise --tries, lower --margin or try another world")
    qs = np.stack(found)
    if args.json:
        print(dumps({"robot": model.name, "world": args.world, "margin": args.margin,
                     "elastic": kappa is not None,
                     "seed": args.seed, "tried": tried, "joint_names": list(model.joint_names),
                     "configurations": qs.tolist()}))
    else:
        where = f"in --world {args.world}" if args.world else "(self-collision only)"
        if kappa is not None:
            where += ", elastic (deflected by gravity)"
        print(f"robot {model.name}: {len(qs)} collision-free configuration"
              f"{'s' if len(qs) != 1 else ''} {where}, margin {args.margin:g} m, from {tried} "
              f"draws (seed {args.seed})")
        print(_config_table(model, qs))
        for q in qs:
            print("--start " + ",".join(f"{v:.6g}" for v in q))
    return 0 if len(qs) >= args.n else 1


# ------------------------------------------------------------------ parser
def add_subcommands(sub: Any) -> None:
    """Add ``plan`` and ``ik`` to the ``jwarp`` subparsers."""
    def common(s: argparse.ArgumentParser, command: str) -> None:
        s.add_argument("--robot", required=True, help="robot name or path to a robot .json")
        s.add_argument("--deg", action="store_true", help="revolute joint values in degrees")
        s.add_argument("--margin", type=real_arg("--margin", 0.0, unit=" [m]"), default=0.0,
                       metavar="M", help="required clearance [m] to obstacles (>= 0; plan: "
                                         "--self-margin between body parts; ik: both)")
        s.add_argument("--seed", type=int_arg("--seed", 0), default=0,
                       help="random seed of the multi-starts (>= 0)")
        s.add_argument("--elastic", action="store_true", help=ELASTIC_HELP[command])
        s.add_argument("--kappa", default=None, metavar="K",
                       help="compliance [rad/(N m)] with --elastic (default: the robot's, else 1e-4)")
        s.add_argument("--rerun", default=None, metavar="FILE.rrd", help="write a rerun recording")
        s.add_argument("--json", action="store_true", help="print JSON")
        s.add_argument("--device", default="cpu", help="Warp device (default cpu; e.g. cuda:0)")
        s.add_argument("--no-collision", action="store_true",
                       help="accept a robot without collision spheres (nothing is then checked "
                            "for collision: get spheres with import-urdf/import-mjcf --spheres "
                            "fit) or in self-collision at its home configurations; without it "
                            "either is an error")

    def scene_options(s: argparse.ArgumentParser) -> None:
        s.add_argument("--voxel", type=real_arg("--voxel", 0.0, lo_open=True, unit=" [m]"),
                       default=None, metavar="V",
                       help="build a signed distance grid of the --scene with this voxel size "
                            "[m] (its interpolation error sqrt(3)/2 V is subtracted); default: "
                            "no grid, the exact objects")
        s.add_argument("--extent", type=_extent, default=None, metavar="X0,X1,Y0,Y1,Z0,Z1",
                       help="grid extent [m] of the --scene SDF (default: the obstacles, "
                            "padded)")

    s = sub.add_parser("plan", help="plan a collision-free path (gradient descent on U_path)")
    common(s, "plan")
    where = s.add_mutually_exclusive_group(required=True)
    where.add_argument("--world", default=None, metavar="SPEC",
                       help="simplex:seed=S[,threshold=T,...], shelf[:voxel=V] or a world .npz file")
    where.add_argument("--scene", default=None, metavar="FILE.yaml",
                       help="a scene file: jwarp scene or MoveIt planning scene (docs/scenes.md)")
    scene_options(s)
    s.add_argument("--start", required=True, metavar="Q",
                   help="start joint values v1,v2,..., or moveit[:FILE] (a MoveIt robot state)")
    s.add_argument("--goal", required=True, metavar="Q",
                   help="goal joint values v1,v2,..., or moveit[:FILE] (goal joint constraints)")
    s.add_argument("--starts", type=int_arg("--starts", 1), default=None, metavar="N",
                   help="multi-starts: the straight line + N-1 random via-point paths (default "
                        "8 on the CPU, 32 on a CUDA device); with --warm-start the network's "
                        "paths count (default: only them)")
    s.add_argument("--iterations", type=int_arg("--iterations", 0, MAX_ITERATIONS), default=200,
                   metavar="N", help="most iterations (default 200; the Python API's "
                                     "plan(iterations=...) default is 100)")
    s.add_argument("--waypoints", type=int_arg("--waypoints", 2), default=None, metavar="W",
                   help="waypoints, >= 2 (default 20; with --warm-start the network's)")
    s.add_argument("--warm-start", default=None, metavar="MODEL.pt",
                   help="start from a motion-planning network (a jwarp train plan checkpoint)")
    s.add_argument("--substeps", type=int_arg("--substeps", 1), default=None, metavar="N",
                   help="substeps per segment (default: sized to the voxel size)")
    s.add_argument("--step", type=real_arg("--step", 0.0, lo_open=True), default=0.01,
                   help="gradient step size, > 0 (default 0.01)")
    s.add_argument("--dtype", default="float32", choices=("float64", "float32"),
                   help="float type of the optimisation (default float32, as jwarp.plan; "
                        "the JSON's start, goal and path endpoints are the float64 inputs)")
    s.add_argument("--time-limit", type=real_arg("--time-limit", 0.0, lo_open=True, unit=" [s]"),
                   default=None, metavar="S",
                   help="stop after S seconds (> 0; default: no limit, only --iterations)")
    s.add_argument("--stop-when-solved", action=argparse.BooleanOptionalAction, default=True,
                   help="stop as soon as a start is feasible (default); --no-stop-when-solved "
                        "optimises every start until it is feasible or out of iterations")
    s.add_argument("--shorten", type=int_arg("--shorten", 0), default=None, metavar="N",
                   help="rounds of shortcuts of the solved path, proven by the exact check "
                        "(default 1 on the CPU, 4 on CUDA; 0: the first feasible path as "
                        "it is; with --stop-when-solved only)")
    s.add_argument("--shorten-budget", type=_shorten_budget, default=0.5,
                   metavar="SHARE|none",
                   help="work of the shortcut rounds after the first check, as a share of "
                        "the optimisation's collision evaluations (default 0.5; none: only "
                        "--shorten bounds them)")
    s.add_argument("--endpoint-margin", type=real_arg("--endpoint-margin", 0.0, unit=" [m]"),
                   default=None, metavar="M",
                   help="clearance [m] of start, goal and the first and last segment, at most "
                        "--margin (grasp poses close to an object); default: --margin")
    s.add_argument("--self-margin", type=real_arg("--self-margin", 0.0, unit=" [m]"),
                   default=0.0, metavar="M",
                   help="clearance [m] between the robot's own links (default 0)")
    s.add_argument("--fallback", type=_fallback, default="rrt", metavar="rrt|none",
                   help="fallback for an unsolved problem: rrt (default: an RRT-Connect path "
                        "seeds one more optimisation) or none")
    s.set_defaults(func=cmd_plan)

    s = sub.add_parser("ik", help="collision-free inverse kinematics (two-stage, multi-start)")
    common(s, "ik")
    s.add_argument("--frame", required=True, help="end-effector frame, e.g. right_tcp")
    s.add_argument("--target", default=None, metavar="X,Y,Z[,RX,RY,RZ]",
                   help="target position [m] and rotation vector [rad] in the base frame "
                        "(3 numbers: the orientation from --quat/--rpy, else identity); or "
                        "give --target-matrix")
    s.add_argument("--quat", default=None, metavar="QX,QY,QZ,QW",
                   help="target orientation as a quaternion, scalar last (ROS/MoveIt order; "
                        "normalised), with a 3-number --target")
    s.add_argument("--rpy", default=None, metavar="R,P,Y",
                   help="target orientation as roll, pitch, yaw [rad, also with --deg] about "
                        "the fixed x, y, z axes (ROS/URDF: Rz(Y) Ry(P) Rx(R)), with a 3-number "
                        "--target")
    s.add_argument("--target-matrix", default=None, metavar="FILE_OR_16_NUMBERS",
                   help="the target as a 4x4 rigid transform, row by row: 16 numbers or a "
                        "text file of them (instead of --target)")
    s.add_argument("--targets", default=None, metavar="FILE",
                   help="many targets in one batch: a CSV (x,y,z[,qx,qy,qz,qw | roll,pitch,"
                        "yaw | rx,ry,rz] or 16 matrix columns; a header line names them) or "
                        ".npy file (N x 3, 7, 16 or N x 4 x 4); needs --out (docs/ik.md)")
    add_out(s, metavar="FILE.csv|FILE.npy",
            help="with --targets: the results, one row per target: q, status, pos_err_m, "
                 "rot_err_rad (written atomically)")
    orient = s.add_mutually_exclusive_group()
    orient.add_argument("--position-only", action="store_true",
                        help="reach the target position only, any orientation (with a "
                             "3-number --target)")
    orient.add_argument("--free-axis", default=None, metavar="X,Y,Z",
                        help="the rotation about this axis of the end-effector frame is free "
                             "(e.g. 0,0,1: a grasp symmetric about the tool's z axis); the "
                             "target's orientation fixes the axis' direction")
    s.add_argument("--tol-pos", type=real_arg("--tol-pos", 0.0, lo_open=True, unit=" [m]"),
                   default=None, metavar="M",
                   help="position tolerance [m], > 0 (default 1e-4, as jwarp.ik)")
    s.add_argument("--tol-rot", type=real_arg("--tol-rot", 0.0, lo_open=True, unit=" [rad]"),
                   default=None, metavar="RAD",
                   help="rotation tolerance [rad], > 0 (default 1e-3, as jwarp.ik)")
    where = s.add_mutually_exclusive_group()
    where.add_argument("--world", default=None, metavar="SPEC",
                       help="optional world: simplex:seed=S[,...], shelf or a world .npz file")
    where.add_argument("--scene", default=None, metavar="FILE.yaml",
                       help="a scene file: jwarp scene or MoveIt planning scene (docs/scenes.md)")
    scene_options(s)
    s.add_argument("--starts", type=int_arg("--starts", 0), default=None, metavar="N",
                   help="seeds, >= 1 (default 16; with --initial it is the first of them); "
                        "with --warm-start the random seeds after the network's, >= 0 "
                        "(default 0)")
    s.add_argument("--iterations", type=int_arg("--iterations", 0, MAX_ITERATIONS), default=200,
                   metavar="N", help="most iterations (default 200)")
    s.add_argument("--initial", default=None, metavar="Q",
                   help="an initial guess v1,v2,... [rad, m; --deg: revolute ones in degrees]: "
                        "the first seed, followed by random ones up to --starts")
    s.add_argument("--dtype", default="float64", choices=("float64", "float32"))
    s.add_argument("--warm-start", default=None, metavar="MODEL.pt",
                   help="start from a trained IK network's prediction (jwarp train ik)")
    s.set_defaults(func=cmd_ik)

    s = sub.add_parser("free-config", help="print collision-free configurations of a robot "
                                           "in a world (a --start or --goal for plan)")
    s.add_argument("--robot", required=True, help="robot name or path to a robot .json")
    s.add_argument("--world", default=None, metavar="SPEC",
                   help="simplex:seed=S[,...], shelf or a world .npz file (default: none, "
                        "self-collision only)")
    s.add_argument("--n", type=int_arg("--n", 1, 10**6), default=1, metavar="N",
                   help="configurations to print (default 1)")
    s.add_argument("--margin", type=real_arg("--margin", 0.0, unit=" [m]"), default=0.0,
                   metavar="M", help="required clearance [m] to the world and between links "
                                     "(default 0)")
    s.add_argument("--seed", type=int_arg("--seed", 0), default=0,
                   help="random seed of the draws (>= 0)")
    s.add_argument("--tries", type=int_arg("--tries", 1, 10**9), default=100_000,
                   metavar="N", help="most configurations drawn (default 100000)")
    s.add_argument("--no-collision", action="store_true",
                   help="accept a robot without collision spheres (joint limits only)")
    s.add_argument("--elastic", action="store_true",
                   help="check the elastic model (the robot deflected by gravity at its "
                        "torque equilibrium), as plan/ik --elastic check their start and goal")
    s.add_argument("--kappa", default=None, metavar="K",
                   help="compliance [rad/(N m)] with --elastic (default: the robot's, else 1e-4)")
    s.add_argument("--device", default="cpu", help="Warp device (default cpu; e.g. cuda:0)")
    s.add_argument("--json", action="store_true", help="print JSON")
    s.set_defaults(func=cmd_free_config)
