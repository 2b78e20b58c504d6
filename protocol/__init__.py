"""zerocal wire protocol, sans-IO: messages (`messages`), framing (`framing`), the
Connection state machine (`connection`, its states in `session_states`), auth (`auth`),
error codes (`errors`) and the admission policies every server shares (`admission`).

Imports only the standard library and pydantic; no sockets, no asyncio. See
docs/protocol.md for the message table, the byte layout and the error codes. Each name is
imported from the module that defines it; this package defines only the default port.
"""

DEFAULT_PORT = 47800
"""TCP port of the zerocal protocol when none is given (controller-stub, hostpc --robot)."""
