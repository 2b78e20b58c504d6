"""stereo_target: a stereo camera on the flange measures a fixed target point.

``KIND`` registers it (``hostpc.dataset.kind_registry``): the file face and model, the
acquisition (``method.py``, with the second centre pass in ``refinement.py``), the frames
``--known`` may hold, and the ``--robot sim`` world: the stub's default scenario with the
target's centre error zero and ``target`` known (makes joint 1 identifiable).
"""

from hostpc.dataset.kind_registry import KindDescriptor, SimDefault
from hostpc.kinds.stereo_target.model import StereoTarget

KIND = KindDescriptor(
    name="stereo_target", model=StereoTarget,
    method="hostpc.kinds.stereo_target.method:StereoTargetMethod",
    known_frames=("tool", "target"),
    sim=SimDefault(
        overrides={"motion": {"time_scale": 0.0}, "target": {"centre_error": [0.0, 0.0, 0.0]}},
        known=("target",)))
