"""What :func:`robocal.workflow.calibrate_file` is asked (:class:`CalibrateRequest`) and what
it answers (:class:`SavedRun`), as frozen values; the stages it reports (:data:`STAGES`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

from robocal.measure.dataset.options import ReaderOptions

if TYPE_CHECKING:
    from robocal.identify.provenance import Provenance
    from robocal.identify.result import CalibrationResult
    from robocal.identify.validate import ValidationStats
    from robocal.measure.measurements import Measurements
    from robocal.model.chain import Model

__all__ = [
    "STAGES",
    "CalibrateFileError",
    "CalibrateRequest",
    "FitOptions",
    "Iteration",
    "Notify",
    "Progress",
    "SavedRun",
]

#: ``progress(stage, fraction)``: the stage a run enters (a key of :data:`STAGES`) and the share
#: of the whole run done when it starts (0 to 1); inside ``calibrate`` again with the engine's
#: share of the fit (:func:`robocal.calibrate`'s ``progress``), up to the next stage's start
Progress = Callable[[str, float], None]

#: ``iteration(evaluations, rms_m)``: a streamed fit's LM (above 50,000 poses, where each pass
#: over the poses takes seconds) after each pass: the passes so far and the RMS of the weighted
#: residuals at the best point (m for unit weights); :func:`robocal.calibrate`'s ``iteration``
Iteration = Callable[[int, float], None]

#: ``notify(kind, text)``: a line for the user as it arises. ``kind``: ``model`` (the model
#: calibrated, before the fit), ``warning`` (a reader's warning), ``dropped`` (rows the reader
#: left out)
Notify = Callable[[str, str], None]

#: The stages of a run in order: key, what the user reads, share of the run done at its start.
STAGES: tuple[tuple[str, str, float], ...] = (
    ("read", "reading the measurements", 0.0),
    ("calibrate", "calibrating", 0.05),
    ("validate", "validating on the held-out poses", 0.80),
    ("save", "saving the result", 0.88),
    ("report", "writing the HTML report", 0.92),
)


class CalibrateFileError(ValueError):
    """A request that cannot be carried out, in one line.

    Attributes:
        field: the request's field at fault (``data``, ``out``, ``noise_m``, ``train_n``,
            ``model``), so that a front end can name its own control or option.
        problem: what is wrong, without the field's name (the file's messages name the file).
    """

    def __init__(self, field: str, problem: str, subject: str | None = None) -> None:
        self.field = field
        self.problem = problem
        super().__init__(problem if subject is None else f"{subject}: {problem}")


@dataclass(frozen=True)
class FitOptions:
    """The calibration's settings (keywords of :func:`robocal.calibrate`).

    ``tool_guess_m``: start value of the measured point on the flange (m, 3) or None;
    ``more``: further keywords of :func:`robocal.calibrate` (``max_std``...), read-only."""

    method: str = "lm"
    measure: str | None = None
    residual: str = "none"
    compliance: bool = False
    level: str | None = None
    loss: str = "linear"
    effects: str | tuple[str, ...] | None = None
    bounds: str | None = None
    per_pose: bool = False
    tool_guess_m: tuple[float, ...] | None = None  # (x, y, z)
    more: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))

    @classmethod
    def from_kwargs(cls, options: Mapping[str, Any]) -> FitOptions:
        """Options from keywords of :func:`robocal.calibrate` (``tool_guess`` in m)."""
        names = {f.name for f in dataclasses.fields(cls)} - {"more", "tool_guess_m"}
        known = {k: v for k, v in options.items() if k in names}
        more = {k: v for k, v in options.items() if k not in names and k != "tool_guess"}
        tool = options.get("tool_guess")
        guess = None if tool is None else tuple(float(v) for v in tool)
        return cls(**known, tool_guess_m=guess, more=MappingProxyType(more))

    def as_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`robocal.calibrate`: the method and every setting that
        differs from its default (the call is that of a caller who gave only those)."""
        import numpy as np

        kwargs: dict[str, Any] = {"method": self.method}
        defaults = FitOptions()
        for name in ("measure", "residual", "compliance", "level", "loss", "bounds", "per_pose"):
            if getattr(self, name) != getattr(defaults, name):
                kwargs[name] = getattr(self, name)
        if self.effects is not None:
            kwargs["effects"] = list(self.effects) if isinstance(self.effects, tuple) else self.effects
        if self.tool_guess_m is not None:
            kwargs["tool_guess"] = np.asarray(self.tool_guess_m, dtype=float)
        return kwargs | dict(self.more)


@dataclass(frozen=True)
class CalibrateRequest:
    """Calibrate one measurement file into a folder.

    Attributes:
        data: the measurement CSV.
        model: the robot model to start from.
        out: the folder for ``model.yaml``, ``measurement_model.yaml`` and ``result.json``
            (and ``report.html``); None: the result is returned, not saved (a fleet saves
            its results where its table is).
        reader: the reader's options.
        fit: the calibration's settings.
        chain: ``complete`` (the complete model built from ``model``'s joint geometry),
            ``catalog`` or None: the complete model for a catalog robot (``from_catalog``),
            ``model``'s own chain otherwise.
        from_catalog: ``model`` is a catalog robot's (not a model file's).
        noise_m: the device's position noise, 1σ per axis (m), for a file without sigma
            columns; None: none stated.
        train_n: calibrate on this many random rows and validate on the rest (drawn with
            ``seed``); None: the file's ``set`` column splits it, else every row calibrates.
        seed: seed of the ``train_n`` draw.
        report: also write ``report.html``.
        force: replace a result already in ``out``.
        progress: called as each stage starts (:data:`Progress`), or None.
        notify: lines for the user as they arise (:data:`Notify`), or None.
        iteration: the engine's LM passes as they end (:data:`Iteration`), or None.
    """

    data: Path
    model: Model
    out: Path | None
    reader: ReaderOptions = field(default_factory=ReaderOptions)
    fit: FitOptions = FitOptions()
    chain: str | None = None
    from_catalog: bool = False
    noise_m: float | None = None
    train_n: int | None = None
    seed: int = 0
    report: bool = False
    force: bool = False
    progress: Progress | None = field(default=None, compare=False)
    notify: Notify | None = field(default=None, compare=False)
    iteration: Iteration | None = field(default=None, compare=False)


@dataclass(frozen=True)
class SavedRun:
    """A calibrated file: where it was saved and what it gave.

    Attributes:
        folder: the result's folder (None when the request had no ``out``).
        result: the calibration result as saved (validation and provenance in it).
        validation: the held-out statistics (position errors in m), or None without held-out rows.
        provenance: the data file, its hash, the reader options, the noise and the split.
        train: the calibration rows; test: the held-out rows (or None).
    """

    folder: Path | None
    result: CalibrationResult
    validation: ValidationStats | None
    provenance: Provenance
    train: Measurements
    test: Measurements | None
