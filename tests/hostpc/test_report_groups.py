"""The report's residual plot names the levels of a group label (dual_loop's ``chain``,
world_point's ``marker``) on its x axis instead of their numeric codes."""

from __future__ import annotations

import html
import re

import numpy as np
import pytest

import hostpc
from hostpc.dataset import Dataset
from hostpc.report import render_html
from hostpc.synthesize_dual_loop import plan_poses, synthesize_dual_loop
from tests.hostpc.test_diagnose_groups import tracker_dataset

FIGURE = "whitened residuals against every variable with binned means"


def _arms() -> Dataset:
    return synthesize_dual_loop({"joint_offsets.left.q3": 1e-3},
                                plan_poses(20, np.random.default_rng(0)), seed=1)


def _figure_texts(report: str) -> list[str]:
    """The <text> contents of the residuals-against-variables figure of a report (each
    figure is one top-level <svg class="plot">; its panels nest <svg>s without xmlns)."""
    figures = report.split('<svg xmlns="http://www.w3.org/2000/svg" class="plot"')
    figure = next(f for f in figures if f'aria-label="{FIGURE}"' in f)
    return [html.unescape(t) for t in re.findall(r"<text[^>]*>([^<]*)</text>", figure)]


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
