"""Each kind's typed sample keeps the journal's JSON key for key (a run journaled before
the samples were typed resumes), and the run's Dataset built from typed samples is the
Dataset its own file reads back as."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from hostpc.dataset import dataset_from_dict
from hostpc.kinds.dual_loop.sample import PoseObservations
from hostpc.kinds.sphere_probe.sample import ProbeSample
from hostpc.kinds.stereo_target.sample import StereoSample
from hostpc.kinds.world_point.sample import WorldPointSample
from hostpc.methods.base import RunSettings, SampleRecord
from hostpc.methods.cell import build_cell
from tests.hostpc.test_planning import stereo_method

COV = [[4e-12, 1e-13, -2e-13], [1e-13, 5e-12, 3e-13], [-2e-13, 3e-13, 9e-12]]
# samples as the acquisition journaled them while they were dicts (the same key order)
JOURNALED: list[tuple[Any, dict[str, Any]]] = [
    (StereoSample, {"q": [0.1, -1.2, 1.3, -1.7, -2.2, -0.09], "p": [0.04, 0.01, 0.3],
                    "cov": COV, "t": 1.25, "approach": [1.0, -1.0, 1.0, 1.0, -1.0, 1.0],
                    "uv": [[640.5, 512.25], [520.0, 512.5]]}),
    (StereoSample, {"q": [0.1, -1.2, 1.3, -1.7, -2.2, -0.09], "p": [0.04, 0.01, 0.3],
                    "cov": COV, "t": 0.0, "approach": [1.0, 1.0, 1.0, 1.0, 1.0, 1.0]}),
    (WorldPointSample, {"q": [-2.49, -0.51, 0.15, 0.54, 0.97, -2.13], "marker": "smr1",
                        "p": [1.39, 0.53, 0.018], "cov": COV, "t": 3.5,
                        "approach": [1.0, 1.0, -1.0, 1.0, -1.0, 1.0]}),
    (ProbeSample, {"q": [-0.07, -3.67, 1.29, 0.36, -1.64, 0.44], "group": 0, "sigma": 1e-06,
                   "approach": [1.0, -1.0, 1.0, 1.0, -1.0, 1.0], "t": 0.83,
                   "extra": {"contact": 3.0, "tip_speed": 0.0136}, "speed": 0.0136}),
    (ProbeSample, {"q": [-0.07, -3.67, 1.29, 0.36, -1.64, 0.44], "group": 2, "sigma": 2e-06,
                   "approach": [1.0, -1.0, 1.0, 1.0, -1.0, 1.0], "t": 0.83,
                   "extra": {"contact": 11.0}}),
    (PoseObservations, {"observations": [
        {"chain": "left", "q_head": [-0.04, -0.55], "q_arm": [0.0, 0.34, 0.4, -1.6, 0.2, 0.87,
                                                              0.28],
         "p": [-0.03, 0.055, 0.366], "cov": COV, "t": 2.0,
         "approach": [1.0, -1.0, 1.0, 1.0, 1.0, -1.0, 1.0],
         "uv": [[600.0, 500.0], [480.0, 500.0]]},
        {"chain": "right", "q_head": [-0.04, -0.55], "q_arm": [0.0, -0.34, -0.4, -1.6, -0.2,
                                                               0.87, -0.28],
         "p": [0.03, 0.055, 0.366], "cov": COV, "t": 2.0}]}),
]


@pytest.mark.parametrize(("kind", "sample"), JOURNALED)
def test_typed_sample_keeps_the_journal_line(kind: Any, sample: dict[str, Any]) -> None:
    line = SampleRecord("fit", 4, True, sample=sample, q_end=[0.0] * 6).to_dict()
    typed = SampleRecord.measured("fit", 4, kind.from_json(sample), q_end=[0.0] * 6)
    assert json.dumps(typed.to_dict(), separators=(",", ":")) == json.dumps(
        line, separators=(",", ":"))


def test_stereo_dataset_from_typed_samples_is_what_its_file_reads(tmp_path: Path) -> None:
    method = stereo_method((), tmp_path)
    samples = [s for kind, s in JOURNALED if kind is StereoSample]
    dataset = method.dataset(samples)
    assert dataset == dataset_from_dict(method.dataset_document(samples))
    assert np.isnan(dataset.samples.uv[1]).all()  # one sample without pixels


def test_dual_loop_dataset_from_typed_samples_is_what_its_file_reads(tmp_path: Path) -> None:
    from hostpc.kinds.dual_loop.method import DualLoopMethod

    method = DualLoopMethod(RunSettings(method="dual_loop"), build_cell({}, "humanoid_upper"),
                            tmp_path)
    samples = [s for kind, s in JOURNALED if kind is PoseObservations]
    dataset = method.dataset(samples)
    assert dataset.n_samples == 2
    assert dataset == dataset_from_dict(method.dataset_document(samples))
