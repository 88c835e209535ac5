"""Start-up of the ``robocal`` command: ``robocal --help`` and ``robocal fk ur10 ...`` in fresh
processes, wall and CPU time (minimum over rounds), with the bare interpreter and
``import numpy`` as references measured in the same run, and optionally another source tree
(``--reference /path/to/src``: e.g. an older checkout) interleaved with this one.

Run: ``python benchmarks/bench_startup.py [--rounds 7] [--reference ../main/src]``.
"""

from __future__ import annotations

import argparse
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

SRC = Path(__file__).resolve().parents[1] / "src"
CLI = "import sys; from robocal.cli import main; sys.argv[0] = 'robocal'; main()"
COMMANDS = {
    "python -c pass": (["-c", "pass"], False),
    "python -c 'import numpy'": (["-c", "import numpy"], False),
    "robocal --help": (["-c", CLI, "--help"], True),
    "robocal fk ur10 --q ... --deg": (["-c", CLI, "fk", "ur10", "--q", "0,-90,90,0,90,0", "--deg"], True),
}


def once(args: list[str], src: Path | None) -> tuple[float, float]:
    """Wall and CPU seconds (user + system) of one child process."""
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1")
    if src is not None:
        env["PYTHONPATH"] = str(src)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    subprocess.run([sys.executable, *args], env=env, stdout=subprocess.DEVNULL, check=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=7)
    parser.add_argument("--reference", type=Path, help="another robocal source tree to compare with")
    args = parser.parse_args()
    trees = {"this tree": SRC} | ({"reference": args.reference.resolve()} if args.reference else {})
    best: dict[tuple[str, str], tuple[float, float]] = {}
    for _ in range(args.rounds):  # interleaved rounds
        for name, (argv, uses_tree) in COMMANDS.items():
            for tree, src in trees.items() if uses_tree else [("-", None)]:
                wall, cpu = once(argv, src)
                old = best.get((name, tree), (float("inf"), float("inf")))
                best[(name, tree)] = (min(old[0], wall), min(old[1], cpu))
    print(f"start-up, minimum of {args.rounds} interleaved rounds (s)")
    print(f"{'command':<34} {'tree':<10} {'wall':>7} {'CPU':>7}")
    for (name, tree), (wall, cpu) in best.items():
        print(f"{name:<34} {tree:<10} {wall:7.3f} {cpu:7.3f}")
    if args.reference:
        for name, (_, uses_tree) in COMMANDS.items():
            if uses_tree:
                ratio = best[(name, "reference")][0] / best[(name, "this tree")][0]
                print(f"{name}: {ratio:.1f}x faster than the reference (wall)")


if __name__ == "__main__":
    main()
