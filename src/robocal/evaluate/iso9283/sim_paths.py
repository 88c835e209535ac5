"""The path tests of the simulated ISO 9283 log: paths and reorientation (clause 8.2-8.4),
cornering (8.5), path velocity (8.6), positioning time (9), compliance (10) and weaving (11)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from robocal.evaluate.iso9283.sim_motion import Builder, Robot, damped_settling_time, trapezoid

Array = NDArray[np.float64]


class PathTests:
    """Methods of :class:`robocal.evaluate.iso9283.sim._Sim`, which provides these attributes
    and ``move``, ``static``, ``_random`` and ``_random_abc``."""

    r: Robot
    e: Any  # LogErrors
    plan: Any  # LogPlan
    rng: np.random.Generator
    b: Builder
    truth: dict[str, Any]
    labels: tuple[str, ...]

    if TYPE_CHECKING:  # defined by _Sim (declared here for the type checker only)

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
        ) -> None: ...

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
        ) -> None: ...

        def _random(self, sigma: float | None = None) -> Array: ...

    # ---- paths
    def _path_run(  # noqa: PLR0913 - a run is its log columns and the path callables
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
        T, s = trapezoid(L, speed or self.plan.path_speed, self.plan.path_accel)
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
            T, _ = trapezoid(dist, self.plan.move_speed, self.plan.move_accel)
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
