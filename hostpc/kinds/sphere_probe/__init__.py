"""sphere_probe: touch contacts on a reference sphere.

``KIND`` registers it (``hostpc.dataset.kind_registry``): the file face and model, the
acquisition (``method.py``: guarded moves or Modbus polling in ``acquisition.py`` and
``probe_modbus.py``, the dataset it builds in ``dataset.py``), the pure planning and
geometry (``planning``), the frames ``--known`` may hold, and the ``--robot sim`` world: the
stub's default scenario with the sphere's centre error zero and ``sphere`` known (makes
joint 1 identifiable).
"""

from hostpc.dataset.kind_registry import KindDescriptor, SimDefault
from hostpc.kinds.sphere_probe.model import SphereProbe

KIND = KindDescriptor(
    name="sphere_probe", model=SphereProbe,
    method="hostpc.kinds.sphere_probe.method:SphereProbeMethod",
    known_frames=("tool", "sphere"),
    sim=SimDefault(
        overrides={"motion": {"time_scale": 0.0},
                   "probe": {"sphere_centre_error": [0.0, 0.0, 0.0]}},
        known=("sphere",)),
    method_options=frozenset({"probe_io"}))
