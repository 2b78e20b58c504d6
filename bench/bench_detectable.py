"""Are the minimum detectable sizes diagnose states right? Check them by simulation.

    python bench/bench_detectable.py [--seeds 40] [--quick]

For each seed, a 120-pose stereo_target dataset with nothing hidden (seeds 100.. as the
null bench) is fitted and the minimum detectable size of the candidate ``depth_scale``
(80 % power at the candidates' threshold; ``hostpc.diagnostics.detectable``) is computed
from its design. The same world (same poses, same noise) is then synthesized with a
depth scale of 1.5x and 0.5x that size, and the candidates are ranked as diagnose ranks
them: "found" when depth_scale is significant (the held-out test included). Done when
found in at least 80 % of the worlds at 1.5x and at most 20 % at 0.5x. ``--quick``: 6 seeds.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.harness import seeds_argument  # noqa: E402

OPTIONAL = True
EFFECT = "depth_scale"
FACTORS = (1.5, 0.5)


def found(size: float, seed: int) -> bool:
    """Whether the candidates' ranking finds EFFECT hidden at ``size`` in world ``seed``."""
    from hostpc.diagnostics import DEFAULT_ALPHA
    from hostpc.diagnostics.candidates import candidate_effects, rank_candidates
    from hostpc.diagnostics.pipeline import DEFAULT_RANK_CV_FOLDS
    from hostpc.fitting import fit
    from hostpc.model.registry import available_effects
    from tests.hostpc.diagnose_support import hidden_dataset

    dataset = hidden_dataset({f"{EFFECT}.s": size}, seed=100 + seed).dataset
    base = fit(dataset, cv_folds=0)
    registry = available_effects()
    names = candidate_effects(base.problem, registry)
    ranked, _ = rank_candidates(base, registry, names, alpha=DEFAULT_ALPHA,
                                cv_folds=DEFAULT_RANK_CV_FOLDS, loss="linear")
    return any(c.effect == EFFECT and c.significant for c in ranked)


def stated_size(seed: int) -> float:
    """The minimum detectable size of EFFECT diagnose states for world ``seed``'s design."""
    from hostpc.diagnostics import DEFAULT_ALPHA
    from hostpc.diagnostics.candidates import candidate_effects
    from hostpc.diagnostics.detectable import candidate_sizes
    from hostpc.fitting import fit
    from hostpc.model.registry import available_effects
    from tests.hostpc.diagnose_support import hidden_dataset

    base = fit(hidden_dataset({}, seed=100 + seed).dataset, cv_folds=0)
    registry = available_effects()
    sizes = candidate_sizes(base, registry, candidate_effects(base.problem, registry),
                            DEFAULT_ALPHA)
    return next(s.size for s in sizes if s.effect == EFFECT)


def run(seeds: int = 40) -> dict[str, float]:
    start = time.perf_counter()
    hits = dict.fromkeys(FACTORS, 0)
    for seed in range(seeds):
        size = stated_size(seed)
        line = [f"seed {100 + seed}: stated {size:.3g}"]
        for factor in FACTORS:
            hit = found(factor * size, seed)
            hits[factor] += hit
            line.append(f"{factor}x {'found' if hit else 'missed'}")
        print("; ".join(line), flush=True)
    return {"worlds": float(seeds), "found_1.5x": hits[1.5] / seeds,
            "found_0.5x": hits[0.5] / seeds, "seconds": time.perf_counter() - start}


def main(argv: list[str] | None = None) -> int:
    figures = run(seeds_argument(__doc__.splitlines()[0], 40, 6, argv))
    print(f"{EFFECT} at 1.5x the stated size found in {figures['found_1.5x']:.0%}, at 0.5x in "
          f"{figures['found_0.5x']:.0%} of {figures['worlds']:.0f} worlds "
          f"({figures['seconds']:.1f} s)")
    return 0 if figures["found_1.5x"] >= 0.8 and figures["found_0.5x"] <= 0.2 else 1


if __name__ == "__main__":
    sys.exit(main())
