"""string_pot: a measurement kind with its OWN instrument, added from this one folder.

A draw-wire length sensor (a "string pot"): its drum is bolted in the cell at ``anchor``
(a point in the robot base frame), its cable hooked to the flange at ``tool`` (a point in
the flange frame); per pose it reads the cable length. Nothing in zerocal knows it:

- ``model.py``: the file face and prediction (``StringPot``, m = 1, with its Jacobian);
- ``method.py``: the acquisition (``StringPotMethod``), imported only by a run; it reads
  the instrument through the generic ``sensor_read`` (``hostpc.robots.base.sensors_of``);
- ``sim_sensor.py``: the instrument simulated by the stub (``SIM_SENSORS``; numpy and
  controller_stub only), which ``--robot sim`` loads from this folder
  (``controller-stub serve --sensor-plugin FOLDER``);
- here: the one descriptor that registers it (``KIND``): the frames ``--known`` may hold
  and the ``--robot sim`` world (the stub's default scenario, the sensor's settings, both
  frames surveyed).

``--plugin tests/kinds_example/string_pot`` is all a run needs (docs/measurement-models.md).
"""

from hostpc.dataset.kind_registry import KindDescriptor, SimDefault

from .model import StringPot

SIMULATED = {"anchor": [0.55, 0.45, -0.15], "tool": [0.0, 0.04, 0.05], "sigma": 2e-5,
             "max_length": 2.0}
"""The simulated cell's instrument (the stub's ``sensors.string_pot`` section): drum and
hook positions (m), the noise of one reading (m) and the cable's range (m)."""

KIND = KindDescriptor(
    name="string_pot", model=StringPot,
    method=f"{__name__}.method:StringPotMethod",  # __name__: this package, as imported
    known_frames=("tool", "anchor"),
    sim=SimDefault(overrides={"motion": {"time_scale": 0.0},
                              "sensors": {"string_pot": SIMULATED}},
                   known=("tool", "anchor")))
