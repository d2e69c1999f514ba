"""Thin script over posedrift.benchmarks.run_cpd_benchmark (as ``posedrift bench cpd``).

Usage: OMP_NUM_THREADS=1 python benchmarks/bench_cpd.py 400,2000 cpd.json
"""

from __future__ import annotations

import json
import sys

from posedrift.benchmarks import markdown_table, run_cpd_benchmark


def main(argv: list[str]) -> None:
    sizes = [int(s) for s in (argv[1] if len(argv) > 1 else "400,2000,10000").split(",")]
    report = run_cpd_benchmark(
        sizes, threads=(1, None), repeats=5, rng=0, progress=lambda m: print(m, file=sys.stderr)
    )
    print(markdown_table(report))
    if len(argv) > 2:
        with open(argv[2], "w") as fh:
            json.dump(report, fh, indent=2)


if __name__ == "__main__":
    main(sys.argv)
