"""Start-up of the ``robocal`` command and its first run, each figure as a ratio against
``python -c "import numpy"`` measured in the same run (CPU time: user + system of the child,
so a loaded machine inflates it less than wall time; wall time beside it).

* start-up: ``robocal --help``, ``robots``, ``fk ur10 ...``, and ``validate`` / ``report`` of
  a calibration folder (the quick demo's, written to a temporary directory first), in fresh
  processes, minimum over interleaved rounds; optionally another source tree
  (``--reference /path/to/src``, e.g. an older checkout) interleaved with this one.
* ``--first-run``: ``robocal demo`` with numba's cache empty (``NUMBA_CACHE_DIR`` a new
  temporary directory: what a fresh installation meets) and again with that cache warm; the
  first run's ratio to the second is issue 35's acceptance (<= 2x).

Nothing is written into the repository: every output goes to a temporary directory.

Run: ``python benchmarks/bench_startup.py [--rounds 7] [--first-run] [--reference ../main/src]
[--md docs/performance.md]`` (``--md`` with ``--first-run``: the first and second runs into the
performance page's ``<!-- bench:first_run -->`` block).
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import readme_table

SRC = Path(__file__).resolve().parents[1] / "src"
CLI = "import sys; from robocal.cli import main; sys.argv[0] = 'robocal'; main()"
REFERENCE = "python -c 'import numpy'"


def commands(folder: Path) -> dict[str, tuple[list[str], bool]]:
    """Label -> (python arguments, whether it runs robocal from the tree under test)."""
    robocal = ["-c", CLI]
    html = str(folder.parent / "report.html")
    return {
        "python -c pass": (["-c", "pass"], False),
        REFERENCE: (["-c", "import numpy"], False),
        "robocal --help": ([*robocal, "--help"], True),
        "robocal robots": ([*robocal, "robots"], True),
        "robocal fk ur10 --q ... --deg": ([*robocal, "fk", "ur10", "--q", "0,-90,90,0,90,0", "--deg"], True),
        "robocal validate FOLDER": ([*robocal, "validate", str(folder)], True),
        "robocal report FOLDER": ([*robocal, "report", str(folder), "--out", html, "--force"], True),
    }


def once(args: list[str], src: Path | None, env: dict[str, str] | None = None) -> tuple[float, float]:
    """Wall and CPU seconds (user + system) of one child process."""
    env = dict(os.environ, **(env or {}))  # as a user runs it (OpenBLAS's threads start with numpy)
    if src is not None:
        env["PYTHONPATH"] = str(src)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, *args], env=env, stdout=subprocess.DEVNULL, check=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def startup(rounds: int, trees: dict[str, Path], folder: Path) -> dict[tuple[str, str], tuple[float, float]]:
    """Minimum wall and CPU of each command (and tree) over interleaved rounds."""
    best: dict[tuple[str, str], tuple[float, float]] = {}
    for _ in range(rounds):
        for name, (argv, uses_tree) in commands(folder).items():
            for tree, src in trees.items() if uses_tree else [("-", None)]:
                wall, cpu = once(argv, src)
                old = best.get((name, tree), (float("inf"), float("inf")))
                best[(name, tree)] = (min(old[0], wall), min(old[1], cpu))
    return best


FIRST = "robocal demo, first run (cache empty)"
SECOND = "robocal demo, second run (cache warm)"
WARM_UP = "compiling in the background (another process)"
#: waits for the first run's background compile; prints its CPU seconds (or nothing)
WAIT = "from robocal.identify.kernel_cache import wait_for_warm_up as w; s = w(); print(s or '')"


def first_run(work: Path) -> dict[str, tuple[float, float]]:
    """``robocal demo`` with an empty numba cache, then with it warm (wall, CPU), and the
    first run's background compile (the wall time from the first run's start until the
    cache is warm, and the CPU seconds that process reports)."""
    env = {"NUMBA_CACHE_DIR": str(work / "numba-cache")}  # new, empty: a fresh installation
    demo = ["-c", CLI, "demo", "--out"]
    t0 = time.perf_counter()
    runs = {FIRST: once([*demo, str(work / "d1")], SRC, env)}
    waited = subprocess.run([sys.executable, "-c", WAIT], env=dict(os.environ, PYTHONPATH=str(SRC), **env),
                            capture_output=True, text=True, check=True)  # fmt: skip
    text = waited.stdout.strip()
    if text:  # a warm-up ran: the next run finds the cache warm
        runs[WARM_UP] = (time.perf_counter() - t0, float(text))
    runs[SECOND] = once([*demo, str(work / "d2")], SRC, env)
    return runs


def table(rows: dict[str, tuple[float, float]], numpy_cpu: float) -> None:
    print(f"{'command':<42} {'wall s':>7} {'CPU s':>7} {'CPU / import numpy':>19}")
    for name, (wall, cpu) in rows.items():
        print(f"{name:<42} {wall:7.3f} {cpu:7.3f} {cpu / numpy_cpu:18.2f}x")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--first-run", action="store_true", help="also time the demo's first and second runs")
    parser.add_argument("--reference", type=Path, help="another robocal source tree to compare with")
    parser.add_argument("--md", metavar="PAGE", help="with --first-run: its bench:first_run block")
    args = parser.parse_args()
    if args.md and (why := readme_table.check(args.md, "first_run")):
        raise SystemExit(why)
    load_start = readme_table.load()
    trees = {"this tree": SRC} | ({"reference": args.reference.resolve()} if args.reference else {})
    with tempfile.TemporaryDirectory(prefix="robocal-bench-startup-") as tmp:
        work = Path(tmp)
        folder = work / "calibration"  # the quick demo's folder: validate and report read it
        once(["-c", CLI, "demo", "--quick", "--out", str(folder)], SRC)
        best = startup(args.rounds, trees, folder)
        numpy_cpu = best[(REFERENCE, "-")][1]
        print(f"start-up, minimum of {args.rounds} interleaved rounds")
        other = {"reference": " [reference]"}
        table({name + other.get(tree, ""): value for (name, tree), value in best.items()}, numpy_cpu)
        if args.reference:
            for name, (_, uses_tree) in commands(folder).items():
                if uses_tree:
                    ratio = best[(name, "reference")][1] / best[(name, "this tree")][1]
                    print(f"{name}: {ratio:.1f}x less CPU than the reference")
        if args.first_run:
            runs = first_run(work)
            print("\nfirst run after installing (numba's cache empty) and the second")
            table(runs, numpy_cpu)
            (w1, c1), (w2, c2) = runs[FIRST], runs[SECOND]
            print(f"first run / second run: {c1 / c2:.2f}x CPU, {w1 / w2:.2f}x wall (issue 35: <= 2x)")
            if args.md:
                _write_first_run(args.md, runs, load_start)


def _write_first_run(page: str, runs: dict[str, tuple[float, float]], load_start: str) -> None:
    """The first and second runs of ``robocal demo`` and their ratio, into ``page``."""
    (w1, c1), (w2, c2) = runs[FIRST], runs[SECOND]
    rows = [[name, f"{wall:.1f}", f"{cpu:.1f}"] for name, (wall, cpu) in runs.items()]
    rows.append(["first / second", f"{w1 / w2:.2f}x", f"{c1 / c2:.2f}x (issue 35: <= 2x)"])
    body = [
        "`python benchmarks/bench_startup.py --first-run --md docs/performance.md` (`robocal demo` "
        "with numba's cache empty, `NUMBA_CACHE_DIR` a new directory, then again with it warm):",
        "",
        *readme_table.markdown_table(["command", "wall s", "CPU s"], rows),
        "",
        readme_table.machine(load_start),
    ]
    readme_table.write_block(page, "first_run", "\n".join(body))


if __name__ == "__main__":
    main()
