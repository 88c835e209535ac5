"""Where a calibration's data came from, so that it can be read again exactly.

``robocal calibrate`` records in ``result.json`` (``metadata["provenance"]``) the data file
(absolute path and SHA-256), the reader options it was read with, the stated noise, the
train/test split (``--train-n`` and its seed, or the file's ``set`` column) and the
versions.  ``robocal validate DIR`` and ``robocal report DIR`` then re-read the
calibration's own data with its own options and split: the training rows are labelled as
calibration poses and only the held-out rows are used as held-out ones.
"""

from __future__ import annotations

import dataclasses
import platform
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from robocal.measure.measurements import Measurements

__all__ = ["READER_DEFAULTS", "Provenance", "SplitRows", "split_rows"]

#: the reader options the CLI records, with their defaults (units as in the file)
READER_DEFAULTS: dict[str, Any] = {
    "length_unit": "m",
    "angle_unit": "rad",
    "columns": None,
    "sep": None,
    "decimal": ".",
    "orientation": "auto",
    "limits": "error",
    "incomplete": "error",
}


@dataclass(frozen=True)
class Provenance:
    """A calibration's input, recorded to read it again.

    Attributes:
        data_file: absolute path of the measurement file.
        data_sha256: its SHA-256 when calibrated.
        reader: the reader options (:data:`READER_DEFAULTS`' keys).
        noise_m: the stated 1-σ position noise per axis (m) given for a file without sigma
            columns (``--noise``), or None.
        train_n, seed: ``--train-n`` and its seed (the split is ``data.with_split``), or
            None when the file's own ``set`` column split it or every row was used.
        versions: robocal, numpy and Python versions.
    """

    data_file: str
    data_sha256: str
    reader: dict[str, Any]
    noise_m: float | None = None
    train_n: int | None = None
    seed: int = 0
    versions: dict[str, str] = dataclasses.field(default_factory=dict)

    @classmethod
    def record(
        cls,
        path: Path,
        sha256: str,
        reader: dict[str, Any],
        noise_m: float | None,
        train_n: int | None,
        seed: int,
    ) -> Provenance:
        from robocal._version import __version__

        versions = {"robocal": __version__, "numpy": np.__version__, "python": platform.python_version()}
        options = {k: reader.get(k, v) for k, v in READER_DEFAULTS.items()}
        return cls(str(Path(path).resolve()), sha256, options, noise_m, train_n, seed, versions)

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_metadata(cls, metadata: dict[str, Any]) -> Provenance | None:
        """The provenance a result recorded, or None (saved by an older robocal, or by the
        library without the CLI)."""
        d = metadata.get("provenance")
        if not isinstance(d, dict):
            return None
        try:
            reader = {k: d["reader"].get(k, v) for k, v in READER_DEFAULTS.items()}
            noise = d.get("noise_m")
            train_n = d.get("train_n")
            return cls(
                data_file=str(d["data_file"]),
                data_sha256=str(d["data_sha256"]),
                reader=reader,
                noise_m=None if noise is None else float(noise),
                train_n=None if train_n is None else int(train_n),
                seed=int(d.get("seed", 0)),
                versions={str(k): str(v) for k, v in dict(d.get("versions", {})).items()},
            )
        except (KeyError, TypeError, ValueError, AttributeError):
            return None


@dataclass(frozen=True)
class SplitRows:
    """A calibration's data, split as it was calibrated.

    Attributes:
        train: the rows the calibration used.
        test: the held-out rows, or None when every row was used.
        how: a short phrase for notes, e.g. ``"--train-n 100 (seed 0)"``.
        every: every row of the file.
    """

    train: Measurements
    test: Measurements | None
    how: str
    every: Measurements


def split_rows(data: Measurements, provenance: Provenance) -> SplitRows:
    """``data`` (the calibration's own file, read with its options) split into the rows the
    calibration used and the held-out rest, as the calibration did."""
    if provenance.noise_m is not None and data.sigma is None:
        data = dataclasses.replace(data, sigma=np.full((data.n, 3), provenance.noise_m))
    if provenance.train_n is not None:
        if not 0 < provenance.train_n < data.n:
            raise ValueError(
                f"the calibration drew {provenance.train_n} training rows but the file now has {data.n}"
            )
        split = data.with_split(provenance.train_n, seed=provenance.seed)
        how = f"--train-n {provenance.train_n} (seed {provenance.seed})"
        return SplitRows(split.split_rows("train"), split.split_rows("test"), how, data)
    if data.split is not None and "test" in set(data.split.tolist()):
        return SplitRows(data.split_rows("train"), data.split_rows("test"), "the file's set column", data)
    return SplitRows(data, None, "every row", data)
