"""Calibrate an arm from its own log: a chain identified from observed end-effector positions, with no
URDF, written as a URDF that Pinocchio loads.

The log is ``examples/data/iiwa14_log.csv``, shipped with the examples: not a real robot's, but motor
babbling of kinlearn's bundled iiwa14 whose every end-effector position carries 1 mm of Gaussian sensor
noise per axis, as a camera would see it (``examples/data/make_log.py`` makes it). So the truth is known:
the calibrated URDF is compared with the bundled iiwa14 on fresh configurations.

    python examples/03_calibrate.py
"""

import tempfile
from pathlib import Path

import torch

import kinlearn
from kinlearn.training.identify import IdentifyConfig

LOG = Path(__file__).resolve().parent / "data" / "iiwa14_log.csv"
work = Path(tempfile.mkdtemp())

# Nothing but the joint count; a short first fit keeps the example quick (the default is 1500 steps).
result = kinlearn.train.identify(LOG, dof=7, config=IdentifyConfig(mlp_steps=400))
print(result.report["initialisation"])
print(f"held-out residual {result.report['holdout_residual']['median'] * 1e3:.2f} mm (with the 1 mm noise)")

urdf = work / "calibrated.urdf"
urdf.write_text(result.urdf("calibrated"))
calibrated = kinlearn.load_robot(urdf, result.ee_frame)
truth = kinlearn.load_robot("iiwa14")
q = truth.sample(2000, torch.Generator().manual_seed(1), dtype=torch.float64)
err = kinlearn.kinematics(calibrated, "pinocchio").position(q) - kinlearn.kinematics(truth).position(q)
print(
    f"calibrated URDF against the true arm (Pinocchio): median {float(err.norm(dim=-1).median()) * 1e3:.3f} mm"
)
assert float(err.norm(dim=-1).median()) < 1e-3
