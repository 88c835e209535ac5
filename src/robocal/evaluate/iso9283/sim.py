"""A simulated ISO 9283 measurement log whose characteristics are known by construction.

:func:`simulate_log` puts a robot model through the standard's tests (§6.8 test cube and
poses P1..P5 on its first diagonal plane, the §6.9 numbers of cycles) and writes what a
laser tracker would have logged, with these error sources (:class:`LogErrors`):

* pose bias: the kinematic error of a "true" robot drawn around the model
  (:func:`robocal.measure.simulate.draw_true_model`) at each pose's joint values;
* random pose error per visit (normal, per axis) and per angle;
* an offset along the approach direction (multi-directional variation, §7.2.3);
* after each commanded move ends, a damped oscillation along the approach direction,
  ``s(t) = A e^{−t/τ} sin(2π f t)`` (stabilisation time, overshoot, positioning time);
* a thermal drift ``δ(t) = δ_∞ (1 − e^{−t/τ_d})`` along base z and a growing random error
  during the drift test;
* an offset per exchanged robot (exchangeability);
* on paths, a lateral deviation ``δ0 + δ1 sin(2π s/L)`` plus a random lateral offset
  per cycle, and an orientation offset on the reorientation path;
* a round-off arc of radius ρ and an outward bump of height CO after each corner;
* a speed error, a per-cycle speed error and a speed ripple on the velocity path;
* a compliance matrix (m/N) under loads along ±x, ±y, ±z;
* a stroke and a frequency error of the weave;
* tracker noise (normal, per axis).

The truth (:attr:`SimulatedLog.truth`) holds the parameters, the drawn random terms and the
values each characteristic has by construction (closed forms, in mm, deg, s, %).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from robocal.evaluate.iso9283.log import TESTS, Iso9283Log
from robocal.evaluate.iso9283.sim_motion import (
    Builder,
    Robot,
    damped_overshoot,
    damped_settling_time,
    euler,
    trapezoid,
)
from robocal.evaluate.iso9283.sim_paths import PathTests
from robocal.model.chain import Model

__all__ = ["LogErrors", "LogPlan", "SimulatedLog", "damped_overshoot", "damped_settling_time", "simulate_log"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class LogErrors:
    """Error sources of a simulated log (SI units: m, rad, s, N).  See the module docstring."""

    length_tol: float = 0.5e-3
    angle_tol: float = math.radians(0.05)
    repeatability: float = 15e-6
    angle_repeatability: float = math.radians(0.002)
    approach_offset: float = 40e-6
    oscillation: float = 0.3e-3
    damping_time: float = 0.05
    oscillation_hz: float = 8.0
    drift: float = 60e-6
    drift_time: float = 3600.0
    drift_repeatability_growth: float = 0.5
    robot_offset: float = 0.1e-3
    path_offset: float = 0.2e-3
    path_wave: float = 0.1e-3
    path_repeatability: float = 20e-6
    orientation_offset: tuple[float, float, float] = (
        math.radians(0.03),
        math.radians(-0.02),
        math.radians(0.01),
    )
    orientation_repeatability: float = math.radians(0.003)
    corner_radius: float = 5e-3
    corner_overshoot: float = 0.3e-3
    corner_bump_length: float = 0.05
    speed_error: float = -0.01
    speed_repeatability: float = 0.002
    speed_ripple: float = 0.02
    speed_ripple_hz: float = 3.0
    compliance: tuple[tuple[float, ...], ...] = ((2.0e-5, 2e-6, 0.0), (0.0, 2.5e-5, 0.0), (1e-6, 0.0, 1.2e-5))
    weave_stroke_error: float = 0.02
    weave_frequency_error: float = -0.01
    noise: float = 5e-6


@dataclass(frozen=True)
class LogPlan:
    """What the simulated tests do.  Cycle counts default to ISO 9283 §6.9's.

    Attributes:
        tests: which of :data:`~robocal.evaluate.iso9283.log.TESTS` to log.
        rate_hz: tracker sample rate of the time records.
        move_speed, move_accel: point-to-point moves (m/s, m/s²).
        path_speed, path_accel: path tests (m/s, m/s²).
        corner_speed: the cornering path (m/s), slower so that the round-off arc is sampled.
        dwell_s: time at each pose after its command ends.
        limit_band: the limit band written to the header (m).
        robots: exchanged robots.
        drift_hours, drift_cycles: drift test duration and cycles per measurement block.
        rated_load: largest compliance load (N), applied in 4 steps.
        weave_stroke, weave_hz, weave_length, weave_speed: the weave (m, Hz, m, m/s).
        distances: positioning-test distances (m); longer ones than the cube side are left out.
    """

    tests: tuple[str, ...] = TESTS
    cycles: dict[str, int] = field(
        default_factory=lambda: {
            "pose": 30,
            "multidirectional": 30,
            "distance": 30,
            "exchangeability": 30,
            "path": 10,
            "reorientation": 10,
            "cornering": 3,
            "velocity": 10,
            "positioning": 3,
            "compliance": 3,
            "weaving": 3,
        }
    )
    rate_hz: float = 125.0
    move_speed: float = 1.0
    move_accel: float = 2.0
    path_speed: float = 0.25
    path_accel: float = 1.0
    corner_speed: float = 0.1
    dwell_s: float = 0.6
    limit_band: float = 0.1e-3
    robots: int = 3
    drift_hours: float = 8.0
    drift_cycles: int = 30
    rated_load: float = 100.0
    weave_stroke: float = 10e-3
    weave_hz: float = 1.0
    weave_length: float = 0.1
    weave_speed: float = 0.01
    distances: tuple[float, ...] = (0.01, 0.02, 0.05, 0.1, 0.2, 0.5, 1.0)


@dataclass(frozen=True)
class SimulatedLog:
    """A simulated log and its truth (parameters, drawn terms, expected characteristics)."""

    log: Iso9283Log
    truth: dict[str, Any]


class _Sim(PathTests):
    """The simulated robot executing the tests: point-to-point moves and the pose tests here, the
    path tests in :class:`~robocal.evaluate.iso9283.sim_paths._PathTests`."""

    def __init__(self, robot: Robot, errors: LogErrors, plan: LogPlan, rng: np.random.Generator) -> None:
        self.r, self.e, self.plan, self.rng = robot, errors, plan, rng
        self.b = Builder(plan.rate_hz, rng, errors.noise)
        self.truth: dict[str, Any] = {}
        self.labels = ("P1", "P2", "P3", "P4", "P5")

    # ---- point-to-point moves with settling
    def _osc(self, t: Array) -> Array:
        e = self.e
        t = np.maximum(t, 0.0)
        return e.oscillation * np.exp(-t / e.damping_time) * np.sin(2 * math.pi * e.oscillation_hz * t)

    def move(
        self,
        test: str,
        cycle: int,
        target: str,
        group: str,
        start: Array,
        end: Array,
        off_start: Array,
        off_end: Array,
        abc: Array,
    ) -> None:
        """One logged move from ``start`` to ``end`` (commanded), the attained offset
        blending from ``off_start`` to ``off_end``, then the oscillation and a dwell."""
        L = float(np.linalg.norm(end - start))
        T, s = trapezoid(L, self.plan.move_speed, self.plan.move_accel)
        t = self.b.clock(T + self.plan.dwell_s)
        tau = t - t[0]
        lam = s(tau) / L if L > 0 else np.ones_like(tau)
        u = (end - start) / L if L > 0 else np.zeros(3)
        cmd = start + lam[:, None] * (end - start)
        cmd[tau >= T] = end
        p = cmd + (1 - lam)[:, None] * off_start + lam[:, None] * off_end + np.outer(self._osc(tau - T), u)
        self.b.add(test, cycle, target, group, t, p, cmd, abc + np.zeros((len(t), 3)), self.r.abc_c)

    def static(
        self,
        test: str,
        cycle: int,
        target: str,
        group: str,
        cmd: Array,
        att: Array,
        abc: Array,
        force: Array | None = None,
    ) -> None:
        self.b.add(
            test, cycle, target, group, self.b.clock(0.0), att[None], cmd[None], abc, self.r.abc_c, force
        )
        self.b.t += 1.0

    def _random(self, sigma: float | None = None) -> Array:
        return self.rng.normal(0.0, self.e.repeatability if sigma is None else sigma, 3)

    def _random_abc(self) -> Array:
        return self.rng.normal(0.0, self.e.angle_repeatability, 3)

    # ---- 7.2, 7.4, 7.5
    def pose(self, n: int) -> None:
        order = (0, 4, 3, 2, 1)  # P1 -> P5 -> P4 -> P3 -> P2 (-> P1 of the next cycle)
        P, B = self.r.points, self.r.bias
        prev, prev_off = P[1], B[1]
        for j in range(1, n + 1):
            for k in order:
                off = B[k] + self._random()
                self.move(
                    "pose",
                    j,
                    self.labels[k],
                    "",
                    prev,
                    P[k],
                    prev_off,
                    off,
                    self.r.abc_c + self.r.bias_abc[k] + self._random_abc(),
                )
                prev, prev_off = P[k], off
        band = self.plan.limit_band
        e = self.e
        self.truth["stabilisation_time_s"] = damped_settling_time(
            e.oscillation, e.damping_time, e.oscillation_hz, band
        )
        self.truth["overshoot_mm"] = 1e3 * damped_overshoot(
            e.oscillation, e.damping_time, e.oscillation_hz, band
        )
        self.truth["RP_mm_expected"] = (
            1e3 * 3.617 * e.repeatability
        )  # l̄ + 3 S_l of a 3-D normal: (1.596 + 3·0.673) σ

    # ---- 7.2.3
    def multidirectional(self, n: int) -> None:
        for k in (0, 1, 3):  # P1, P2, P4
            for name, axis in (("+x", 0), ("+y", 1), ("+z", 2)):
                u = np.eye(3)[axis]
                for j in range(1, n + 1):
                    att = self.r.points[k] + self.r.bias[k] + self.e.approach_offset * u + self._random()
                    self.static(
                        "multidirectional",
                        j,
                        self.labels[k],
                        name,
                        self.r.points[k],
                        att,
                        self.r.abc_c + self.r.bias_abc[k] + self._random_abc(),
                    )
        self.truth["vAP_mm_expected"] = 1e3 * math.sqrt(2) * self.e.approach_offset

    # ---- 7.3
    def distance(self, n: int) -> None:
        P, B = self.r.points, self.r.bias
        for j in range(1, n + 1):
            for k in (1, 3):
                self.static(
                    "distance",
                    j,
                    self.labels[k],
                    "",
                    P[k],
                    P[k] + B[k] + self._random(),
                    self.r.abc_c + self.r.bias_abc[k] + self._random_abc(),
                )
        D_c = np.linalg.norm(P[1] - P[3])
        self.truth["AD_mm_expected"] = 1e3 * float(np.linalg.norm(P[1] + B[1] - P[3] - B[3]) - D_c)
        self.truth["RD_mm_expected"] = 1e3 * 3 * math.sqrt(2) * self.e.repeatability

    # ---- 7.6
    def drift(self, n: int) -> None:
        e, P, B = self.e, self.r.points, self.r.bias
        minutes = [0, 10, 20, 30, 40, 50, 60] + [60 * h for h in range(2, int(self.plan.drift_hours) + 1)]
        t0 = self.b.t
        for block, m in enumerate(minutes):
            self.b.t = t0 + 60.0 * m
            grow = 1 - math.exp(-60.0 * m / e.drift_time)
            delta = np.array([0.0, 0.0, e.drift * grow])
            sigma = e.repeatability * (1 + e.drift_repeatability_growth * grow)
            for j in range(1, n + 1):
                att = P[0] + B[0] + delta + self._random(sigma)
                self.static(
                    "drift",
                    block * n + j,
                    "P1",
                    f"{m:03d} min",
                    P[0],
                    att,
                    self.r.abc_c + self.r.bias_abc[0] + self._random_abc(),
                )
        T = 60.0 * minutes[-1]
        end = B[0] + np.array([0.0, 0.0, e.drift * (1 - math.exp(-T / e.drift_time))])
        self.truth["dAP_mm_expected"] = 1e3 * abs(float(np.linalg.norm(end) - np.linalg.norm(B[0])))
        growth = e.drift_repeatability_growth * (1 - math.exp(-T / e.drift_time))
        self.truth["dRP_mm_expected"] = 1e3 * 3.617 * e.repeatability * growth

    # ---- 7.7
    def exchangeability(self, n: int) -> None:
        offsets = self.rng.normal(0.0, self.e.robot_offset, (self.plan.robots, 3))
        for r, o in enumerate(offsets):
            for j in range(1, n + 1):
                for k in range(5):
                    att = self.r.points[k] + self.r.bias[k] + o + self._random()
                    self.static(
                        "exchangeability",
                        j,
                        self.labels[k],
                        f"robot{r + 1}",
                        self.r.points[k],
                        att,
                        self.r.abc_c + self.r.bias_abc[k] + self._random_abc(),
                    )
        self.truth["robot_offsets_mm"] = (1e3 * offsets).tolist()
        pair = max(np.linalg.norm(offsets[h] - offsets[k]) for h in range(len(offsets)) for k in range(h))
        self.truth["E_mm_expected"] = 1e3 * float(pair)


def _robot_geometry(model: Model, true_model: Model, seed: int, cube: Any) -> tuple[Robot, Any]:
    from robocal.measure.poses import iso9283_poses

    iso = iso9283_poses(model, cube, seed=seed)
    T_nom = model.fk(iso.q)
    T_true = true_model.fk(iso.q)
    bias = T_true[:, :3, 3] - T_nom[:, :3, 3]
    abc_nom = euler(T_nom[:, :3, :3])
    bias_abc = np.pi - np.mod(np.pi - (euler(T_true[:, :3, :3]) - abc_nom), 2 * np.pi)
    corners = iso.cube.plane_corners(iso.plane)
    u = corners[1] - corners[0]
    v = corners[3] - corners[0]
    robot = Robot(
        points=iso.positions,
        bias=bias,
        bias_abc=bias_abc,
        abc_c=abc_nom[0],
        plane_u=u / np.linalg.norm(u),
        plane_v=v / np.linalg.norm(v),
    )
    return robot, iso.cube


def simulate_log(
    model: Model,
    *,
    errors: LogErrors | None = None,
    plan: LogPlan | None = None,
    seed: int = 0,
    cube: Any = None,
) -> SimulatedLog:
    """A simulated ISO 9283 log of ``model`` (see the module docstring).

    Args:
        model: the nominal robot (what the controller believes); the "true" robot is drawn
            around it with ``errors.length_tol`` / ``errors.angle_tol``.
        errors: the error sources (default :class:`LogErrors`).
        plan: which tests, cycles and speeds (default :class:`LogPlan`: all tests, ISO cycles).
        seed: seeds the true robot, the random terms and the tracker noise.
        cube: the ISO test cube (:class:`robocal.measure.poses.Cube`); default the largest.
    """
    from robocal.measure.true_model import draw_true_model

    errors = errors or LogErrors()
    plan = plan or LogPlan()
    unknown = [t for t in plan.tests if t not in TESTS]
    if unknown:
        raise ValueError(f"unknown test(s) {', '.join(unknown)}; known: {', '.join(TESTS)}")
    rng = np.random.default_rng(seed)
    true_rng = np.random.default_rng([seed, 1])
    true = draw_true_model(model, length=errors.length_tol, angle=errors.angle_tol, seed=true_rng)
    robot, cube = _robot_geometry(model, true, seed, cube)
    sim = _Sim(robot, errors, plan, rng)
    cyc = plan.cycles
    steps = {
        "pose": lambda: sim.pose(cyc.get("pose", 30)),
        "multidirectional": lambda: sim.multidirectional(cyc.get("multidirectional", 30)),
        "distance": lambda: sim.distance(cyc.get("distance", 30)),
        "drift": lambda: sim.drift(plan.drift_cycles),
        "exchangeability": lambda: sim.exchangeability(cyc.get("exchangeability", 30)),
        "path": lambda: sim.paths(cyc.get("path", 10)),
        "reorientation": lambda: sim.reorientation(cyc.get("reorientation", 10)),
        "cornering": lambda: sim.cornering(cyc.get("cornering", 3)),
        "velocity": lambda: sim.velocity(cyc.get("velocity", 10)),
        "positioning": lambda: sim.positioning(cyc.get("positioning", 3)),
        "compliance": lambda: sim.compliance(cyc.get("compliance", 3)),
        "weaving": lambda: sim.weaving(cyc.get("weaving", 3)),
    }
    for test in TESTS:
        if test in plan.tests:
            steps[test]()
    conditions = {
        "robot": model.name,
        "simulated": f"robocal simulate --log, seed {seed}",
        "test_cube": f"centre {np.round(cube.center * 1e3, 1).tolist()} mm, side {cube.side * 1e3:.1f} mm",
        "limit_band_mm": f"{plan.limit_band * 1e3:g}",
        "path_speed_mm_s": f"{plan.path_speed * 1e3:g}",
        "rated_load_N": f"{plan.rated_load:g}",
        "device": f"laser tracker, noise {errors.noise * 1e3:g} mm per axis",
    }
    truth = {
        "seed": seed,
        "robot": model.name,
        "errors": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(errors).items()},
        "poses_mm": (1e3 * robot.points).tolist(),
        "bias_mm": (1e3 * robot.bias).tolist(),
        "bias_abc_deg": np.degrees(robot.bias_abc).tolist(),
        "AP_mm_deterministic": (1e3 * np.linalg.norm(robot.bias, axis=1)).tolist(),
        **sim.truth,
    }
    truth["errors"]["compliance"] = [list(r) for r in errors.compliance]
    return SimulatedLog(sim.b.log(conditions), truth)
