"""Accuracy on the real UR10 (series A): physical models, the learned residual and GP peers.

Data: ``../shared/data/ur10_laser_tracker/measurements_grid.csv`` (11,911 poses, Leica
laser tracker, T-Mac probe about 109 mm from the flange; see its README).  For each
training size (100, 300, 1,000 random rows) and seed (0-4) every model is calibrated on
the training rows only and validated on all the other rows (10,910-11,810 held-out
poses).  Models:

* plain DH            — the catalog's DH chain (``rc.robot("ur10")``), geometry only;
* complete            — seed 000's complete model (``rc.calibration_model``), geometry only;
* complete + compliance — plus joint compliance under gravity (catalog masses);
* robocal default     — what ``robocal calibrate ur10`` does: k-fold
  cross-validation on the training rows chooses among the above physics and the learned
  per-joint angle errors (``residual="auto"``);
* + GP (ARD, exact)   — peer: complete + compliance, then a Gaussian process on the
  position residual (base frame) with an ARD Matérn-3/2 kernel on (sin q, cos q) of all
  six joints, hyperparameters by marginal likelihood (scikit-learn);
* + GP (sparse, 300)  — the same with 300 inducing points (subset of regressors; the
  hyperparameters from a 300-pose subset): the form that scales to thousands of poses.

Per pose, the default is also compared with *physics alone*: the physics-only calibration
the default stores with it (``result.json``'s ``physics_only``, what a URDF export carries;
the default itself when CV chose no residual), on the same held-out poses: the share of
held-out poses the default predicts worse, the largest increase and the change at the 95th
percentile of the per-pose changes (``--tail`` prints only the default and this table, the
figures of docs/concepts/residual.md).  ``--cv-grid 8,16,24,32,48,64`` prints only the
cross-validation errors on the training rows per number of harmonics (the evidence for
the default's grid).

``--pose`` adds the default path calibrated on pose data (the probe's measured
orientation, XYZ Euler degrees, in the identification) to show whether orientation
helps; ``--probe`` only prints which joints the physics' remaining error follows.
Times are the fit on this machine (BLAS single-threaded); the held-out columns
are means over the seeds.  Run: ``python benchmarks/bench_real_accuracy.py [--seeds 5]
[--sizes 100,300,1000] [--no-gp] [--pose] [--tail]`` (about 5 minutes with the GP peers).
"""

from __future__ import annotations

import argparse
import os
import platform
import time
import warnings
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small matrices: threads only add noise
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

import robocal as rc

ROOT = Path(__file__).resolve().parents[1]
DATA = ROOT.parent / "shared" / "data" / "ur10_laser_tracker" / "measurements_grid.csv"
JOINTS = (
    "q1=shoulder_pan_joint,q2=shoulder_lift_joint,q3=elbow_joint,"
    "q4=wrist_1_joint,q5=wrist_2_joint,q6=wrist_3_joint"
)
POSITION = "x=measurement_x,y=measurement_y,z=measurement_z"
ROTATION = "rx=measurement_rx,ry=measurement_ry,rz=measurement_rz"
PROBE = [0.0, 0.0, 0.109]


def read(path: Path, pose: bool = False) -> rc.Measurements:
    columns = f"{JOINTS},{POSITION}" + (f",{ROTATION}" if pose else "")
    return rc.read_measurements(
        path, length_unit="mm", decimal=",", sep=";", columns=columns,
        orientation="euler:XYZ:deg" if pose else "none",
    )  # fmt: skip


def _features(q: np.ndarray) -> np.ndarray:
    return np.hstack([np.sin(q), np.cos(q)])


def gp_peer(result: rc.CalibrationResult, train: rc.Measurements, inducing: int | None):
    """A scikit-learn GP on the position residual of ``result``; returns predict(q) -> (n, 3)
    device-frame positions.  ``inducing``: subset-of-regressors with that many points."""
    from sklearn.gaussian_process import GaussianProcessRegressor
    from sklearn.gaussian_process.kernels import ConstantKernel, Matern, WhiteKernel

    X = _features(train.q)
    r = (train.position - result.predict(train.q)[:, :3, 3]) * 1e3  # mm
    kernel = ConstantKernel(0.1, (1e-4, 10.0)) * Matern(
        np.ones(X.shape[1]), (1e-2, 1e3), nu=1.5
    ) + WhiteKernel(1e-3, (1e-6, 1.0))
    rng = np.random.default_rng(0)
    subset = (
        np.arange(len(X)) if inducing is None else rng.choice(len(X), min(inducing, len(X)), replace=False)
    )
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gp = GaussianProcessRegressor(kernel, n_restarts_optimizer=0).fit(X[subset], r[subset])
    if inducing is None:
        return lambda q: result.predict(q)[:, :3, 3] + gp.predict(_features(q)) * 1e-3
    k_signal, noise = gp.kernel_.k1, gp.kernel_.k2.noise_level
    Z = X[subset]
    Kmn = k_signal(Z, X)  # (m, n): memory O(m n), never n x n
    A = noise * k_signal(Z) + Kmn @ Kmn.T
    w = np.linalg.solve(A + 1e-9 * np.trace(A) / len(A) * np.eye(len(A)), Kmn @ r)
    return lambda q: result.predict(q)[:, :3, 3] + (k_signal(_features(q), Z) @ w) * 1e-3


def _stats(predicted: np.ndarray, test: rc.Measurements) -> tuple[float, float, float, float]:
    e = np.linalg.norm(predicted - test.position, axis=1)
    return float(e.mean()), float(np.sqrt(np.mean(e**2))), float(np.percentile(e, 95)), float(e.max())


def _against_physics(result: rc.CalibrationResult, test: rc.Measurements) -> tuple[float, ...]:
    """The default's held-out error per pose against its stored physics-only fit's: share of
    poses worse (%), the 95th percentile and the largest increase (m), both models' largest
    error (m)."""
    from robocal.compensate.export import kinematic_part

    physics = kinematic_part(result).calibrated if result.model.residual is not None else result
    e = np.linalg.norm(result.predict(test.q)[:, :3, 3] - test.position, axis=1)
    e_physics = np.linalg.norm(physics.predict(test.q)[:, :3, 3] - test.position, axis=1)
    change = e - e_physics
    worse = 100.0 * float(np.mean(change > 0.0))
    p95, largest = float(np.percentile(change, 95)), float(change.max())
    return worse, p95, largest, float(e.max()), float(e_physics.max())


TAIL: dict[int, list[tuple[float, ...]]] = {}  # training poses -> per seed: _against_physics
DEFAULT = "robocal default (CV: physics + learned angle errors)"


def run(
    sizes: list[int], seeds: int, gp: bool, pose: bool, only_default: bool = False
) -> dict[tuple[str, int], list[tuple]]:
    data = read(DATA)
    data_pose = read(DATA, pose=True) if pose else None
    dh, complete = rc.robot("ur10"), rc.calibration_model("ur10", "position")
    rows: dict[tuple[str, int], list[tuple]] = {}

    def add(name: str, n: int, predicted: np.ndarray, test: rc.Measurements, seconds: float) -> None:
        rows.setdefault((name, n), []).append((*_stats(predicted, test), seconds))

    for n in sizes:
        for seed in range(seeds):
            split = data.with_split(n, seed=seed)
            train, test = split.split_rows("train"), split.split_rows("test")
            fits = {
                "plain DH": (dh, {"residual": "none"}),
                "complete": (complete, {"residual": "none"}),
                "complete + compliance": (complete, {"residual": "none", "compliance": True}),
                DEFAULT: (complete, {"residual": "auto"}),
            }
            if only_default:
                fits = {DEFAULT: fits[DEFAULT]}
            results = {}
            for name, (model, options) in fits.items():
                t = time.perf_counter()
                result = rc.calibrate(model, train, tool_guess=PROBE, **options)
                seconds = time.perf_counter() - t
                results[name] = (result, seconds)
                add(name, n, result.predict(test.q)[:, :3, 3], test, seconds)
            TAIL.setdefault(n, []).append(_against_physics(results[DEFAULT][0], test))
            if gp and not only_default:
                physics, t_physics = results["complete + compliance"]
                peers = (("+ GP (ARD, exact)", None), ("+ GP (sparse, 300 inducing)", 300))
                for suffix, inducing in peers:
                    name = f"complete + compliance {suffix}"
                    if inducing is not None and n <= inducing:
                        continue
                    t = time.perf_counter()
                    predict = gp_peer(physics, train, inducing)
                    add(name, n, predict(test.q), test, t_physics + time.perf_counter() - t)
            if data_pose is not None and not only_default:
                split = data_pose.with_split(n, seed=seed)
                train, test = split.split_rows("train"), split.split_rows("test")
                t = time.perf_counter()
                result = rc.calibrate(
                    rc.calibration_model("ur10", "pose"), train, tool_guess=PROBE, residual="auto"
                )
                seconds = time.perf_counter() - t
                add(
                    "robocal default, pose data (orientation used)",
                    n,
                    result.predict(test.q)[:, :3, 3],
                    test,
                    seconds,
                )
            print(f"  {n} poses, seed {seed} done", flush=True)
    return rows


def probe(folds: int = 5) -> None:
    """Which joints the physics' remaining error follows: a nearest-neighbour regression of
    the residual of complete + compliance (fitted on all poses) on subsets of the joint
    angles, k-fold over all poses; mean error of each (mm)."""
    from sklearn.model_selection import KFold, cross_val_predict
    from sklearn.neighbors import KNeighborsRegressor

    data = read(DATA)
    result = rc.calibrate(rc.calibration_model("ur10", "position"), data, tool_guess=PROBE, compliance=True)
    r = data.position - result.predict(data.q)[:, :3, 3]
    mean = np.linalg.norm(r, axis=1).mean()
    print(f"complete + compliance on all {data.n} poses: residual mean {mean * 1e3:.3f} mm")
    for joints in ((0, 1, 2, 3, 4, 5), (1, 2, 3, 4, 5), (3, 4, 5), (1, 2), (0, 1, 2)):
        X = np.hstack([np.sin(data.q[:, joints]), np.cos(data.q[:, joints])])
        split = KFold(folds, shuffle=True, random_state=0)
        predicted = cross_val_predict(KNeighborsRegressor(5, weights="distance"), X, r, cv=split)
        e = np.linalg.norm(r - predicted, axis=1).mean()
        print(f"  5 nearest neighbours in joints {[j + 1 for j in joints]}: {e * 1e3:.3f} mm")


def cv_grid(sizes: list[int], seeds: int, grid: tuple[int, ...]) -> None:
    """The CV evidence behind the default's harmonics: for each training size and seed the
    default calibrated with ``residual_harmonics=grid``; per number of harmonics the mean
    5-fold CV error on the training rows (the lower of the physical variants'), averaged
    over the seeds, and how often each was chosen.  Held-out rows never enter."""
    data = read(DATA)
    model = rc.calibration_model("ur10", "position")
    print(f"| training poses | {' | '.join(f'H={h} CV mean mm' for h in grid)} | chosen (seeds) |")
    print("|---:|" + "---:|" * len(grid) + "---|")
    for n in sizes:
        cv_means, chosen = np.zeros((seeds, len(grid))), []
        for seed in range(seeds):
            train = data.with_split(n, seed=seed).split_rows("train")
            result = rc.calibrate(model, train, tool_guess=PROBE, residual="auto", residual_harmonics=grid)
            table = result.metadata["cv"]
            for i, h in enumerate(grid):
                cv_means[seed, i] = min(c["cv_mean_mm"] for c in table["candidates"] if c["harmonics"] == h)
            chosen.append(next(c["harmonics"] for c in table["candidates"] if c["name"] == table["chosen"]))
        counts = ", ".join(f"H={h}: {chosen.count(h)}" for h in sorted(set(chosen), key=lambda h: h or 0))
        print(f"| {n} | {' | '.join(f'{v:.4f}' for v in cv_means.mean(axis=0))} | {counts} |", flush=True)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--sizes", default="100,300,1000")
    parser.add_argument("--no-gp", action="store_true", help="leave out the scikit-learn GP peers")
    parser.add_argument("--pose", action="store_true", help="also calibrate with the measured orientations")
    parser.add_argument("--probe", action="store_true", help="only: which joints the remaining error follows")
    parser.add_argument("--tail", action="store_true", help="only the default and its per-pose change")
    parser.add_argument("--cv-grid", default="", help="only: CV errors of these harmonics, e.g. 8,24,48")
    args = parser.parse_args(argv)
    if args.probe:
        probe()
        return
    sizes = [int(s) for s in args.sizes.split(",")]
    if args.cv_grid:
        cv_grid(sizes, args.seeds, tuple(int(h) for h in args.cv_grid.split(",")))
        return
    print(
        f"real UR10, series A; {args.seeds} seeds; {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} cores, Python {platform.python_version()}, numpy {np.__version__}, "
        f"BLAS threads {os.environ['OPENBLAS_NUM_THREADS']}"
    )
    rows = run(sizes, args.seeds, not args.no_gp, args.pose, args.tail)
    print("| model | training poses | held-out mean mm | RMS mm | p95 mm | max mm | fit s |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for n in sizes:
        for (name, size), values in rows.items():
            if size != n:
                continue
            v = np.array(values)
            mean, rms, p95, worst, seconds = v.mean(axis=0)
            spread = v[:, 0].std()
            print(
                f"| {name} | {n} | {mean * 1e3:.3f} (± {spread * 1e3:.3f}) | {rms * 1e3:.3f} | "
                f"{p95 * 1e3:.3f} | {worst * 1e3:.3f} | {seconds:.2f} |"
            )
    print_tail(sizes)


def print_tail(sizes: list[int]) -> None:
    """The per-pose change of the default against physics alone (means over the seeds; the
    largest increase and both maxima: the worst seed's)."""
    print()
    print(
        "| training poses | held-out poses worse than physics alone % | p95 of the change mm | "
        "largest increase mm | max error default / physics alone mm (worst seed) | "
        "seeds with the default's max above physics alone's |"
    )
    print("|---:|---:|---:|---:|---:|---:|")
    for n in sizes:
        v = np.array(TAIL.get(n, []))
        if not len(v):
            continue
        worse, p95, largest = v[:, 0].mean(), v[:, 1].mean(), v[:, 2].max()
        print(
            f"| {n} | {worse:.1f} (range {v[:, 0].min():.1f}-{v[:, 0].max():.1f}) | {p95 * 1e3:+.3f} | "
            f"{largest * 1e3:.3f} | {v[:, 3].max() * 1e3:.3f} / {v[:, 4].max() * 1e3:.3f} | "
            f"{int(np.sum(v[:, 3] > v[:, 4]))} of {len(v)} |"
        )


if __name__ == "__main__":
    main()
