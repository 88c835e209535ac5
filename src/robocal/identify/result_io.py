"""``result.json``: a :class:`~robocal.identify.result.CalibrationResult` written, read back
and saved as one transaction with its model files.

The file's layout is that of earlier robocal versions (the typed fields of the result are
written under their older ``metadata`` keys: ``warnings`` as texts, ``residuals_mm``,
``fit_to_noise``, ``cv``, ``provenance``, ``validation``...), so results saved by an
earlier robocal load, and a file that is not a result is refused with its path and the
field that is wrong.  Lengths in the file are in mm where the key says so, SI otherwise.

The learned residual's covariances (``(m, m)`` and ``(p, m)``: 166,000 + 23,000 numbers at 48
harmonics on 6 joints, 3.8 MB of JSON that took 0.26 s to write) are kept beside it in
:data:`RESIDUAL_COVARIANCE_FILE`, an ``.npz`` of float64 arrays (bit for bit what the fit
gave), named in ``result.json``'s ``residual_covariance_file`` with its SHA-256: a sidecar
that is missing, altered or from another run is refused by name.  Files written before it
(the covariances inline, ``residual_covariance_upper`` and ``residual_cross_covariance``
to 9 digits) load as they did.  Above :data:`RESIDUALS_INLINE_POSES` poses the per-pose
residuals go beside it too (:data:`RESIDUALS_FILE`: 1,000,000 poses were 61 MB of JSON).

This module does not import :mod:`robocal.identify.result` (which calls it): it reads and
writes a result's fields, and the result class builds itself from them.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import math
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from robocal.identify.effects import parameter_unit
from robocal.identify.noise_check import FitToNoise
from robocal.model.dynamics import Payload
from robocal.model.files import load_model, save_model
from robocal.model.rank import Dropped
from robocal.model.yaml_files import ModelFileError
from robocal.outdir import atomic_write_bytes, atomic_write_text
from robocal.safe_output import strict_json

if TYPE_CHECKING:
    from robocal.model.chain import Model

__all__ = [
    "RESIDUALS_FILE",
    "RESIDUALS_INLINE_POSES",
    "RESIDUAL_COVARIANCE_FILE",
    "RESULT_FILES",
    "ResultFileError",
    "file_hash",
    "load_result_fields",
    "metadata_dict",
    "read_residual_covariance",
    "read_residuals",
    "result_dict",
    "save_result",
]

Array = NDArray[np.float64]

#: the learned residual's covariances beside ``result.json`` (arrays ``covariance`` (m, m)
#: and ``cross_covariance`` (p, m), float64, ``numpy.savez``)
RESIDUAL_COVARIANCE_FILE = "residual_covariance.npz"
#: the per-pose residuals beside ``result.json`` (array ``residuals`` (n, rows), m and rad,
#: float64) when there are more than :data:`RESIDUALS_INLINE_POSES` poses
RESIDUALS_FILE = "residuals.npz"
#: up to this many poses the residuals are written inline (``residuals_mm``: about 35 bytes
#: of JSON a pose)
RESIDUALS_INLINE_POSES = 10_000

#: the files of a calibration result folder (written and replaced together)
RESULT_FILES = (
    "model.yaml",
    "measurement_model.yaml",
    "result.json",
    RESIDUAL_COVARIANCE_FILE,
    RESIDUALS_FILE,
    "report.html",
    "train.csv",
    "test.csv",
    "evaluation.json",
    "true_model.yaml",
)

#: keys of result.json that are fields of the result, or derived from them
_FIELDS = {
    "run_id", "robocal_version", "residual_cross_covariance", "residual_covariance_upper", "payload",
    "model", "rms_before_mm", "rms_after_mm", "residual_std_mm", "parameters", "high_correlations",
    "frame", "method", "measure", "n", "success", "message", "iterations", "seconds", "covariance",
    "dropped", "compliance_rad_per_Nm", "gravity", "condition_number",
    # the metadata keys of the typed fields
    "solve_seconds", "evaluations", "residuals_mm", "level", "outlier_poses", "effects", "at_bounds",
    "objective", "fit_to_noise", "warnings", "warning_codes", "cv", "residual_rms_after_mm",
    "load_passes", "provenance", "validation", "saved_run_id", "residual_covariance_file", "residuals_file",
}  # fmt: skip


class ResultFileError(ValueError):
    """A file of a result folder beside ``result.json`` is missing, altered or unreadable
    (the message names it)."""


def _version() -> str:
    from robocal._version import __version__

    return __version__


def file_hash(path: str | Path) -> str:
    """SHA-256 of a file (recorded in results so that a calibration can be traced)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def metadata_dict(result: Any, inline_residuals: bool = True) -> dict[str, Any]:
    """The result's diagnostics, warnings, provenance and records under their
    ``result.json`` keys (the older ``metadata`` dict; ``inline_residuals``: with the
    per-pose residuals, ``residuals_mm``)."""
    d = result.diagnostics
    out: dict[str, Any] = {"solve_seconds": d.solve_seconds, "evaluations": d.evaluations}
    if result.residuals is not None and inline_residuals:  # per pose, predicted minus measured (device frame)
        out["residuals_mm"] = np.round(np.asarray(result.residuals) * 1e3, 6).tolist()
    out |= {"level": d.level, "outlier_poses": list(d.outlier_poses), "effects": d.effects}
    if d.at_bounds is not None:
        out["at_bounds"] = list(d.at_bounds)
    if d.objective is not None:
        out["objective"] = dict(d.objective)
    if d.fit_to_noise is not None:
        out["fit_to_noise"] = d.fit_to_noise.to_dict()
    out["warnings"] = [w.message for w in result.warnings]
    out["warning_codes"] = [w.code for w in result.warnings]
    if d.load_passes is not None:
        out["load_passes"] = d.load_passes
    if d.cv is not None:
        out["cv"] = dict(d.cv)
    if d.residual_rms_after_mm is not None:
        out["residual_rms_after_mm"] = d.residual_rms_after_mm
    if d.streaming is not None:
        out["streaming"] = dict(d.streaming)
    out |= dict(result.records)
    if result.provenance is not None:
        out["provenance"] = result.provenance.to_dict()
    if result.validation is not None:
        out["validation"] = dict(result.validation)
    if result.run_id is not None:
        out["saved_run_id"] = result.run_id
    return out


def _payload_dict(payload: Payload) -> dict[str, Any]:
    out: dict[str, Any] = {"mass": payload.mass, "com": list(payload.com)}
    if payload.inertia is not None:
        out["inertia"] = list(payload.inertia)
    return out


def result_dict(
    result: Any, residual_file: dict[str, Any] | None = None, residuals_file: dict[str, Any] | None = None
) -> dict[str, Any]:
    """The content of ``result.json`` (JSON types; lengths in mm where a key says so).

    ``residual_file``: the reference to the learned residual's covariances written beside it
    (:func:`save_result`); None: those covariances inline (to 9 digits), as earlier files
    have them, so that the dict stands alone.  ``residuals_file``: the reference to the
    per-pose residuals written beside it; None: inline (``residuals_mm``)."""
    r = result
    rot = {s.name: s.is_rotation for s in (r.measurement_chain or r.model).steps}
    meta = metadata_dict(r, inline_residuals=residuals_file is None)
    if residuals_file is not None:
        meta["residuals_file"] = residuals_file
    meta.pop("saved_run_id", None)  # the file's run id is written by save_result
    return {
        "robocal_version": _version(),
        "model": r.model.name,
        "method": r.method,
        "measure": r.measure,
        "n": r.n,
        "success": r.success,
        "message": r.message,
        "iterations": r.iterations,
        "seconds": r.seconds,
        "rms_before_mm": r.rms_before * 1e3,
        "rms_after_mm": r.rms_after * 1e3,
        "residual_std_mm": r.residual_std * 1e3,
        "condition_number": r.condition_number,
        "frame": {"T_device_base": np.asarray(r.T_device_base).tolist()},
        "parameters": [
            {
                "name": n,
                "unit": parameter_unit(n, rot.get(n, False)),
                "nominal": float(v0),
                "estimate": float(v),
                "delta": float(v - v0),
                "std": float(s),
            }
            for n, v0, v, s in zip(r.names, r.nominal, r.estimates, r.std, strict=True)
        ],
        "covariance": np.asarray(r.covariance).tolist(),
        "dropped": [
            {
                "name": d.name,
                "reason": d.reason,
                "absorbed_by": [list(a) for a in d.absorbed_by],
                **({"sigma_mm": d.sigma * 1e3} if d.sigma is not None else {}),
                **({"detail": d.detail} if d.detail else {}),
            }
            for d in r.dropped
        ],
        "high_correlations": [list(c) for c in r.high_correlations],
        "compliance_rad_per_Nm": dict(r.compliance),
        "gravity": list(r.gravity),
        **({"payload": _payload_dict(r.payload)} if r.payload is not None else {}),
        **_residual_covariance_entries(r, residual_file),
        **meta,
    }


def _residual_covariance_entries(result: Any, residual_file: dict[str, Any] | None) -> dict[str, Any]:
    """``result.json``'s entries for the learned residual's covariances: the sidecar's
    reference, or (none given) the covariances inline; none without a residual."""
    learned = result.model.residual
    if result.residual_cross_covariance is None or learned is None:
        return {}
    if residual_file is not None:
        return {"residual_covariance_file": residual_file}
    return {
        "residual_covariance_upper": learned.covariance_upper(),
        "residual_cross_covariance": [
            [float(f"{v:.9g}") for v in row] for row in result.residual_cross_covariance
        ],
    }


def _write_residual_covariance(result: Any, folder: Path) -> dict[str, Any] | None:
    """Write the learned residual's covariances to ``folder``/:data:`RESIDUAL_COVARIANCE_FILE`
    (float64, exact) and return ``result.json``'s reference to it (name, SHA-256 of its
    bytes, shapes); None (and no file) without a residual."""
    learned = result.model.residual
    cross = result.residual_cross_covariance
    if cross is None or learned is None:
        return None
    arrays = {
        "covariance": np.ascontiguousarray(learned.covariance, dtype=np.float64),
        "cross_covariance": np.ascontiguousarray(cross, dtype=np.float64),
    }
    buffer = io.BytesIO()
    # uncompressed (random digits do not shrink); float arrays are never pickled (and numpy
    # 1.26 would store an allow_pickle keyword as an array)
    np.savez(buffer, covariance=arrays["covariance"], cross_covariance=arrays["cross_covariance"])
    data = buffer.getvalue()
    atomic_write_bytes(folder / RESIDUAL_COVARIANCE_FILE, data)
    return {
        "name": RESIDUAL_COVARIANCE_FILE,
        "sha256": hashlib.sha256(data).hexdigest(),
        **{f"{key}_shape": list(a.shape) for key, a in arrays.items()},
    }


def _write_residuals(result: Any, folder: Path) -> dict[str, Any] | None:
    """Write the per-pose residuals to ``folder``/:data:`RESIDUALS_FILE` (float64, exact)
    when there are more than :data:`RESIDUALS_INLINE_POSES` poses, and return
    ``result.json``'s reference to it (name, SHA-256, shape); None (and no file) otherwise."""
    if result.residuals is None or len(result.residuals) <= RESIDUALS_INLINE_POSES:
        return None
    residuals = np.ascontiguousarray(result.residuals, dtype=np.float64)
    buffer = io.BytesIO()
    np.savez(buffer, residuals=residuals)  # uncompressed, never pickled (as the covariances')
    data = buffer.getvalue()
    atomic_write_bytes(folder / RESIDUALS_FILE, data)
    return {
        "name": RESIDUALS_FILE,
        "sha256": hashlib.sha256(data).hexdigest(),
        "shape": list(residuals.shape),
    }


def save_result(result: Any, directory: str | Path, also: Callable[[Path], object] | None = None) -> str:
    """:meth:`CalibrationResult.save`: the files as one transaction; returns their run id."""
    from robocal.outdir import transaction

    with transaction(directory, RESULT_FILES) as stage:
        save_model(result.model, stage.path / "model.yaml", run_id=stage.run_id)
        if result.measurement_chain is not None:
            save_model(result.measurement_chain, stage.path / "measurement_model.yaml", run_id=stage.run_id)
        # the model file's digest: an export refuses a model.yaml edited after the calibration
        digest = {"model_sha256": file_hash(stage.path / "model.yaml")}
        residual_file = _write_residual_covariance(result, stage.path)
        residuals_file = _write_residuals(result, stage.path)
        content = result_dict(result, residual_file, residuals_file) | {"run_id": stage.run_id} | digest
        text = strict_json(content, indent=2) + "\n"
        atomic_write_text(stage.path / "result.json", text)
        if also is not None:
            also(stage.path)
    return stage.run_id


def load_result_fields(directory: str | Path) -> dict[str, Any]:
    """:meth:`CalibrationResult.load`: the result's fields read from ``directory`` (its
    ``warnings`` as ``(code, message)`` pairs and its ``diagnostics`` as keywords)."""
    from robocal.run_ids import check_consistent

    directory = Path(directory)
    path = directory / "result.json"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError as err:
        raise ValueError(f"{path}: not UTF-8 text (byte {err.start})") from None
    except json.JSONDecodeError as err:
        raise ValueError(
            f"{path}: not valid JSON (line {err.lineno}, column {err.colno}: {err.msg})"
        ) from None
    except RecursionError:
        raise ValueError(f"{path}: nested too deeply to be a calibration result") from None
    if not isinstance(data, dict):
        raise ValueError(
            f"{path}: not a calibration result (a JSON object expected, got {type(data).__name__})"
        )
    # not train.csv, test.csv or evaluation.json: a user may put their own there for `report`
    check_consistent(directory, ("model.yaml", "measurement_model.yaml", "report.html"))
    if not (directory / "model.yaml").is_file():
        raise ValueError(f"{directory}: model.yaml is missing beside result.json; calibrate again")
    try:
        return _from_dict(directory, data)
    except (KeyError, TypeError, ValueError, IndexError, AttributeError) as err:
        if isinstance(err, ModelFileError | ResultFileError):
            raise
        what = f"missing field {err.args[0]!r}" if isinstance(err, KeyError) else str(err)
        raise ValueError(f"{path}: not a calibration result written by robocal ({what})") from None


def _warnings(data: dict[str, Any]) -> tuple[tuple[str, str], ...]:
    texts = [str(w) for w in data.get("warnings", [])]
    codes = data.get("warning_codes")
    if not isinstance(codes, list) or len(codes) != len(texts):  # an older file: no codes
        codes = ["unknown"] * len(texts)
    return tuple((str(c), t) for c, t in zip(codes, texts, strict=True))


def _diagnostics(data: dict[str, Any]) -> dict[str, Any]:
    noise = data.get("fit_to_noise")
    at_bounds = data.get("at_bounds")
    passes = data.get("load_passes")
    rms = data.get("residual_rms_after_mm")
    return dict(
        solve_seconds=float(data.get("solve_seconds", 0.0)),
        evaluations=int(data.get("evaluations", 0)),
        level=int(data.get("level", 2)),
        effects=str(data.get("effects", "none")),
        load_passes=None if passes is None else int(passes),
        outlier_poses=tuple(int(i) for i in data.get("outlier_poses", [])),
        fit_to_noise=None if noise is None else FitToNoise.from_dict(noise),
        cv=data.get("cv"),
        residual_rms_after_mm=None if rms is None else float(rms),
        at_bounds=None if at_bounds is None else tuple(at_bounds),
        objective=data.get("objective"),
        streaming=data.get("streaming"),
    )


def _from_dict(directory: Path, data: dict[str, Any]) -> dict[str, Any]:
    from robocal.identify.provenance import Provenance

    model = load_model(directory / "model.yaml")
    chain_path = directory / "measurement_model.yaml"
    params = data["parameters"]
    cov = np.array(data["covariance"], dtype=float).reshape(len(params), len(params))
    std = np.array([p["std"] for p in params], dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.outer(std, std)
    model, cross = _residual_covariances(directory, data, model, len(params))
    residuals = data.get("residuals_mm")  # mm inline, or (m, exact) beside result.json
    residuals = None if residuals is None else np.array(residuals, dtype=float) / 1e3
    if "residuals_file" in data:
        residuals = read_residuals(directory, data["residuals_file"], int(data["n"]))
    return dict(
        model=model,
        T_device_base=np.array(data["frame"]["T_device_base"], dtype=float).reshape(4, 4),
        measure=data["measure"],
        method=data["method"],
        names=tuple(p["name"] for p in params),
        estimates=np.array([p["estimate"] for p in params], dtype=float),
        nominal=np.array([p["nominal"] for p in params], dtype=float),
        std=std,
        covariance=cov,
        correlation=corr,
        dropped=tuple(
            Dropped(
                d["name"],
                d["reason"],
                tuple(tuple(a) for a in d["absorbed_by"]),
                sigma=d["sigma_mm"] / 1e3 if "sigma_mm" in d else None,
                detail=d.get("detail", ""),
            )
            for d in data["dropped"]
        ),
        residual_std=data["residual_std_mm"] / 1e3,
        rms_before=data["rms_before_mm"] / 1e3,
        rms_after=data["rms_after_mm"] / 1e3,
        condition_number=math.inf if data["condition_number"] is None else float(data["condition_number"]),
        n=data["n"],
        success=data["success"],
        message=data["message"],
        iterations=data["iterations"],
        seconds=data["seconds"],
        measurement_chain=load_model(chain_path) if chain_path.exists() else None,
        compliance=dict(data.get("compliance_rad_per_Nm", {})),
        gravity=tuple(data.get("gravity", (0.0, 0.0, -9.81))),
        payload=Payload(**data["payload"]) if data.get("payload") else None,
        residual_cross_covariance=cross,
        residuals=residuals,
        warnings=_warnings(data),
        diagnostics=_diagnostics(data),
        provenance=Provenance.from_metadata(data),
        validation=data.get("validation"),
        records={k: v for k, v in data.items() if k not in _FIELDS},
        run_id=data.get("run_id"),
    )


def _residual_covariances(
    directory: Path, data: dict[str, Any], model: Model, p: int
) -> tuple[Model, Array | None]:
    """The model with its learned residual's covariance, and the ``(p, m)`` cross-covariance
    with the parameters: from the sidecar ``result.json`` names, or (a file written before
    it) from ``result.json`` itself; ``(model, None)`` without them."""
    learned = model.residual
    if learned is None:
        return model, None
    entry = data.get("residual_covariance_file")
    if entry is None:  # the older layout: both inline
        upper, cross = data.get("residual_covariance_upper"), data.get("residual_cross_covariance")
        if upper is not None:
            model = dataclasses.replace(model, residual=learned.with_covariance_upper(upper))
        return model, None if cross is None else np.array(cross, dtype=float)
    covariance, cross = read_residual_covariance(directory, entry, learned.size, p)
    return dataclasses.replace(model, residual=dataclasses.replace(learned, covariance=covariance)), cross


def read_residual_covariance(directory: Path, entry: dict[str, Any], m: int, p: int) -> tuple[Array, Array]:
    """The ``(m, m)`` covariance and ``(p, m)`` cross-covariance in the sidecar that
    ``result.json``'s ``residual_covariance_file`` ``entry`` names, checked against its
    SHA-256 and shapes; :class:`ResultFileError` naming the file otherwise."""
    raw = _sidecar_bytes(directory, entry, RESIDUAL_COVARIANCE_FILE, "residual_covariance_file")
    path = directory / RESIDUAL_COVARIANCE_FILE
    try:
        with np.load(io.BytesIO(raw), allow_pickle=False) as arrays:
            covariance, cross = arrays["covariance"], arrays["cross_covariance"]
    except (OSError, ValueError, KeyError, zipfile.BadZipFile) as err:
        raise ResultFileError(f"{path}: not robocal's residual covariances ({err})") from None
    for name, a, shape in (("covariance", covariance, (m, m)), ("cross_covariance", cross, (p, m))):
        if a.dtype != np.float64 or a.shape != shape:
            raise ResultFileError(f"{path}: {name} is {a.dtype} {a.shape}, the result needs float64 {shape}")
    return covariance, cross


def _sidecar_bytes(directory: Path, entry: Any, name: str, key: str) -> bytes:
    """The bytes of the file ``name`` beside ``result.json`` that its ``key`` ``entry``
    names, checked against the SHA-256 it records; :class:`ResultFileError` naming the file
    otherwise."""
    if not isinstance(entry, dict) or entry.get("name") != name:
        raise ResultFileError(f"{directory / 'result.json'}: {key} must name {name}")
    path = directory / name
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise ResultFileError(f"{path}: missing beside result.json; calibrate again") from None
    except OSError as err:
        raise ResultFileError(f"{path}: cannot be read ({err.strerror})") from None
    if hashlib.sha256(raw).hexdigest() != entry.get("sha256"):
        raise ResultFileError(
            f"{path}: not the file result.json was saved with (its SHA-256 differs); calibrate again"
        )
    return raw


def read_residuals(directory: Path, entry: dict[str, Any], n: int) -> Array:
    """The ``(n, rows)`` per-pose residuals (m, rad) in the sidecar that ``result.json``'s
    ``residuals_file`` ``entry`` names, checked against its SHA-256 and ``n`` poses;
    :class:`ResultFileError` naming the file otherwise."""
    raw = _sidecar_bytes(directory, entry, RESIDUALS_FILE, "residuals_file")
    path = directory / RESIDUALS_FILE
    try:
        with np.load(io.BytesIO(raw), allow_pickle=False) as arrays:
            r = arrays["residuals"]
    except (OSError, ValueError, KeyError, zipfile.BadZipFile) as err:
        raise ResultFileError(f"{path}: not robocal's per-pose residuals ({err})") from None
    if r.dtype != np.float64 or r.ndim != 2 or r.shape[0] != n or r.shape[1] not in (3, 6):
        raise ResultFileError(
            f"{path}: residuals are {r.dtype} {r.shape}, the result needs float64 ({n}, 3|6)"
        )
    return r
