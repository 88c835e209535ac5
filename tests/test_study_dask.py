"""Studies on Dask: the study file's scheduler address, robocal's local cluster, a fleet of
10,000 virtual robots through a ``distributed.Client`` (slow)."""

from __future__ import annotations

import csv
import logging
import sys
from pathlib import Path

import pytest
import yaml

from robocal import study
from robocal.study import StudyConfig, StudyError, run_study

ROOT = Path(__file__).resolve().parents[1]


def _config(**changes) -> StudyConfig:
    base = dict(
        name="t",
        robot="ur10",
        robots=3,
        seed=3,
        tool=(0.0, 0.0, 109.0),
        pose_sets=[{"name": "r30", "kind": "random", "n": 30}],
        devices=[{"name": "t20", "kind": "laser-tracker", "noise": "0.02mm"}],
        validation={"n": 40},
        chunk=2,
    )
    base.update(changes)
    return StudyConfig.model_validate(base)


def _rows(path: Path) -> dict[str, dict[str, str]]:
    with open(path, newline="") as fh:
        return {r["case"]: r for r in csv.DictReader(fh)}


def test_the_study_file_points_the_study_at_a_scheduler(tmp_path):
    """``dask: {scheduler: ADDRESS}`` in the study file, named by the call: the study runs on
    that cluster's workers (here an in-process cluster), with the rows of a run in this
    process; the address is not part of the study's identity (the same study resumes
    wherever it runs)."""
    from distributed import LocalCluster

    reference = _rows(run_study(_config(), tmp_path / "ref", workers=0).out / "results.csv")
    with LocalCluster(n_workers=1, processes=False, dashboard_address=None, silence_logs=logging.ERROR) as c:
        doc = _config(dask={"scheduler": c.scheduler_address}).model_dump(mode="json")
        path = tmp_path / "study.yaml"
        path.write_text(yaml.safe_dump(doc))
        # the command line names the file's scheduler (a study file alone never connects)
        run = run_study(study.load_study_config(path), tmp_path / "dask", scheduler=c.scheduler_address)
        assert run.workers == 1 and run.computed == 3
    rows = _rows(tmp_path / "dask" / "results.csv")
    assert rows.keys() == reference.keys()
    for key, row in rows.items():
        assert float(row["true_rms_mm"]) == pytest.approx(float(reference[key]["true_rms_mm"]), rel=1e-9)
    again = run_study(_config(robots=3), tmp_path / "dask", workers=0)  # no dask section: same study
    assert again.resumed == 3 and again.computed == 0


@pytest.mark.parametrize(
    ("dask", "message"),
    [
        ({"scheduler": "not an address"}, "dask.scheduler"),
        ({"scheduler": "tcp://h:1", "nodes": 3}, "dask.nodes"),
        ({"workers": -1}, "dask.workers"),
    ],
)
def test_bad_dask_sections_name_the_field(tmp_path, dask, message):
    doc = _config().model_dump(mode="json")
    doc["dask"] = dask
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(doc))
    with pytest.raises(StudyError, match=message):
        study.load_study_config(path)


@pytest.mark.slow
def test_a_fleet_of_10000_virtual_robots_through_a_dask_client(tmp_path):
    """10,000 virtual UR10s calibrated and validated on a two-worker cluster through a
    ``distributed.Client`` (benchmarks/bench_fleet.py), the progress bar fed to the end."""
    from distributed import Client

    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_fleet import calibrate_fleet

    seen: list[tuple[int, int]] = []
    with study.local_cluster(2) as cluster, Client(cluster) as client:
        run = calibrate_fleet(client, 10_000, tmp_path / "fleet", on_progress=lambda *d: seen.append(d))
    assert seen[-1] == (10_000, 10_000) and len(seen) == 200  # one update per task of 50 robots
    assert run.workers == 2 and run.computed == 10_000 and run.errors == 0
    group = run.summary["groups"][0]
    assert group["ok"] + group["not_converged"] + group["failed"] == 10_000 and group["ok"] >= 9_900
    assert 0.005 < group["true_rms_mm"]["mean"] < 0.05  # 20 µm tracker, 50 poses
    assert len(_rows(tmp_path / "fleet" / "results.csv")) == 10_000
