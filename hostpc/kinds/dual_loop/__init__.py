"""dual_loop: a pan-tilt head camera observes a target on each arm of a humanoid.

``KIND`` registers it (``hostpc.dataset.kind_registry``): the file face and model, the
look-at pose planning (``planning.py``), the acquisition (``method.py``), the frames
``--known`` may hold, and the ``--robot sim`` world: the stub's packaged humanoid world with
nothing known.
"""

from hostpc.dataset.kind_registry import KindDescriptor, SimDefault
from hostpc.kinds.dual_loop.model import DualLoop
from hostpc.kinds.stereo_target import PIXEL_FLOOR_OPTION

KIND = KindDescriptor(
    name="dual_loop", model=DualLoop,
    method="hostpc.kinds.dual_loop.method:DualLoopMethod",
    known_frames=("camera", "left_base", "right_base", "left_target", "right_target"),
    sim=SimDefault(scenario="humanoid.yaml"), cli_options=(PIXEL_FLOOR_OPTION,))
