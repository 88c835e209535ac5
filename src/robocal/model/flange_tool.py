"""The measured tool at the end of a calibrated model, apart from the robot (issue 32 item 5).

A calibration appends the tool it measured (``tcp_*`` steps, :attr:`Role.TOOL
<robocal.model.steps.Role>`) to the robot's chain; the controller, the joint loads, the
URDF and the program frames want the robot to its flange alone, and a model read back
from ``model.yaml`` carries its tool as the start of the next calibration.  This module is
the one place that tells the two apart (:func:`split_tool`) and puts them together again
(:meth:`FlangeTool.on`).  Units: SI (m, rad).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from robocal import spatial
from robocal.model.chain import Model
from robocal.model.steps import Role, Step

__all__ = ["FlangeTool", "split_tool", "tool_steps"]

Array = NDArray[np.float64]


@dataclass(frozen=True)
class FlangeTool:
    """A model split at its flange.

    Attributes:
        robot: the chain to the flange (the model without its tool steps; its other fields
            — joint effects, residual, bodies — as they were).
        steps: the tool's steps, flange to the measured point or frame, in chain order
            (empty: the model ends at its flange).
    """

    robot: Model
    steps: tuple[Step, ...]

    @property
    def T_flange_tool(self) -> Array | None:
        """``(4, 4)`` the tool in the flange frame (m); None without tool steps."""
        if not self.steps:
            return None
        return spatial.chain_product([s.motion for s in self.steps], [s.value for s in self.steps])

    def on(self, robot: Model) -> Model:
        """``robot`` (a chain to the flange) with these tool steps appended (itself without)."""
        if not self.steps:
            return robot
        return dataclasses.replace(robot, steps=(*robot.steps, *self.steps))


def tool_steps(model: Model) -> tuple[Step, ...]:
    """The measured tool's steps at the end of ``model`` (as :func:`split_tool`, without
    building the robot's model: every calibration reads its tool's steps).

    Raises:
        ValueError: as :func:`split_tool`.
    """
    return model.steps[_flange_index(model) :]


def _flange_index(model: Model) -> int:
    """The index of the first tool step (``len(model.steps)`` without one); ValueError for a
    tool step elsewhere in the chain."""
    k = len(model.steps)
    while k and model.steps[k - 1].role is Role.TOOL and model.steps[k - 1].joint is None:
        k -= 1
    misplaced = [s.name for s in model.steps[:k] if s.role is Role.TOOL]
    if misplaced:
        raise ValueError(
            f"model {model.name!r}: tool step(s) {', '.join(misplaced)} before the robot's last step; "
            "the measured tool must be the chain's last steps"
        )
    return k


def split_tool(model: Model) -> FlangeTool:
    """``model`` split into the robot and the measured tool at its end: the trailing steps
    of role :attr:`~robocal.model.steps.Role.TOOL` without a joint.

    Raises:
        ValueError: a tool step elsewhere in the chain (before a robot step or a joint):
            it is neither the robot's geometry nor the tool at the flange.
    """
    k = _flange_index(model)
    if k == len(model.steps):
        return FlangeTool(model, ())
    return FlangeTool(dataclasses.replace(model, steps=model.steps[:k]), tuple(model.steps[k:]))
