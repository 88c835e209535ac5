"""How many poses does a UR10 calibration need?  Optimal (O1) versus random poses.

A virtual UR10 differs from its nominal model by uniform random errors of up to
±0.5 mm on every length and ±0.05° on every angle of its 24 DH parameters.  It is
"measured" at n poses (tool-flange position, Gaussian noise 0.02 mm per axis) and
calibrated with a plain Gauss–Newton least squares on the identifiable subset of the
parameters (column-pivoted QR over a large random pool: 18 of 24 for position
measurements).  The calibrated model is scored on 500 held-out random poses (mean
position error against the true robot).

For n = 8, 10, 12, 15, 20, 30, 50, 100 the poses are either drawn at random from a
seeded pool of 2000 random poses, or selected from the same pool by maximising the
observability index O1 (greedy + exchange, robocal.identify.observability).  Several
seeds each.  The asymptote is the 100-pose error; the script reports the smallest n
whose mean held-out error is within 10 % of it, for each method.

Run:  python examples/pose_count_study.py [--seeds 10] [--out pose_count_study.png]
(``--out docs/pose_count_study.png`` regenerates the documentation's figure)
(about 30 s; --quick for a smoke run).
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np

import robocal as rc
from robocal.identify.observability_indices import identifiable_parameters, observability
from robocal.identify.pose_selection import select_poses
from robocal.measure.poses import random_poses

COUNTS = (8, 10, 12, 15, 20, 30, 50, 100)
LENGTH_ERROR = 0.5e-3  # m, uniform ±
ANGLE_ERROR = math.radians(0.05)  # rad, uniform ±
NOISE = 0.02e-3  # m, standard deviation per axis
POOL = 2000
TEST = 500


def true_robot(nominal: rc.Model, rng: np.random.Generator) -> rc.Model:
    """The nominal model with every free parameter changed by a uniform random error."""
    values = {}
    for name, value in zip(nominal.free_names, nominal.free_values, strict=True):
        tol = ANGLE_ERROR if nominal.step(name).is_rotation else LENGTH_ERROR
        values[name] = value + rng.uniform(-tol, tol)
    return nominal.with_values(values)


def calibrate(nominal: rc.Model, params: tuple[str, ...], q: np.ndarray, p_meas: np.ndarray) -> rc.Model:
    """Plain Gauss–Newton on ``params`` from the nominal values: x += lstsq(J, p_meas − p(x))."""
    cols = [nominal.free_names.index(p) for p in params]
    model = nominal
    for _ in range(10):
        T, J = model.fk_jacobian(q)
        r = (p_meas - T[:, :3, 3]).reshape(-1)
        dx = np.linalg.lstsq(J[:, cols], r, rcond=None)[0]
        model = model.with_values({p: model.step(p).value + d for p, d in zip(params, dx, strict=True)})
        if np.abs(dx).max() < 1e-12:
            break
    return model


def held_out_error(true: rc.Model, model: rc.Model, q_test: np.ndarray) -> float:
    """Mean position error (m) of ``model`` against the true robot at ``q_test``."""
    return float(np.linalg.norm(true.fk(q_test)[:, :3, 3] - model.fk(q_test)[:, :3, 3], axis=1).mean())


def run(seeds: int, counts: tuple[int, ...]) -> dict[str, np.ndarray]:
    nominal = rc.robot("ur10")
    params = identifiable_parameters(nominal, random_poses(nominal, POOL, seed=12345)).kept
    print(f"identifiable parameters ({len(params)} of {len(nominal.free_names)}): {', '.join(params)}")
    err = {m: np.zeros((seeds, len(counts))) for m in ("optimal", "random")}
    before = np.zeros(seeds)
    o1 = {m: np.zeros((seeds, len(counts))) for m in ("optimal", "random")}
    for s in range(seeds):
        rng = np.random.default_rng(1000 + s)
        true = true_robot(nominal, rng)
        pool = random_poses(nominal, POOL, seed=2000 + s)
        q_test = random_poses(nominal, TEST, seed=3000 + s)
        order = rng.permutation(POOL)
        before[s] = held_out_error(true, nominal, q_test)
        for k, n in enumerate(counts):
            sets = {
                "optimal": select_poses(nominal, pool, n, params=params).q,
                "random": pool[order[:n]],
            }
            for method, q in sets.items():
                p_meas = true.fk(q)[:, :3, 3] + rng.normal(0.0, NOISE, (n, 3))
                model = calibrate(nominal, params, q, p_meas)
                err[method][s, k] = held_out_error(true, model, q_test)
                o1[method][s, k] = observability(nominal, q, params=params).O1
        print(
            f"seed {s}: "
            + "  ".join(
                f"n={n}: {err['optimal'][s, k] * 1e3:.4f}/{err['random'][s, k] * 1e3:.4f}"
                for k, n in enumerate(counts)
            )
            + " mm (optimal/random)"
        )
    return {
        "err_optimal": err["optimal"],
        "err_random": err["random"],
        "o1_optimal": o1["optimal"],
        "o1_random": o1["random"],
        "before": before,
    }


def report(results: dict[str, np.ndarray], counts: tuple[int, ...]) -> dict[str, int | None]:
    mean = {m: results[f"err_{m}"].mean(axis=0) for m in ("optimal", "random")}
    asymptote = min(mean["optimal"][-1], mean["random"][-1])
    print(f"\nasymptote (best mean held-out error at n = {counts[-1]}): {asymptote * 1e3:.4f} mm")
    print(f"{'n':>5} {'optimal mm':>11} {'random mm':>11} {'O1 opt':>9} {'O1 rnd':>9}")
    for k, n in enumerate(counts):
        print(
            f"{n:>5} {mean['optimal'][k] * 1e3:>11.4f} {mean['random'][k] * 1e3:>11.4f} "
            f"{results['o1_optimal'][:, k].mean():>9.3g} {results['o1_random'][:, k].mean():>9.3g}"
        )
    reach = {}
    for m in ("optimal", "random"):
        ok = [n for k, n in enumerate(counts) if mean[m][k] <= 1.1 * asymptote]
        reach[m] = ok[0] if ok else None
        print(f"{m}: first n within 10 % of the asymptote: {reach[m]}")
    print(f"before calibration: {results['before'].mean() * 1e3:.3f} mm mean held-out error")
    for m in ("optimal", "random"):
        ok = [n for k, n in enumerate(counts) if mean[m][k] <= NOISE]
        c = mean[m] * np.sqrt(counts)
        print(
            f"{m}: first n with mean error <= {NOISE * 1e3:g} mm (the noise): {ok[0] if ok else None}; "
            f"error * sqrt(n) = {', '.join(f'{v * 1e3:.3f}' for v in c)} mm"
        )
    return reach


def plot(results: dict[str, np.ndarray], counts: tuple[int, ...], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5))
    n = np.array(counts)
    for m, colour in (("optimal", "tab:blue"), ("random", "tab:orange")):
        e = results[f"err_{m}"] * 1e3
        ax.plot(n, e.mean(axis=0), "o-", color=colour, label=f"{m} poses (mean of {len(e)} seeds)")
        ax.fill_between(n, e.min(axis=0), e.max(axis=0), color=colour, alpha=0.2)
    asym = min(results["err_optimal"].mean(axis=0)[-1], results["err_random"].mean(axis=0)[-1]) * 1e3
    ax.axhline(1.1 * asym, color="grey", ls="--", lw=1, label="asymptote + 10 %")
    ax.axvline(15, color="grey", ls=":", lw=1, label="seed 000: 15 points")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xticks(n, [str(v) for v in n])
    ax.set_xlabel("number of calibration poses n")
    ax.set_ylabel("held-out mean position error (mm)")
    ax.set_title("UR10, ±0.5 mm / ±0.05° errors, 0.02 mm noise, 500 held-out poses")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=120)
    print(f"plot saved to {out}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=10)
    # the working folder by default: a run never rewrites the repository's docs/ figure unasked
    parser.add_argument("--out", type=Path, default=Path("pose_count_study.png"))
    parser.add_argument("--quick", action="store_true", help="1 seed, 3 pose counts (smoke test)")
    args = parser.parse_args()
    counts = (8, 15, 30) if args.quick else COUNTS
    seeds = 1 if args.quick else args.seeds
    t0 = time.perf_counter()
    results = run(seeds, counts)
    report(results, counts)
    plot(results, counts, args.out)
    print(f"total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
