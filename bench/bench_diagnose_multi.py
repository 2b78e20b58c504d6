"""Several effects hidden at once: what `hostpc diagnose --ladder` does, seed by seed.

    python bench/bench_diagnose_multi.py [--seeds 8] [--quick]

For stereo_target and world_point (laser tracker) data, 120 poses, with compliance +
geometry and with compliance + backlash + thermal expansion (8 K warm-up) hidden
(tests/hostpc/multi_effects.py), prints per seed: the effects the ladder added in order
(``-NAME``: dropped again at that step), the final chi2/dof and verdict, the worst
(fitted - true) / sigma of the hidden sizes, and the worst zero-offset error against the
truth at each step (deg, and in units of its sigma). docs/diagnostics.md quotes the figures.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.harness import seeds_argument  # noqa: E402

OPTIONAL = True


def run(seeds: int = 8) -> dict[str, float]:
    from tests.hostpc.multi_effects import CASES, MAKERS, hidden_effects, run_case

    right = total = 0
    for method in MAKERS:
        for case in CASES:
            for seed in range(seeds):
                outcome = run_case(method, case, seed)
                ladder = outcome.diagnosis.ladder or ()
                found = set(ladder[-1].effects) - set(ladder[0].effects)
                ok = found == hidden_effects(CASES[case]) and ladder[-1].adequate
                right += ok
                total += 1
                print(f"{method} {case} seed {seed}: {outcome.line()}", flush=True)
    return {"cases": float(total), "right_and_adequate": float(right)}


def main(argv: list[str] | None = None) -> int:
    figures = run(seeds_argument(__doc__.splitlines()[0], 8, 2, argv))
    print(f"{figures['right_and_adequate']:.0f} of {figures['cases']:.0f}: the ladder ends "
          "with exactly the hidden effects and an adequate model")
    return 0


if __name__ == "__main__":
    sys.exit(main())
