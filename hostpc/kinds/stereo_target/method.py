"""stereo_target: a stereo camera on the flange measures a fixed circular target.

Per pose: move, capture a stereo pair, detect the dot in both images, triangulate its
centre in the LEFT camera optical frame (`hostpc.vision.TargetMeasurer`), and record the
sample `q` (joint angles at exposure), `p` (m), `cov` (m^2), `uv` (px), `t` (s since the
run started) and `approach` (sign of each joint's last motion). A target the vision
rejects is journaled as skipped with the reason.

The rig: `--rig FILE` (copied into the run folder), else with `--rig-cache DIR` the cached
rig of the camera the controller names if it still fits a fresh chessboard view
(`rig_cache.py`), else calibrated first from the controller's chessboard captures
(`capture("chessboard", view)` for every view the cell's chessboard description lists); saved
as `rig.json` in the run folder; a resume reuses it.

Dataset frames: `tool` = left camera optical frame in the flange frame (nominal mount from
the cell), `target` = target centre in base (nominal from the cell); `known` from the cell.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from hostpc.dataset import Dataset, RobotDescription
from hostpc.errors import ControllerError, InputError, ZerocalError
from hostpc.files import write_json_atomic
from hostpc.kinds.stereo_target.sample import StereoSample, stereo_samples
from hostpc.kinematics import forward, get_robot, invert_transform, pose_to_transform
from hostpc.methods.approach_moves import ApproachMoves
from hostpc.methods.base import (
    Method,
    Phase,
    Progress,
    SampleRecord,
    floats,
    matrix,
)
from hostpc.methods.cell import require_camera_cell
from hostpc.model.measurements.predict import predict
from hostpc.model.problem import build_problem
from hostpc.planning.design import ShortPlan, look_at_candidates
from hostpc.robots.base import RobotAdapter, RobotState

if TYPE_CHECKING:  # OpenCV's layer, loaded by prepare
    from hostpc.vision import TargetMeasurer

RIG_FILE = "rig.json"
RIG_REPORT_FILE = "rig_calibration.json"
CENTROID_SIGMA_PX = 0.05
"""Planning noise model without a calibrated rig: pixel precision of the dot centre in
each image (conservative, a real camera's; the simulator's images are better);
`planning_sigma_px` takes the rig's measured RMS instead (CENTRE_PER_CORNER)."""
CENTRE_PER_CORNER = 0.25
"""The dot centre's pixel sigma per unit of the rig calibration's reprojection RMS (a
chessboard corner's). Both scale with the camera's grey-level noise over its edge
gradient; the dot's centroid averages some hundred edge pixels, a corner a few. Measured
in the simulator: the detector states 0.0057-0.0083 px per image coordinate (a 47-23 px
radius dot at 0.3-0.6 m) against a rig RMS of 0.030 px, 0.19-0.28 of it."""
PIXEL_FLOOR_PX = 0.01
"""Floor added to every measured covariance, in px per image coordinate (independent per
sample): a weighting, and what the push's chi2/dof band sees. The reported covariance takes
it back out (the dataset's `rig_uncertainty` block declares it; hostpc.fitting.shared_errors
reports the sandwich for the pixel noise plus the rig's shared error, scaled by the fit's
residuals): docs/vision.md section 3.3."""
"""Controller refusals that skip one pose instead of ending the run."""


class RigCalibrationFailed(ZerocalError):
    """The stereo rig could not be calibrated from the chessboard captures."""

    exit_code = 4


class StereoTargetMethod(Method):
    """See the module docstring. options: `rig` (path of a rig file), `depth`
    ("triangulate" or "sgbm"), `distance` ([min, max] m of the viewpoints), `pixel_floor`
    (px, the systematic floor added to each measured covariance), `rig_coverage` (the
    chessboard coverage the rig calibration plans for, rig_planning.TARGET_COVERAGE)."""

    name: ClassVar[str] = "stereo_target"
    default_target_sigma_deg: ClassVar[float | None] = 0.002
    staged: ClassVar[bool] = True
    short_plan: ClassVar[ShortPlan] = ShortPlan(selection="per_second", shorten="selection",
                                                verify_power=0.94)  # 3 verification poses

    @classmethod
    def short_plan_warning(cls, n_fit: int) -> str | None:
        """Below the centre refinement's MIN_SAMPLES the disk centres keep the nominal
        normal's bias (docs/vision.md 3.2)."""
        from hostpc.kinds.stereo_target.refinement import MIN_SAMPLES

        if n_fit >= MIN_SAMPLES:
            return None
        return (f"plan: {n_fit} fit poses, fewer than the {MIN_SAMPLES} the centre "
                "refinement needs: the disk centres keep the nominal normal's bias and "
                "the sigmas may be too small")

    def __init__(self, settings: Any, cell: Any, run_dir: Path) -> None:
        super().__init__(settings, cell, run_dir)
        self.rig: Any = None
        self.rig_report: dict[str, Any] = {}
        self.rig_plan: dict[str, Any] = {}
        self._measurer: TargetMeasurer | None = None
        self._tool, self._target = require_camera_cell(cell)
        tool = self._tool
        self._chain = get_robot(cell.robot)
        self._T_flange_tool = pose_to_transform(tool.xyz, tool.rpy)
        self._t0: float = 0.0
        # an approach-dependent effect (backlash) in the model: each joint arrives from
        # both sides, through via-points where needed (methods/approach_moves.py)
        self._moves = ApproachMoves(settings, self._chain)
        self._joint_estimate = np.zeros(self._chain.n)  # set_joint_estimate
        # (effects, x) of the frames the last refined set's own fit found (samples_dataset)
        self._fitted_frames: tuple[tuple[str, ...], np.ndarray] | None = None

    def set_joint_estimate(self, estimate: np.ndarray, new_stage: bool = False) -> None:
        """The joints are about `estimate` off (staging): the plate normal the detector
        corrects the disk centre with is taken where the robot is, not where it reads (a
        staged run's model check reads 15 deg off; its verify set is too small for the
        refinement's own fit)."""
        self._joint_estimate = np.asarray(estimate, float)

    # ---------------------------------------------------------------- set-up

    @property
    def rig_path(self) -> Path:
        return self.run_dir / RIG_FILE

    def sample_clock(self) -> StereoTargetMethod:
        return self

    def set_time_origin(self, t0: float) -> None:
        """Controller time (s) at the start of the run: sample `t` counts from here."""
        self._t0 = float(t0)

    def check_inputs(self) -> None:
        """Load --rig now so that a bad file fails before anything moves (exit code 2)."""
        from hostpc.vision import load_rig

        rig_option = self.settings.options.get("rig")
        if rig_option and not self.rig_path.is_file():
            self.rig = load_rig(rig_option)
        cache = self.settings.options.get("rig_cache")
        if cache and not rig_option and not self.rig_path.is_file():
            from hostpc.kinds.stereo_target.rig_cache import check_folder

            problem = check_folder(cache)
            if problem:
                raise InputError(problem)
        depth = self.settings.options.get("depth", "triangulate")
        if depth not in ("triangulate", "sgbm"):
            raise InputError(f"--depth {depth!r}: expected triangulate or sgbm")

    async def prepare(self, robot: RobotAdapter, progress: Progress) -> None:
        """Load the run's rig, or the --rig file, or calibrate one from chessboard views."""
        from hostpc.vision import TargetMeasurer, load_rig, save_rig

        if self.rig_path.is_file():
            self.rig = load_rig(self.rig_path)
            self._rig_report_of_this_run()
            progress.message(f"rig: {self.rig_path} (from this run)")
        elif self.settings.options.get("rig"):
            if self.rig is None:
                self.rig = load_rig(self.settings.options["rig"])
            save_rig(self.rig, self.rig_path)
            progress.message(f"rig: {self.settings.options['rig']}")
        else:
            cached = await self._cached_rig(robot, progress)
            self.rig = cached if cached is not None else await self._calibrate_rig(robot,
                                                                                  progress)
            save_rig(self.rig, self.rig_path)  # the run's own rig.json first
            if cached is None:
                self._store_in_cache(progress)
        if self.cell.image_size and tuple(self.rig.image_size) != tuple(self.cell.image_size):
            raise InputError(
                f"rig image size {self.rig.image_size[0]}x{self.rig.image_size[1]} differs "
                f"from the camera's {self.cell.image_size[0]}x{self.cell.image_size[1]}: "
                "wrong --rig file?"
            )
        depth = self.settings.options.get("depth", "triangulate")
        self._measurer = TargetMeasurer(self.rig, self.cell.target_radius, depth=depth)

    def _rig_report_of_this_run(self) -> None:
        """A resumed run: what rig_calibration.json says of its rig (calibrated or cached)."""
        import json

        try:
            report = json.loads((self.run_dir / RIG_REPORT_FILE).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return
        if isinstance(report, dict):
            self.rig_report = report

    def rig_source(self) -> str:
        """Which rig the run used, as summary.txt says it: cached FILE, calibrated in this
        run, --rig FILE."""
        if self._cached_rig_used():
            captures = self.rig_report.get("captures")
            return f"cached {self._cached_rig_used()}" + (
                f" ({captures}-capture check)" if captures else "")
        if "rms_px" in self.rig_report:
            return "calibrated in this run"
        if self.settings.options.get("rig"):
            return f"--rig {self.settings.options['rig']}"
        return f"{self.rig_path}"

    def _cached_rig_used(self) -> str | None:
        """The cached rig file the run used (it fit), None if it used none."""
        cached = self.rig_report.get("cached")
        return str(cached) if cached and self.rig_report.get("fits") else None

    def refusal_hint(self) -> str | None:
        """A cached rig is the first suspect of a refused push: say which file, and how
        to do without it, before --force."""
        cached = self._cached_rig_used()
        if not cached:
            return None
        return (f"the rig was the cached {cached}: rerun without --rig-cache, or delete "
                f"{cached}, before --force")

    def _store_in_cache(self, progress: Progress) -> None:
        """Store the rig just calibrated in the rig cache; a failed write is a warning (the
        run has its own rig.json)."""
        from hostpc.kinds.stereo_target.rig_cache import CHECK_VIEW_KEY
        from hostpc.vision import save_rig

        path = self._rig_cache_file
        if path is None:
            return
        check_view = self.rig_report.get(CHECK_VIEW_KEY)
        try:
            save_rig(self.rig, path, {CHECK_VIEW_KEY: check_view} if check_view else None)
        except InputError as exc:
            progress.message(f"warning: rig not stored in the cache: {exc}")
            return
        progress.message(f"rig: stored in the cache as {path}")

    @property
    def _rig_cache_file(self) -> Path | None:
        """The cached rig of this camera (option rig_cache, the controller's camera_serial:
        rig_cache.py), None without either."""
        from hostpc.kinds.stereo_target.rig_cache import cache_path

        folder = self.settings.options.get("rig_cache")
        serial = self.cell.raw.get("camera_serial")
        if not folder or not isinstance(serial, str) or not serial.strip():
            return None
        return cache_path(folder, serial)

    async def _cached_rig(self, robot: RobotAdapter, progress: Progress) -> Any:
        """The cached rig of this camera if it still fits fresh chessboard views (rig_cache.py:
        view 0 and the cache file's check view, or views 0..CHECK_VIEWS-1 for a file without
        one), else None (the run then calibrates one)."""
        from hostpc.kinds.stereo_target.rig_cache import check_rig, load_cached

        path, board = self._rig_cache_file, self.cell.chessboard
        if path is None and self.settings.options.get("rig_cache"):
            progress.message("rig: the controller reports no camera_serial, so --rig-cache "
                             "is not used: calibrating")
        if path is None or not board:
            return None
        camera = path.stem
        if not path.is_file():
            progress.message(f"rig: none cached for camera {camera} ({path}): calibrating")
            return None
        try:
            rig, check_view = load_cached(path, self._board_views(board)[1])
        except InputError as exc:
            progress.message(f"rig: the cached rig is unusable ({exc}): calibrating anew")
            return None
        if self.cell.image_size and tuple(rig.image_size) != tuple(self.cell.image_size):
            progress.message(f"rig: the cached rig {path} is for another image size "
                             f"({rig.image_size[0]}x{rig.image_size[1]}): calibrating anew")
            return None
        spec = self._board_spec(board)

        async def capture(view: int) -> tuple[Any, Any]:
            return (await self._chessboard_view(robot, view, spec))[1]

        check = await check_rig(rig, spec.object_points(), check_view, capture)
        self.rig_report = {"cached": str(path), **check.report()}
        if not check.fits:
            progress.message(f"rig: the cached rig {path} does not fit {check.said()}: "
                             "calibrating anew")
            return None
        write_json_atomic(self.run_dir / RIG_REPORT_FILE, self.rig_report)
        progress.message(f"rig: cached for camera {camera} ({path}), fits {check.said()}")
        return rig

    @staticmethod
    def _board_views(board: Mapping[str, Any]) -> tuple[int, int]:
        """(the views a rig calibration plans, the views the controller offers) of the cell's
        chessboard description."""
        n_views = int(board.get("n_views", 20))
        return n_views, max(n_views, int(board.get("max_views", n_views)))

    @staticmethod
    def _board_spec(board: Mapping[str, Any]) -> Any:
        """The ChessboardSpec of the cell's chessboard description."""
        from hostpc.vision import ChessboardSpec

        return ChessboardSpec(int(board["cols"]), int(board["rows"]),
                              float(board["square_size"]))

    @staticmethod
    async def _chessboard_view(robot: RobotAdapter, view: int, spec: Any
                               ) -> tuple[tuple[np.ndarray, np.ndarray], tuple[Any, Any]]:
        """Chessboard view `view` captured: its (left, right) grey images and the corners
        found in each (None where the board was not found)."""
        from hostpc.vision.rig_calibration import as_gray, find_chessboard

        capture = await robot.capture("chessboard", view)
        left, right = as_gray(capture.left, "left"), as_gray(capture.right, "right")
        return (left, right), (find_chessboard(left, spec), find_chessboard(right, spec))

    async def _calibrate_rig(self, robot: RobotAdapter, progress: Progress) -> Any:
        from hostpc.vision import calibrate_rig
        from hostpc.vision.rig_planning import TARGET_COVERAGE, CoveragePlanner

        board = self.cell.chessboard
        if not board:
            raise InputError("no --rig given and the controller describes no chessboard to "
                             "calibrate one; give --rig FILE")
        n_views, max_views = self._board_views(board)
        spec = self._board_spec(board)
        progress.stage("rig calibration", n_views)
        pairs, corners, planner = [], [], None
        for view in range(max_views):
            if planner is not None and planner.done():
                break
            (left, right), found = await self._chessboard_view(robot, view, spec)
            if planner is None:
                planner = CoveragePlanner(n_views, (left.shape[1], left.shape[0]), float(
                    self.settings.options.get("rig_coverage", TARGET_COVERAGE)))
            if planner.offer(view, *found):
                pairs.append((left, right))
                corners.append(found)  # detected once: calibrate_rig reuses them
            covered = min(planner.coverage)
            progress.advance(min(len(pairs), n_views),
                             f"chessboard view {view + 1}: {len(pairs)} kept, "
                             f"coverage {100 * covered:.0f}%")
        assert planner is not None
        self.rig_plan = {"views_kept": list(planner.kept),
                         "views_rejected": [[v, r] for v, r in planner.rejected],
                         "coverage": list(planner.coverage)}
        if not pairs:
            raise RigCalibrationFailed(
                f"stereo rig calibration failed: the chessboard was found in none of the "
                f"{len(planner.rejected)} views")
        progress.stage("rig solve")
        result = calibrate_rig(pairs, spec, corners)
        self.rig_report = {
            **({"cache_check": self.rig_report} if self.rig_report else {}),  # did not fit
            **self._check_view(result, spec, planner.kept, corners),
            "ok": bool(result.ok),
            "rms_px": float(result.rms),
            "per_view_rms_px": [float(v) for v in result.per_view_rms],
            "used_views": [int(v) for v in result.used_views],
            "warnings": [str(w) for w in result.warnings],
            "corner_sigma_px": result.corner_sigma_px,
            "plan": self.rig_plan,
        }
        write_json_atomic(self.run_dir / RIG_REPORT_FILE, self.rig_report)
        for warning in result.warnings:
            progress.message(f"rig calibration: {warning}")
        if not result.ok:
            raise RigCalibrationFailed(
                f"stereo rig calibration failed (RMS {result.rms:.3f} px, "
                f"{len(result.used_views)} of {len(pairs)} views usable): "
                + ("; ".join(result.warnings) or "see rig_calibration.json")
            )
        progress.message(f"rig calibrated: RMS {result.rms:.3f} px from "
                         f"{len(result.used_views)} views, baseline "
                         f"{result.rig.baseline * 1e3:.2f} mm")
        return result.rig

    def _check_view(self, result: Any, spec: Any, kept: Sequence[int],
                    corners: Sequence[tuple[Any, Any]]) -> dict[str, Any]:
        """{CHECK_VIEW_KEY: ...} of a rig calibrated for the rig cache: the calibration's
        used view a later run's 2-capture check captures besides view 0
        (rig_cache.choose_check_view); {} without a cache."""
        from hostpc.kinds.stereo_target.rig_cache import CHECK_VIEW_KEY, choose_check_view

        if self._rig_cache_file is None:
            return {}
        chosen = choose_check_view(result.rig, spec.object_points(),
                                   [(kept[i], corners[i][0]) for i in result.used_views])
        return {} if chosen is None else {CHECK_VIEW_KEY: chosen}

    # ---------------------------------------------------------------- planning

    def _right_centre(self) -> np.ndarray:
        """(3,) right camera centre in the left camera frame (m)."""
        return np.asarray(-self.rig.R.T @ self.rig.T, float)

    def candidates(self, state: RobotState, rng: np.random.Generator) -> np.ndarray:
        """Look-at poses around the target, kept only if the dot projects well inside both
        images (nominal model, rig intrinsics) at a usable depth."""
        self._moves.bound(state.q_min, state.q_max)
        baseline = self.rig.baseline
        distance = self.settings.options.get("distance") or (max(0.25, 2.5 * baseline),
                                                             max(0.5, 5.0 * baseline))
        q = look_at_candidates(
            self._chain, self._T_flange_tool, self._target, self.cell.target_normal,
            int(self.settings.n_candidates * 1.25), rng, state.q, state.q_min, state.q_max,
            distance=(float(distance[0]), float(distance[1])),
            aim_offset=0.5 * self._right_centre(),
        )
        if q.shape[0] == 0:
            return q
        visible = self.visible(q)
        return q[visible][: self.settings.n_candidates]

    def target_in_camera(self, q: np.ndarray) -> np.ndarray:
        """(N, 3) nominal target position in the left camera frame at poses q (N, n)."""
        T_base_tool = forward(self._chain, q).T_base_flange @ self._T_flange_tool
        T_tool_base = invert_transform(T_base_tool)
        return (np.einsum("nij,j->ni", T_tool_base[:, :3, :3], self._target)
                + T_tool_base[:, :3, 3])

    def normal_in_camera(self, q: np.ndarray) -> np.ndarray:
        """(3,) the target plate normal in the left camera frame at pose q (n,), nominal."""
        T_base_tool = forward(self._chain, np.asarray(q, float)[None, :]).T_base_flange[0] \
            @ self._T_flange_tool
        return np.asarray(T_base_tool[:3, :3].T @ self.cell.target_normal, float)

    def visible(self, q: np.ndarray) -> np.ndarray:
        """(N,) the dot (with a margin of twice its radius) inside both images, in front."""
        p_left = self.target_in_camera(q)
        p_right = p_left @ self.rig.R.T + self.rig.T
        width, height = self.rig.image_size
        ok = np.ones(q.shape[0], dtype=bool)
        for p, K in ((p_left, self.rig.K_left), (p_right, self.rig.K_right)):
            z = p[:, 2]
            front = z > 0.05
            zs = np.where(front, z, 1.0)
            u = K[0, 0] * p[:, 0] / zs + K[0, 2]
            v = K[1, 1] * p[:, 1] / zs + K[1, 2]
            margin = K[0, 0] * 2.5 * self.cell.target_radius / zs + 10.0
            ok &= front & (u > margin) & (u < width - margin) & (v > margin) & (
                v < height - margin)
        return ok

    def expected_covariance(self, p: np.ndarray, sigma_px: float = CENTROID_SIGMA_PX
                            ) -> np.ndarray:
        """(N, 3, 3) covariance of points p (N, 3) in the left camera frame triangulated
        from image centres with sigma_px per coordinate: lateral z*s/f, depth
        z^2*sqrt(2)*s/(f*b) (diagonal approximation)."""
        f = float(self.rig.K_left[0, 0])
        b = self.rig.baseline
        z = np.maximum(np.abs(p[:, 2]), 1e-3)
        cov = np.zeros((p.shape[0], 3, 3))
        lateral = z * sigma_px / f
        cov[:, 0, 0] = cov[:, 1, 1] = lateral**2
        cov[:, 2, 2] = (z**2 * np.sqrt(2.0) * sigma_px / (f * b)) ** 2
        return cov

    @property
    def planning_sigma_px(self) -> float:
        """The pixel noise the plan assumes per image coordinate: what each sample's
        covariance will hold, the dot centre's noise and the systematic floor added to it
        (`pixel_floor`) in quadrature. The dot centre's is CENTRE_PER_CORNER x the rig
        calibration's reprojection RMS when there is one (measured on this camera, this run
        or the station's --rig file: 0.030 px in the simulator, 0.0075 px for the centre,
        0.0125 px with the floor; a real camera's more, which plans more poses), else
        CENTROID_SIGMA_PX. The fit reports its own sigma from the measurements; the bench
        (bench/bench_robot_time.py) prints both."""
        rms = float(getattr(self.rig, "rms", 0.0) or 0.0)
        centre = CENTRE_PER_CORNER * rms if rms > 0.0 else CENTROID_SIGMA_PX
        return float(np.hypot(centre, self.pixel_floor))

    @property
    def pixel_floor(self) -> float:
        """The systematic floor (px) added to measured covariances (option pixel_floor)."""
        return float(self.settings.options.get("pixel_floor", PIXEL_FLOOR_PX))

    def design_dataset(self, q: np.ndarray) -> Dataset:
        """Nominal predicted points at q (N, n) with the planning covariance."""
        n = q.shape[0]
        placeholder = self.samples_dataset(
            [StereoSample(q=floats(row), p=(0.0, 0.0, 0.5), cov=matrix(np.eye(3) * 1e-8))
             for row in q])
        problem = build_problem(placeholder, "joint_offsets")
        p, _ = predict(problem, np.zeros(problem.layout.size), jacobian=False)
        cov = self.expected_covariance(p, self.planning_sigma_px)
        return self.samples_dataset(
            [StereoSample(q=floats(q[k]), p=floats(p[k]), cov=matrix(cov[k]), t=float(k))
             for k in range(n)])

    # ---------------------------------------------------------------- acquisition

    async def acquire(self, robot: RobotAdapter, phase: Phase, index: int, q: np.ndarray,
                      q_from: np.ndarray | None) -> SampleRecord:
        """Move to q, capture, detect and triangulate (see the module docstring)."""
        from hostpc.vision import TargetRejected

        outcome = await self._moves.move(robot, phase, index, q, q_from)
        if isinstance(outcome, SampleRecord):
            return outcome
        capture = await robot.capture("target")
        if self._measurer is None:
            raise ControllerError("stereo_target: prepare() was not run")
        observation = self._measurer.measure(
            capture.left, capture.right,
            normal_hint=self.normal_in_camera(np.asarray(capture.q, float)
                                              + self._joint_estimate))
        if isinstance(observation, TargetRejected):
            return SampleRecord(phase, index, False,
                                reason=f"target rejected: {observation.reason}",
                                q_end=outcome.q.tolist())
        p = np.asarray(observation.p, float)
        cov = np.asarray(observation.cov, float)
        if self.pixel_floor > 0:
            cov = cov + self.expected_covariance(p[None, :], self.pixel_floor)[0]
        sample = StereoSample(
            q=floats(capture.q), p=floats(p), cov=matrix(cov),
            t=float(capture.t) - self._t0,
            approach=floats(self._moves.signs(q_from, capture.q)),
            uv=None if observation.uv is None else matrix(observation.uv))
        return SampleRecord.measured(phase, index, sample, q_end=outcome.q.tolist())

    # ---------------------------------------------------------------- dataset

    def dataset_document(self, samples: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
        """The samples as a `zerocal-dataset/1` document (`dataset`, written)."""
        from hostpc.dataset import dataset_to_dict

        return dataset_to_dict(self.dataset(samples))

    def dataset(self, samples: Sequence[Mapping[str, Any]]) -> Dataset:
        """The journaled samples as a Dataset with the cell's nominal frames and `known`,
        built from the typed samples; the disk centres re-corrected with the normals of a
        preliminary fit when every sample carries `uv`
        (hostpc.kinds.stereo_target.refinement)."""
        return self.samples_dataset([StereoSample.from_json(s) for s in samples])

    def samples_dataset(self, typed: Sequence[StereoSample]) -> Dataset:
        """`dataset` of typed samples."""
        dataset = Dataset(
            method=self.name, robot=RobotDescription(name=self.cell.robot),
            frames={"tool": self._tool, "target": self._target},
            samples=stereo_samples(typed, self._chain.n), known=tuple(self.cell.known),
            extra_fields=self._rig_uncertainty())
        if self.rig is None or not typed or any(s.uv is None for s in typed):
            return dataset
        from hostpc.kinds.stereo_target.refinement import (
            MIN_SAMPLES,
            frames_only,
            refine_dataset,
        )

        # each set of MIN_SAMPLES or more by its own preliminary fit; a smaller one (the 4
        # verification poses of a plan) by the frames of the last such fit, the joints
        # where the robot is (never that fit's joint offsets: a push moved them into the
        # readings); left as measured before any. Staged: refined where the robot is (the
        # detector's normal hint was taken there)
        shift = self._joint_estimate
        q = np.asarray(dataset.samples.q, float)
        shifted = dataset.with_samples(dataclasses.replace(dataset.samples, q=q + shift))
        small = len(typed) < MIN_SAMPLES
        refined, fitted = refine_dataset(shifted, self.rig, self.cell.target_radius,
                                         self.cell.target_normal,
                                         self._fitted_frames if small else None)
        if not small and fitted is not None:
            self._fitted_frames = frames_only(shifted, fitted)
        return refined.with_samples(dataclasses.replace(refined.samples, q=q))

    def _rig_uncertainty(self) -> dict[str, Any]:
        """The dataset's `rig_uncertainty` block (the rig and its calibration covariance,
        hostpc.fitting.shared_errors), or nothing for a rig without a covariance."""
        if self.rig is None or self.rig.covariance is None:
            return {}
        from hostpc.vision.rig_uncertainty import uncertainty_document

        return {"rig_uncertainty": uncertainty_document(self.rig, self.rig.covariance,
                                                        self.pixel_floor)}

    def describe(self) -> dict[str, Any]:
        """Rig facts for the result document."""
        if self.rig is None:
            return {}
        return {
            "rig": {"file": str(self.rig_path), "rms_px": float(self.rig.rms),
                    "baseline_mm": self.rig.baseline * 1e3,
                    "image_size": list(self.rig.image_size), "source": self.rig_source(),
                    "calibrated_in_this_run": "rms_px" in self.rig_report,
                    "cached": self._cached_rig_used()},
            "depth": self.settings.options.get("depth", "triangulate"),
            "pixel_floor_px": self.pixel_floor,
        }
