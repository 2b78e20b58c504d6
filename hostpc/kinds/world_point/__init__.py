"""world_point: a point fixed to the flange measured in a fixed instrument's frame (laser
tracker, motion capture, CMM).

``KIND`` registers it (``hostpc.dataset.kind_registry``): the file face and model, the
acquisition with the stub's laser tracker (``method.py``), and the ``--robot sim`` world: a
laser tracker with a surveyed registration and a dowel-pinned reflector nest
(controller_stub/sensors/world_point.py), both frames known so every joint's zero is defined.
"""

from hostpc.dataset.kind_registry import KindDescriptor, SimDefault
from hostpc.kinds.world_point.model import WorldPoint

KIND = KindDescriptor(
    name="world_point", model=WorldPoint,
    method="hostpc.kinds.world_point.method:WorldPointMethod",
    sim=SimDefault(overrides={"motion": {"time_scale": 0.0}}, known=("world", "markers")),
    csv_rows="point")
