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
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench import bench_diagnose_null  # noqa: E402

OPTIONAL = True


def frame_alarms(seed: int) -> list[str]:
    """What diagnose --ladder flags on the laser-tracker world ``seed`` (seed 100 + seed)."""
    import hostpc
    from tests.hostpc.diagnose_support import hidden_world_point

    dataset = hidden_world_point({}, seed=100 + seed, swing=2.0).dataset
    diagnosis = hostpc.diagnose(dataset, ladder=True)
    alarms = list(diagnosis.check.adequacy.reasons)
    return alarms + [f"ladder adds {s.added}" for s in diagnosis.ladder or () if s.added]


if __name__ == "__main__":
    sys.exit(bench_diagnose_null.main(None, frame_alarms, __doc__.splitlines()[0]))
