"""The report's residual plot names the levels of a group label (dual_loop's ``chain``,
world_point's ``marker``) on its x axis instead of their numeric codes."""

from __future__ import annotations

import html
import itertools
import re

import numpy as np
import pytest

import hostpc
from hostpc.dataset import Dataset
from hostpc.kinds.dual_loop.planning import plan_poses
from hostpc.kinds.dual_loop.synthesize import synthesize_dual_loop
from hostpc.report import render_html
from tests.hostpc.diagnose_support import sphere_contact_dataset
from tests.hostpc.test_diagnose_groups import tracker_dataset

FIGURE = "whitened residuals against every variable with binned means"


def _arms() -> Dataset:
    return synthesize_dual_loop({"joint_offsets.left.q3": 1e-3},
                                plan_poses(20, np.random.default_rng(0)), seed=1)


def _figure(report: str) -> str:
    """The residuals-against-variables figure of a report (each figure is one top-level
    <svg class="plot">; its panels nest <svg>s without xmlns)."""
    figures = report.split('<svg xmlns="http://www.w3.org/2000/svg" class="plot"')
    return next(f for f in figures if f'aria-label="{FIGURE}"' in f)


def _figure_texts(report: str) -> list[str]:
    """The <text> contents of the residuals-against-variables figure of a report."""
    return [html.unescape(t) for t in re.findall(r"<text[^>]*>([^<]*)</text>", _figure(report))]


@pytest.mark.parametrize(("make", "variable", "levels"), [
    (_arms, "chain", ("left", "right")),
    (lambda: tracker_dataset(0, 3e-4), "marker", ("a", "b", "c")),
])
def test_group_levels_are_named_on_the_x_axis(make, variable: str,  # type: ignore[no-untyped-def]
                                              levels: tuple[str, ...]) -> None:
    diagnosis = hostpc.diagnose(make())
    pattern = next(p for p in diagnosis.residuals.patterns if p.variable == variable)
    assert pattern.levels == levels
    texts = _figure_texts(render_html(diagnosis))
    assert any(t.startswith(f"{variable}  p=") for t in texts)  # the group's panel
    for level in levels:
        assert texts.count(level) == 1, (level, texts)


def test_many_levels_keep_readable_labels_that_do_not_overlap() -> None:
    """40 probe orientations in one 206 px panel: the level names stay at least 7 px high
    (every k-th level named) and no two drawn names overlap (width ~0.6 em a character)."""
    diagnosis = hostpc.diagnose(sphere_contact_dataset({}, n_samples=200), cv_folds=0,
                                rank_cv_folds=0)
    pattern = next(p for p in diagnosis.residuals.patterns if p.variable == "probe_group")
    assert len(pattern.levels) == 40
    panels = _figure(render_html(diagnosis)).split("<svg x=")  # one chunk a panel
    panel = next(p for p in panels if "probe_group  p=" in p)
    drawn = [(float(x), float(size), html.unescape(text)) for x, size, text in
             re.findall(r'<text x="([-\d.]+)" y="[-\d.]+" font-size="([\d.]+)" '
                        r'text-anchor="middle">([^<]*)</text>', panel)
             if not text.startswith("probe_group")]
    assert {text for _, _, text in drawn} <= set(pattern.levels)
    assert len(drawn) >= 8 and drawn[0][2] == "0"  # the first level is always named
    assert all(size >= 7.0 for _, size, _ in drawn), drawn
    for (x0, size0, text0), (x1, size1, text1) in itertools.pairwise(drawn):
        assert x1 - x0 >= 0.3 * (size0 * len(text0) + size1 * len(text1)), (text0, text1)
