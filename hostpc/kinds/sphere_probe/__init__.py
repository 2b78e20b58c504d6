"""sphere_probe: touch contacts on a reference sphere.

``KIND`` registers it (``hostpc.dataset.kind_registry``): the file face and model, the
acquisition (``method.py``: guarded moves or Modbus polling in ``acquisition.py`` and
``probe_modbus.py``, the dataset it builds in ``dataset.py``), the pure planning and
geometry (``planning``), the frames ``--known`` may hold, and the ``--robot sim`` world: the
stub's default scenario with the sphere's centre error zero and ``sphere`` known (makes
joint 1 identifiable).
"""

from hostpc.dataset.kind_registry import KindDescriptor, KindOption, SimDefault
from hostpc.kinds.sphere_probe.model import SphereProbe

PROBE_IO_OPTION = KindOption(
    "probe_io", choices=("guarded", "modbus"), default="guarded", exclusive=True,
    help="sphere_probe contacts: the controller's latched guarded move (default) or stepping "
    "while polling the probe line over Modbus TCP")
MODBUS_OPTION = KindOption(
    "modbus", metavar="HOST[:PORT]", needs=("probe_io", "modbus"),
    help="with --probe-io modbus: the Modbus server (default: the robot's host, port 502; "
    "with --robot sim the simulator's)")

KIND = KindDescriptor(
    name="sphere_probe", model=SphereProbe,
    method="hostpc.kinds.sphere_probe.method:SphereProbeMethod",
    known_frames=("tool", "sphere"),
    sim=SimDefault(
        overrides={"motion": {"time_scale": 0.0},
                   "probe": {"sphere_centre_error": [0.0, 0.0, 0.0]}},
        known=("sphere",)),
    cli_options=(PROBE_IO_OPTION, MODBUS_OPTION))
