"""stereo_target: a stereo camera on the flange measures a fixed target point.

``KIND`` registers it (``hostpc.dataset.kind_registry``): the file face and model, the
acquisition (``method.py``, with the second centre pass in ``refinement.py``), the frames
``--known`` may hold, the ``--robot sim`` world: the stub's default scenario with the
target's centre error zero and ``target`` known (makes joint 1 identifiable), and its
``hostpc calibrate`` options (the rig, the depth method, the pixel floor dual_loop shares).
"""

from hostpc.dataset.kind_registry import KindDescriptor, KindOption, SimDefault
from hostpc.kinds.stereo_target.model import StereoTarget

DEPTH_OPTION = KindOption(
    "depth", choices=("triangulate", "sgbm"), default="triangulate", record_default=True,
    help="stereo depth method (default triangulate)")
PIXEL_FLOOR_OPTION = KindOption(
    "pixel_floor", metavar="PX", number=True, least=0.0,
    help="systematic floor (px per image coordinate) added to each measured covariance for "
    "rig calibration and detection errors (default 0.01 for stereo_target, 0 for "
    "dual_loop; 0 = image noise only)")
RIG_OPTION = KindOption(
    "rig", metavar="FILE", path=True,
    help="calibrated stereo rig JSON (default: calibrate from chessboard captures through "
    "the controller)")
RIG_CACHE_OPTION = KindOption(
    "rig_cache", metavar="DIR", path=True,
    help="a station's rig cache: the rig of the camera the controller names (camera_serial) "
    "is DIR/<serial>.json, reused when it still fits a fresh chessboard view, else "
    "calibrated and stored (default: calibrate in every run)")
RIG_COVERAGE_OPTION = KindOption(
    "rig_coverage", metavar="F", number=True, least=0.5, most=1.0,
    help="rig calibration: chessboard coverage to plan for (default 0.5)")

KIND = KindDescriptor(
    name="stereo_target", model=StereoTarget,
    method="hostpc.kinds.stereo_target.method:StereoTargetMethod",
    known_frames=("tool", "target"),
    sim=SimDefault(
        overrides={"motion": {"time_scale": 0.0}, "target": {"centre_error": [0.0, 0.0, 0.0]}},
        known=("target",)),
    cli_options=(DEPTH_OPTION, PIXEL_FLOOR_OPTION, RIG_OPTION, RIG_CACHE_OPTION,
                 RIG_COVERAGE_OPTION))
