# long: the demo reads top to bottom as the steps it prints (model, robot, poses, fit, ISO 9283)
"""``robocal demo``: the whole of robocal on a virtual robot, in well under a minute.

The default: a UR10 whose "real" twin has millimetre geometric errors and joints that
give way under gravity, measured by a laser tracker.  The demo

1. builds the complete, minimal, singularity-free calibration model from the robot's
   joint geometry (seed 000), with the catalog's link masses;
2. draws the real robot (±1 mm, ±0.1° parameter errors; joint compliance deflecting
   the joints by 0.2-0.6 mrad at their largest gravity torque; encoder noise) and
   places a laser tracker (15 µm + 6 µm/m) 2-3 m away;
3. plans poses: a pool of random configurations, the calibration set chosen from it
   by D-optimal selection (observability index O1), random held-out poses, the ISO
   9283 test cube with P1-P5 and two test paths in its diagonal plane;
4. simulates the measurements, calibrates (geometry + joint compliance, and a
   geometric-only calibration for comparison), validates on the held-out poses;
5. compensates the ISO poses and paths (``rc.compensate_targets`` when robocal has it, else
   the demo's own compensation by inverse kinematics on the calibrated model) and
   measures ISO 9283 AP, RP, AT and RT with nominal and with compensated commands;
6. writes the calibration, the data, ``evaluation.json`` and the HTML report.

Everything is seeded: the same seed gives the same numbers.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import spatial
from robocal.model.chain import Model
from robocal.model.steps import Body

if TYPE_CHECKING:
    from robocal.measure.poses import IsoPoses

__all__ = [
    "DEFAULT_ROBOT",
    "GravityCompliance",
    "compensate_positions",
    "complete_model",
    "geometry_of",
    "run_demo",
]

Array = NDArray[np.float64]

DEFAULT_ROBOT = "ur10"
#: the reflector's nominal offset from the flange (m): the tool point measured.
SMR_OFFSET = (0.0, 0.0, 0.1)


# ------------------------------------------------------------------ models
def geometry_of(model: Model) -> tuple[list, Any]:
    """Joint geometry of a chain at its zero configuration, as the builder takes it
    (:func:`robocal.model.complete.geometry_from_model`)."""
    from robocal.model.complete import geometry_from_model

    return geometry_from_model(model)


def complete_model(robot: str | Model, measure: str = "position", payload: float = 5.0) -> Model:
    """The complete, minimal, singularity-free calibration model of a robot (seed 000):
    :func:`robocal.calibration_model`, its link masses carried over.  A robot without mass
    properties gets a point payload of ``payload`` kg at its tool, so that gravity loads
    its joints.

    Args:
        robot: a catalog name or a model.
        measure: ``"position"`` or ``"pose"`` measurement (decides the tool link).
        payload: kg, used only when the robot has no masses.
    """
    from robocal.model.complete import calibration_model

    built = calibration_model(robot, measure)  # type: ignore[arg-type]
    if not built.bodies and payload > 0:
        built = dataclasses.replace(built, bodies=(Body("payload", built.steps[-1].name, float(payload)),))
    return built


@dataclass(frozen=True)
class GravityCompliance:
    """Joint effect: each joint gives way under the torque that holds the arm against
    gravity, ``δθ_j = −c_j τ_j(q)`` (c in rad per N·m; τ from the model's masses by
    Pinocchio).  The same law :func:`robocal.calibrate` identifies with ``compliance=True``.
    """

    compliance: Mapping[str, float]
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)

    def __call__(self, model: Model, q: Array) -> Array:
        from robocal.model.dynamics import gravity_torques

        q = np.atleast_2d(q)
        tau = gravity_torques(model, q, np.asarray(self.gravity))
        d = np.zeros((len(q), model.dof, 3))
        for name, c in self.compliance.items():
            j = model.joint_names.index(name)
            d[:, j, 2] = -c * tau[:, j]
        return d

    def to_dict(self) -> dict[str, Any]:
        return {
            "type": "gravity-compliance",
            "compliance": dict(self.compliance),
            "gravity": list(self.gravity),
        }


# ------------------------------------------------------------------ compensation
def _ik_compensation(result, targets: Array, q_start: Array, iterations: int = 5) -> Array:
    """Joint commands that put the calibrated robot's tool point on ``targets``:
    inverse kinematics of the calibrated model from the nominal commands, repeated with
    the target shifted by the remaining error of the full prediction (joint effects
    included) until it is below 0.1 µm."""
    from robocal.measure.ik import solve_ik

    goal = targets.copy()
    q = q_start.copy()
    for _ in range(iterations):
        q = solve_ik(result.model, goal, kind="position", q0=q, restarts=0, tol=1e-8).q
        err = targets - result.predict(q, frame=np.eye(4))[:, :3, 3]
        if np.abs(err).max() < 1e-7:
            break
        goal = goal + err
    return q


def compensate_positions(result, targets: ArrayLike, q_start: ArrayLike) -> tuple[Array, str]:
    """Compensated joint commands ``(n, dof)`` for tool-point ``targets`` ``(n, 3)`` (m,
    robot base frame), starting from the nominal commands ``q_start`` ``(n, dof)``.

    Uses ``robocal.compensate_targets`` when this robocal has it (and it accepts these
    arguments); otherwise inverse kinematics on the calibrated model, joint effects
    included.  Returns the commands and a description of the method used.
    """
    import robocal as rc

    targets = np.atleast_2d(np.asarray(targets, dtype=float))
    q_start = np.atleast_2d(np.asarray(q_start, dtype=float))
    note = ""
    if hasattr(rc, "compensate_targets"):
        for call in (
            lambda: rc.compensate_targets(result, targets, q0=q_start),
            lambda: rc.compensate_targets(result, targets),
        ):
            try:
                out = call()
            except TypeError as err:
                note = f"rc.compensate_targets did not accept (result, targets): {err}"
                continue
            except ValueError as err:
                note = f"rc.compensate_targets failed: {err}"
                break
            q = np.asarray(getattr(out, "q", out), dtype=float)
            if q.shape == q_start.shape and np.all(np.isfinite(q)):
                status = ""
                if not getattr(out, "success", True):
                    status = f" ({getattr(out, 'message', 'not every target reached')})"
                return q, "robocal.compensate_targets: inverse kinematics of the calibrated model" + status
            note = f"rc.compensate_targets returned shape {q.shape}, expected {q_start.shape}"
            break
    method = "inverse kinematics on the calibrated model (joint effects included)"
    return _ik_compensation(result, targets, q_start), method + (f"; {note}" if note else "")


def _tracker_frame(rng: np.random.Generator) -> Array:
    """``T_device_base``: a tracker 2.5 m in front of the robot, turned, slightly tilted."""
    angle = rng.uniform(-np.pi, np.pi)
    p = np.array([2.5 * math.cos(angle), 2.5 * math.sin(angle), rng.uniform(-0.3, 0.3)])
    R = spatial.euler_to_matrix(
        [angle + np.pi + rng.uniform(-0.3, 0.3), rng.uniform(-0.02, 0.02), rng.uniform(-0.02, 0.02)], "ZYX"
    )
    return spatial.inverse(spatial.homogeneous(R, p))  # tracker pose in base -> base in tracker


def _measure_cycles(robot, q: Array, cycles: int, seed: int, T_base_device: Array) -> Array:
    """Attained tool-point positions ``(cycles, n, 3)`` in the robot base frame (m), as
    measured by the tracker and mapped with the identified frame ``T_base_device``."""
    from robocal.measure.simulate import simulate

    data = simulate(robot, np.tile(q, (cycles, 1)), seed=seed)  # one batched call
    assert data.position is not None  # a simulated tracker measures positions
    p = data.position @ T_base_device[:3, :3].T + T_base_device[:3, 3]
    return p.reshape(cycles, len(q), 3)


def run_demo(
    robot: str = DEFAULT_ROBOT,
    out: str | Path | None = "robocal-demo",
    *,
    seed: int = 0,
    n_calibration: int = 50,
    n_validation: int = 300,
    cycles: int = 30,
    quick: bool = False,
    verbose: bool = True,
) -> dict[str, Any]:
    """Run the demo (see the module docstring) and return its numbers (mm, deg, s).

    Args:
        robot: catalog robot (default ``"ur10"``).
        out: output directory (calibration, data, ``evaluation.json``,
            ``report.html``); None writes nothing.
        seed: seeds everything.
        n_calibration: calibration poses chosen from the candidate pool.
        n_validation: held-out poses.
        cycles: ISO 9283 cycles at P1..P5 (paths: a third of them, at least 3).
        quick: smaller pool, cube search and cycles (for tests).
        verbose: Rich progress and the closing summary.
    """
    from robocal.demo.console import Steps, print_summary, summary_numbers

    t_start = time.perf_counter()
    demo = _Demo(robot, seed, quick, min(cycles, 5) if quick else cycles)
    steps = Steps(
        [
            "building the calibration model (Motta 2005, seed 000)",
            "drawing the real robot and placing the tracker",
            "planning poses (O1-optimal, held-out, ISO 9283 cube)",
            "simulating the laser-tracker measurements",
            "calibrating (geometry + joint compliance)",
            "validating on held-out poses",
            "compensating ISO 9283 poses and paths",
            "writing the report",
        ],
        verbose,
    )
    stages = (
        demo.build_model,
        demo.draw_robot,
        lambda: demo.plan_poses(n_calibration, n_validation),
        demo.simulate_measurements,
        demo.calibrate,
        demo.validate,
        demo.compensate,
        lambda: demo.write(None if out is None else Path(out), steps.timings),
    )
    with steps.running():
        for name, stage in zip(steps.names, stages, strict=True):
            with steps.step(name):
                stage()
    seconds = time.perf_counter() - t_start
    numbers = summary_numbers(
        demo.result, demo.before, demo.after, demo.after_geo, demo.ev, seconds, demo.report_path
    )
    numbers["timings_s"] = dict(steps.timings)
    if verbose:
        print_summary(numbers)
    return numbers


class _Demo:
    """The demo's state, built up step by step (one method per step of :func:`run_demo`)."""

    def __init__(self, robot: str, seed: int, quick: bool, cycles: int) -> None:
        self.robot, self.seed, self.quick, self.cycles = robot, seed, quick, cycles
        self.path_cycles = max(3, cycles // 3)
        self.rng = np.random.default_rng(seed)
        self.ev: dict[str, Any] = {"robot": robot, "seed": seed}
        self.report_path: Path | None = None

    def build_model(self) -> None:
        from robocal.identify.problem import measurement_chain

        self.nominal = complete_model(self.robot, "position")
        self.tool = np.array(SMR_OFFSET)
        self.nominal_tool = measurement_chain(
            self.nominal, np.eye(4), spatial.homogeneous(p=self.tool), "position", False
        )

    def draw_robot(self) -> None:
        from robocal.measure.devices import LaserTracker
        from robocal.measure.poses import random_poses
        from robocal.measure.true_model import draw_true_model
        from robocal.model.dynamics import gravity_torques

        nominal, rng = self.nominal, self.rng
        self.true = true = draw_true_model(nominal, length=1e-3, angle=math.radians(0.1), seed=rng)
        self.pool = random_poses(nominal, 400 if self.quick else 1000, seed=rng, margin=0.05)
        tau = np.abs(gravity_torques(true, self.pool)).max(axis=0)
        self.compliance = {
            name: float(rng.uniform(2e-4, 6e-4) / tau[j])
            for j, name in enumerate(nominal.joint_names)
            if tau[j] > 0.05 * tau.max()
        }
        T_device_base = _tracker_frame(rng)
        self.tracker = LaserTracker(
            T_device_base=T_device_base, p_tool_target=self.tool, sigma=15e-6, sigma_per_m=6e-6
        )
        self.encoder = 1e-5  # rad, 1-sigma: repeatability
        truth_deltas = {
            n: float(v - v0)
            for n, v, v0 in zip(true.names, true.values, nominal.values, strict=True)
            if abs(v - v0) > 0
        }
        self.ev["truth"] = {
            "parameter_deltas": truth_deltas,
            "compliance_rad_per_Nm": self.compliance,
            "T_device_base": T_device_base.tolist(),
            "encoder_noise_rad": self.encoder,
            "tracker": "15 µm + 6 µm/m (1σ per axis)",
            "tolerances": "±1 mm lengths, ±0.1° angles (uniform)",
        }

    def virtual(self, noise_seed: int) -> Any:
        """The real robot measured by the tracker, its encoders' noise seeded with ``noise_seed``."""
        from robocal.measure.joint_effects import EncoderNoise, JointEffect
        from robocal.measure.simulate import VirtualRobot

        effects: list[JointEffect] = [
            GravityCompliance(self.compliance),
            EncoderNoise(self.encoder, noise_seed),
        ]
        return VirtualRobot(self.nominal, self.true, self.tracker, effects)

    def _flange_cube(self):
        """The ISO test cube of the robot with its tool (:meth:`plan_poses`) moved back by
        the fixed tool orientation times the tool offset: a flange pose of that cube is a
        tool pose of the tool's cube in the same configuration, so the bare robot reaches
        it as well (only for a fixed full orientation; None otherwise: a search)."""
        if self.iso is None or self.iso.kind != "pose":
            return None
        from robocal.measure.cube import Cube

        centre = self.iso.cube.center - np.asarray(self.iso.orientation) @ self.tool
        return Cube(center=centre, side=self.iso.cube.side)

    def plan_poses(self, n_calibration: int, n_validation: int) -> None:
        from robocal.identify.pose_selection import select_poses
        from robocal.measure.poses import iso9283_poses, random_poses

        selection = select_poses(self.nominal, self.pool, n_calibration)
        self.q_train = selection.q
        self.q_test = random_poses(self.nominal, n_validation, seed=self.rng, margin=0.05)
        # largest_cube's search options (its defaults unless quick)
        search: dict[str, Any] = {"samples": 1000, "candidates": 2} if self.quick else {}
        self.iso = None
        try:
            self.iso = iso9283_poses(self.nominal_tool, seed=self.seed, **search)
        except ValueError as err:  # e.g. a robot that cannot hold the orientation over a cube
            self.ev["iso_error"] = str(err)
        self.ev["poses"] = {
            "calibration": len(self.q_train),
            "held_out": len(self.q_test),
            "pool": len(self.pool),
            "selection_index": selection.index,
            "O1": selection.value,
        }

    def simulate_measurements(self) -> None:
        from robocal.measure.simulate import simulate

        rng = self.rng
        self.train = simulate(
            self.virtual(int(rng.integers(1 << 31))), self.q_train, seed=int(rng.integers(1 << 31))
        )
        self.test = simulate(
            self.virtual(int(rng.integers(1 << 31))), self.q_test, seed=int(rng.integers(1 << 31))
        )

    def calibrate(self) -> None:
        import robocal as rc

        self.result = rc.calibrate(self.nominal, self.train, tool_guess=self.tool, compliance=True)
        self.geometric = rc.calibrate(self.nominal, self.train, tool_guess=self.tool)
        # what each model leaves unexplained, from its residuals against the tracker noise
        self.ev["fit_to_noise"] = {
            "geometric calibration": self.geometric.metadata.get("fit_to_noise"),
            "geometry + joint compliance": self.result.metadata.get("fit_to_noise"),
        }

    def validate(self) -> None:
        import robocal as rc
        from robocal.evaluate.report import before_validation

        self.after = rc.validate(self.result, self.test)
        self.after_geo = rc.validate(self.geometric, self.test)
        self.before = before_validation(self.result, self.test)
        self.result = self.result.with_validation(self.after.to_dict())
        self.ev["comparison"] = [
            {
                "model": "nominal (tracker frame and tool fitted)",
                **(self.before.to_dict() if self.before else {}),
            },
            {"model": "geometric calibration", **self.after_geo.to_dict()},
            {"model": "geometric + joint compliance", **self.after.to_dict()},
        ]

    def compensate(self) -> None:
        iso = self.iso
        if iso is None:
            return
        T_base_device = spatial.inverse(self.result.frame)
        commanded = iso.positions
        q_comp, method = compensate_positions(self.result, commanded, iso.q)
        cases = {"nominal commands": iso.q, "compensated commands": q_comp}
        cycles, seed = self.cycles, self.seed
        self.ev["iso_poses"] = {
            "labels": list(iso.labels),
            "commanded": commanded.tolist(),
            "cube": {"center": iso.cube.center.tolist(), "side": iso.cube.side, "plane": iso.plane},
            "cycles": cycles,
            "cases": {
                name: _measure_cycles(self.virtual(100 + k), q, cycles, seed + 100 + k, T_base_device)
                .transpose(1, 0, 2)
                .tolist()
                for k, (name, q) in enumerate(cases.items())
            },
        }
        paths, method = self._paths(iso, T_base_device, method)
        self.ev["paths"] = paths
        self.ev["compensation"] = {
            "method": method,
            "max_joint_change_deg": float(np.degrees(np.abs(q_comp - iso.q).max())),
        }

    def _paths(self, iso: IsoPoses, T_base_device: Array, method: str) -> tuple[list[dict[str, Any]], str]:
        """ISO 9283 AT/RT: a line P2-P4 and a circle about P1 in the cube's diagonal plane,
        with nominal and compensated commands; and the last compensation method used."""
        from robocal.measure.paths import Circle, circle_path, joint_path, line_path

        seed, path_cycles = self.seed, self.path_cycles
        commanded = iso.positions
        paths: list[dict[str, Any]] = []
        centre, side = iso.cube.center, iso.cube.side
        corners = iso.cube.plane_corners(iso.plane)
        k_samples = 40 if self.quick else 120
        line = line_path(commanded[1], commanded[3], k_samples)
        normal = np.cross(corners[1] - corners[0], corners[3] - corners[0])
        u = commanded[1] - centre
        u -= normal * (u @ normal) / (normal @ normal)
        circle = circle_path(
            Circle(centre, 0.3 * side, normal / np.linalg.norm(normal), u / np.linalg.norm(u)),
            k_samples,
        )
        for name, pts in (("line P2–P4", line), ("circle r = 0.3 × side about P1", circle)):
            frames = spatial.homogeneous(np.broadcast_to(iso.orientation, (len(pts), 3, 3)), pts)
            jp = joint_path(self.nominal_tool, frames, kind=iso.kind, q0=iso.q[0])
            if not jp.reachable.all():
                continue
            q_c, method = compensate_positions(self.result, pts, jp.q)
            nominal_cycles = _measure_cycles(
                self.virtual(200 + len(paths)), jp.q, path_cycles, seed + 200, T_base_device
            )
            compensated_cycles = _measure_cycles(
                self.virtual(300 + len(paths)), q_c, path_cycles, seed + 300, T_base_device
            )
            paths.append(
                {
                    "name": name,
                    "commanded": pts.tolist(),
                    "cycles": path_cycles,
                    "cases": {
                        "nominal commands": nominal_cycles.tolist(),
                        "compensated commands": compensated_cycles.tolist(),
                    },
                    "max_joint_change_deg": float(np.degrees(np.abs(q_c - jp.q).max())),
                }
            )
        return paths, method

    def write(self, out: Path | None, timings: Mapping[str, float]) -> None:
        """The calibration, the data, ``evaluation.json`` and the report, all or nothing."""
        if out is None:
            return
        from robocal.evaluate.report import write_report
        from robocal.measure.dataset.writer import write_measurements
        from robocal.model.files import save_model
        from robocal.outdir import atomic_write_text
        from robocal.safe_output import strict_json

        result = self.result.with_records(source="robocal demo", robot=self.robot, seed=self.seed)
        ev = self.ev
        if not self.quick:  # ISO 9283's fourteen characteristics, from a simulated timed log
            from robocal.evaluate.iso9283.report import evaluate_log
            from robocal.evaluate.iso9283.sim import simulate_log

            try:  # the test cube of the poses above, for the bare robot: no second search (~1.5 s)
                log = simulate_log(self.nominal, seed=self.seed, cube=self._flange_cube())
            except ValueError:  # its IK missed a pose of the moved cube: a cube of its own
                log = simulate_log(self.nominal, seed=self.seed)
            ev["iso9283"] = evaluate_log(log.log).to_dict()
        ev["timings_s"] = dict(timings)

        def the_rest(stage: Path) -> None:  # written with the result, all or nothing
            from robocal.run_ids import read_run_id

            run_id = read_run_id(stage / "result.json")  # each file carries the result's run id
            write_measurements(self.train, stage / "train.csv", run_id=run_id)
            write_measurements(self.test, stage / "test.csv", run_id=run_id)
            save_model(self.true, stage / "true_model.yaml", run_id=run_id)
            evaluation = ev | ({"run_id": run_id} if run_id else {})
            atomic_write_text(stage / "evaluation.json", strict_json(evaluation) + "\n")
            report = stage / "report.html"
            write_report(result, report, data=self.train, test_data=self.test, evaluation=ev, run_id=run_id)

        result.save(out, also=the_rest)
        self.report_path = out / "report.html"
