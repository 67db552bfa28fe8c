"""Hard cases that must stay numerically stable: run the suite, write its table and figure.

Run from the repository root::

    .venv/bin/python bench/hard_cases.py              # every case, full size (a few minutes)
    .venv/bin/python bench/hard_cases.py --quick      # the short versions (under a minute)
    .venv/bin/python bench/hard_cases.py --cases pendulum_near_top tennis_racket

Each case (``modelgen/bench/hard_cases.py``) simulates through
``CompiledModel.simulate`` and compares against a reference modelgen does not
compute: a closed form (pendulum period, Lagrange top separatrix, sleeping top
threshold, tennis racket flip period, Coulomb stop time), a 30-digit mpmath
solve of equations written by hand, scipy's matrix exponential, or MuJoCo
(a case whose peer is not installed is *skipped*, not failed).  Prints the
markdown table (case, what is tried, reference, tolerance, measured figure,
verdict) and writes it to ``docs/hard_cases.md`` with the figure
``docs/hard_cases.png`` (energy drift, error growth, cost versus stiffness...).

*Method*: correctness only, no timing; costs are counted in rhs evaluations
(``Result.nfev``), never in seconds.  Models are built once into
``generated/hard_cases/`` (the 100-link chain takes minutes the first time).
Exit status 1 when a case fails.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from modelgen.bench.hard_cases import CASES, figure, markdown, run_cases  # noqa: E402

HEADER = """# Hard cases: what was tried, against what, to what figure

Written by `bench/hard_cases.py`{quick} (machine load average {load}). Every case
simulates through `CompiledModel.simulate` and is checked against a reference
that modelgen does not compute. Curves: `hard_cases.png`.

"""


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the short version of each case")
    parser.add_argument("--cases", nargs="+", choices=sorted(CASES), help="run only these")
    parser.add_argument("--out", type=Path, default=REPO / "docs",
                        help="where hard_cases.md and hard_cases.png go (default docs/)")
    parser.add_argument("--build-root", type=Path, default=REPO / "generated" / "hard_cases")
    args = parser.parse_args(argv)
    results = run_cases(args.cases, quick=args.quick, build_root=args.build_root,
                        progress=lambda name: print(f"... {name}", file=sys.stderr, flush=True))
    table = markdown(results)
    print(table)
    for r in results:
        if r.passed is not True and r.note:
            print(f"{r.name} ({r.verdict}): {r.note}")
    args.out.mkdir(parents=True, exist_ok=True)
    load = ", ".join(f"{v:.1f}" for v in os.getloadavg())
    (args.out / "hard_cases.md").write_text(
        HEADER.format(quick=" --quick" if args.quick else "", load=load) + table)
    figure(results).savefig(args.out / "hard_cases.png", dpi=80)
    print(f"wrote {args.out / 'hard_cases.md'} and {args.out / 'hard_cases.png'}")
    return 1 if any(r.passed is False for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
