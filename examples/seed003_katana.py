"""Seed 003 on a virtual Katana 450: joint tilting from clearance, backlash and compliance.

    python examples/seed003_katana.py [--out seed003_report] [--quick]

First the pieces, step by step (joint loads from Pinocchio, the joint effects of
Table 5.2, a virtual robot that tilts, three calibrations), then the whole experiment
of ``robocal reproduce seed003`` (tables like the thesis' Tables 4.5/4.6, the circle
of §5.5, where the simulation agrees with the thesis and where not), written to
``--out``.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from pathlib import Path

import numpy as np

import robocal as rc
from robocal.experiments import seed003
from robocal.measure.devices import OpticalCMM
from robocal.measure.poses import random_poses
from robocal.measure.simulate import VirtualRobot, simulate
from robocal.model.joints import JointTilting, joint_perturbations, load_moments


def walkthrough() -> None:
    katana = rc.robot("katana450")  # seed 003's model, masses (Table 4.2) and joint effects (Table 5.2)
    q = np.radians([[30, 60, -40, 50, 20]])
    eta = load_moments(katana, q)[0]  # load moments on each joint, its own frame (N·m)
    d = joint_perturbations(katana, q)[0]  # (δα, δβ, δθ) per joint (rad)
    print("load moments [ηx ηy ηz] N·m and joint perturbations [δα δβ δθ] deg at q =", np.degrees(q[0]))
    for j, name in enumerate(katana.joint_names):
        print(f"  {name}: η = {np.round(eta[j], 3)}   δ = {np.round(np.degrees(d[j]), 4)}")
    shift = katana.fk(q, d[None])[0, :3, 3] - katana.fk(q)[0, :3, 3]
    print(f"  the tool moves by {np.linalg.norm(shift) * 1e3:.3f} mm")

    # a real Katana: the thesis' geometric errors, the Table 5.2 joints, an Optotrak-like CMM
    true = katana.with_values(
        {k: katana.step(k).value + v for k, v in seed003.THESIS_GEOMETRIC_ERRORS.items()}
    )
    device = OpticalCMM(T_device_base=np.eye(4), working_range=None, sigma=0.01e-3)
    robot = VirtualRobot(katana, true, device, JointTilting())
    box = np.array([[-0.6, -0.6, 0.05], [0.6, 0.6, 0.8]])
    train = simulate(robot, random_poses(katana, 118, seed=1, box=box), seed=2)
    test = simulate(robot, random_poses(katana, 200, seed=3, box=box), seed=4)
    geometric = dataclasses.replace(katana, joint_effects=())
    options = dict(frame="fixed", tool=None, measure="position")  # the CMM measures in the robot's base
    runs = {
        "conventional (level 2)": rc.calibrate(geometric, train, level=2, **options),
        "two-stage (Table 5.2 predicted)": rc.calibrate(katana, train, effects="predict", **options),
        "simultaneous (level 3)": rc.calibrate(geometric, train, level=3, **options),
    }
    before = np.linalg.norm(geometric.fk(test.q)[:, :3, 3] - test.position, axis=1).mean()
    print(f"\nheld-out mean |ΔP|: before {before * 1e3:.3f} mm")
    for label, result in runs.items():
        print(f"  {label:<34} {rc.validate(result, test).mean * 1e3:.4f} mm")
    print("\nthe simultaneous calibration's joint parameters (± 1σ):")
    from robocal.identify.effects import effect_lines

    for line in effect_lines(runs["simultaneous (level 3)"].effect_estimates()):
        print("  " + line)
    deg = math.radians(1)
    clearance = [round(e.clearance_tilt / deg, 3) for e in true.joint_effects]
    backlash = [round(e.backlash / deg, 3) for e in true.joint_effects]
    print(f"  (true, Table 5.2: clearance {clearance} deg, backlash {backlash} deg)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("seed003_report"), help="report directory")
    parser.add_argument("--quick", action="store_true", help="a smaller, faster run")
    args = parser.parse_args()
    walkthrough()
    print("\n=== robocal reproduce seed003 ===")
    seed003.run(out=args.out, quick=args.quick, verbose=True)
    print(
        f"wrote {args.out / 'seed003.json'}, {args.out / 'seed003.md'} and {args.out / 'seed003_circle.png'}"
    )


if __name__ == "__main__":
    main()
