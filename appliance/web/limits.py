"""What the web server accepts from the network before Flask sees a request.

waitress reads a request's whole body (spooling anything past `inbuf_overflow`
to a temporary file) before it calls the application, so a check in Flask
comes after the disk is already filled. Two things are decided here instead,
on the headers alone:

- A body bigger than ANON_BODY_BYTES, or sent chunked (size unknown), is
  refused with 401 unless the headers carry a valid session cookie or API
  token (`app.extensions["inkslice"]["may_send_body"]`). The rest of the
  body is then never read: waitress closes the connection after the reply.
  ANON_BODY_BYTES stays below `inbuf_overflow`, so an anonymous body never
  touches the disk at all. Logged-in bodies are capped by
  `max_request_body_size` (the upload cap plus multipart overhead).
- One client address may hold at most `per_address` connections; past that a
  new one is closed at once. With `connection_limit` well above that and
  poll() instead of select() (which stops at 1024 descriptors), a few hundred
  idle or slow sockets from one address cannot keep the owner's phone out.

server_settings() gives the waitress adjustments; gate_server() installs both
checks on a server made by waitress.create_server.
"""

from __future__ import annotations

import resource

from waitress.channel import HTTPChannel
from waitress.parser import HTTPRequestParser
from waitress.utilities import Error

ANON_BODY_BYTES = 64 * 1024  # the login form is a few hundred bytes
MULTIPART_SLACK = 1024 * 1024  # form boundaries and fields around an upload's file
CONNECTION_LIMIT = 1000
PER_ADDRESS = 64
OPEN_FILES = 4096


class LoginFirst(Error):
    code = 401
    reason = "Unauthorized"


def server_settings(max_upload_bytes: int, threads: int) -> dict:
    return {
        "threads": threads,
        "max_request_body_size": int(max_upload_bytes) + MULTIPART_SLACK,
        "inbuf_overflow": 512 * 1024,  # > ANON_BODY_BYTES: anonymous bodies stay in memory
        # headers are held in memory until complete: 1000 half-sent ones at waitress's default
        # 256 KiB would be 256 MB; ours (a cookie, a token) fit in a few hundred bytes
        "max_request_header_size": 16 * 1024,
        "connection_limit": CONNECTION_LIMIT,
        "asyncore_use_poll": True,
        # an idle socket (no request in progress) is closed after channel_timeout; the sweep runs
        # every cleanup_interval. Requests in progress (live streams, uploads) are not affected.
        "channel_timeout": 30,
        "cleanup_interval": 5,
        # lets a running request notice that its client hung up (the live streams use it)
        "channel_request_lookahead": 5,
        "ident": "inkslice",
    }


def raise_open_files(want: int = OPEN_FILES) -> int:
    """Lift the soft descriptor limit (often 1024) towards `want`, within the hard limit."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    target = want if hard == resource.RLIM_INFINITY else min(want, hard)
    if soft != resource.RLIM_INFINITY and soft < target:
        try:
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
        except (OSError, ValueError):
            return soft  # the unit's system-call filter forbids it: its LimitNOFILE= applies
        return target
    return soft


def gate_server(server, may_send_body, per_address: int | None = PER_ADDRESS):
    """Make `server` (a waitress TcpWSGIServer) refuse anonymous bodies and connection floods.

    may_send_body(cookie_header, authorization_header) -> bool says whether the headers
    belong to somebody logged in. per_address None switches the per-address cap off
    (behind a trusted proxy every connection comes from the proxy).
    """

    class Parser(HTTPRequestParser):
        def received(self, data):
            was_in_headers = not self.headers_finished
            n = super().received(data)
            if was_in_headers and self.headers_finished and not self.error and self._refuse_body():
                self.error = LoginFirst(f"log in before sending a body of more than {ANON_BODY_BYTES} bytes")
                self.completed = True
                self.expect_continue = False  # no "100 Continue": the body is not wanted
                if self.body_rcv is not None:
                    self.body_rcv.getbuf().close()
            return n

        def _refuse_body(self):
            if not self.chunked and self.content_length <= ANON_BODY_BYTES:
                return False
            return not may_send_body(self.headers.get("COOKIE", ""), self.headers.get("AUTHORIZATION", ""))

    class Channel(HTTPChannel):
        parser_class = Parser

        def __init__(self, srv, sock, addr, adj, map=None):
            super().__init__(srv, sock, addr, adj, map=map)
            if per_address is not None and _connections_from(map or {}, addr) > per_address:
                self.will_close = True  # closed by the loop before anything is read

    server.channel_class = Channel
    return server


def _connections_from(channels: dict, addr) -> int:
    host = addr[0] if isinstance(addr, tuple) else addr
    return sum(
        1
        for ch in channels.values()
        if isinstance(ch, HTTPChannel) and isinstance(ch.addr, tuple) and ch.addr[0] == host
    )
