"""The arm's scale when no length was measured (issue 33).

Fixed points and unknown planes do not see the robot's size: the robot, its tool and the
scene scaled together fit them as well.  The rank test must then hold one length at its
nominal value, and that value sets the scale of everything else.  Which one matters: a
length's error relative to its size is the scale's error.  The ball's offset on the flange
(~0.1 m, nominal from a drawing) made a simulated UR10 0.43 % large, 3.9 mm off a held-out
tracker file (nominal robot: 1.05 mm); the longest link (0.61 m, machined) carries the same
absolute error as a 6x smaller relative one.  So the longest free robot length is tested
last (held when the scale is the only thing it shares), and the summary says so.
"""

from __future__ import annotations

from robocal.measure.constraints.data_set import ConstraintSet
from robocal.model.chain import Model

__all__ = ["no_length_measured", "scale_anchor", "scale_note"]


def no_length_measured(data: ConstraintSet) -> bool:
    """Whether ``data`` has position-like rows but nothing that measures a length (a known
    distance between points, a ball-bar pair, a tracker row, a stated plane)."""
    measured = len(data.point_pairs) or len(data.pairs) or data.tracked.any()
    stated = any(not data.unknown_plane(k) for k in range(data.n_planes))
    return bool(data.constrained.any()) and not measured and not stated


def scale_anchor(model: Model, data: ConstraintSet) -> str | None:
    """The free robot length to hold for the scale (the longest by nominal value), or None
    when a length was measured or the model frees none."""
    if not no_length_measured(data):
        return None
    lengths = [
        (abs(s.value), s.name)
        for s in model.steps
        if s.free and not s.is_rotation and not s.name.startswith(("base_", "tool_", "tcp_"))
    ]
    return max(lengths)[1] if lengths else None


def scale_note(anchor: str, held: bool) -> str:
    """The summary's sentence on the scale, ``held``: whether the rank test held ``anchor``."""
    rests = f"it rests on the nominal {anchor}" if held else "it rests on the nominal lengths held"
    return (
        "no length was measured (no known distance, ball-bar pair, tracker row or stated plane): the "
        f"arm's overall scale is not calibrated, {rests}; state a distance between two points "
        "(--distance 0,1=50mm) to calibrate it"
    )
