"""Start-up time of the ``twin`` command line: ``twin --help`` and an argument error.

Each figure is the wall time of a fresh interpreter (``python -m twin.cli``),
fastest and median of ``--repeat`` runs, so it includes interpreter start and
every import the command line makes before it answers.

    python bench/cli_startup.py                # 7 runs of each
    python bench/cli_startup.py --repeat 15
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time

CASES = {"twin --help": ["--help"], "twin run (missing argument)": ["run"],
         "twin gap diagnose --help": ["gap", "diagnose", "--help"]}


def wall_times(args, repeat):
    """Seconds of ``repeat`` fresh ``python -m twin.cli ARGS`` processes (``None``: a bare ``python -c pass``)."""
    command = [sys.executable, "-c", "pass"] if args is None else [sys.executable, "-m", "twin.cli", *args]
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        subprocess.run(command, stdout=subprocess.DEVNULL,
                       stderr=subprocess.DEVNULL, check=False)
        times.append(time.perf_counter() - start)
    return times


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--repeat", type=int, default=7)
    args = p.parse_args(argv)
    python = wall_times(None, args.repeat)
    print(f"{'bare python start':32s} fastest {min(python):.3f} s, median {statistics.median(python):.3f} s")
    for label, cli_args in CASES.items():
        t = wall_times(cli_args, args.repeat)
        print(f"{label:32s} fastest {min(t):.3f} s, median {statistics.median(t):.3f} s")


if __name__ == "__main__":
    main()
