"""Where the nominal twin's held-out residual sits, by part, on cases of the independent gap benchmark (prints).

Run from the repository root (the truths come from the user cache, or are made: 20–50 s each)::

    python bench/gap_where.py convection_enclosure column_source

For each case: the verdict, the parts' estimated uniform temperature errors (K RMS, largest first, from
:func:`twin.gap.attribution.region_estimate` on the nominal twin's residual) each with its resolution (the
diagonal of the model-resolution matrix: 1 = the sensors decide the part's error, 0 = only the prior; parts
below ``RESOLVED`` are not a location), and per drift or strain line the parts' shares of its residual (they
sum to about 1 where the estimate explains the line) with the unresolved parts' combined share, then what
the discovery reports.  This is the part-share "where" of the report's attribution figure, which the
benchmark does not score.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from twin.gap.benchmark import independent_cases, independent_record
from twin.gap.diagnose import _machine, diagnose


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("cases", nargs="+", help="independent case names (twin gap benchmark --independent)")
    args = parser.parse_args()
    machine = _machine("vmc_ram")
    for case in independent_cases(",".join(args.cases)):
        d = diagnose(independent_record(case), machine)
        est = d.attribution["regions"]
        print(f"== {case.name}: {d.outcome}, named {d.winner.name if d.winner else 'none'}")
        worst = sorted(est["rms_K"].items(), key=lambda kv: -kv[1])[:5]
        res = est["resolution"]
        print("   part temperature error (K RMS, resolution):",
              ", ".join(f"{r} {v:.3f} (res {res[r]:.2f})" for r, v in worst),
              "| parts with a thermometer:", ", ".join(str(r) for r in est["observed_regions"]),
              "| resolved:", ", ".join(str(r) for r in est["resolved"]) or "none")
        for line, shares in est["shares"].items():
            top = sorted(shares.items(), key=lambda kv: -abs(kv[1]["share"]))[:4]
            total = sum(v["share"] for v in shares.values())
            print(f"   {line} ({est['units'][line]}): "
                  + ", ".join(f"{r} {v['share']:+.2f}{'' if r in est['resolved'] else '*'}" for r, v in top)
                  + f"  (all parts {total:+.2f}; unresolved (*) together {est['unresolved_share'][line]:+.2f})")
        if d.discovery is not None:
            print("   discovery:", "; ".join(d.discovery.as_dict().get("summary", [])))


if __name__ == "__main__":
    main()
