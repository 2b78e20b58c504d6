"""Scenario files: the simulated world's configuration and hidden truth (`spec`); the
packaged examples are `controller_stub/scenarios/*.yaml`."""
