"""Samples named so they can be traced back: every sample of one pose as that pose.

A pose measured with several markers (three reflectors on the flange) gives one sample per
marker; when a pose's joint reading is wrong, every one of its samples is an outlier, and
naming them one by one hides that there is one measurement to check. Poses are found as
the fit's folds find them (``hostpc.fitting.folds.pose_groups``) and numbered ``#0..`` in
the order they first appear in the dataset (as samples are).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from hostpc.dataset import Samples
from hostpc.fitting.folds import pose_groups


def _span(indices: list[int]) -> str:
    """'#33-#35' for consecutive indices, else '#3, #7'."""
    if len(indices) > 1 and indices[-1] - indices[0] == len(indices) - 1:
        return f"#{indices[0]}-#{indices[-1]}"
    return ", ".join(f"#{i}" for i in indices)


def whole_poses(indices: Iterable[int], samples: Samples) -> dict[int, list[int]]:
    """{pose number: its samples} for each pose of more than one sample all of whose
    samples are in ``indices`` (pose numbers in order of first appearance)."""
    chosen = sorted({int(i) for i in indices})
    if not chosen:
        return {}
    groups = pose_groups(samples)
    _, first = np.unique(groups, return_index=True)
    order = np.empty(first.size, dtype=np.int64)
    order[np.argsort(first)] = np.arange(first.size)  # group id -> number by appearance
    poses: dict[int, list[int]] = {}
    for group in sorted({int(groups[i]) for i in chosen}, key=lambda g: int(order[g])):
        members = [int(i) for i in np.flatnonzero(groups == group)]
        if len(members) > 1 and set(members) <= set(chosen):
            poses[int(order[group])] = members
    return poses


def poses_text(poses: dict[int, list[int]]) -> str:
    """'pose #11 (samples #33-#35, every sample of it)' for each of ``whole_poses``."""
    return ", ".join(f"pose #{pose} (samples {_span(members)}, every sample of it)"
                     for pose, members in poses.items())


def name_samples(indices: Iterable[int], samples: Samples) -> str:
    """The samples ``indices`` (dataset indices), a whole pose as 'pose #11 (samples
    #33-#35, every sample of it)', the rest as '#85'."""
    chosen = sorted({int(i) for i in indices})
    poses = whole_poses(chosen, samples)
    grouped = {i for members in poses.values() for i in members}
    parts = [poses_text(poses)] if poses else []
    parts += [f"#{i}" for i in chosen if i not in grouped]
    return ", ".join(parts)
