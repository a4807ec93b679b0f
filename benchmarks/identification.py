"""Calibration measured against the truth: a chain identified from noisy babbling of a true robot that
is unlike the bundled URDF, exported as a URDF, its forward kinematics through Pinocchio compared
with the true robot's on fresh configurations over the whole joint range.

    python benchmarks/identification.py [--robots iiwa14 panda ur5 xarm7 z1] [--samples 60000]
        [--noise 0.001] [--outliers 0.02] [--threads 1]

For each arm: a true robot written by this script (every joint origin's translation scaled by up to
±3%, its rotation tilted by up to 0.5° about a random axis, each joint zero off by up to 1.5°;
:func:`kinlearn.evaluation.model_error.write_perturbed_urdf`), ``--samples`` babbled states observed
with ``--noise`` m Gaussian noise per axis (and, in the outlier rows, ``--outliers`` of them displaced
by 5 cm). Rows: identified with the nominal URDF as prior, and with no prior but the joint count;
each with and without outliers. Columns: the exported URDF's FK error against the true robot on
20,000 fresh configurations (median, p99, max, mm), the nominal URDF's own error for scale, the
outliers dropped, the wall time of the identification.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import torch
from _common import header, table, write_result

from kinlearn.body.kinematics import kinematics
from kinlearn.body.robot import ROBOTS, load_robot
from kinlearn.data.babbling import BabblingConfig, babble
from kinlearn.evaluation.model_error import write_perturbed_urdf
from kinlearn.training.identify import identify


def _error_mm(a, b, q) -> torch.Tensor:
    return (kinematics(a, "pinocchio").position(q) - kinematics(b, "fast").position(q)).norm(dim=-1) * 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--robots", nargs="+", default=["iiwa14", "panda", "ur5", "xarm7", "z1"])
    ap.add_argument("--samples", type=int, default=60_000)
    ap.add_argument("--noise", type=float, default=1e-3)
    ap.add_argument("--outliers", type=float, default=0.02)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--threads", type=int, default=1)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    print(header("Identification against a true robot unlike the URDF", args.threads))
    print(
        f"{args.samples:,} babbled samples, {args.noise * 1e3:g} mm noise; outlier rows: {args.outliers:.0%} "
        "displaced by 5 cm\n"
    )
    columns = ["arm", "prior", "outliers", "exported URDF FK error median / p99 / max (mm)",
               "nominal URDF median (mm)", "dropped", "time (s)"]  # fmt: skip
    print("| " + " | ".join(columns) + " |")
    print("|:--|:--|--:|--:|--:|--:|--:|")
    rows = []
    folder = Path(tempfile.mkdtemp())
    for name in args.robots:
        nominal = load_robot(name)
        path = write_perturbed_urdf(
            name, folder / f"true_{name}.urdf", length_error=0.03, angle_error_deg=1.5, misalign_deg=0.5,
            seed=args.seed,
        )  # fmt: skip
        true = load_robot(path, ROBOTS[name].ee_frame)
        q = true.sample(20_000, torch.Generator().manual_seed(args.seed + 100), dtype=torch.float64)
        nominal_err = _error_mm(nominal, true, q)
        for outliers in (0.0, args.outliers):
            cfg = BabblingConfig(
                robot=true.name, walkers=1000, steps=-(-args.samples // 1000), seed=args.seed, dtype="float64",
                ef_noise=args.noise, outliers=outliers, urdf=str(path), ee_frame=true.ee_frame,
            )  # fmt: skip
            data = babble(cfg, robot=true)
            for prior in (True, False):
                t0 = time.perf_counter()
                result = identify(data, robot=nominal, prior=prior)
                dt = time.perf_counter() - t0
                out = folder / f"{name}_{prior}_{outliers}.urdf"
                out.write_text(result.urdf())
                err = _error_mm(load_robot(out, result.ee_frame), true, q)
                row = [
                    name,
                    "nominal URDF" if prior else "none (joint count)",
                    f"{outliers:.0%}",
                    f"{err.median():.4f} / {err.quantile(0.99):.4f} / {err.max():.3f}",
                    f"{nominal_err.median():.1f}",
                    result.report["outliers_dropped"],
                    f"{dt:.1f}",
                ]
                rows.append(row)
                print("| " + " | ".join(str(c) for c in row) + " |", flush=True)
    caption = (
        f"{args.samples:,} babbled samples, {args.noise * 1e3:g} mm noise; outlier rows: {args.outliers:.0%} "
        "displaced by 5 cm; errors on 20,000 fresh configurations."
    )
    write_result(
        "identification",
        {"identification": table(columns, rows, caption=caption)},
        title="Calibration: chains identified from noisy babbling of a robot unlike its URDF",
        threads=args.threads,
    )


if __name__ == "__main__":
    main()
