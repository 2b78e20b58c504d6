"""Universal Robots personality of the simulated controller (`controller-stub serve --ur`).

RTDE on 30004 (`rtde_server`), the dashboard on 29999 (`dashboard`), the script port 30003
(`script_server`) and an emulation of ur_rtde's control script (`control_script`), wired to
one `Simulation` by `personality.UrPersonality`. See docs/robots.md.
"""

from controller_stub.ur.personality import UrPersonality

__all__ = ["UrPersonality"]
