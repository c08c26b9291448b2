"""Reproduce the IK warm-start networks shipped in ``jwarp/learn/models/``.

    python examples/train_ik_models.py --device cuda:0 --out-dir jwarp/learn/models

Trains (unsupervised, twin heads, unit vectors, boosting) a world-aware planar5 network on
random simplex worlds (BPS of 256 points) and a justin19 network for the shelf world, and
keeps for each the epoch with the best validation feasibility (after 10 solver
iterations). ``--only supervised`` trains the supervised baselines of Table 3.5 and
``--only ablation`` the 8 justin19 variants of Table 3.4 (reduced sizes); evaluate them with
``jwarp eval ik`` (docs/learning.md). ``--quick`` shrinks everything (a smoke run, not a
useful model).
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

from jwarp.core.arrays import init_warp
from jwarp.learn.checkpoint import save_checkpoint
from jwarp.learn.train_ik import TrainIKOptions, train_ik, train_ik_supervised

RUNS = {
    "planar5_random": dict(robot="planar5", frame="tcp", world="random", n_worlds=64,
                           n_targets=512, n_bps=256, hidden=256, n_blocks=4,
                           batch_size=1024, worlds_per_batch=8, epochs=20, steps_per_epoch=200,
                           lr=1e-3, lr_decay=0.85),
    # 50 % of the targets are the shelf's grasp poses (the task the network serves:
    # jwarp.world.scenes.shelf_grasp_poses), the rest reachable poses of the whole workspace;
    # 128 wide x 3 blocks: as feasible as 256 x 4 here, and 0.16 ms per target on a CPU core
    "justin19_shelf": dict(robot="justin19", frame="right_tcp", world="shelf", n_worlds=1,
                           n_targets=20000, n_bps=0, hidden=128, n_blocks=3,
                           mix=(0.3, 0.1, 0.1, 0.5),
                           batch_size=1024, worlds_per_batch=1, epochs=20, steps_per_epoch=200,
                           lr=1e-3, lr_decay=0.85),
}
#: the networks shipped in jwarp/learn/models
SHIPPED = ("planar5_random", "justin19_shelf")
#: Table 3.5's second row: the supervised baseline on the same targets (labels from the
#: IK solver, 16 starts, 200 iterations)
for _name in SHIPPED:
    RUNS[_name + "_supervised"] = dict(RUNS[_name], supervised=True)
#: Table 3.4 (reduced: 8 epochs of 150 steps): justin19 in the shelf, boosting x twin heads
#: x unit vectors
for _b in (True, False):
    for _t in (True, False):
        for _u in (True, False):
            RUNS["justin19_ablation_" + "".join("1" if v else "0" for v in (_b, _t, _u))] = dict(
                RUNS["justin19_shelf"], boosting=_b, twin=_t, unit_vectors=_u, epochs=8,
                steps_per_epoch=150)
GROUPS = {"shipped": SHIPPED, "supervised": tuple(n + "_supervised" for n in SHIPPED),
          "ablation": tuple(n for n in RUNS if "_ablation_" in n)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--out-dir", default="jwarp/learn/models")
    ap.add_argument("--only", default="shipped",
                    help="comma-separated run names or groups (shipped, supervised, ablation; "
                         "default shipped)")
    ap.add_argument("--epochs", type=int, default=None)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    out_dir = Path(a.out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        ap.error(f"--out-dir: {out_dir} is not a folder")
    init_warp()
    names: list[str] = []
    for name in a.only.split(","):
        if name not in RUNS and name not in GROUPS:
            ap.error(f"--only: unknown run {name!r} (known: {', '.join([*GROUPS, *RUNS])})")
        names += GROUPS.get(name, (name,))
    for name in names:
        kw = dict(RUNS[name], device=a.device)
        supervised = kw.pop("supervised", False)
        if a.epochs:
            kw["epochs"] = a.epochs
        if a.quick:
            kw.update(n_worlds=min(kw["n_worlds"], 2), n_targets=256, epochs=2,
                      steps_per_epoch=5, batch_size=64, worlds_per_batch=min(kw["worlds_per_batch"], 2))
        tmp = Path(tempfile.mkdtemp())
        best = {"val_feasible": -1.0}

        def keep_best(rec: dict, net, tmp=tmp, best=best, kw=kw, supervised=supervised) -> None:
            if rec["epoch"] > 0 and rec["val_feasible"] > best["val_feasible"]:
                best.update(rec)
                save_checkpoint(tmp / "best.pt", net, world_distribution=kw["world"],
                                training={**TrainIKOptions(**kw).to_dict(),
                                          "supervised": supervised},
                                metrics={k: v for k, v in rec.items() if k != "epoch"},
                                epoch=int(rec["epoch"]))

        train = train_ik_supervised if supervised else train_ik
        train(TrainIKOptions(**kw, checkpoint=str(tmp / "last.pt")), callback=keep_best)
        out_dir.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(tmp / "best.pt", out_dir / f"{name}.pt")
        print(f"{name}: kept epoch {best['epoch']} (val_feasible "
              f"{100 * best['val_feasible']:.1f}%) -> {out_dir / (name + '.pt')}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
