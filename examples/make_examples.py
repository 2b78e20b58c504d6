"""Make the example datasets in this folder (seeded: the same files every time).

    python examples/make_examples.py [OUTDIR]

Each dataset is written with a `<name>.truth.json` beside it holding the injected truth.
The measurements come from hostpc's own measurement model (hostpc.synthesize) with
Gaussian noise drawn from each sample's stereo covariance.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from hostpc.synthesize import random_truth, synthesize_stereo_target, write_example


def main(outdir: Path) -> None:
    outdir.mkdir(parents=True, exist_ok=True)
    truth = random_truth(np.random.default_rng(7))
    # 1. camera frame and target both unknown: q1 and q6 cannot be separated from them
    write_example(outdir / "ur5e_stereo.json",
                  synthesize_stereo_target(truth, robot="ur5e", n_samples=60, seed=7))
    # 2. tool and target measured beforehand (known): every zero offset is identifiable
    offsets_only = {k: v for k, v in truth.items() if k.startswith("joint_offsets")}
    write_example(outdir / "ur5e_stereo_known_frames.json",
                  synthesize_stereo_target(offsets_only, robot="ur5e", n_samples=60, seed=8,
                                           known=("tool", "target")))
    # 3. a hidden effect: joints bend under gravity (for `hostpc diagnose`)
    hidden = dict(truth)
    hidden.update({"joint_compliance.c2": 2.0e-5, "joint_compliance.c3": 2.5e-5})
    write_example(outdir / "ur5e_stereo_hidden_compliance.json",
                  synthesize_stereo_target(hidden, robot="ur5e", n_samples=120, seed=9))
    print(f"wrote examples to {outdir}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).parent)
