"""A Gaussian prior of a constraint fit's robot geometry about its nominal values (a MAP fit).

One row per robot parameter, ``(θ - θ_nominal) / σ_prior``, after the measurement rows of
:class:`~robocal.identify.constraints.model.ConstraintProblem`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal.model.chain import Model

__all__ = ["NominalPrior"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class NominalPrior:
    """A Gaussian prior of the robot's geometry around its nominal values (a MAP fit).

    Few configurations in one region of joint space determine some parameter
    combinations poorly; the prior holds those near the nominal geometry instead of
    letting the noise set them (ridge regression in the measurement's units).  The
    measured tool (``tool_*``, ``tcp_*``: a ball whose offset is nominal only) and the
    device frame get none.

    Attributes:
        length_std: σ of each length parameter about its nominal value (m).
        angle_std: σ of each angle parameter about its nominal value (rad).
    """

    length_std: float = 0.3e-3
    angle_std: float = 5e-3

    def __post_init__(self) -> None:
        if not (self.length_std > 0 and self.angle_std > 0):
            raise ValueError("a prior's length_std and angle_std must be > 0 (m, rad)")

    def weights(self, chain: Model, robot_names: tuple[str, ...]) -> Array:
        """``(p_chain,)`` 1/σ per free chain parameter (1/m, 1/rad); 0 where no prior."""
        out = []
        for step in (s for s in chain.steps if s.free):
            robot = step.name in robot_names and not step.name.startswith(("tool_", "tcp_"))
            out.append(0.0 if not robot else 1.0 / (self.angle_std if step.is_rotation else self.length_std))
        return np.array(out, dtype=float)

    def line(self) -> str:
        """How the summary names it (mm, mrad)."""
        return (
            f"prior toward the nominal geometry: lengths sigma {self.length_std * 1e3:g} mm, "
            f"angles sigma {self.angle_std * 1e3:g} mrad"
        )
