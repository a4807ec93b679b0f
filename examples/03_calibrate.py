"""Calibrate an arm from its own log: a chain identified from observed end-effector positions, with no
URDF, written as a URDF that Pinocchio loads.

The "real" arm here is an iiwa14 whose links are a few percent off its datasheet (a URDF written by
the script); its log is motor babbling whose end effector a camera sees with 1 mm of noise.

    python examples/03_calibrate.py
"""

import tempfile
from pathlib import Path

import torch

import kinlearn
from kinlearn.data.babbling import BabblingConfig, babble
from kinlearn.data.recorded import Observations, save_recorded
from kinlearn.evaluation.model_error import write_perturbed_urdf
from kinlearn.training.identify import IdentifyConfig

work = Path(tempfile.mkdtemp())
true_urdf = write_perturbed_urdf(
    "iiwa14", work / "real_arm.urdf", length_error=0.03, misalign_deg=0.5, seed=4
)
real = kinlearn.load_robot(true_urdf, "iiwa_link_ee")

# The log: joints as the encoders read them, the end effector as the camera saw it.
cfg = BabblingConfig(walkers=200, steps=40, ef_noise=1e-3, urdf=str(true_urdf), ee_frame="iiwa_link_ee")
log = save_recorded(
    work / "log.csv", Observations.from_transitions(babble(cfg, robot=real), real.joint_names)
)

# Nothing but the joint count; a short first fit keeps the example quick (the default is 1500 steps).
result = kinlearn.train.identify(log, dof=7, config=IdentifyConfig(mlp_steps=400))
print(result.report["initialisation"])
print(f"held-out residual {result.report['holdout_residual']['median'] * 1e3:.2f} mm (with the 1 mm noise)")

urdf = work / "calibrated.urdf"
urdf.write_text(result.urdf("calibrated"))
calibrated = kinlearn.load_robot(urdf, result.ee_frame)
q = real.sample(2000, torch.Generator().manual_seed(1), dtype=torch.float64)
err = kinlearn.kinematics(calibrated, "pinocchio").position(q) - kinlearn.kinematics(real).position(q)
print(
    f"calibrated URDF against the real arm (Pinocchio): median {float(err.norm(dim=-1).median()) * 1e3:.3f} mm"
)
assert float(err.norm(dim=-1).median()) < 5e-4
