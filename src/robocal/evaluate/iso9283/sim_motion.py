"""Motion profiles, their closed-form settling figures and the log builder of the simulated ISO 9283 log."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal import spatial
from robocal.evaluate.iso9283.log import ANGLES, Iso9283Log

Array = NDArray[np.float64]


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


def trapezoid(L: float, v: float, a: float) -> tuple[float, Any]:
    """Duration and ``s(t)`` of a trapezoidal (or triangular) speed profile over ``L``."""
    if L <= 0:
        return 0.0, lambda t: np.zeros_like(np.asarray(t, dtype=float))
    if v * v / a > L:
        v = math.sqrt(L * a)
    ta = v / a
    T = L / v + ta

    def s(time: ArrayLike) -> Array:
        t = np.clip(np.asarray(time, dtype=float), 0.0, T)
        return np.where(
            t < ta,
            0.5 * a * t**2,
            np.where(t > T - ta, L - 0.5 * a * (T - t) ** 2, 0.5 * a * ta**2 + v * (t - ta)),
        )

    return T, s


def euler(R: Array) -> Array:
    return spatial.matrix_to_euler(R, ANGLES)


def _frame_from_angles(abc: Array) -> Array:
    return spatial.euler_to_matrix(abc, ANGLES)


# ------------------------------------------------------------------ the log builder
class Builder:
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
class Robot:
    points: Array  # (5, 3) P1..P5 commanded
    bias: Array  # (5, 3)
    bias_abc: Array  # (5, 3) rad
    abc_c: Array  # (3,) commanded angles of the poses
    plane_u: Array  # unit vector along the plane's first edge
    plane_v: Array  # unit vector along the plane's diagonal direction
