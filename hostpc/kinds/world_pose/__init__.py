"""world_pose: a frame fixed to the flange measured in full (position and orientation) in a
fixed instrument's frame. Imported from metrology files (``hostpc import``); it has no live
acquisition.
"""

from hostpc.dataset.kind_registry import KindDescriptor
from hostpc.kinds.world_pose.model import WorldPose

KIND = KindDescriptor(name="world_pose", model=WorldPose, csv_rows="pose")
