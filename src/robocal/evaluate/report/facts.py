"""The one place the report reads a calibration result's data.

Everything the report shows about the result itself is read by
:func:`report_data_from_result` from the frozen result's typed fields (``warnings``,
``diagnostics.fit_to_noise`` and ``diagnostics.cv``, ``validation``, ``run_id`` and the
``records`` ``data_file``, ``data_sha256``, ``train_n``, ``seed``, ``source``) into a
frozen :class:`~robocal.evaluate.report.data.ResultFacts`.  The report still *computes*
with the result object (``validate``, ``predict``, ``joint_perturbations``); those are
methods, not stored data.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from robocal.evaluate.report.data import ResultFacts
from robocal.identify.result import CalibrationResult
from robocal.identify.validate import ValidationStats
from robocal.measure.measurements import Measurements
from robocal.model.chain import Model

__all__ = ["before_validation", "report_data_from_result", "start_chain"]

#: result.records keys shown under provenance as the calibration's input, with their labels
INPUT_KEYS: tuple[tuple[str, str], ...] = (
    ("data_file", "data file"),
    ("data_sha256", "data SHA-256"),
    ("train_n", "train n"),
)
INPUT_KEYS += (("seed", "seed"), ("source", "source"))


def _effect_estimates(result: CalibrationResult) -> dict[str, dict[str, tuple[float, float | None]]]:
    """``CalibrationResult.effect_estimates()``, {} for a result of another robocal version."""
    method = getattr(result, "effect_estimates", None)
    if method is None:
        return {}
    try:
        return dict(method() or {})
    except (AttributeError, KeyError, ImportError, ValueError):
        return {}


def _cv_table(result: CalibrationResult) -> Any | None:
    try:
        return result.diagnostics.cv_table()
    except (KeyError, TypeError, ValueError):  # written by another robocal version
        return None


def _inputs(records: Mapping[str, Any]) -> tuple[tuple[str, str], ...]:
    return tuple((label, str(records[key])) for key, label in INPUT_KEYS if records.get(key) is not None)


def report_data_from_result(result: CalibrationResult) -> ResultFacts:
    """The result's data the report shows, read once (see the module docstring for the
    fields)."""
    from robocal.run_ids import is_run_id

    noise = result.fit_to_noise
    stored = result.validation
    run_id = result.run_id  # set by save() and load()
    return ResultFacts(
        model=result.model,
        measurement_chain=result.measurement_chain,
        T_device_base=np.asarray(result.T_device_base, dtype=float),
        measure=str(result.measure),
        method=str(result.method),
        converged=bool(result.success),
        message=str(result.message),
        n=int(result.n),
        iterations=int(result.iterations),
        seconds=float(result.seconds),
        residual_std_m=float(result.residual_std),
        rms_before_m=float(result.rms_before),
        rms_after_m=float(result.rms_after),
        condition_number=float(result.condition_number),
        names=tuple(result.names),
        nominal=np.asarray(result.nominal, dtype=float),
        estimates=np.asarray(result.estimates, dtype=float),
        std=np.asarray(result.std, dtype=float),
        dropped=tuple(result.dropped),
        correlations=tuple(result.high_correlations),
        compliance=dict(result.compliance),
        effects=_effect_estimates(result),
        fit_to_noise=None if noise is None else noise.summary(),
        warnings=tuple(result.warning_texts),
        cv=_cv_table(result),
        stored_validation=stored if isinstance(stored, Mapping) and "n" in stored else None,
        inputs=_inputs(result.records),
        run_id=run_id if is_run_id(run_id) else None,
    )


def start_chain_of(facts: ResultFacts) -> Model | None:
    chain = facts.measurement_chain
    if chain is None:
        return None
    names = set(chain.names)
    return chain.with_values(
        {n: float(v) for n, v in zip(facts.names, facts.nominal, strict=True) if n in names}
    )


def start_chain(result: CalibrationResult) -> Model | None:
    """The measurement chain at the identification's start values: the nominal robot
    with the device frame and the tool fitted in closed form (None for results saved
    without their measurement chain)."""
    return start_chain_of(report_data_from_result(result))


def start_validation(facts: ResultFacts, data: Measurements) -> ValidationStats | None:
    """Errors of the start model (nominal robot, fitted frame and tool) on ``data``."""
    from robocal.identify.validate import validation_statistics

    chain = start_chain_of(facts)
    if chain is None or data.position is None or data.dof != facts.model.dof:
        return None
    return validation_statistics(chain.fk(data.q), data, "start fit")


def before_validation(result: CalibrationResult, data: Measurements) -> ValidationStats | None:
    """Errors of the start model (nominal robot, fitted frame and tool) on ``data``."""
    return start_validation(report_data_from_result(result), data)
