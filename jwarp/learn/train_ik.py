"""Training of the IK networks (thesis 3.4.4, eq. 3.28; IK paper III-D, Tables 3.4/3.5).

Unsupervised (:func:`train_ik`): the network's prediction q(Theta) for a target is scored
by U_ik (eq. 3.19: pose error, world and self collision, distance to the default pose)
through :func:`jwarp.learn.torch_costs.u_ik` (the solver's own Warp kernels) and the
gradient flows dU/dq dq/dTheta. Per batch of ``worlds_per_batch`` worlds x
``batch_size / worlds_per_batch`` targets (u_ik takes one world per call):

- single head: ``L = mean U_ik(q)``;
- twin heads (``twin``): ``L = mean_b min_h U_ik(q_bh) + mean_weight * mean_bh U_ik(q_bh)
  + head_weight * mean_b exp(-d_b^2 / head_scale^2)``, ``d_b`` the distance between the
  two heads in joint space scaled by the joint ranges (``(qa - qb) / (upper - lower)``).
  The first term trains each sample's better head, the second keeps the other one
  sensible, the third is the thesis' U_H = ||qa - qb|| as a bounded reward (between 0 and
  ``head_weight``; it cannot run away however far the heads move);
- boosting (``boosting``): a sample whose (best-head) cost exceeds ``boost_factor`` (4) x
  the rolling mean (an exponential average of the batch means) joins the hard set of its
  world (``hard_set_size`` in all, a ring per world, the oldest overwritten); a fraction
  ``boost_fraction`` of every world group is redrawn from that world's hard set, and a hard
  sample drawn again whose cost is no longer above the threshold leaves the set.

Every epoch: validation on fixed unseen targets (and, for random worlds, unseen worlds):
the raw validation cost (mean best-head U_ik) and the validation feasibility, the fraction
of targets whose best head is feasible after ``val_iterations`` solver iterations
(:class:`jwarp.solvers.ik.IKSolver` seeded with the heads); a per-epoch line, the optional
``callback(record, net)``, and a checkpoint (atomic, with the optimizer and hard set:
``resume=True`` continues from it).

Supervised baseline (:func:`train_ik_supervised`, Table 3.5's second row): the same
targets, labelled by the solver (:class:`IKSolver`, random multi-start; where it finds no
feasible solution, the collision-free configuration the target was sampled from), trained
with the mean squared joint error scaled by the joint ranges (twin: the better head, plus
``mean_weight`` x both).
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np
import torch
import warp as wp

from jwarp.core.arrays import device_name, init_warp
from jwarp.core.threads import ThreadFollower, torch_threads
from jwarp.learn.checkpoint import check_weights, read_checkpoint, save_checkpoint
from jwarp.learn.ik_data import DEFAULT_MIX, IKData, check_mix, make_ik_data
from jwarp.learn.ik_net import IKNet, IKNetConfig
from jwarp.learn.torch_costs import ik_objective, u_ik
from jwarp.plugins.registry import robot as get_robot
from jwarp.solvers.ik import IKOptions, IKSolver
from jwarp.utils.checks import check_int

if TYPE_CHECKING:
    from jwarp.world.sdf import World

__all__ = ["TrainIKOptions", "train_ik", "train_ik_supervised", "ik_loss", "IKTrainer"]


@dataclass
class TrainIKOptions:
    """Settings of :func:`train_ik` / :func:`train_ik_supervised` (module docstring).

    Data: robot, frame, world ("random" | "shelf" | "none"), n_worlds (random worlds for
    training), n_targets (per training world), n_val_worlds, n_val (targets per validation
    world), mix (uniform / near obstacles / border [/ scene tasks] fractions,
    :mod:`jwarp.learn.ik_data`).
    Network: n_bps (0: world-unaware), hidden, n_blocks, twin, unit_vectors.
    Optimisation: batch_size (targets per step, split evenly over worlds_per_batch worlds),
    epochs (total, counting resumed ones), steps_per_epoch, lr, lr_decay (per epoch).
    Loss: head_weight, head_scale, mean_weight, boosting, boost_factor, boost_fraction,
    hard_set_size. Validation: val_iterations (solver iterations). Run: device (torch
    device string, "cpu", "cuda", "cuda:0"; None: Warp's default device, docs/api.md
    "Devices"), dtype ("float32" | "float64"), seed,
    checkpoint (path or None), resume.
    """

    robot: str = "planar5"
    frame: str | int = "tcp"
    world: str = "random"
    n_worlds: int = 8
    n_targets: int = 2000
    n_val_worlds: int = 2
    n_val: int = 128
    mix: tuple = DEFAULT_MIX
    n_bps: int = 0
    hidden: int = 128
    n_blocks: int = 3
    twin: bool = True
    unit_vectors: bool = True
    batch_size: int = 256
    worlds_per_batch: int = 4
    epochs: int = 10
    steps_per_epoch: int = 100
    lr: float = 1e-3
    lr_decay: float = 1.0
    head_weight: float = 0.1
    head_scale: float = 0.5
    mean_weight: float = 0.1
    boosting: bool = True
    boost_factor: float = 4.0
    boost_fraction: float = 0.25
    hard_set_size: int = 4096
    val_iterations: int = 10
    device: str | None = None
    dtype: str = "float32"
    seed: int = 0
    checkpoint: str | None = None
    resume: bool = False

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        for name, lo in (("n_worlds", 1), ("n_targets", 1), ("n_val_worlds", 1), ("n_val", 1),
                         ("n_bps", 0), ("hidden", 1), ("n_blocks", 1), ("batch_size", 1),
                         ("worlds_per_batch", 1), ("epochs", 0), ("steps_per_epoch", 1),
                         ("hard_set_size", 1), ("val_iterations", 0)):
            v = getattr(self, name)
            check_int(v, name, lo)
            setattr(self, name, int(v))
        if self.world not in ("random", "shelf", "none"):
            raise ValueError(f"world: expected 'random', 'shelf' or 'none', got {self.world!r}")
        if self.world != "random":
            self.worlds_per_batch = 1
        if self.batch_size % self.worlds_per_batch:
            raise ValueError(f"batch_size: {self.batch_size} is not a multiple of "
                             f"worlds_per_batch ({self.worlds_per_batch})")
        for name in ("lr", "lr_decay", "head_scale", "boost_factor"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name}: expected a number > 0, got {getattr(self, name)!r}")
            setattr(self, name, v)
        for name in ("head_weight", "mean_weight"):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name}: expected a number >= 0, got {getattr(self, name)!r}")
            setattr(self, name, v)
        if not 0.0 <= float(self.boost_fraction) < 1.0:
            raise ValueError(f"boost_fraction: expected [0, 1), got {self.boost_fraction!r}")
        if self.dtype not in ("float32", "float64"):
            raise ValueError(f"dtype: expected 'float32' or 'float64', got {self.dtype!r}")
        for name in ("twin", "unit_vectors", "boosting", "resume"):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise TypeError(f"{name}: expected a bool, got {getattr(self, name)!r}")
        check_mix(self.mix)  # ValueError naming mix
        self.mix = tuple(float(v) for v in self.mix)

    def net_config(self) -> IKNetConfig:
        return IKNetConfig(robot=get_robot(self.robot).name, frame=self.frame,
                           n_bps=self.n_bps, hidden=self.hidden, n_blocks=self.n_blocks,
                           twin=self.twin, unit_vectors=self.unit_vectors)

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["mix"] = list(self.mix)
        return d


def ik_loss(net: IKNet, q: torch.Tensor, targets: torch.Tensor, world: World,
            options: TrainIKOptions) -> tuple[torch.Tensor, dict, torch.Tensor]:
    """The unsupervised loss of predictions q (m, H, n_dof) for targets (m, 4, 4) in one
    world: ``(loss, terms, best (m,) detached)`` (module docstring); ``terms``: floats
    ``u_ik`` (mean best-head U_ik), ``u_mean`` (mean over heads), ``head`` (the U_H term)."""
    m, H, n = q.shape
    tgt = targets.to(dtype=q.dtype)
    if H > 1:
        tgt = tgt.repeat_interleave(H, dim=0)
    U = u_ik(q.reshape(m * H, n), tgt, net.robot, net.frame, world=world).view(m, H)
    best = U.min(dim=1).values
    loss = best.mean()
    terms = {"u_ik": float(best.detach().mean()), "u_mean": float(U.detach().mean()),
             "head": 0.0}
    if H > 1:
        loss = loss + options.mean_weight * U.mean()
        inv = 1.0 / torch.as_tensor(net.codec.upper - net.codec.lower, dtype=q.dtype,
                                    device=q.device)
        d2 = (((q[:, 0] - q[:, 1]) * inv) ** 2).sum(dim=-1)
        uh = options.head_weight * torch.exp(-d2 / options.head_scale ** 2).mean()
        loss = loss + uh
        terms["head"] = float(uh.detach())
        terms["head_distance"] = float(d2.detach().sqrt().mean())
    return loss, terms, best.detach()


class IKTrainer:
    """The state of one training run (network, optimizer, data, hard set, validation
    solvers); :func:`train_ik` and :func:`train_ik_supervised` drive it."""

    def __init__(self, options: TrainIKOptions, supervised: bool = False,
                 data: IKData | None = None, label_starts: int = 16,
                 label_iterations: int = 200):
        o = options
        self.options = o
        self.supervised = supervised
        self.model = get_robot(o.robot)
        self.tdev = torch.device(device_name(o.device))
        if self.tdev.type == "cuda" and self.tdev.index is None:
            self.tdev = torch.device("cuda", torch.cuda.current_device())
        init_warp()
        self.wdev = wp.device_from_torch(self.tdev)
        self.tdt = torch.float64 if o.dtype == "float64" else torch.float32
        self.data = data if data is not None else make_ik_data(
            self.model, o.frame, o.world, n_worlds=o.n_worlds, n_targets=o.n_targets,
            n_val_worlds=o.n_val_worlds, n_val=o.n_val, seed=o.seed, mix=o.mix,
            device=self.wdev)
        d = self.data
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(o.seed)
            self.net = IKNet(o.net_config()).to(device=self.tdev, dtype=self.tdt)
        self.H = self.net.n_heads
        self.m = o.batch_size // o.worlds_per_batch
        self.opt = torch.optim.Adam(self.net.parameters(), lr=o.lr)

        def tens(a: np.ndarray) -> torch.Tensor:
            return torch.as_tensor(a, dtype=self.tdt, device=self.tdev)

        self.T = [tens(t) for t in d.targets]
        self.val_T = [tens(t) for t in d.val_targets]
        self.bps = self.val_bps = None
        if self.net.bps is not None:
            self.bps = [self.net.world_bps(w)[0] for w in d.worlds]
            self.val_bps = [self.net.world_bps(w)[0] for w in d.val_worlds]
        # hold the cost objectives of every world and batch size (u_ik's cache keeps the
        # last few only): one per training world (m x H) and validation world (n_val x H)
        sc = np.float64 if self.tdt == torch.float64 else np.float32
        self._objectives = [ik_objective(self.model, o.frame, self.m * self.H, world=w,
                                         device=self.wdev, dtype=sc) for w in d.worlds]
        self._objectives += [ik_objective(self.model, o.frame, o.n_val * self.H, world=w,
                                          device=self.wdev, dtype=sc) for w in d.val_worlds]
        vopt = IKOptions(n_starts=self.H, iterations=o.val_iterations, seed=o.seed)
        self.solvers = [IKSolver(self.model, o.frame, o.n_val, vopt, world=w, device=self.wdev)
                        for w in d.val_worlds]
        # hard set: a ring per training world
        W = len(d.worlds)
        self.cap = max(1, o.hard_set_size // W)
        self.hard_T = [torch.zeros((self.cap, 4, 4), dtype=self.tdt, device=self.tdev)
                       for _ in range(W)]
        self.hard_ok = [np.zeros(self.cap, bool) for _ in range(W)]
        self.hard_ptr = [0] * W
        self.rolling: float | None = None  # rolling mean of the batch costs
        self.epoch = 0
        self.history: list[dict] = []
        self.labels = None
        if supervised:
            self.labels = self._labels(label_starts, label_iterations)

    # ------------------------------------------------------------------ labels
    def _labels(self, n_starts: int, max_iterations: int) -> list[torch.Tensor]:
        o, out, feas = self.options, [], []
        for w, T, q0 in zip(self.data.worlds, self.data.targets, self.data.q):
            s = IKSolver(self.model, o.frame, len(T), IKOptions(
                n_starts=n_starts, iterations=max_iterations, seed=o.seed),
                world=w, device=self.wdev)
            r = s.solve(T)
            # unsolved: the configuration the target came from (scene tasks have none:
            # the solver's best infeasible answer)
            q = np.where(r.feasible[:, None] | np.isnan(q0), r.q, q0)
            feas.append(np.asarray(r.feasible, bool))
            out.append(torch.as_tensor(q, dtype=self.tdt, device=self.tdev))
        #: fraction of training targets the solver labelled (the others: their sample)
        self.label_feasible = float(np.mean(np.concatenate(feas)))
        return out

    # ------------------------------------------------------------------ hard set
    def hard_size(self) -> int:
        return int(sum(h.sum() for h in self.hard_ok))

    def _draw(self, wi: int, rng: np.random.Generator) -> tuple[torch.Tensor, np.ndarray, np.ndarray]:
        """A world group: targets (m, 4, 4), their pool indices (-1: from the hard set),
        and the hard-set slots of the first rows (drawn from the hard set)."""
        o, m = self.options, self.m
        idx = rng.integers(len(self.T[wi]), size=m)
        slots = np.empty(0, np.int64)
        if o.boosting:
            ok = np.flatnonzero(self.hard_ok[wi])
            k = min(int(o.boost_fraction * m), len(ok))
            if k:
                slots = rng.choice(ok, size=k, replace=False)
        T = self.T[wi][torch.as_tensor(idx, device=self.tdev)]
        if len(slots):
            T[:len(slots)] = self.hard_T[wi][torch.as_tensor(slots, device=self.tdev)]
        return T, idx, slots

    def _boost(self, wi: int, T: torch.Tensor, best: torch.Tensor, slots: np.ndarray) -> None:
        o = self.options
        mean = float(best.mean())
        self.rolling = mean if self.rolling is None else 0.95 * self.rolling + 0.05 * mean
        if not o.boosting:
            return
        hard = (best > o.boost_factor * self.rolling).cpu().numpy()
        k = len(slots)
        if k:  # drawn from the hard set: leave it once no longer hard
            self.hard_ok[wi][slots[~hard[:k]]] = False
        new = np.flatnonzero(hard[k:]) + k
        for i in new[: self.cap]:
            p = self.hard_ptr[wi]
            self.hard_T[wi][p] = T[i]
            self.hard_ok[wi][p] = True
            self.hard_ptr[wi] = (p + 1) % self.cap

    # ------------------------------------------------------------------ steps
    def step(self, rng: np.random.Generator) -> dict:
        o, d = self.options, self.data
        W = len(d.worlds)
        k = o.worlds_per_batch
        worlds = rng.choice(W, size=k, replace=k > W)
        self.net.train()
        self.opt.zero_grad(set_to_none=True)
        acc: dict = {}
        for wi in worlds:
            T, self._last_idx, slots = self._draw(int(wi), rng)
            b = self.bps[wi].expand(len(T), -1) if self.bps is not None else None
            q = self.net.predict(T, b)
            if self.supervised:
                loss, terms, best = self._supervised_loss(q, T, int(wi))
            else:
                loss, terms, best = ik_loss(self.net, q, T, d.worlds[wi], o)
            (loss / k).backward()
            self._boost(int(wi), T, best, slots)
            terms["loss"] = float(loss.detach())
            for key, v in terms.items():
                acc[key] = acc.get(key, 0.0) + v / k
        self.opt.step()
        return acc

    def _supervised_loss(self, q: torch.Tensor, T: torch.Tensor, wi: int
                         ) -> tuple[torch.Tensor, dict, torch.Tensor]:
        # the labels of the drawn targets: rows from the hard set carry no pool index, so
        # the supervised trainer draws without boosting (set in train_ik_supervised)
        idx = self._last_idx
        labels = cast("list[torch.Tensor]", self.labels)  # the supervised trainer labels
        y = labels[wi][torch.as_tensor(idx, device=self.tdev)]
        inv = 1.0 / torch.as_tensor(self.net.codec.upper - self.net.codec.lower,
                                    dtype=q.dtype, device=q.device)
        e = (((q - y[:, None, :]) * inv) ** 2).mean(dim=-1)  # (m, H)
        best = e.min(dim=1).values
        loss = best.mean() + (self.options.mean_weight * e.mean() if self.H > 1 else 0.0)
        return loss, {"mse": float(best.detach().mean())}, best.detach()

    # ------------------------------------------------------------------ validation
    @torch.no_grad()
    def validate(self) -> dict:
        o, d = self.options, self.data
        self.net.eval()
        costs, feas, feas_head = [], [], []
        for j, w in enumerate(d.val_worlds):
            T = self.val_T[j]
            b = self.val_bps[j].expand(len(T), -1) if self.val_bps is not None else None
            q = self.net.predict(T, b)
            m, H, n = q.shape
            tgt = T.repeat_interleave(H, dim=0) if H > 1 else T
            U = u_ik(q.reshape(m * H, n).contiguous(), tgt, self.model, o.frame,
                     world=w).view(m, H)
            costs.append(U.min(dim=1).values.double().cpu().numpy())
            seeds = q.double().cpu().numpy()
            r = self.solvers[j].solve(d.val_targets[j], seeds=seeds)
            feas.append(np.asarray(r.feasible, bool))
            feas_head.append(np.asarray(r.all_feasible, bool)[:, 0])
        return {"val_cost": float(np.mean(np.concatenate(costs))),
                "val_feasible": float(np.mean(np.concatenate(feas))),
                "val_feasible_head1": float(np.mean(np.concatenate(feas_head)))}

    # ------------------------------------------------------------------ checkpoints
    def state(self) -> dict:
        return {"hard_T": [t.detach().cpu() for t in self.hard_T],
                "hard_ok": [torch.as_tensor(h) for h in self.hard_ok],
                "hard_ptr": list(self.hard_ptr),
                "rolling": self.rolling, "supervised": self.supervised}

    def save(self, path: str | os.PathLike) -> None:
        last = self.history[-1] if self.history else {}
        save_checkpoint(path, self.net, world_distribution=self.data.distribution,
                        training={**self.options.to_dict(), "supervised": self.supervised},
                        metrics={**{k: v for k, v in last.items() if k != "epoch"},
                                 "history": self.history},
                        epoch=self.epoch, optimizer_state=self.opt.state_dict(),
                        training_state=self.state())

    def load(self, path: str | os.PathLike) -> None:
        doc = read_checkpoint(path)
        if doc["config"] != self.net.config.to_dict() or doc["robot"] != self.model.name:
            raise ValueError(f"resume: checkpoint '{path}' holds another network "
                             f"({doc['robot']}, {doc['config']}) than these options "
                             f"({self.model.name}, {self.net.config.to_dict()})")
        check_weights(IKNet, self.net.config, self.net.bps, doc, path)  # one line, no dump
        self.net.load_state_dict(doc["state_dict"])
        if doc.get("optimizer_state") is not None:
            self.opt.load_state_dict(doc["optimizer_state"])
        self.epoch = int(doc.get("epoch", 0))
        self.history = list(doc.get("metrics", {}).get("history", []))
        st = doc.get("training_state") or {}
        if st.get("hard_T") is not None and len(st["hard_T"]) == len(self.hard_T) \
                and all(t.shape == h.shape for t, h in zip(st["hard_T"], self.hard_T)):
            self.hard_T = [t.to(dtype=self.tdt, device=self.tdev) for t in st["hard_T"]]
            self.hard_ok = [np.asarray(h.numpy(), bool).copy() for h in st["hard_ok"]]
            self.hard_ptr = [int(p) for p in st["hard_ptr"]]
        self.rolling = st.get("rolling")


def _line(rec: dict, epochs: int, supervised: bool) -> str:
    if rec["epoch"] == 0:
        terms = "untrained"
    elif supervised:
        terms = f"mse {rec.get('mse', float('nan')):.4g}"
    else:
        terms = (f"loss {rec.get('loss', float('nan')):.4g} u_ik {rec.get('u_ik', float('nan')):.4g} "
                 f"U_H {rec.get('head', 0.0):.3g}")
    return (f"epoch {rec['epoch']}/{epochs} {terms} hard {rec.get('hard_set', 0)} "
            f"val_cost {rec['val_cost']:.4g} val_feasible {100 * rec['val_feasible']:.1f}% "
            f"({rec.get('samples_per_s', 0.0):.0f} samples/s)")


def _run(trainer: IKTrainer, progress: bool, callback: Callable | None) -> tuple[IKNet, list]:
    """The training loop, inside :func:`jwarp.core.threads.torch_threads` (a thread count
    that does not oversubscribe the CPUs)."""
    with torch_threads():
        return _epochs(trainer, progress, callback)


def _epochs(trainer: IKTrainer, progress: bool, callback: Callable | None
            ) -> tuple[IKNet, list]:
    o = trainer.options
    path = o.checkpoint
    if o.resume and path is not None and Path(path).is_file():
        trainer.load(path)
        if progress:
            print(f"resumed from '{path}' after epoch {trainer.epoch}")
    if not trainer.history:
        rec = {"epoch": 0, **trainer.validate(), "hard_set": 0}
        trainer.history.append(rec)
        if progress:
            print(_line(rec, o.epochs, trainer.supervised))
        if callback is not None:
            callback(rec, trainer.net)
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is a dependency
        tqdm = None
    for g in trainer.opt.param_groups:
        g["lr"] = o.lr * o.lr_decay ** trainer.epoch
    follow = ThreadFollower()  # a job started beside the training: fewer threads
    while trainer.epoch < o.epochs:
        e = trainer.epoch + 1
        follow(force=True)
        rng = np.random.default_rng((o.seed, e))
        t0 = time.perf_counter()
        sums: dict = {}
        it = range(o.steps_per_epoch)
        bar = None
        if progress and tqdm is not None:
            bar = tqdm(it, desc=f"epoch {e}/{o.epochs}", leave=False, dynamic_ncols=True)
            it = bar
        for _ in it:
            follow()  # within the epoch too, at most every second
            terms = trainer.step(rng)
            for k, v in terms.items():
                sums[k] = sums.get(k, 0.0) + v
            if bar is not None:
                bar.set_postfix(loss=f"{terms.get('loss', 0.0):.3g}", hard=trainer.hard_size())
        if bar is not None:
            bar.close()
        dt = time.perf_counter() - t0
        for g in trainer.opt.param_groups:
            g["lr"] *= o.lr_decay
        trainer.epoch = e
        rec = {"epoch": e, **{k: v / o.steps_per_epoch for k, v in sums.items()},
               "hard_set": trainer.hard_size(), **trainer.validate(),
               "train_time_s": dt, "samples_per_s": o.steps_per_epoch * o.batch_size / dt,
               "lr": trainer.opt.param_groups[0]["lr"]}
        trainer.history.append(rec)
        if progress:
            print(_line(rec, o.epochs, trainer.supervised))
        if path is not None:
            trainer.save(path)
        if callback is not None:
            callback(rec, trainer.net)
    trainer.net.eval()
    trainer.net.meta = {"history": trainer.history, "world_distribution": trainer.data.distribution,
                        "training": o.to_dict(), "epoch": trainer.epoch}
    return trainer.net, trainer.history


def train_ik(options: TrainIKOptions, *, progress: bool = True,
             callback: Callable[[dict, IKNet], None] | None = None,
             data: IKData | None = None) -> tuple[IKNet, list[dict]]:
    """Unsupervised training (module docstring). Returns ``(net, history)``: history[0]
    is the validation of the untrained network (epoch 0), then one record per epoch (loss
    terms, hard-set size, val_cost, val_feasible, samples/s). ``data``: prepared
    :class:`IKData` (None: :func:`jwarp.learn.ik_data.make_ik_data` from the options)."""
    return _run(IKTrainer(options, data=data), progress, callback)


def train_ik_supervised(options: TrainIKOptions, *, progress: bool = True,
                        callback: Callable[[dict, IKNet], None] | None = None,
                        data: IKData | None = None, label_starts: int = 16,
                        label_iterations: int = 200) -> tuple[IKNet, list[dict]]:
    """The supervised baseline (module docstring): labels from :class:`IKSolver`
    (``label_starts`` random starts, ``label_iterations`` iterations) for the same targets,
    mean squared (range-scaled) joint error; no boosting."""
    options = dataclasses.replace(options, boosting=False)
    trainer = IKTrainer(options, supervised=True, data=data, label_starts=label_starts,
                        label_iterations=label_iterations)
    return _run(trainer, progress, callback)
