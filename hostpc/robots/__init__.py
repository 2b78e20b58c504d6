"""Robot adapters: one interface (hostpc.robots.base.RobotAdapter) over every controller."""
