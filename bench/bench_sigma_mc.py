"""Is the reported sigma honest against the simulator? A Monte Carlo over simulated worlds.

For each method and each world seed k, run the whole procedure against the simulated
controller (`hostpc calibrate --robot sim --scenario <the method's default world, seed k>
--no-push`), read the fitted joint offsets' errors against the simulator's hidden truth
(`result.json` "truth") and their reported sigma (`fit.json`), and print per joint

    ratio = mean over worlds of (error / sigma)^2

with a 95 % interval (if the sigma is honest, n * ratio follows chi-square with n degrees of
freedom, so 40 worlds allow 0.6-1.5 around 1), and how many worlds' chi2/dof is above the
push's band, plain and with the rig's (head camera's) covariance inside (the chi2 the push
tests when the dataset carries it, hostpc.fitting.shared_chi2). Each world is a new seed:
new zero errors, new camera mount error, new rig-calibration views, new noise. Failed runs
are counted.

    python bench/bench_sigma_mc.py [--worlds 40] [--methods stereo_target,sphere_probe,dual_loop]
                                   [--first-seed 1] [--keep DIR [--reuse [--refit]]]
                                   [--json OUT]

--reuse reads the runs already kept in DIR; --refit also fits each kept `dataset.json` again
with the current code (`hostpc.fit`, the run's own effects) instead of reading its
`fit.json`: the error is then the run's error plus the change of the estimate (a fit that
changes only the reported covariance, e.g. of the shared errors, is re-analysed in seconds
per world without running the simulator again).

Slow (about 7-10 s per world and method): `bench/run.py` runs it only when asked by name
(`python bench/run.py sigma_mc`), with 8 worlds.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np
import yaml
from scipy import stats

ROOT = Path(__file__).resolve().parent.parent
METHODS = ("stereo_target", "sphere_probe", "dual_loop")
OPTIONAL = True
"""bench/run.py skips this module unless its name is asked for (slow)."""


def world(method: str, seed: int) -> tuple[dict[str, Any], list[str]]:
    """The method's default simulated world with `seed`, and its extra calibrate options."""
    name = "humanoid.yaml" if method == "dual_loop" else "default.yaml"
    text = (ROOT / "controller_stub" / "scenarios" / name).read_text()
    scenario = yaml.safe_load(text)
    scenario["seed"] = int(seed)
    scenario.setdefault("motion", {})["time_scale"] = 0.0
    if method == "stereo_target":
        scenario["target"]["centre_error"] = [0.0, 0.0, 0.0]
        return scenario, ["--known", "target"]
    if method == "sphere_probe":
        scenario["probe"]["sphere_centre_error"] = [0.0, 0.0, 0.0]
        return scenario, ["--known", "sphere"]
    return scenario, []


def refitted(fit_path: Path, dataset_path: Path) -> tuple[dict[str, Any], dict[str, Any]]:
    """The fit.json `parameters` of the kept run, fitted again with the current code: per
    name the std (SI) and "shift", the value's change against the run's own fit; and the
    refit's chi2/dof figures (`band`)."""
    if str(ROOT) not in sys.path:  # run as a script from anywhere
        sys.path.insert(0, str(ROOT))
    import hostpc
    from hostpc.calibrate.push import chi2_dof_upper
    from hostpc.dataset import load_dataset
    from hostpc.fitting.shared_errors import result_shared_chi2

    kept = json.loads(fit_path.read_text())
    result = hostpc.fit(load_dataset(dataset_path), kept.get("effects"))
    out: dict[str, Any] = {}
    for name, entry in kept["parameters"].items():
        estimate = result.parameters[name]
        std = estimate.std if estimate.std is not None and math.isfinite(estimate.std) else None
        out[name] = {"std": None if entry.get("std") is None else std,
                     "shift": float(estimate.value) - float(entry["value"])}
    full = result_shared_chi2(result)
    return out, {"chi2_dof": result.chi2_dof, "chi2_dof_upper": chi2_dof_upper(result.dof),
                 "chi2_dof_with_calibration": None if full is None else full.chi2_dof}


def band(fit: dict[str, Any]) -> dict[str, Any]:
    """Is the run's chi2/dof above the push band, plain and with the shared error inside
    (None where the run has no such figure)? fit: result.json's "fit" (or `refitted`'s)."""
    upper = fit.get("chi2_dof_upper")
    if upper is None or fit.get("chi2_dof") is None:
        return {}
    shared = fit.get("chi2_dof_with_calibration")
    return {"above_band": bool(fit["chi2_dof"] > upper),
            "above_band_shared": None if shared is None else bool(shared > upper)}


def run_world(method: str, seed: int, folder: Path, reuse: bool = False,
              refit: bool = False) -> dict[str, Any]:
    """One calibration; {"errors": [...] rad or None, "sigmas": [...] rad} or {"failed": msg}.
    reuse: read a finished run already in `folder` instead of running it again; refit:
    fit its dataset again with the current code (`refitted`)."""
    out = folder / f"{method}_{seed}"
    result_path, fit_path = out / "result.json", out / "fit.json"
    if not (reuse and result_path.is_file() and fit_path.is_file()):
        scenario, options = world(method, seed)
        scenario_path = folder / f"{method}_{seed}.yaml"
        scenario_path.write_text(yaml.safe_dump(scenario))
        command = [sys.executable, "-m", "hostpc.cli.main", "calibrate", "--robot", "sim",
                   "--method", method, "--scenario", str(scenario_path), "--no-push",
                   "--out", str(out), *options, *EXTRA_OPTIONS]
        done = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, check=False)
        if not (result_path.is_file() and fit_path.is_file()):
            last = (done.stderr.strip().splitlines() or ["no output"])[-1]
            return {"failed": f"exit {done.returncode}: {last}"}
    document = json.loads(result_path.read_text())
    truth = document.get("truth") or {}
    errors_deg = truth.get("joint_offsets_error_deg")
    if errors_deg is None:
        return {"failed": "no truth comparison in result.json"}
    parameters = json.loads(fit_path.read_text())["parameters"]
    figures = band(document.get("fit") or {})
    if refit:
        parameters, refit_figures = refitted(fit_path, out / "dataset.json")
        figures = band(refit_figures)
    errors, sigmas, names, shifts = [], [], [], []
    for name, entry in parameters.items():
        if not name.startswith("joint_offsets."):
            continue
        names.append(name.split(".", 1)[1])
        sigmas.append(math.nan if entry.get("std") is None else float(entry["std"]))
        shifts.append(float(entry.get("shift", 0.0)))
    for value, shift in zip(errors_deg[: len(names)], shifts, strict=False):
        errors.append(math.nan if value is None else math.radians(float(value)) + shift)
    return {"names": names, "errors": errors, "sigmas": sigmas, **figures}


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """Per joint: worlds, ratio mean((e/s)^2), its 95 % chi-square interval, mean error/sigma."""
    good = [r for r in runs if "errors" in r]
    if not good:
        return {"worlds": 0, "failed": len(runs), "joints": {}}
    names = good[0]["names"]
    joints: dict[str, Any] = {}
    for j, name in enumerate(names):
        z = np.array([r["errors"][j] / r["sigmas"][j] for r in good
                      if j < len(r["errors"]) and math.isfinite(r["errors"][j])
                      and math.isfinite(r["sigmas"][j]) and r["sigmas"][j] > 0])
        if z.size == 0:
            joints[name] = {"worlds": 0}
            continue
        n = z.size
        ratio = float(np.mean(z**2))
        joints[name] = {
            "worlds": n,
            "ratio": ratio,
            "ci95": [n * ratio / float(stats.chi2.ppf(0.975, n)),
                     n * ratio / float(stats.chi2.ppf(0.025, n))],
            "mean_z": float(np.mean(z)),
        }
    failures = [r["failed"] for r in runs if "failed" in r]
    above = {key: [r[key] for r in good if r.get(key) is not None]
             for key in ("above_band", "above_band_shared")}
    return {"worlds": len(good), "failed": len(failures), "failures": failures[:5],
            "joints": joints,
            **{key: {"worlds": len(v), "above": int(sum(v))} for key, v in above.items() if v}}


def run(worlds: int = 8, methods: tuple[str, ...] = METHODS, first_seed: int = 1,
        keep: Path | None = None, reuse: bool = False, refit: bool = False) -> dict[str, Any]:
    """The Monte Carlo; returns {method: summary} (see `summarise`)."""
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="zerocal-sigma-mc-") as tmp:
        folder = keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        for method in methods:
            runs = []
            for seed in range(first_seed, first_seed + worlds):
                runs.append(run_world(method, seed, folder, reuse and keep is not None,
                                      refit and reuse and keep is not None))
                status = runs[-1].get("failed", "ok")
                print(f"  {method} world {seed}: {status}", file=sys.stderr, flush=True)
            out[method] = summarise(runs)
    return out


def print_table(figures: dict[str, Any]) -> None:
    for method, summary in figures.items():
        print(f"{method}: {summary['worlds']} worlds, {summary['failed']} failed")
        for failure in summary.get("failures", []):
            print(f"  failed: {failure}")
        for key, what in (("above_band", "plain chi2"),
                          ("above_band_shared", "chi2 with the rig/camera covariance")):
            if key in summary:
                print(f"  above the push band ({what}): {summary[key]['above']} of "
                      f"{summary[key]['worlds']} worlds")
        print("  joint  worlds  MSE/sigma^2  95% interval    mean error/sigma")
        for name, j in summary["joints"].items():
            if not j.get("worlds"):
                print(f"  {name:5s}  {0:6d}  (not identifiable)")
                continue
            lo, hi = j["ci95"]
            print(f"  {name:5s}  {j['worlds']:6d}  {j['ratio']:11.2f}  {lo:5.2f} - {hi:5.2f}"
                  f"    {j['mean_z']:+.2f}")


EXTRA_OPTIONS: list[str] = []
"""More `hostpc calibrate` options for every run (--calibrate-args, e.g. '--poses 60')."""


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", type=int, default=8)
    parser.add_argument("--methods", default=",".join(METHODS))
    parser.add_argument("--first-seed", type=int, default=1)
    parser.add_argument("--keep", type=Path, default=None, help="keep the run folders here")
    parser.add_argument("--json", type=Path, default=None, help="write the figures here")
    parser.add_argument("--reuse", action="store_true",
                        help="with --keep: read runs already finished there instead of rerunning")
    parser.add_argument("--refit", action="store_true",
                        help="with --reuse: fit each kept dataset again with the current code")
    parser.add_argument("--calibrate-args", default="",
                        help="more hostpc calibrate options for every run, e.g. '--poses 60'")
    args = parser.parse_args(argv)
    EXTRA_OPTIONS[:] = shlex.split(args.calibrate_args)
    if args.worlds < 1:
        parser.error("--worlds: expected at least 1")
    methods = tuple(m for m in args.methods.split(",") if m)
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        parser.error(f"--methods: unknown {', '.join(unknown)} (expected {', '.join(METHODS)})")
    if args.refit and not (args.reuse and args.keep):
        parser.error("--refit: needs --keep DIR --reuse")
    figures = run(args.worlds, methods, args.first_seed, args.keep, args.reuse, args.refit)
    print_table(figures)
    if args.json:
        args.json.write_text(json.dumps(figures, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
