"""sphere_probe: touch contacts on a reference sphere (the method class in `method`, its
acquisition by guarded moves or Modbus polling, the dataset it builds). Planning and
geometry are pure and live in hostpc.planning."""

from hostpc.methods.sphere_probe.method import SphereProbeMethod

__all__ = ["SphereProbeMethod"]
