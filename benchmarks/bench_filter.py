"""Program filtering at size: time for a long URScript and peak memory for a large file.

Two cases from issue 38 (bounded work):

* a URScript of ``--targets`` joint targets ``movej([...])`` (every one corrected through a
  calibrated UR10 whose geometry differs from the nominal by ~2 mm / 0.2°): the wall time of
  :func:`robocal.compensate.programs.filter_file.filter_program_text`, split into parsing (with the
  comment/string mask), correction and rewriting; linear-time parsing and rewriting keep the
  whole in seconds;
* a comment-only program of ``--comment-mb`` MB given to
  :func:`robocal.compensate.programs.filter_file.filter_program_file`: refused before it is read when above
  the size cap (``MAX_PROGRAM_BYTES``), else filtered; the peak memory allocated while filtering
  (tracemalloc) is reported: a small multiple of the file size.

Measured on 2 shared cores (issue 38; before = commit 185cf0e, after = this script's commit
and later): 40,000 joint targets parse 25.6 s -> 1.75 s, end to end 74 s -> 12.8 s; 10,000
named Cartesian targets parse 9.2 s -> 0.30 s, end to end 115 s -> 15.7 s (the rest is one IK
solve per target); a 150 MB comment-only program filtered in 6.3 s with 300 MB allocated ->
refused before reading; 20 MB (just under the cap): 74 MB allocated.

Run: ``python benchmarks/bench_filter.py [--targets 40000] [--poses 10000] [--comment-mb 150]``
(``--poses``: a program of named Cartesian targets, each one its own IK solve).
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _program(n: int, seed: int = 0) -> str:
    """``n`` joint targets, one ``movej([...])`` each."""
    rng = np.random.default_rng(seed)
    q = rng.uniform(-2.5, 2.5, (n, 6))
    lines = ["def big():", "  # a long program: one movej per target"]
    lines += [
        f"  movej([{', '.join(f'{v:.6f}' for v in row)}], a=1.4, v=1.05)  # {k}" for k, row in enumerate(q)
    ]
    return "\n".join(lines) + "\nend\n"


def _pose_program(n: int) -> str:
    """``n`` named Cartesian targets ``t_k = p[...]``, each moved to by ``movel(t_k)``."""
    import robocal as rc
    from robocal import spatial

    T = rc.robot("ur10").fk(np.array([[0.3, -1.2, 1.4, -1.7, -1.5, 0.2]]))[0]
    rv = spatial.matrix_to_rotvec(T[:3, :3])
    lines = ["def poses():"]
    for k in range(n):
        v = [*(T[:3, 3] + [0.0, 0.0, 1e-5 * k]), *rv]
        lines += [f"  t{k} = p[{', '.join(f'{x:.6f}' for x in v)}]", f"  movel(t{k}, a=0.5, v=0.1)"]
    return "\n".join(lines) + "\nend\n"


def bench_long(text: str, what: str) -> None:
    import robocal as rc
    import robocal.compensate.programs.steps as steps
    from robocal.compensate.programs.filter_file import filter_program_text
    from robocal.measure import draw_true_model

    nominal = rc.robot("ur10")
    real = draw_true_model(nominal, length=2e-3, angle=np.radians(0.2), seed=3)
    label = "big.script"
    filter_program_text({label: _program(3)}, "urscript", real, nominal)  # compile kernels
    t0 = time.perf_counter()
    parsed = steps.parse_program({label: text}, "urscript", 6)
    t_parse = time.perf_counter() - t0
    t0 = time.perf_counter()
    result = filter_program_text({label: text}, "urscript", real, nominal)
    t_all = time.perf_counter() - t0
    print(
        f"URScript, {what} ({len(text) / 1e6:.1f} MB): parse {t_parse:.2f} s, "
        f"filter end to end {t_all:.2f} s; {len(parsed.targets)} targets, "
        f"{int(result.changed.sum())} corrected"
    )


_MEMORY_SCRIPT = """
import sys, time, tracemalloc
import robocal as rc
from robocal.compensate.programs.filter_file import ProgramError, filter_program_file
model = rc.robot("ur10")
tracemalloc.start()
t0 = time.perf_counter()
try:
    filter_program_file(sys.argv[1], model)
    outcome = "filtered"
except ProgramError as err:
    outcome = "refused: " + str(err).split(": ", 1)[1]
dt = time.perf_counter() - t0
peak = tracemalloc.get_traced_memory()[1] / 1e6
print(f"{outcome}; {dt:.2f} s; peak memory allocated while filtering {peak:.0f} MB")
"""


def bench_memory(mb: float) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "comments.script"
        line = "# " + "x" * 77 + "\n"
        with path.open("w") as f:
            f.write("def p():\n")
            for _ in range(int(mb * 1_000_000) // len(line)):
                f.write(line)
            f.write("end\n")
        cmd = [sys.executable, "-c", _MEMORY_SCRIPT, str(path)]
        out = subprocess.run(cmd, capture_output=True, text=True, check=True)
        print(f"comment-only program, {path.stat().st_size / 1e6:.0f} MB: {out.stdout.strip()}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--targets", type=int, default=40_000)
    parser.add_argument("--poses", type=int, default=10_000)
    parser.add_argument("--comment-mb", type=int, default=150)
    args = parser.parse_args()
    if args.targets:
        bench_long(_program(args.targets), f"{args.targets} joint targets")
    if args.poses:
        bench_long(_pose_program(args.poses), f"{args.poses} named Cartesian targets")
    bench_memory(19.5)  # just under the cap: memory a small multiple of the file
    bench_memory(args.comment_mb)


if __name__ == "__main__":
    main()
