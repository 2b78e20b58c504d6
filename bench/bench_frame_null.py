"""False alarms of `hostpc diagnose --ladder` on laser-tracker data with nothing hidden,
where the generated frame effects (``hostpc.diagnostics.frame_candidates``: the tracker's
registration and the reflectors, lines and steps in t, per marker) can be proposed.

    python bench/bench_frame_null.py [--seeds 24] [--quick]

For each seed, a 120-sample world_point dataset (a ur5e warming up by 2 K, seeds 100..;
tests/hostpc/diagnose_support.hidden_world_point) is diagnosed with the ladder. An alarm
is any reason the current model is said not to be adequate, or any effect the ladder adds;
the stated rate and the allowed count are those of bench/bench_diagnose_null.py.
``--quick``: 4 seeds.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.harness import seeds_argument  # noqa: E402

OPTIONAL = True


def run(seeds: int = 24) -> dict[str, float]:
    import hostpc
    from tests.hostpc.diagnose_support import allowed_alarms, hidden_world_point, null_alarm_rate

    start = time.perf_counter()
    alarmed = 0
    for seed in range(seeds):
        dataset = hidden_world_point({}, seed=100 + seed, swing=2.0).dataset
        diagnosis = hostpc.diagnose(dataset, ladder=True)
        alarms = list(diagnosis.check.adequacy.reasons)
        alarms += [f"ladder adds {s.added}" for s in diagnosis.ladder or () if s.added]
        alarmed += bool(alarms)
        print(f"seed {100 + seed}: {'; '.join(alarms) if alarms else 'no alarm'}", flush=True)
    rate = null_alarm_rate()
    return {"datasets": float(seeds), "alarms": float(alarmed), "rate_bound": rate,
            "allowed": float(allowed_alarms(seeds, rate)),
            "seconds": time.perf_counter() - start}


def main(argv: list[str] | None = None) -> int:
    figures = run(seeds_argument(__doc__.splitlines()[0], 24, 4, argv))
    print(f"{figures['alarms']:.0f} of {figures['datasets']:.0f} datasets alarmed; stated "
          f"rate <= {figures['rate_bound']:.3g} a dataset allows {figures['allowed']:.0f} "
          f"(P(more) < 1 %); {figures['seconds']:.1f} s")
    return 0 if figures["alarms"] <= figures["allowed"] else 1


if __name__ == "__main__":
    sys.exit(main())
