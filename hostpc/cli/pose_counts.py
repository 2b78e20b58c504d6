"""How many poses `hostpc calibrate` measures when the user does not say.

- A method with a default target sigma (stereo_target: 0.002 deg) measures the fewest fit
  poses that reach it, at most --poses (default 60), unless --poses alone asks for a fixed
  count (the behaviour before the short plan: exactly N poses);
- with a target sigma the verification takes the fewest poses whose chi-square test has
  95 % power for an error of d2 = 10 per pose (hostpc.planning.verify_poses: 4), else 10.
"""

from __future__ import annotations

import argparse

from hostpc.methods import method_class
from hostpc.planning.verify_poses import verify_poses_for_power

DEFAULT_MAX_POSES = 60
"""Fit poses without --poses: the most with a target sigma, else the count."""
DEFAULT_VERIFY_POSES = 10
"""Verification poses without --verify-poses and without a target sigma."""


def pose_counts(args: argparse.Namespace) -> tuple[int, int, float | None]:
    """(fit poses, verification poses, target sigma in deg or None) from the options and
    the method's defaults: a method with a default target sigma (stereo_target) stops at
    it unless --poses alone asks for a fixed count; with a target sigma the verification
    takes the poses its power needs (hostpc.planning.verify_poses), else 10."""
    target = args.target_sigma
    if target is None and args.poses is None:
        target = getattr(method_class(args.method), "default_target_sigma_deg", None)
    poses = DEFAULT_MAX_POSES if args.poses is None else args.poses
    verify = args.verify_poses
    if verify is None:
        verify = verify_poses_for_power() if target is not None else DEFAULT_VERIFY_POSES
    return poses, verify, target
