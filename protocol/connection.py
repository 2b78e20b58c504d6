"""`Connection`: the protocol state machine, turning messages into bytes and bytes into events.

No I/O, no clock, no asyncio (the h11 pattern). The driver feeds received bytes to
`receive_data()` (b"" means end of stream) and gets events back; it writes the bytes that
`send()` returns, and after every `receive_data()` it also writes `data_to_send()`: the
replies the connection produced on its own (handshake answers, error replies to malformed
input). When `state` becomes `CLOSED` the driver flushes `data_to_send()` and closes.

States and the events reported: `protocol.session_states`.

The handshake is run by the connection itself: a client `Connection` sends `hello` from
`initiate()`, checks the server's version and, if it holds a token, answers the challenge
and verifies the server's proof. A server `Connection` checks the version and the proof and
answers both; the application only ever sees requests it is allowed to execute.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator

from protocol import auth
from protocol.errors import (
    FATAL_CODES,
    ErrorCode,
    LocalProtocolError,
    ProtocolError,
    RemoteProtocolError,
)
from protocol.framing import DEFAULT_MAX_FRAME_SIZE, Frame, FrameDecoder, encode_frame
from protocol.header_parsing import _find_id, parse_frame
from protocol.message_base import PROTOCOL_VERSION, Reply, Request, _Message
from protocol.messages import (
    EVENT_KINDS,
    REPLY_KIND,
    Auth,
    AuthReply,
    ErrorReply,
    Hello,
    HelloReply,
)
from protocol.session_states import (
    ALLOWED_REQUESTS,
    REFUSAL_CODE,
    TRANSITIONS,
    ConnectionClosed,
    ConnectionState,
    Event,
    Rejected,
    Role,
    S,
    StateChanged,
    refusal_text,
)


class Connection:
    """One end of a zerocal protocol session, without I/O.

    role: CLIENT or SERVER. token: the shared secret (a client without a token gets a
    read-only session). max_frame_size: largest frame accepted from the peer (bytes);
    larger ones are rejected and close the connection. pre_auth_max_frame_size: a smaller
    limit (bytes) that applies until the session is authenticated (server role: requests
    carry no attachments, so an anonymous peer never needs big frames); None = no separate
    limit. server_name / robot_name: what a server announces in hello_reply.
    """

    def __init__(
        self,
        role: Role,
        *,
        token: str | None = None,
        max_frame_size: int = DEFAULT_MAX_FRAME_SIZE,
        pre_auth_max_frame_size: int | None = None,
        server_name: str = "zerocal-controller",
        robot_name: str = "",
        client_name: str = "zerocal",
    ) -> None:
        if role is Role.SERVER and not token:
            raise ValueError("a server Connection needs a token")
        self.role = role
        self.state = ConnectionState.AWAITING_HELLO
        self.peer_version: int | None = None
        self.peer_name: str | None = None
        self.robot_name = robot_name
        self._token = token
        self._server_name = server_name
        self._client_name = client_name
        self._max_frame_size = max_frame_size
        initial_limit = max_frame_size
        if pre_auth_max_frame_size is not None:
            initial_limit = min(max_frame_size, pre_auth_max_frame_size)
        self._decoder = FrameDecoder(initial_limit)
        self._outgoing: list[bytes] = []
        self._ids: Iterator[int] = itertools.count()
        self._client_nonce: str | None = None
        self._server_nonce: str | None = None
        self._hello_id: int | None = None
        # Requests in flight: id -> kind (client: sent, not answered; server: received, not
        # answered by the application).
        self._pending: dict[int, str] = {}

    # ----------------------------------------------------------------- public interface

    @property
    def closed(self) -> bool:
        """True once the session is over (fatal error, end of stream)."""
        return self.state is ConnectionState.CLOSED

    @property
    def has_token(self) -> bool:
        """True if this end holds a token (a client without one stays read-only)."""
        return bool(self._token)

    @property
    def authenticated(self) -> bool:
        """True once the challenge-response succeeded."""
        return self.state is ConnectionState.READY

    @property
    def max_frame_size(self) -> int:
        """Largest frame accepted from the peer now (bytes); grows to the configured limit
        once the session is authenticated if a pre-auth limit was given."""
        return self._decoder.max_frame_size

    @property
    def buffered(self) -> int:
        """Bytes received but not yet complete as a frame (a frame in progress)."""
        return self._decoder.buffered

    def next_id(self) -> int:
        """A fresh request id for this connection (client role)."""
        return next(self._ids)

    def initiate(self) -> bytes:
        """Client: the bytes of the opening `hello` (call once, first)."""
        if self.role is not Role.CLIENT:
            raise LocalProtocolError(ErrorCode.UNEXPECTED_MESSAGE, "only a client says hello")
        if self._hello_id is not None:
            raise LocalProtocolError(ErrorCode.UNEXPECTED_MESSAGE, "hello already sent")
        self._client_nonce = auth.new_nonce()
        hello = Hello(
            id=self.next_id(),
            protocol_version=PROTOCOL_VERSION,
            client_name=self._client_name,
            client_nonce=self._client_nonce,
        )
        self._hello_id = hello.id
        self._pending[hello.id] = "hello"
        return self._encode(hello)

    def send(self, message: _Message) -> bytes:
        """Encode `message` (with its attachments) as bytes to write; checks it is allowed.

        Raises LocalProtocolError if this role may not send it in the current state.
        """
        if self.state is ConnectionState.CLOSED:
            raise LocalProtocolError(
                ErrorCode.UNEXPECTED_MESSAGE, f"cannot send {message.kind}: connection closed"
            )
        if self.role is Role.CLIENT:
            self._check_client_send(message)
        else:
            self._check_server_send(message)
        data = self._encode(message)
        if self.role is Role.SERVER:
            self._after_server_sent(message)
        return data

    def send_error(
        self,
        reply_to: int | None,
        code: ErrorCode,
        message: str,
        reason: str | None = None,
    ) -> bytes:
        """Server: encode an error reply (a fatal code closes the connection)."""
        return self.send(ErrorReply(reply_to=reply_to, code=code, message=message, reason=reason))

    def receive_data(self, data: bytes | bytearray | memoryview) -> list[Event]:
        """Feed received bytes (b"" = end of stream); return the events they complete."""
        if self.state is ConnectionState.CLOSED:
            return []
        events: list[Event] = []
        if not data:
            events.extend(self._close())
            events.append(ConnectionClosed())
            return events
        self._decoder.feed(data)
        while not self.closed:
            try:
                frame = self._decoder.next_frame()
            except RemoteProtocolError as exc:
                events.extend(self._reject(exc, None))
                break
            if frame is None:
                break
            events.extend(self._receive_frame(frame))
        return events

    def data_to_send(self) -> bytes:
        """Bytes the connection produced on its own since the last call (may be empty)."""
        data = b"".join(self._outgoing)
        self._outgoing.clear()
        return data

    def pending_requests(self) -> dict[int, str]:
        """Requests in flight: id -> kind."""
        return dict(self._pending)

    # ------------------------------------------------------------------------ sending

    def _encode(self, message: _Message) -> bytes:
        attachments = message.attachments
        if len(attachments) != message.expected_attachments():
            raise LocalProtocolError(
                ErrorCode.BAD_MESSAGE,
                f"{message.kind} needs {message.expected_attachments()} attachments, "
                f"has {len(attachments)}",
            )
        header = message.model_dump_json().encode("utf-8")
        return encode_frame(header, attachments)

    def _check_client_send(self, message: _Message) -> None:
        if not isinstance(message, Request) or isinstance(message, (Hello, Auth)):
            raise LocalProtocolError(
                ErrorCode.UNEXPECTED_MESSAGE, f"a client cannot send {message.kind}"
            )
        if self.state is ConnectionState.AWAITING_HELLO:
            raise LocalProtocolError(
                ErrorCode.UNEXPECTED_MESSAGE,
                f"cannot send {message.kind} before the hello exchange completes",
            )
        if message.id in self._pending:
            raise LocalProtocolError(
                ErrorCode.BAD_MESSAGE, f"request id {message.id} is already in flight"
            )
        self._pending[message.id] = message.kind

    def _check_server_send(self, message: _Message) -> None:
        if isinstance(message, Request):
            raise LocalProtocolError(
                ErrorCode.UNEXPECTED_MESSAGE, f"a server cannot send {message.kind}"
            )
        if message.kind in EVENT_KINDS:
            if self.state is not ConnectionState.READY:
                raise LocalProtocolError(
                    ErrorCode.UNEXPECTED_MESSAGE,
                    f"cannot push {message.kind} to a session in state {self.state}",
                )
            return
        reply_to = message.reply_to if isinstance(message, (Reply, ErrorReply)) else None
        if reply_to is None:
            return  # an error that answers no request
        request_kind = self._pending.get(reply_to)
        if request_kind is None:
            raise LocalProtocolError(
                ErrorCode.UNEXPECTED_MESSAGE,
                f"{message.kind} answers request {reply_to}, which is not pending",
            )
        if message.kind not in (REPLY_KIND[request_kind], "error"):
            raise LocalProtocolError(
                ErrorCode.UNEXPECTED_MESSAGE,
                f"{message.kind} cannot answer {request_kind}",
            )

    def _after_server_sent(self, message: _Message) -> None:
        reply_to = getattr(message, "reply_to", None)
        if reply_to is not None:
            self._pending.pop(reply_to, None)
        next_state = TRANSITIONS.get((self.state, message.kind))
        if next_state is not None:
            self.state = next_state
            if next_state is ConnectionState.READY:
                self._decoder.max_frame_size = self._max_frame_size
        if isinstance(message, ErrorReply) and message.code in FATAL_CODES:
            self.state = ConnectionState.CLOSED

    def _queue(self, message: _Message) -> None:
        self._outgoing.append(self.send(message))

    # ---------------------------------------------------------------------- receiving

    def _receive_frame(self, frame: Frame) -> list[Event]:
        try:
            message = parse_frame(frame)
        except RemoteProtocolError as exc:
            return self._reject(exc, _find_id(frame.header))
        try:
            if self.role is Role.SERVER:
                return self._server_received(message)
            return self._client_received(message)
        except RemoteProtocolError as exc:
            return self._reject(exc, getattr(message, "id", None))

    def _server_received(self, message: _Message) -> list[Event]:
        if isinstance(message, ErrorReply):
            return [message]  # the client complains; the application may log it
        if not isinstance(message, Request):
            raise RemoteProtocolError(
                ErrorCode.UNEXPECTED_MESSAGE, f"a client cannot send {message.kind}"
            )
        if message.id in self._pending:
            raise RemoteProtocolError(
                ErrorCode.BAD_MESSAGE, f"request id {message.id} is already in flight"
            )
        if message.kind not in ALLOWED_REQUESTS[self.state]:
            code = REFUSAL_CODE[self.state]
            if message.kind in ("hello", "auth") and self.state is not S.AWAITING_HELLO:
                code = ErrorCode.UNEXPECTED_MESSAGE
            raise RemoteProtocolError(code, refusal_text(message.kind, self.state, code))
        self._pending[message.id] = message.kind
        old = self.state
        if isinstance(message, Hello):
            self._answer_hello(message)
        elif isinstance(message, Auth):
            self._answer_auth(message)
        else:
            return [message]
        return [StateChanged(old, self.state)] if self.state is not old else []

    def _answer_hello(self, hello: Hello) -> None:
        if hello.protocol_version != PROTOCOL_VERSION:
            raise RemoteProtocolError(
                ErrorCode.VERSION_MISMATCH,
                f"client speaks protocol version {hello.protocol_version}, "
                f"this server speaks version {PROTOCOL_VERSION}",
            )
        self.peer_version = hello.protocol_version
        self.peer_name = hello.client_name
        self._client_nonce = hello.client_nonce
        self._server_nonce = auth.new_nonce()
        self._queue(
            HelloReply(
                reply_to=hello.id,
                protocol_version=PROTOCOL_VERSION,
                server_name=self._server_name,
                robot_name=self.robot_name,
                server_nonce=self._server_nonce,
            )
        )

    def _answer_auth(self, message: Auth) -> None:
        assert self._token and self._server_nonce and self._client_nonce
        expected = auth.client_proof(self._token, self._server_nonce, self._client_nonce)
        if not auth.proofs_match(expected, message.proof):
            raise RemoteProtocolError(ErrorCode.AUTH_FAILED, "authentication failed: wrong token")
        proof = auth.server_proof(self._token, self._server_nonce, self._client_nonce)
        self._queue(AuthReply(reply_to=message.id, server_proof=proof))

    def _client_received(self, message: _Message) -> list[Event]:
        if message.kind in EVENT_KINDS:
            return [message]
        if not isinstance(message, (Reply, ErrorReply)):
            raise RemoteProtocolError(
                ErrorCode.UNEXPECTED_MESSAGE, f"a server cannot send {message.kind}"
            )
        if message.reply_to is None or (
            isinstance(message, ErrorReply) and message.reply_to not in self._pending
        ):
            # An error about something we sent that the server could not read as a request
            # (no id, or an id we never had in flight): pass it on for the caller to log.
            return self._after_client_received(message)
        request_kind = self._pending_kind(message.reply_to)
        if message.kind not in (REPLY_KIND[request_kind], "error"):
            raise RemoteProtocolError(
                ErrorCode.UNEXPECTED_MESSAGE,
                f"{message.kind} cannot answer {request_kind} (request {message.reply_to})",
            )
        del self._pending[message.reply_to]
        if isinstance(message, HelloReply):
            self._check_hello_reply(message)
        elif isinstance(message, AuthReply):
            self._check_auth_reply(message)
        return self._after_client_received(message)

    def _pending_kind(self, reply_to: int) -> str:
        kind = self._pending.get(reply_to)
        if kind is None:
            raise RemoteProtocolError(
                ErrorCode.UNEXPECTED_MESSAGE, f"reply to request {reply_to}, which is not pending"
            )
        return kind

    def _check_hello_reply(self, reply: HelloReply) -> None:
        if reply.protocol_version != PROTOCOL_VERSION:
            raise RemoteProtocolError(
                ErrorCode.VERSION_MISMATCH,
                f"server speaks protocol version {reply.protocol_version}, "
                f"this client speaks version {PROTOCOL_VERSION}",
            )
        self.peer_version = reply.protocol_version
        self.peer_name = reply.server_name
        self.robot_name = reply.robot_name
        self._server_nonce = reply.server_nonce
        if self._token:
            assert self._client_nonce is not None
            proof = auth.client_proof(self._token, self._server_nonce, self._client_nonce)
            message = Auth(id=self.next_id(), proof=proof)
            self._pending[message.id] = "auth"
            self._outgoing.append(self._encode(message))

    def _check_auth_reply(self, reply: AuthReply) -> None:
        assert self._token and self._server_nonce and self._client_nonce
        expected = auth.server_proof(self._token, self._server_nonce, self._client_nonce)
        if not auth.proofs_match(expected, reply.server_proof):
            raise RemoteProtocolError(
                ErrorCode.AUTH_FAILED, "the server failed to prove it holds the token"
            )

    def _after_client_received(self, message: _Message) -> list[Event]:
        events: list[Event] = []
        old = self.state
        next_state = TRANSITIONS.get((self.state, message.kind))
        if next_state is not None:
            self.state = next_state
            if next_state is ConnectionState.READY:
                self._decoder.max_frame_size = self._max_frame_size
        if isinstance(message, ErrorReply) and message.code in FATAL_CODES:
            self.state = ConnectionState.CLOSED
            self._pending.clear()
        events.append(message)
        if self.state is not old:
            events.append(StateChanged(old, self.state))
        return events

    # ------------------------------------------------------------------------- errors

    def _reject(self, exc: ProtocolError, reply_to: int | None) -> list[Event]:
        events: list[Event] = [Rejected(exc.code, str(exc), reply_to, exc.fatal)]
        if self.role is Role.SERVER:
            # Not through send(): the offending request was never accepted as pending.
            error = ErrorReply(reply_to=reply_to, code=exc.code, message=str(exc)[:4000])
            self._outgoing.append(self._encode(error))
        if exc.fatal:
            events.extend(self._close())
        return events

    def _close(self) -> list[Event]:
        if self.state is ConnectionState.CLOSED:
            return []
        old = self.state
        self.state = ConnectionState.CLOSED
        self._pending.clear()
        return [StateChanged(old, ConnectionState.CLOSED)]
