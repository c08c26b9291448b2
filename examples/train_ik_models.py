"""Reproduce the IK warm-start networks shipped in ``jwarp/learn/models/``.

    python examples/train_ik_models.py --device cuda:0 --out-dir jwarp/learn/models

Trains (unsupervised, twin heads, unit vectors, boosting) a world-aware planar5 network on
random simplex worlds (BPS of 256 points) and a justin19 network for the shelf world, and
keeps for each the epoch with the best validation feasibility (after 10 solver
iterations). ``--quick`` shrinks everything (a smoke run, not a useful model).
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from pathlib import Path

from jwarp.core.arrays import init_warp
from jwarp.learn.checkpoint import save_checkpoint
from jwarp.learn.train_ik import TrainIKOptions, train_ik

RUNS = {
    "planar5_random": dict(robot="planar5", frame="tcp", world="random", n_worlds=64,
                           n_targets=512, n_bps=256, hidden=256, n_blocks=4,
                           batch_size=1024, worlds_per_batch=8, epochs=20, steps_per_epoch=200,
                           lr=1e-3, lr_decay=0.85),
    "justin19_shelf": dict(robot="justin19", frame="right_tcp", world="shelf", n_worlds=1,
                           n_targets=20000, n_bps=0, hidden=256, n_blocks=4,
                           batch_size=1024, worlds_per_batch=1, epochs=20, steps_per_epoch=200,
                           lr=1e-3, lr_decay=0.85),
}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--out-dir", default="jwarp/learn/models")
    ap.add_argument("--only", default=",".join(RUNS), help="comma-separated run names")
    ap.add_argument("--epochs", type=int, default=None)
    ap.add_argument("--quick", action="store_true")
    a = ap.parse_args(argv)
    out_dir = Path(a.out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        ap.error(f"--out-dir: {out_dir} is not a folder")
    init_warp()
    for name in a.only.split(","):
        if name not in RUNS:
            ap.error(f"--only: unknown run {name!r} (known: {', '.join(RUNS)})")
        kw = dict(RUNS[name], device=a.device)
        if a.epochs:
            kw["epochs"] = a.epochs
        if a.quick:
            kw.update(n_worlds=min(kw["n_worlds"], 2), n_targets=256, epochs=2,
                      steps_per_epoch=5, batch_size=64, worlds_per_batch=min(kw["worlds_per_batch"], 2))
        tmp = Path(tempfile.mkdtemp())
        best = {"val_feasible": -1.0}

        def keep_best(rec: dict, net, tmp=tmp, best=best) -> None:
            if rec["epoch"] > 0 and rec["val_feasible"] > best["val_feasible"]:
                best.update(rec)
                save_checkpoint(tmp / "best.pt", net, world_distribution=kw["world"],
                                training=TrainIKOptions(**kw).to_dict(),
                                metrics={k: v for k, v in rec.items() if k != "epoch"},
                                epoch=int(rec["epoch"]))

        train_ik(TrainIKOptions(**kw, checkpoint=str(tmp / "last.pt")), callback=keep_best)
        out_dir.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(tmp / "best.pt", out_dir / f"{name}.pt")
        print(f"{name}: kept epoch {best['epoch']} (val_feasible "
              f"{100 * best['val_feasible']:.1f}%) -> {out_dir / (name + '.pt')}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
