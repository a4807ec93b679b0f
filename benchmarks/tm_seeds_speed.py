"""A seed sweep's TM training: seeds in lockstep against one run per seed, same process, same pairs.

    python benchmarks/tm_seeds_speed.py [--threads 1] [--seeds 10] [--pairs 6000] [--epochs 1]

For each FM/IM size (the paper's and the ``improved`` preset's, untrained: their cost does not depend
on their weights) it times ``--epochs`` epochs of the paper's Table 1 setting (paper loss, RMSprop
1e-3, batch 64) trained once per seed with ``train_tm`` (one seed timed, multiplied by ``--seeds``),
and for all seeds at once with ``train_tm_seeds``. The ratio is the sweep's speed-up; ``reproduce``
trains its Table 1 sweep the second way.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import torch
from _common import header, show, write_result

from kinlearn.data.endpoints import EndpointConfig, make_endpoints
from kinlearn.models.forward_inverse import LearnedFM, LearnedIM, fm_config, im_config, save_model
from kinlearn.training.loop import OptimConfig
from kinlearn.training.tm import tm_preset, train_tm
from kinlearn.training.tm_seeds import train_tm_seeds


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--pairs", type=int, default=6000)
    ap.add_argument("--epochs", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(header("TM seed sweep: lockstep against one run per seed", args.threads))
    pairs = make_endpoints(EndpointConfig(robot="iiwa14", n=args.pairs, seed=0))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for preset in ("paper", "improved"):
            models = Path(tmp) / preset
            models.mkdir()
            torch.manual_seed(0)
            save_model(LearnedFM(fm_config("iiwa14", preset)), models / "fm.pt")
            save_model(LearnedIM(im_config("iiwa14", preset)), models / "im.pt")
            cfg = tm_preset(
                "paper",
                loss="paper",
                optim=OptimConfig(name="rmsprop", lr=1e-3, alpha=0.99),
                models_dir=str(models),
                epochs=args.epochs,
            )
            warm = pairs.split(256)[0]  # first calls pay for loading and allocation: not timed
            train_tm(cfg, Path(tmp) / f"{preset}-warm", warm, progress=False)
            train_tm_seeds(
                cfg, [0, 1], [Path(tmp) / f"{preset}-warm{s}" for s in (0, 1)], warm, progress=False
            )
            t0 = time.perf_counter()
            train_tm(cfg, Path(tmp) / f"{preset}-one", pairs, progress=False)
            one = time.perf_counter() - t0
            seeds = list(range(args.seeds))
            t0 = time.perf_counter()
            train_tm_seeds(
                cfg, seeds, [Path(tmp) / f"{preset}-lock{s}" for s in seeds], pairs, progress=False
            )
            lock = time.perf_counter() - t0
            rows.append(
                [
                    f"{preset} FM/IM",
                    f"{one:.2f}",
                    f"{one * args.seeds:.1f}",
                    f"{lock:.1f}",
                    f"{lock / args.seeds:.2f}",
                    f"{one * args.seeds / lock:.2f}×",
                ]
            )
    caption = f"{args.epochs} epoch(s) of {args.pairs} pairs at batch 64 per seed, {args.seeds} seeds."
    print(caption + "\n")
    figures: dict = {}
    show(
        figures,
        "seed sweep",
        [
            "FM/IM",
            "one seed alone (s)",
            f"{args.seeds} seeds one by one (s)",
            f"{args.seeds} seeds in lockstep (s)",
            "lockstep per seed (s)",
            "speed-up",
        ],
        rows,
        caption=caption,
    )
    write_result(
        "tm_seeds_speed", figures, title="A seed sweep's TM training: seeds in lockstep", threads=args.threads
    )


if __name__ == "__main__":
    main()
