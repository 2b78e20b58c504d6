"""Robot time against its physical floor, per method, with the sigmas' honesty (issue 28).

For each method and held-out world seed k (default 201-240: the worlds tuned on were 1-40),
one default `hostpc calibrate --robot sim --method M --scenario <the method's world, seed k>`
(the worlds of `bench_sigma_mc.world`), then from its result.json:

- robot time (the simulator's clock: rig + measure + verify) and the plan's prediction;
- the floor: settle + capture of the fewest poses that reach the target sigma (the run's
  --target-sigma, else 0.002 deg) and of the verification poses, no motion
  (`hostpc.planning.robot_time`; the plan's `predicted_robot_time_s.floor`);
- poses (fit + verification) and the largest joint move between consecutive poses;
- MSE / sigma^2 of every identifiable joint offset over the worlds (`bench_sigma_mc.summarise`;
  honest: 0.6-1.5 over 40 worlds);
- stereo_target as on a line (default; --no-station: a rig calibrated in every world):
  one stereo camera mounted on robot after robot, its rig calibrated once (in a warm-up
  world, first seed - 1, not counted) and reused from the station's `--rig-cache` after a
  check against two fresh chessboard views per world, view 0 and the check view the cache
  stored (the table says so; docs/vision.md). The station shows the camera the same board
  poses in every world (the warm-up world's: the scenario's `chessboard.views_seed`);
  --fresh-board-poses: each world draws its own (the rig check may then add views); every
  world's
  fit then shares that rig's calibration error, as a line's robots do;
- verdict power (stereo_target only, the one hidden-effect world: `bench_verdicts.power`,
  the stereo_hidden_compliance world with --force: FAILs of --worlds forced pushes).

--all-joints: each method's all-joint plan instead (`all_joint_world`): the frames that make
every joint identifiable (J1 and J6; dual_loop's head and q1/q7) declared known and true (their
hidden errors zero); stereo_target a cell reference recorded in each world from a
commissioning run (its own rig; the recording is not counted; a commissioning run whose
verification FAILs is run once more with fresh noise, as a cell would, and the output lists
these reruns; a world whose second one FAILs too counts as failed, with that reason; a
failed verification is never recorded with --force). The plan aims its target
sigma at every joint; the power column gives the clean worlds' PASS count (issue 28 asks
these plans to meet the same floor).

    python bench/bench_robot_time.py [--worlds 40] [--first-seed 201] [--methods ...]
                                     [--jobs 2] [--json OUT] [--speed S] [--all-joints]

(--speed: the calibrations' `--speed`, default the CLI's; the verdict power's forced pushes
keep the default.)

Slow (one simulated calibration per world and method, 5-20 s each): bench/run.py runs it
only when named (`python bench/run.py robot_time`, 8 worlds by default).
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
from bench.bench_sigma_mc import summarise, world  # noqa: E402
from bench.bench_verdicts import power  # noqa: E402
from hostpc.planning.robot_time import largest_joint_moves  # noqa: E402

METHODS = ("stereo_target", "sphere_probe", "world_point", "dual_loop")
OPTIONAL = True
"""bench/run.py skips this module unless its name is asked for (slow)."""

ALL_JOINT_FRAMES: dict[str, tuple[tuple[str, ...], dict[str, Any]]] = {
    # the default tip sits on the flange axis, where no frame gives J6 (docs/calibrate.md):
    # the all-joint cell's stylus is off it, as tests/integration/test_calibrate_reference.py
    "sphere_probe": (("tool", "sphere"), {"probe": {
        "tip": [0.03, -0.02, 0.12], "tip_error": [0.0, 0.0, 0.0],
        "sphere_centre_error": [0.0, 0.0, 0.0]}}),
    "world_point": (("world", "markers"), {}),  # the default tracker's frames are true
    "dual_loop": (("camera", "left_base", "right_base", "left_target", "right_target"),
                  {"humanoid": {
                      "camera_error": {"xyz": [0.0, 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]},
                      "left_base_error": {"xyz": [0.0, 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]},
                      "right_base_error": {"xyz": [0.0, 0.0, 0.0], "rpy": [0.0, 0.0, 0.0]},
                      "left_target_error": [0.0, 0.0, 0.0],
                      "right_target_error": [0.0, 0.0, 0.0]}}),
}
"""Per method: the frames its all-joint plan declares known, and the scenario sections that
make them true (hidden errors zero). stereo_target has none: its camera frame is the rig's
left optical frame, which no housing survey gives (`--known tool` with a zero mount error is
still off by the rig's own error), so its all-joint cell is a reference (`stereo_reference`)."""
COMMISSIONING_ZEROS = [0.0, 0.0021, -0.0013, 0.0017, -0.0009, 0.0]
"""The zero errors (rad) of the run a stereo reference is recorded from: J1 and J6 good."""
COMMISSIONING_NOISE = (10000, 20000)
"""Noise seed offsets of a world's commissioning run and of its one rerun (the scenario's seed
draws only noise here: the zero errors are COMMISSIONING_ZEROS, the frames the scenario's)."""


def _calibrate(scenario: dict[str, Any], method: str, out: Path, options: list[str],
               speed: float | None) -> None:
    """`hostpc calibrate --robot sim --scenario` (written beside `out`) into `out`."""
    scenario_path = out.parent / f"{out.name}.yaml"
    scenario_path.write_text(yaml.safe_dump(scenario))
    subprocess.run([sys.executable, "-m", "hostpc.cli.main", "calibrate", "--robot", "sim",
                    "--method", method, "--scenario", str(scenario_path), "--no-report",
                    "--out", str(out), *options,
                    *(() if speed is None else ("--speed", str(speed)))],
                   cwd=ROOT, capture_output=True, text=True, check=False, timeout=900)


def _verdict(run: Path) -> str:
    """The commissioning run's verification in a few words ("FAIL, p=0.004")."""
    try:
        verify = json.loads((run / "result.json").read_text()).get("verify") or {}
    except (OSError, ValueError):
        return "no result.json"
    p_value = verify.get("p_value")
    return f"{verify.get('verdict')}{'' if p_value is None else f', p={p_value:.3g}'}"


def stereo_reference(seed: int, folder: Path, speed: float | None
                     ) -> tuple[list[str] | None, list[str]]:
    """stereo_target's all-joint options in world `seed` (None: no reference could be
    recorded), and the verdicts of the commissioning runs that were refused. A cell reference
    is recorded (`hostpc reference record`, never --force) from a commissioning run of the
    same cell (the world's frames and target, its own rig, zero errors COMMISSIONING_ZEROS,
    noise seed + COMMISSIONING_NOISE[0]); one whose verification FAILs (a false FAIL in
    alpha = 1 % of them) is run once more, as a cell would, with fresh noise (seed +
    COMMISSIONING_NOISE[1]) and the same truth."""
    refused: list[str] = []
    for attempt, noise in enumerate(COMMISSIONING_NOISE):
        scenario, options = world("stereo_target", seed + noise)
        scenario["truth"] = {**scenario["truth"], "zero_errors": COMMISSIONING_ZEROS}
        out = folder / f"stereo_target_{seed}_commissioning{'' if attempt == 0 else attempt}"
        _calibrate(scenario, "stereo_target", out, options, speed)
        reference = folder / f"stereo_target_{seed}_cell_ref.json"
        recorded = subprocess.run(
            [sys.executable, "-m", "hostpc.cli.main", "reference", "record", "--run",
             str(out), "--out", str(reference)],
            cwd=ROOT, capture_output=True, text=True, check=False, timeout=900)
        if recorded.returncode == 0:
            return [*options, "--reference", str(reference),
                    "--rig", str(reference.with_suffix(".rig.json"))], refused
        refused.append(_verdict(out))
    return None, refused


def all_joint_world(method: str, seed: int, folder: Path, speed: float | None = None
                    ) -> tuple[dict[str, Any], list[str] | None, list[str]]:
    """`method`'s world `seed` (`bench_sigma_mc.world`) as an all-joint cell: the frames of
    ALL_JOINT_FRAMES true and declared known, or stereo_target's `stereo_reference` (its
    options None if no reference was recorded, and its refused commissioning runs)."""
    scenario, options = world(method, seed)
    if method == "stereo_target":
        return scenario, *stereo_reference(seed, folder, speed)
    frames, sections = ALL_JOINT_FRAMES[method]
    for key, section in sections.items():
        scenario[key] = {**scenario.get(key, {}), **section}
    return scenario, ["--known", ",".join(frames)], []  # replaces world's one --known


def run_world(method: str, seed: int, folder: Path, speed: float | None = None,
              rig_cache: Path | None = None, all_joints: bool = False,
              views_seed: int | None = None) -> dict[str, Any]:
    """One default calibration in `method`'s world `seed` (at `speed`, None: the CLI's
    default; rig_cache: stereo_target's --rig-cache folder; all_joints: its all-joint cell,
    `all_joint_world`; views_seed: the chessboard's board poses, the station's): robot time,
    plan, errors; "commissioning": the refused commissioning runs' verdicts, if any."""
    refused: list[str] = []
    if all_joints:
        scenario, cell, refused = all_joint_world(method, seed, folder, speed)
        if cell is None:
            return {"failed": f"no cell reference: {len(refused)} commissioning runs "
                    f"refused ({'; '.join(refused)})", "commissioning": refused}
        options = cell
    else:
        scenario, options = world(method, seed)
    if rig_cache is not None:
        options = [*options, "--rig-cache", str(rig_cache)]
    if views_seed is not None:
        scenario["chessboard"] = {**scenario.get("chessboard", {}), "views_seed": views_seed}
    out = folder / f"{method}_{seed}"
    _calibrate(scenario, method, out, options, speed)
    try:
        document = json.loads((out / "result.json").read_text())
        parameters = json.loads((out / "fit.json").read_text())["parameters"]
    except (OSError, ValueError):
        return {"failed": "no result.json", "commissioning": refused}
    plan = document["plan"]
    names = [n.split(".", 1)[1] for n in parameters if n.startswith("joint_offsets.")]
    sigmas = [math.nan if parameters[f"joint_offsets.{n}"].get("std") is None
              else float(parameters[f"joint_offsets.{n}"]["std"]) for n in names]
    errors_deg = (document.get("truth") or {}).get("joint_offsets_error_deg") or []
    errors = [math.nan if e is None else math.radians(float(e)) for e in errors_deg[:len(names)]]
    header = json.loads((out / "run.json").read_text())
    moves = largest_joint_moves(np.asarray(header["initial"]["q"], float),
                                np.vstack([header["plan"]["q"], header["plan"]["q_verify"]]))
    planned = plan.get("predicted_robot_time_s") or {}
    return {"names": names, "errors": errors, "sigmas": sigmas,
            "robot_time": document["robot_time_s"]["total"],
            "rig": document["robot_time_s"]["rig"],
            "planned": planned.get("total"), "floor": planned.get("floor"),
            "poses": plan["n_poses"] + plan["n_verify"],
            "largest_move_deg": float(np.degrees(np.max(moves))),
            "verdict": (document.get("verify") or {}).get("verdict"),
            "commissioning": refused}


def run(worlds: int = 8, methods: tuple[str, ...] = METHODS, first_seed: int = 201,
        jobs: int = 2, speed: float | None = None, station: bool = True,
        all_joints: bool = False, fresh_board_poses: bool = False) -> dict[str, Any]:
    """{method: figures}; see the module docstring (station: stereo_target's worlds share
    one camera's cached rig, calibrated in a warm-up world first_seed - 1 not counted;
    all_joints: each method's all-joint cell, no verdict power)."""
    out: dict[str, Any] = {}
    with tempfile.TemporaryDirectory(prefix="zerocal-robot-time-") as tmp:
        folder = Path(tmp)
        for method in methods:
            seeds = range(first_seed, first_seed + worlds)
            cache = views_seed = None
            if method == "stereo_target" and station and not all_joints:  # one camera
                cache = folder / "rig-cache"
                views_seed = None if fresh_board_poses else first_seed - 1
                run_world(method, first_seed - 1, folder, speed, cache, views_seed=views_seed)
            with ThreadPoolExecutor(jobs) as pool:
                runs = list(pool.map(lambda s, m=method, c=cache, v=views_seed: run_world(
                    m, s, folder, speed, c, all_joints, v), seeds))
            good = [r for r in runs if "failed" not in r]
            times = np.array([r["robot_time"] for r in good])
            floors = np.array([r["floor"] for r in good if r["floor"] is not None])
            honesty = summarise(runs)
            out[method] = {
                "worlds": len(good), "failed": len(runs) - len(good),
                "robot_time_median": float(np.median(times)) if good else None,
                "robot_time_max": float(np.max(times)) if good else None,
                "rig_median": float(np.median([r["rig"] for r in good])) if good else None,
                "planned_median": float(np.median([r["planned"] for r in good
                                                    if r["planned"] is not None] or [np.nan])),
                "floor_median": float(np.median(floors)) if floors.size else None,
                "poses_median": float(np.median([r["poses"] for r in good])) if good else None,
                "largest_move_deg": max((r["largest_move_deg"] for r in good), default=None),
                "pass": sum(r["verdict"] == "PASS" for r in good),
                "mse_over_sigma2": {name: round(j["ratio"], 2)
                                    for name, j in honesty["joints"].items() if "ratio" in j},
            }
            by_world = dict(zip(seeds, runs, strict=True))
            reruns = [f"world {s}: {r['commissioning'][0]}" for s, r in by_world.items()
                      if r.get("commissioning")]
            if reruns:  # a cell runs a commissioning that FAILed once more (stereo_reference)
                out[method]["commissioning_reruns"] = reruns
            failures = {str(s): r["failed"] for s, r in by_world.items() if "failed" in r}
            if failures:
                out[method]["failures"] = failures
            if cache is not None:
                out[method]["rig"] = ("one camera's rig, calibrated in a warm-up world not "
                                      "counted, reused from the station's --rig-cache after "
                                      "a check of view 0 and the cache's check view, "
                                      + ("each world's own board poses" if fresh_board_poses
                                         else "the station's board poses in every world"))
                out[method]["rig_captures"] = [round(r["rig"] / 0.1) for r in good]
            print(f"  {method}: {out[method]}", file=sys.stderr, flush=True)
        if "stereo_target" in methods and not all_joints:
            forced = power(worlds, folder, first_seed)
            out["stereo_target"]["power"] = f"{forced['fails']} of {forced['runs']}"
    return out


def print_table(figures: dict[str, Any]) -> None:
    print("| method | worlds | robot time median / max (s) | of it rig | planned | floor | "
          "median x floor | poses | largest joint move | MSE/sigma^2 per offset | power |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for method, f in figures.items():
        if not f.get("worlds"):
            print(f"| {method} | 0 ({f.get('failed')} failed) |")
            continue
        ratio = f["robot_time_median"] / f["floor_median"] if f["floor_median"] else math.nan
        mse = ", ".join(f"{k} {v:.2f}" for k, v in f["mse_over_sigma2"].items())
        power = f.get("power", f"- ({f['pass']} of {f['worlds']} clean PASS)")
        print(f"| {method} | {f['worlds']} | {f['robot_time_median']:.1f} / "
              f"{f['robot_time_max']:.1f} | {f['rig_median']:.1f} | {f['planned_median']:.1f} "
              f"| {f['floor_median']:.1f} | {ratio:.1f}x | {f['poses_median']:.0f} | "
              f"{f['largest_move_deg']:.0f} deg | {mse} | {power} |")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", type=int, default=8)
    parser.add_argument("--first-seed", type=int, default=201)
    parser.add_argument("--methods", default=",".join(METHODS))
    parser.add_argument("--jobs", type=int, default=2, help="calibrations at a time")
    parser.add_argument("--json", metavar="OUT", help="also write the figures as JSON")
    parser.add_argument("--speed", type=float, help="the calibrations' --speed")
    parser.add_argument("--all-joints", action="store_true",
                        help="each method's all-joint cell: the frames that make every joint "
                        "identifiable known and true (stereo_target: a cell reference "
                        "recorded in each world)")
    parser.add_argument("--no-station", action="store_true",
                        help="stereo_target calibrates its rig in every world (default: one "
                        "camera's rig from a station's --rig-cache, as on a line)")
    parser.add_argument("--fresh-board-poses", action="store_true",
                        help="stereo_target's station worlds draw their own chessboard poses "
                        "(default: the warm-up world's, as a station shows them)")
    args = parser.parse_args(argv)
    figures = run(args.worlds, tuple(m for m in args.methods.split(",") if m),
                  args.first_seed, args.jobs, args.speed, not args.no_station,
                  args.all_joints, args.fresh_board_poses)
    print_table(figures)
    for method, f in figures.items():
        if f.get("rig"):
            captures = f["rig_captures"]
            print(f"{method}: {f['rig']}; rig check captures: " + ", ".join(
                f"{n} in {captures.count(n)} worlds" for n in sorted(set(captures))))
        if f.get("commissioning_reruns"):
            reruns = f["commissioning_reruns"]
            print(f"{method}: commissioning reruns: {len(reruns)} ({'; '.join(reruns)})")
        for seed, reason in (f.get("failures") or {}).items():
            print(f"{method}: world {seed} failed: {reason}")
    if args.json:
        Path(args.json).write_text(json.dumps(figures, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
