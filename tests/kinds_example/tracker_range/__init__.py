"""tracker_range: a new measurement kind added from this one folder (``--plugin FOLDER``).

The laser tracker's absolute distance meter alone: per pose, the distance from the tracker
to a reflector on the flange (its angle encoders are not used). It reuses the simulated
tracker the stub already has (``measure_tracker``: the distance is the norm of the measured
point in the tracker frame), so neither the stub nor any hostpc file changes for it.

- ``model.py``: the file face and prediction (``TrackerRange``, m = 1, with its Jacobian);
- ``method.py``: the acquisition (``TrackerRangeMethod``), imported only by a run;
- here: the one descriptor that registers it (``KIND``): the frames ``--known`` may hold and
  the ``--robot sim`` world (the stub's default scenario with its tracker, both frames
  surveyed).
"""

from hostpc.dataset.kind_registry import KindDescriptor, SimDefault

from .model import TrackerRange

KIND = KindDescriptor(
    name="tracker_range", model=TrackerRange,
    method=f"{__name__}.method:TrackerRangeMethod",  # __name__: this package, as imported
    known_frames=("tool", "anchor"),
    sim=SimDefault(overrides={"motion": {"time_scale": 0.0}}, known=("tool", "anchor")))
