"""False alarms of `hostpc diagnose --ladder` on data with nothing hidden.

    python bench/bench_diagnose_null.py [--seeds 24] [--quick]

For each seed, a 120-pose stereo_target dataset (random zero offsets and frame errors, no
hidden effect; seeds 100.. as tests/hostpc/test_diagnose_null.py) is diagnosed with the
ladder and the generated "P linear in V" effects on. An alarm is any reason the current
model is said not to be adequate, or any effect the ladder adds. The stated rate is the
union bound over the families of tests (chi-square band at ADEQUACY_P_MIN, outliers,
candidates, interactions, each at the family-wise DEFAULT_ALPHA): at most 4e-3 per dataset,
so more than 1 alarm in 24 datasets has probability < 1 % (binomial). Prints one line a
seed, the count and the bound; :func:`run` returns them. ``--quick``: 4 seeds.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.harness import seeds_argument  # noqa: E402

OPTIONAL = True


def run(seeds: int = 24, alarms_of: Callable[[int], list[str]] | None = None
        ) -> dict[str, float]:
    """alarms_of(seed): what diagnose --ladder flags on world ``seed`` (default: the
    stereo_target worlds of ``null_alarms``)."""
    from tests.hostpc.diagnose_support import allowed_alarms, null_alarm_rate, null_alarms

    start = time.perf_counter()
    alarmed = 0
    for seed in range(seeds):
        alarms = (alarms_of or null_alarms)(seed)
        alarmed += bool(alarms)
        print(f"seed {100 + seed}: {'; '.join(alarms) if alarms else 'no alarm'}", flush=True)
    rate = null_alarm_rate()
    return {"datasets": float(seeds), "alarms": float(alarmed), "rate_bound": rate,
            "allowed": float(allowed_alarms(seeds, rate)),
            "seconds": time.perf_counter() - start}


def main(argv: list[str] | None = None, alarms_of: Callable[[int], list[str]] | None = None,
         description: str | None = None) -> int:
    figures = run(seeds_argument(description or __doc__.splitlines()[0], 24, 4, argv),
                  alarms_of)
    print(f"{figures['alarms']:.0f} of {figures['datasets']:.0f} datasets alarmed; stated "
          f"rate <= {figures['rate_bound']:.3g} a dataset allows {figures['allowed']:.0f} "
          f"(P(more) < 1 %); {figures['seconds']:.1f} s")
    return 0 if figures["alarms"] <= figures["allowed"] else 1


if __name__ == "__main__":
    sys.exit(main())
