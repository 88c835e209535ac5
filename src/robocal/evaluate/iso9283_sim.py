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
from numpy.typing import ArrayLike, NDArray

from robocal import spatial
from robocal.evaluate.iso9283_log import ANGLES, TESTS, Iso9283Log
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
        tests: which of :data:`~robocal.evaluate.iso9283_log.TESTS` to log.
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


# ------------------------------------------------------------------ closed forms
def damped_overshoot(A: float, tau: float, hz: float, band: float) -> float:
    """§7.5 overshoot (m) of ``s(t) = A e^{−t/τ} sin(ωt)`` after a command that ends
    within the band: its first peak ``A e^{−t_p/τ} sin(ω t_p)``, ``t_p = atan(ωτ)/ω``,
    if that exceeds the band, else 0."""
    w = 2 * math.pi * hz
    tp = math.atan(w * tau) / w
    peak = abs(A) * math.exp(-tp / tau) * math.sin(w * tp)
    return peak if peak > band else 0.0


def damped_settling_time(A: float, tau: float, hz: float, band: float) -> float:
    """§7.4 stabilisation time (s) of ``s(t)``: the last instant ``|s(t)| > band``
    (found on a 10 µs grid over the envelope's reach), 0 if never."""
    if abs(A) <= band:
        return 0.0
    t_env = tau * math.log(abs(A) / band)  # after this the envelope is inside the band
    t = np.arange(0.0, t_env + 1e-5, 1e-5)
    out = np.flatnonzero(np.abs(A * np.exp(-t / tau) * np.sin(2 * math.pi * hz * t)) > band)
    return float(t[out[-1]]) if len(out) else 0.0


def _trapezoid(L: float, v: float, a: float) -> tuple[float, Any]:
    """Duration and ``s(t)`` of a trapezoidal (or triangular) speed profile over ``L``."""
    if L <= 0:
        return 0.0, lambda t: np.zeros_like(np.asarray(t, dtype=float))
    if v * v / a > L:
        v = math.sqrt(L * a)
    ta = v / a
    T = L / v + ta

    def s(t: ArrayLike) -> Array:
        t = np.clip(np.asarray(t, dtype=float), 0.0, T)
        return np.where(
            t < ta,
            0.5 * a * t**2,
            np.where(t > T - ta, L - 0.5 * a * (T - t) ** 2, 0.5 * a * ta**2 + v * (t - ta)),
        )

    return T, s


def _euler(R: Array) -> Array:
    return spatial.matrix_to_euler(R, ANGLES)


def _frame_from_angles(abc: Array) -> Array:
    return spatial.euler_to_matrix(abc, ANGLES)


# ------------------------------------------------------------------ the log builder
class _Builder:
    def __init__(self, rate: float, rng: np.random.Generator, noise: float) -> None:
        self.rate, self.rng, self.noise = rate, rng, noise
        self.t = 0.0
        self.cols: dict[str, list[Any]] = {k: [] for k in ("time", "test", "cycle", "target", "group")}
        self.p: list[Array] = []
        self.c: list[Array] = []
        self.a: list[Array] = []
        self.ac: list[Array] = []
        self.f: list[Array] = []

    def add(
        self,
        test: str,
        cycle: int,
        target: str,
        group: str,
        t: Array,
        p: Array,
        c: Array,
        abc: Array,
        abc_c: Array,
        force: Array | None = None,
    ) -> None:
        k = len(t)
        self.cols["time"].append(np.asarray(t, dtype=float))
        for key, v in (("test", test), ("cycle", cycle), ("target", target), ("group", group)):
            self.cols[key].append(np.full(k, v))
        self.p.append(np.asarray(p) + self.rng.normal(0.0, self.noise, (k, 3)))
        self.c.append(np.asarray(c))
        self.a.append(np.broadcast_to(abc, (k, 3)))
        self.ac.append(np.broadcast_to(abc_c, (k, 3)))
        self.f.append(np.zeros((k, 3)) if force is None else np.broadcast_to(force, (k, 3)))
        self.t = float(t[-1]) + 1.0 / self.rate

    def clock(self, duration: float) -> Array:
        k = math.floor(duration * self.rate + 1e-9) + 1
        return self.t + np.arange(k) / self.rate

    def log(self, conditions: dict[str, str]) -> Iso9283Log:
        cat = np.concatenate
        return Iso9283Log(
            source="<simulated>",
            conditions=conditions,
            time=cat(self.cols["time"]),
            test=cat(self.cols["test"]).astype(str),
            cycle=cat(self.cols["cycle"]).astype(int),
            target=cat(self.cols["target"]).astype(str),
            group=cat(self.cols["group"]).astype(str),
            position=cat(self.p),
            commanded=cat(self.c),
            rotation=_frame_from_angles(cat(self.a)),
            commanded_rotation=_frame_from_angles(cat(self.ac)),
            force=cat(self.f),
        )


@dataclass
class _Robot:
    points: Array  # (5, 3) P1..P5 commanded
    bias: Array  # (5, 3)
    bias_abc: Array  # (5, 3) rad
    abc_c: Array  # (3,) commanded angles of the poses
    plane_u: Array  # unit vector along the plane's first edge
    plane_v: Array  # unit vector along the plane's diagonal direction


class _Sim:
    def __init__(self, robot: _Robot, errors: LogErrors, plan: LogPlan, rng: np.random.Generator) -> None:
        self.r, self.e, self.plan, self.rng = robot, errors, plan, rng
        self.b = _Builder(plan.rate_hz, rng, errors.noise)
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
        T, s = _trapezoid(L, self.plan.move_speed, self.plan.move_accel)
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

    # ---- paths
    def _path_run(
        self,
        test: str,
        cycle: int,
        name: str,
        geom: Any,
        L: float,
        lateral: Any,
        abc_of_s: Any,
        abc_offset: Array,
        speed_scale: Any = None,
        commanded_geom: Any = None,
        speed: float | None = None,
    ) -> None:
        T, s = _trapezoid(L, speed or self.plan.path_speed, self.plan.path_accel)
        t = self.b.clock(T + 0.2)
        tau = t - t[0]
        sc = s(tau)
        sa = sc if speed_scale is None else speed_scale(tau, sc, T, L)
        cmd, _ = (commanded_geom or geom)(sc)
        pa, n = geom(sa)
        att = pa + n * lateral(sa)[:, None]
        self.b.add(test, cycle, name, "", t, att, cmd, abc_of_s(sa) + abc_offset, abc_of_s(sc))

    def _line(self) -> tuple[Any, float]:
        A, C = self.r.points[1], self.r.points[3]  # P2 -> P4, the plane's diagonal
        L = float(np.linalg.norm(C - A))
        u = (C - A) / L
        n = np.cross(np.cross(self.r.plane_u, self.r.plane_v), u)
        n /= np.linalg.norm(n)
        return (lambda s: (A + np.outer(s, u), np.broadcast_to(n, (len(s), 3)))), L

    def _circle(self) -> tuple[Any, float]:
        c = self.r.points[0]
        side = float(np.linalg.norm(self.r.points[1] - self.r.points[2])) / 0.8  # P2-P3 spans 80 % of an edge
        radius = 0.4 * side  # ISO: the large circle's diameter is 80 % of the cube side (our reading)
        e1, e2 = self.r.plane_u, self.r.plane_v

        def geom(s: Array) -> tuple[Array, Array]:
            phi = np.asarray(s) / radius
            radial = np.outer(np.cos(phi), e1) + np.outer(np.sin(phi), e2)
            return c + radius * radial, radial

        return geom, 2 * math.pi * radius

    def paths(self, n: int) -> None:
        e = self.e
        for name, (geom, L) in (("line", self._line()), ("circle", self._circle())):
            r = self.rng.normal(0.0, e.path_repeatability, n)
            for j in range(1, n + 1):

                def lat(s: Array, rj: float = r[j - 1], L: float = L) -> Array:
                    return e.path_offset + e.path_wave * np.sin(2 * np.pi * s / L) + rj

                self._path_run(
                    "path",
                    j,
                    name,
                    geom,
                    L,
                    lat,
                    lambda s: np.broadcast_to(self.r.abc_c, (len(s), 3)),
                    np.zeros(3),
                )
            self.truth[f"path_{name}_lateral_random_mm"] = (1e3 * r).tolist()
            self.truth[f"path_{name}_length_mm"] = 1e3 * L
        self.truth["AT_deterministic_mm"] = 1e3 * (abs(e.path_offset) + abs(e.path_wave))

    def reorientation(self, n: int) -> None:
        e = self.e
        geom, L = self._line()
        off = np.array(e.orientation_offset)
        r = self.rng.normal(0.0, e.orientation_repeatability, (n, 3))
        gamma = math.radians(30.0)

        def abc(s: Array) -> Array:
            out = np.broadcast_to(self.r.abc_c, (len(s), 3)).copy()
            out[:, 2] += gamma * (2 * np.asarray(s) / L - 1)  # c sweeps -30..+30 deg about base z
            return out

        for j in range(1, n + 1):
            self._path_run(
                "reorientation", j, "line", geom, L, lambda s: np.zeros(len(s)), abc, off + r[j - 1]
            )
        self.truth["reorientation_random_deg"] = np.degrees(r).tolist()
        self.truth["AT_abc_deg_expected"] = np.degrees(np.abs(off + r.mean(axis=0))).tolist()

    def cornering(self, n: int) -> None:
        e = self.e
        E = self.r.points[[1, 2, 3, 4, 1]]  # E1..E4 = P2..P5, closed
        seg = np.diff(E, axis=0)
        lengths = np.linalg.norm(seg, axis=1)
        d = seg / lengths[:, None]
        cum = np.r_[0.0, np.cumsum(lengths)]
        rho, bump, co = e.corner_radius, e.corner_bump_length, e.corner_overshoot

        def polyline(s: Array) -> tuple[Array, Array]:
            s = np.asarray(s, dtype=float)
            k = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(d) - 1)
            p = E[k] + (s - cum[k])[:, None] * d[k]
            return p, np.zeros_like(p)

        def geom(s: Array) -> tuple[Array, Array]:
            p, _ = polyline(s)
            s = np.asarray(s, dtype=float)
            for i in range(1, len(d)):  # corners E2, E3, E4 (E1 is the start and end, with a stop)
                corner, d1, d2 = E[i], d[i - 1], d[i]
                rel = s - cum[i]
                arc = np.abs(rel) <= rho
                phi = (rel[arc] + rho) / (2 * rho) * (np.pi / 2)
                centre = corner - rho * d1 + rho * d2
                p[arc] = centre + rho * (-np.outer(np.cos(phi), d2) + np.outer(np.sin(phi), d1))
                after = (rel > rho) & (rel < rho + bump)
                p[after] += np.outer(co * np.sin(np.pi * (rel[after] - rho) / bump), d1)
            return p, np.zeros_like(p)

        for j in range(1, n + 1):
            self._path_run(
                "cornering",
                j,
                "rectangle",
                geom,
                float(cum[-1]),
                lambda s: np.zeros(len(s)),
                lambda s: np.broadcast_to(self.r.abc_c, (len(s), 3)),
                np.zeros(3),
                commanded_geom=polyline,
                speed=self.plan.corner_speed,
            )
        self.truth["CR_mm_expected"] = (
            1e3 * rho * (math.sqrt(2) - 1)
        )  # the corners of P2..P5 are right angles
        self.truth["CO_mm_expected"] = 1e3 * co

    def velocity(self, n: int) -> None:
        e = self.e
        geom, L = self._line()
        ej = self.rng.normal(0.0, e.speed_repeatability, n)
        for j in range(1, n + 1):

            def scale(tau: Array, sc: Array, T: float, L: float, ej: float = ej[j - 1]) -> Array:
                v = np.gradient(sc, tau) * (
                    1 + e.speed_error + ej + e.speed_ripple * np.sin(2 * np.pi * e.speed_ripple_hz * tau)
                )
                s = np.r_[0.0, np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(tau))]
                return np.clip(s, 0.0, L)

            self._path_run(
                "velocity",
                j,
                "line",
                geom,
                L,
                lambda s: np.zeros(len(s)),
                lambda s: np.broadcast_to(self.r.abc_c, (len(s), 3)),
                np.zeros(3),
                scale,
            )
        self.truth["speed_cycle_errors"] = ej.tolist()
        self.truth["AV_percent_expected"] = 100.0 * (e.speed_error + float(ej.mean()))
        self.truth["v_c_mm_s"] = 1e3 * self.plan.path_speed

    def positioning(self, n: int) -> None:
        P1, B = self.r.points[0], self.r.bias[0]
        side = float(np.linalg.norm(self.r.points[1] - self.r.points[2])) / 0.8
        dists = [d for d in self.plan.distances if d <= side + 1e-9]
        u = self.r.plane_u
        e = self.e
        settle = damped_settling_time(e.oscillation, e.damping_time, e.oscillation_hz, self.plan.limit_band)
        expected = {}
        for j in range(1, n + 1):
            for dist in dists:
                a, b = P1 - 0.5 * dist * u, P1 + 0.5 * dist * u
                self.move(
                    "positioning", j, f"{1e3 * dist:g}mm", "", a, b, B, B, self.r.abc_c + self.r.bias_abc[0]
                )
        for dist in dists:
            T, _ = _trapezoid(dist, self.plan.move_speed, self.plan.move_accel)
            expected[f"{1e3 * dist:g}"] = T + settle
        self.truth["positioning_time_s_expected"] = expected

    def compliance(self, n: int) -> None:
        C = np.array(self.e.compliance)
        P1, B = self.r.points[0], self.r.bias[0]
        abc = self.r.abc_c + self.r.bias_abc[0]
        for j in range(1, n + 1):
            home = B + self._random()
            for _ in range(3):
                self.static("compliance", j, "P1", "", P1, P1 + home, abc, np.zeros(3))
            for axis in range(3):
                for sign in (1.0, -1.0):
                    for frac in (0.25, 0.5, 0.75, 1.0):
                        f = sign * frac * self.plan.rated_load * np.eye(3)[axis]
                        self.static("compliance", j, "P1", "", P1, P1 + home + C @ f, abc, f)
        self.truth["compliance_mm_per_N_expected"] = {
            f"{s}{a}": 1e3 * float(np.linalg.norm(C[:, k])) for k, a in enumerate("xyz") for s in "+-"
        }

    def weaving(self, n: int) -> None:
        pl, e = self.plan, self.e
        start = self.r.points[0] - 0.5 * pl.weave_length * self.r.plane_v
        axis, across = self.r.plane_v, self.r.plane_u
        T = pl.weave_length / pl.weave_speed
        for j in range(1, n + 1):
            t = self.b.clock(T)
            tau = t - t[0]
            base = start + np.outer(pl.weave_speed * tau, axis)
            wc = 0.5 * pl.weave_stroke * np.sin(2 * np.pi * pl.weave_hz * tau)
            wa = (
                0.5
                * pl.weave_stroke
                * (1 + e.weave_stroke_error)
                * np.sin(2 * np.pi * pl.weave_hz * (1 + e.weave_frequency_error) * tau)
            )
            self.b.add(
                "weaving",
                j,
                "weave",
                "",
                t,
                base + np.outer(wa, across),
                base + np.outer(wc, across),
                self.r.abc_c,
                self.r.abc_c,
            )
        self.truth["WS_percent_expected"] = 100.0 * e.weave_stroke_error
        self.truth["WF_percent_expected"] = 100.0 * e.weave_frequency_error


def _robot_geometry(model: Model, true_model: Model, seed: int, cube: Any) -> tuple[_Robot, Any]:
    from robocal.measure.poses import iso9283_poses

    iso = iso9283_poses(model, cube, seed=seed)
    T_nom = model.fk(iso.q)
    T_true = true_model.fk(iso.q)
    bias = T_true[:, :3, 3] - T_nom[:, :3, 3]
    abc_nom = _euler(T_nom[:, :3, :3])
    bias_abc = np.pi - np.mod(np.pi - (_euler(T_true[:, :3, :3]) - abc_nom), 2 * np.pi)
    corners = iso.cube.plane_corners(iso.plane)  # type: ignore[union-attr]
    u = corners[1] - corners[0]
    v = corners[3] - corners[0]
    robot = _Robot(
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
    from robocal.measure.simulate import draw_true_model

    errors = errors or LogErrors()
    plan = plan or LogPlan()
    unknown = [t for t in plan.tests if t not in TESTS]
    if unknown:
        raise ValueError(f"unknown test(s) {', '.join(unknown)}; known: {', '.join(TESTS)}")
    rng = np.random.default_rng(seed)
    true = draw_true_model(model, length=errors.length_tol, angle=errors.angle_tol, seed=[seed, 1])
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
