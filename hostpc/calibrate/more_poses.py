"""More fit poses when a short plan's model fails (the runner's diagnostics safeguard).

A target-sigma plan (stereo_target's default) measures the fewest poses that reach the
sigma: enough to fit a model that is right, too few for `hostpc diagnose` to tell which
effect a wrong one lacks (with 7 poses the ladder names the wrong effect in the
hidden-compliance world). So when the fit does not explain its measurements (the chi2/dof
the push guard tests, `hostpc.calibrate.push.adequacy_chi2`: with the camera calibration's
covariance inside when the dataset carries it, above its band `chi2_dof_upper`), the runner measures
the plan's further poses (`Plan.q_more`: the rest of the nested D-optimal selection, up to
--poses) and fits again before the push decision. The decision is journaled
(`{"event": "more_poses", ...}`) so a resume measures the same poses.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from hostpc.calibrate.journal import Journal
from hostpc.calibrate.journal_events import MorePoses
from hostpc.calibrate.push import adequacy_chi2
from hostpc.calibrate.run_result import GROWN_TIME
from hostpc.diagnostics.adequacy import chi2_dof_upper
from hostpc.fitting import FitResult
from hostpc.methods.base import Plan


def more_poses_reason(journal: Journal, plan: Plan, result: FitResult,
                      pushed: bool = False) -> str | None:
    """Why the runner measures `plan.more` (journaled once), or None: the plan has no
    further poses, or the fit explains its measurements and none were asked before, or
    offsets were already pushed (``pushed``): poses measured under the pushed offsets cannot
    join a fit of poses measured under the initial ones, so a resumed run whose new model
    fails never grows after a push (its push is refused by the model check instead)."""
    if plan.more.shape[0] == 0:
        return None
    asked = journal.last(MorePoses)
    if asked is not None:
        return asked.reason
    if pushed:
        return None
    tested = adequacy_chi2(result)
    chi2_dof, upper = tested.chi2_dof, chi2_dof_upper(tested.dof)
    if not (math.isfinite(upper) and chi2_dof > upper):
        return None
    what = " with the camera calibration's covariance" if tested.shared else ""
    reason = (f"the model does not explain the {plan.q.shape[0]} poses (chi2/dof{what} "
              f"{chi2_dof:.3g} above its band {upper:.3g})")
    journal.append(MorePoses(reason=reason, n=int(plan.more.shape[0])))
    return reason


def more_poses_message(reason: str, journal: Journal, plan: Plan) -> str:
    """The progress line when the plan grows: how many further poses are measured now and
    how many a resume replays from the journal (never "measuring 49 more" while it only
    reads them back)."""
    first, total = plan.q.shape[0], plan.more.shape[0]
    journaled = sum(first <= r.index < first + total for r in journal.records("fit"))
    grown = plan.info.get(GROWN_TIME)
    time = (f"; the plan's predicted robot time of measure + verify is now "
            f"{grown['total']:.1f} s" if isinstance(grown, Mapping) else "")
    if journaled == 0:
        return f"{reason}: measuring {total} more poses{time}"
    if journaled >= total:
        return (f"{reason}: the {total} more poses were measured before; replaying them "
                f"from the journal{time}")
    return (f"{reason}: {total} more poses, {journaled} replayed from the journal, measuring "
            f"{total - journaled}{time}")
