"""Seed 001's set-up: the published numbers, the arm (nominal and drawn true arms), the boards
and the directional backlash."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from robocal.measure.ik import solve_ik
from robocal.measure.paths import cubic_spline
from robocal.measure.true_model import draw_true_model
from robocal.model.catalog import robot
from robocal.model.chain import Model

Array = NDArray[np.float64]


#: The seed's numbers (conclusion, Tables 4 and 6 as described in its text; mm, %).
PUBLISHED: dict[str, Any] = {
    "source": "Li, Yang, Chan & Lin, SpringerPlus 5:1771 (2016), seed 001",
    "initial_mean_error_mm": 26.850,
    "table4": {  # verification points 1-6, after calibration on each board orientation
        "normal": {"after_mm": 16.436, "improvement_pct": 38.789},
        "roll": {"after_mm": 19.099, "improvement_pct": 28.866},
        "pitch": {"after_mm": 22.207, "improvement_pct": 17.292},
    },
    "table6": {  # a different trajectory
        "normal_and_roll_improvement_pct": [32.1, 53.0],
        "pitch": "no effect (backlash)",
    },
    "board_tilt_deg": {"roll": 11.7, "pitch": 11.8},
    "bounds": {"length_mm": 5.0, "angle_deg": 2.0},
    "calibration_points": 33,
    "vicon_sigma_mm": 0.28,
}


#: Board orientations (roll, pitch) in degrees: the seed's three calibrations.
BOARDS: dict[str, tuple[float, float]] = {"normal": (0.0, 0.0), "roll": (11.7, 0.0), "pitch": (0.0, 11.8)}


#: Assumptions (the seed gives no numbers for these).
BOARD_CENTER = (0.45, 0.0, 0.0)  # m, base frame: in front of the arm, 76 mm below the shoulder


Q_BRANCH = np.array([0.0, -1.0, 0.1])  # rad: the arm's working configuration (reaching down)


Q_HOME = np.zeros(3)  # rad: where each run starts (first approach direction)


BACKLASH_DEG = 1.0  # total play of joints 2 and 3 in the backlash variant


SWEEP_DEG = (0.0, 0.25, 0.5, 1.0, 2.0)


N_ARMS = 20


# ---------------------------------------------------------------------- the arm
def nominal_arm() -> Model:
    """Seed 001's arm with the twelve DH parameters of joints 1-3 free (the end link
    ``d4``/``alpha4`` of its appendix matrix 3A4 is fixed, as in the seed's eq. 4)."""
    return robot("li2016_3dof").fixed(["d4", "alpha4"])


def true_arm(seed: int, nominal: Model | None = None) -> Model:
    """A real arm: the twelve DH parameters off by uniform amounts within ±5 mm / ±2°."""
    nominal = nominal or nominal_arm()
    return draw_true_model(nominal, length=5e-3, angle=math.radians(2.0), seed=seed)


def verification_points() -> Array:
    """Verification points 1-6, ``(6, 3)`` m: a 60 mm hexagon 30 mm above the board
    centre (assumed; not calibration points)."""
    a = np.radians(np.arange(6) * 60.0)
    c = np.asarray(BOARD_CENTER)
    return c + np.stack([0.06 * np.cos(a), 0.06 * np.sin(a), np.full(6, 0.03)], axis=1)


def spline_targets(n: int = 40) -> Array:
    """The other trajectory, ``(n, 3)`` m: seed 001's Cartesian cubic spline (eq. 3)
    through five waypoints over the board (assumed), zero velocity at the ends."""
    waypoints = np.array(
        [[0.36, -0.14, 0.10], [0.44, -0.06, 0.17], [0.53, 0.02, 0.07], [0.46, 0.10, 0.15], [0.37, 0.17, 0.06]]
    )
    return cubic_spline(waypoints).sample(n)[1]


def table_arm(nominal: Model | None = None, arms: int = N_ARMS) -> tuple[int, float]:
    """The seed of the arm (of ``arms`` draws) whose mean initial error at the
    verification points (nominal commands, no backlash, no noise) is closest to the
    seed's 26.850 mm, and that error (m)."""
    nominal = nominal or nominal_arm()
    P = verification_points()
    q = solve_ik(nominal, P, q0=Q_BRANCH, restarts=0).q
    errors = [
        float(np.linalg.norm(true_arm(s, nominal).fk(q)[:, :3, 3] - P, axis=1).mean()) for s in range(arms)
    ]
    k = int(np.argmin(np.abs(np.array(errors) - PUBLISHED["initial_mean_error_mm"] * 1e-3)))
    return k, errors[k]


# ---------------------------------------------------------------------- backlash
@dataclass(frozen=True)
class DirectionalBacklash:
    """Joint effect: motor backlash, the link lagging its motor by half the play.

    Along the executed sequence of commands (the rows of ``q``, in order, starting from
    ``q_start``), joint ``j`` with total play ``play[j]`` (rad) sits at
    ``δθ_j = −(play_j / 2)·s_j``, ``s_j`` the sign of its last motion (kept through
    moves smaller than ``threshold`` rad).  A history effect: it depends on the order of
    the rows, so it belongs to a simulated execution, not to a model of the robot.

    Attributes:
        play: total play (rad) by joint index (0-based).
        q_start: configuration before the first row.
        threshold: smaller moves keep the previous direction (rad).
    """

    play: dict[int, float]
    q_start: tuple[float, ...] = (0.0, 0.0, 0.0)
    threshold: float = 1e-9

    def signs(self, q: ArrayLike) -> Array:
        """``(n, dof)`` direction of the last motion, +1 or −1, of every joint."""
        q = np.atleast_2d(np.asarray(q, dtype=float))
        start = np.broadcast_to(np.asarray(self.q_start, dtype=float), q.shape[1:])
        dq = np.diff(np.vstack([start, q]), axis=0)
        moved = np.abs(dq) > self.threshold
        # forward-fill the sign of the last real move (first: +1)
        step = np.where(moved, np.sign(dq), 0.0)
        idx = np.where(moved, np.arange(len(q))[:, None], -1)
        last = np.maximum.accumulate(idx, axis=0)
        filled = np.take_along_axis(step, np.maximum(last, 0), axis=0)
        return np.where(last >= 0, filled, 1.0)

    def __call__(self, model: Model, q: Array) -> Array:
        q = np.atleast_2d(np.asarray(q, dtype=float))
        d = np.zeros((len(q), model.dof, 3))
        s = self.signs(q)
        for j, b in self.play.items():
            d[:, j, 2] = -0.5 * b * s[:, j]
        return d


def backlash_of(play_deg: float) -> DirectionalBacklash | None:
    if play_deg <= 0:
        return None
    b = math.radians(play_deg)
    return DirectionalBacklash({1: b, 2: b}, q_start=tuple(Q_HOME))
