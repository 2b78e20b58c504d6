"""How many poses `hostpc calibrate` measures when the user does not say.

- A method with a default target sigma (stereo_target: 0.002 deg) measures the fewest fit
  poses that reach it, at most --poses (default 60), unless --poses alone asks for a fixed
  count (the behaviour before the short plan: exactly N poses);
- with a target sigma the verification takes the fewest poses whose chi-square test has
  95 % power for an error of d2 = 10 per pose at the run's --verify-alpha
  (hostpc.planning.verify_poses: 4 at alpha 0.01, 5 at 0.001; stereo_target, whose short
  plan chooses them for power, 94 %, `ShortPlan.verify_power`: 3 at 0.01), else 10; a
  method that plans whole groups of poses (sphere_probe) takes whole groups for both (the fewest
  orientations that reach the sigma; verification: 3 contacts, one orientation).
"""

from __future__ import annotations

import argparse

from hostpc.methods import method_class
from hostpc.model.measurements.registry import measurement_model
from hostpc.planning.verify_poses import DETECTABLE_POWER, verify_poses_for_power

DEFAULT_MAX_POSES = 60
"""Fit poses without --poses: the most with a target sigma, else the count."""
DEFAULT_VERIFY_POSES = 10
"""Verification poses without --verify-poses and without a target sigma."""
VERIFY_ALPHA = 0.01
"""The verification's false-FAIL rate without --verify-alpha (hostpc.calibrate.verify)."""


def _measured_per_pose(args: argparse.Namespace) -> int:
    """Coordinates one verification pose adds to the chi-square test: the method's
    measurement size (per sample; stereo_target: a 3-D point). A kind that measures several
    samples per pose adds more, so its pose count is on the safe side."""
    return measurement_model(args.method, tuple(args.plugin)).measurement_size


def pose_counts(args: argparse.Namespace) -> tuple[int, int, float | None]:
    """(fit poses, verification poses, target sigma in deg or None) from the options and
    the method's defaults: a method with a default target sigma (stereo_target) stops at
    it unless --poses alone asks for a fixed count; with a target sigma the verification
    takes the poses its power needs (hostpc.planning.verify_poses), else 10."""
    method = method_class(args.method, tuple(args.plugin))
    target = args.target_sigma
    if target is None and args.poses is None:
        target = method.default_target_sigma_deg
    poses = DEFAULT_MAX_POSES if args.poses is None else args.poses
    verify = args.verify_poses
    if verify is None:
        alpha = VERIFY_ALPHA if args.verify_alpha is None else float(args.verify_alpha)
        power = method.short_plan.verify_power or DETECTABLE_POWER  # stereo_target: 3
        verify = (verify_poses_for_power(power=power, alpha=alpha, m=_measured_per_pose(args))
                  if target is not None else DEFAULT_VERIFY_POSES)
    return poses, verify, target
