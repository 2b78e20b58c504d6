"""Are the minimum detectable sizes diagnose states right? Check them by simulation.

    python bench/bench_detectable.py [--seeds 40] [--quick] [--effects A,B,...]

For each seed, a 120-pose stereo_target dataset with nothing hidden (seeds 100.. as the
null bench) is fitted and the minimum detectable size of each candidate of ``--effects``
(default depth_scale, thermal_expansion, encoder_scale; its best-seen parameter, 80 % power
at the candidates' threshold; ``hostpc.diagnostics.detectable``) is computed from its
design. The same world (same poses, same noise) is then synthesized with that parameter at
1.5x and 0.5x that size, and the candidates are ranked as diagnose ranks them: "found" when
the effect is significant (the held-out test included). Done when, for every effect, found
in at least 80 % of the worlds at 1.5x and at most 20 % at 0.5x. ``--quick``: 6 seeds.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

OPTIONAL = True
EFFECTS = ("depth_scale", "thermal_expansion", "encoder_scale")
FACTORS = (1.5, 0.5)


def found(effect: str, parameter: str, size: float, seed: int) -> bool:
    """Whether the candidates' ranking finds ``effect`` with ``parameter`` hidden at
    ``size`` in world ``seed``."""
    from hostpc.diagnostics import DEFAULT_ALPHA
    from hostpc.diagnostics.candidates import candidate_effects, rank_candidates
    from hostpc.diagnostics.pipeline import DEFAULT_CV_FOLDS
    from hostpc.fitting import fit
    from hostpc.model.registry import available_effects
    from tests.hostpc.diagnose_support import hidden_dataset

    dataset = hidden_dataset({parameter: size}, seed=100 + seed).dataset
    base = fit(dataset, cv_folds=0)
    registry = available_effects()
    names = candidate_effects(base.problem, registry)
    ranked, _ = rank_candidates(base, registry, names, alpha=DEFAULT_ALPHA,
                                cv_folds=DEFAULT_CV_FOLDS, loss="linear")
    return any(c.effect == effect and c.significant for c in ranked)


def stated_sizes(seed: int, effects: tuple[str, ...]) -> dict[str, tuple[str, float]]:
    """effect -> (its best-seen parameter, the minimum detectable size diagnose states)
    for world ``seed``'s design."""
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
    return {s.effect: (s.parameter, s.size) for s in sizes if s.effect in effects}


def run(seeds: int = 40, effects: tuple[str, ...] = EFFECTS) -> dict[str, dict[str, float]]:
    start = time.perf_counter()
    hits = {e: dict.fromkeys(FACTORS, 0) for e in effects}
    for seed in range(seeds):
        stated = stated_sizes(seed, effects)
        line = [f"seed {100 + seed}:"]
        for effect in effects:
            parameter, size = stated[effect]
            line.append(f"{parameter} stated {size:.3g}")
            for factor in FACTORS:
                hit = found(effect, parameter, factor * size, seed)
                hits[effect][factor] += hit
                line.append(f"{factor}x {'found' if hit else 'missed'}")
        print(" ".join(line), flush=True)
    seconds = time.perf_counter() - start
    return {e: {"worlds": float(seeds), "found_1.5x": hits[e][1.5] / seeds,
                "found_0.5x": hits[e][0.5] / seeds, "seconds": seconds} for e in effects}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=40)
    parser.add_argument("--quick", action="store_true", help="6 seeds")
    parser.add_argument("--effects", default=",".join(EFFECTS),
                        help=f"candidates to check (default {','.join(EFFECTS)})")
    args = parser.parse_args(argv)
    effects = tuple(e.strip() for e in args.effects.split(",") if e.strip())
    figures = run(6 if args.quick else args.seeds, effects)
    ok = True
    for effect, f in figures.items():
        print(f"{effect} at 1.5x the stated size found in {f['found_1.5x']:.0%}, at 0.5x in "
              f"{f['found_0.5x']:.0%} of {f['worlds']:.0f} worlds")
        ok = ok and f["found_1.5x"] >= 0.8 and f["found_0.5x"] <= 0.2
    print(f"({next(iter(figures.values()))['seconds']:.1f} s)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
