"""Print the default machine's calibration table (targets from the thesis, simulated values).

    python bench/calibration.py [machine]
"""
import sys
import time

from twin.core.machine import build_machine
from twin.run.calibration import calibration_table, format_table


def main():
    machine = sys.argv[1] if len(sys.argv) > 1 else "vmc_ram"
    start = time.perf_counter()
    rows = calibration_table(build_machine(machine))
    print(format_table(rows))
    print(f"\n({time.perf_counter() - start:.1f} s; noise-free runs of the scenarios named)")
    return 0 if all(ok for _, _, ok in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
