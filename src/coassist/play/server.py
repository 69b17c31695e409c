"""The web server of ``coassist play``: a Starlette app on uvicorn, one websocket per page.

Routes: ``/`` the page, ``/static/*`` its script and style (package data), ``/ws`` the
live link. The control loop runs in the session's own thread
(:class:`~coassist.play.session.PlaySession`); this module only carries messages:

- page → loop: every text message is validated (:func:`coassist.play.protocol.parse_message`);
  an invalid one is dropped and counted by reason, never raised into the loop. The first
  page to connect is the hand; later ones watch (their input is dropped, counted as
  ``"watcher"``). More than :data:`MAX_RATE` messages a second from one page are dropped.
  When the hand's link closes the hand lets go at once (:meth:`BrowserHand.release`).
- loop → page: the loop thread hands each frame to :class:`Hub` through
  ``call_soon_threadsafe``; each page's sender sends queued messages in order and only
  the newest frame (a slow page skips frames, it never delays the loop).

Security: the server binds 127.0.0.1 unless told otherwise; a non-loopback bind requires
a token, which the websocket must present (``/ws?token=…``, compared in constant time).
A token given for a non-loopback bind must be one a peer on the network cannot guess
online (:func:`check_token`: at least :data:`MIN_TOKEN_CHARS` characters and
:data:`MIN_TOKEN_BITS` bits by the estimate there); the one coassist makes
(:func:`new_token`) has 128 random bits.
A request whose ``Host`` is not one this server was started for is refused
(:func:`host_allowed`: against DNS rebinding, where a page on another site re-points its
own name at 127.0.0.1 and sends ``Host`` and ``Origin`` both naming itself), and a
websocket whose ``Origin`` is not the server's own is refused (a web page elsewhere
cannot drive the robot through the person's browser). Frames above
:data:`WS_MAX_SIZE` bytes close the link at the protocol level.
"""

from __future__ import annotations

import asyncio
import functools
import ipaddress
import json
import math
import secrets
import socket
import threading
import time
from collections import Counter, deque
from importlib.resources import files
from typing import Any

from coassist.play.protocol import (
    Abort,
    Answers,
    InvalidMessage,
    Next,
    Ping,
    Pointer,
    Start,
    parse_message,
)
from coassist.play.session import PlaySession

__all__ = [
    "MIN_TOKEN_BITS",
    "MIN_TOKEN_CHARS",
    "Hub",
    "PlayServer",
    "check_token",
    "create_app",
    "host_allowed",
    "is_loopback",
    "new_token",
]

#: Fewest characters of a token guarding a non-loopback bind.
MIN_TOKEN_CHARS = 16
#: Fewest bits of a token guarding a non-loopback bind, estimated as length · log2(distinct
#: characters): an upper bound on the entropy of a token drawn uniformly from its own
#: characters. 2^64 guesses at 10^4 websocket handshakes a second take 5·10^7 years.
MIN_TOKEN_BITS = 64.0
#: Characters a token may hold: RFC 3986's unreserved set, so the URL carries it unescaped.
_TOKEN_CHARS = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-._~")

#: Messages a second one page may send before the rest of that second is dropped.
MAX_RATE = 1000
#: Messages kept for one page that has not read them: a page that pings and never reads gets no more pongs.
MAX_QUEUED = 1000
#: Largest websocket frame the server reads at all [bytes]; larger ones close the link.
WS_MAX_SIZE = 65536
#: [s] how often the server pings each page, and how long it waits for the answer before closing the link (a browser
#: answers pings itself, in a background tab too): a link gone silent without closing is let go within 7 s, then its
#: trial is aborted after the session's ``grace``, not written (uvicorn's own 20 s + 20 s let such a trial run to its
#: end). Not shorter: a 1 s timeout closed a healthy link on a 1.5 s Wi-Fi pause, and a loaded machine (a browser, the
#: loop and the test workers on two cores) must not lose a page mid-questionnaire.
WS_PING_INTERVAL = 2.0
WS_PING_TIMEOUT = 5.0


def _split_host(header: str) -> tuple[str, int | None] | None:
    """A Host header's (name, port): ``name``, ``name:port``, ``[v6]`` or ``[v6]:port``; None when malformed."""
    header = header.strip().lower()
    if header.startswith("["):
        name, sep, rest = header[1:].partition("]")
        if not sep or (rest and not rest.startswith(":")):
            return None
        port_text = rest[1:] if rest else None
    else:
        name, sep, port_text = header.rpartition(":")
        if not sep:
            name, port_text = header, None
    if not name:
        return None
    if port_text is None:
        return name, None
    if not port_text.isdigit() or len(port_text) > 5:
        return None
    return name, int(port_text)


def _is_ip(name: str) -> bool:
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


def host_allowed(header: str | None, bind_host: str, port: int) -> bool:
    """Whether a request's ``Host`` header names this server (bound to ``bind_host:port``).

    The port must be the server's. The name must be an IP address literal or
    ``localhost`` — names no attacker can point elsewhere — and for a loopback bind a
    loopback one; for a bind to a specific address, that address (or this machine's
    host name for 0.0.0.0 / ::, where the page may be opened by name). Any other name
    is what DNS rebinding sends: ``evil.example`` resolved to 127.0.0.1.
    """
    parsed = _split_host(header or "")
    if parsed is None:
        return False
    name, p = parsed
    if (p if p is not None else 80) != port:
        return False
    if is_loopback(bind_host):
        return is_loopback(name)
    if bind_host in ("0.0.0.0", "::"):
        return _is_ip(name) or name == "localhost" or name in _own_names()
    # A bind to a host name: only that name (an address literal cannot be compared with it).
    return name == bind_host.lower() or (
        _is_ip(name) and _is_ip(bind_host) and ipaddress.ip_address(name) == ipaddress.ip_address(bind_host)
    )


@functools.cache
def _own_names() -> frozenset[str]:
    """This machine's host names, looked up once: getfqdn is a reverse DNS query that can take
    seconds, and host_allowed runs on the event loop for every request."""
    return frozenset({socket.gethostname().lower(), socket.getfqdn().lower()})


def is_loopback(host: str) -> bool:
    """True for 127.0.0.0/8, ::1 and ``localhost``."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


class _Client:
    def __init__(self, websocket) -> None:
        self.websocket = websocket
        self.queue: deque[dict] = deque()
        self.frame: dict | None = None
        self.wake = asyncio.Event()
        self.window_start = time.monotonic()
        self.window_count = 0
        self.last_pointer_seq = 0  # the page numbers its messages in order within a connection


class Hub:
    """The pages connected to one session, and the counters the page shows."""

    def __init__(self, session: PlaySession) -> None:
        self.session = session
        self.clients: list[_Client] = []
        self.hand: _Client | None = None
        self.dropped: Counter[str] = Counter()
        self.loop: asyncio.AbstractEventLoop | None = None
        session.publish = self.publish

    # called from the loop thread
    def publish(self, message: dict) -> None:
        loop = self.loop
        if loop is not None and not loop.is_closed():
            message = self.session.for_page(message)  # what a page may see of it (a study blinds it)
            try:
                loop.call_soon_threadsafe(self._deliver, message)
            except RuntimeError:  # the event loop is shutting down
                pass

    def _deliver(self, message: dict) -> None:
        for c in self.clients:
            if message.get("type") == "frame":
                c.frame = message  # only the newest frame waits: a slow page skips frames
            else:
                if c.frame is not None:  # keep the order: the frames before a result go first
                    c.queue.append(self._stamp(c.frame))
                    c.frame = None
                c.queue.append(message)
            c.wake.set()

    def _stamp(self, frame: dict) -> dict:
        return dict(frame, dropped=sum(self.dropped.values()))

    def drop(self, reason: str) -> None:
        self.dropped[reason] += 1

    def init_message(self, client: _Client) -> dict[str, Any]:
        s = self.session
        cur = s.current
        return s.for_page(
            {
                "type": "init",
                "role": "hand" if client is self.hand else "watcher",
                "user": s.config.user,
                "mode": "monitor" if getattr(s, "watch_only", False) else "play",
                "folder": str(s.config.folder),
                "bounds": s.bounds,
                "controllers": list(s.config.controllers),
                "model": s.source.model_id,
                "preset": s.config.preset,
                "running": s.running,
                "scene": cur["scene"] if cur else s.scene(),
                "controller": cur["controller"] if cur else None,
                "results": [r.to_json() for r in s.results],
                "summary": s.summary(),
            }
        )


def create_app(
    session: PlaySession, *, bind: tuple[str, int], token: str | None = None, frame_rate: float | None = None
):
    """The Starlette app of ``session`` (module docstring).

    bind : (host, port) the server listens on; a request whose ``Host`` does not name it
    (:func:`host_allowed`) gets 421 (the page) or a closed websocket.
    token : required on /ws when given.  frame_rate : [1/s] send frames at most this often
    (None: every control period, the default; a fixed 30/s is the benchmark's naive baseline).
    """
    from starlette.applications import Starlette
    from starlette.responses import HTMLResponse, PlainTextResponse
    from starlette.routing import Mount, Route, WebSocketRoute
    from starlette.staticfiles import StaticFiles
    from starlette.websockets import WebSocket, WebSocketDisconnect

    static = files("coassist.play") / "static"
    page = (static / "index.html").read_text(encoding="utf-8")
    hub = Hub(session)

    bind_host, bind_port = bind

    async def index(request):
        if not host_allowed(request.headers.get("host"), bind_host, bind_port):
            return PlainTextResponse("unknown host", status_code=421)
        return HTMLResponse(page, headers={"Cache-Control": "no-store"})

    async def ws_endpoint(websocket: WebSocket) -> None:
        if not host_allowed(websocket.headers.get("host"), bind_host, bind_port):
            await websocket.close(code=1008)
            return
        presented = websocket.query_params.get("token", "").encode("utf-8", "surrogatepass")
        if token is not None and not secrets.compare_digest(presented, token.encode("utf-8")):
            await websocket.close(code=1008)
            return
        origin = websocket.headers.get("origin")
        host = websocket.headers.get("host", "")
        if origin is not None and origin not in (f"http://{host}", f"https://{host}"):
            await websocket.close(code=1008)
            return
        await websocket.accept()
        hub.loop = asyncio.get_running_loop()
        client = _Client(websocket)
        hub.clients.append(client)
        if hub.hand is None and not getattr(session, "watch_only", False):
            hub.hand = client
            session.hand_back()
        sender = asyncio.create_task(_send(client))
        client.queue.append(hub.init_message(client))
        notice = session.notice
        if notice is not None and not session.running:  # how the last trial ended, which this page did not see
            client.queue.append(notice)
        client.wake.set()
        try:
            while True:
                message = await websocket.receive()
                if message["type"] == "websocket.disconnect":
                    break
                _handle(client, message.get("text"))
        except WebSocketDisconnect:
            pass
        finally:
            sender.cancel()
            hub.clients.remove(client)
            if hub.hand is client:  # the hand let go: zero force now, the trial waits `grace` for it
                hub.hand = None
                session.hand_left()
                if hub.clients and not session.running:  # another tab open: it is the hand now, and told so (it
                    hub.hand = successor = hub.clients[0]  # stayed "watching (another page is the hand)", unable
                    session.hand_back()  # to start, until it was reloaded)
                    successor.queue.append(hub.init_message(successor))
                    successor.wake.set()

    def _handle(client: _Client, text: str | None) -> None:
        now = time.monotonic()
        if now - client.window_start >= 1.0:
            client.window_start, client.window_count = now, 0
        client.window_count += 1
        if client.window_count > MAX_RATE:
            hub.drop("rate")
            return
        try:
            msg = parse_message(text, session.bounds, session.page_choices())
        except InvalidMessage as exc:
            hub.drop(str(exc))
            return
        except Exception:  # noqa: BLE001 - whatever a message makes the parser raise, the link stays up
            hub.drop("unparseable")
            return
        if isinstance(msg, Ping):
            if len(client.queue) >= MAX_QUEUED:  # a page that pings and never reads: its pongs are not kept
                hub.drop("pong queue full")
                return
            client.queue.append({"type": "pong", "seq": msg.seq})
            client.wake.set()
            return
        if client is not hub.hand:
            hub.drop("watcher")
            return
        if isinstance(msg, Pointer):
            # one older than the last (a message overtaken, or replayed) would move the hand back and keep it held
            if msg.seq <= client.last_pointer_seq:
                hub.drop("pointer: stale seq")
                return
            client.last_pointer_seq = msg.seq
            session.hand.set_pointer(msg.x, msg.y, msg.down, msg.seq)
        elif isinstance(msg, Start):
            if not session.start_trial(msg.controller):  # start_trial tells the pages
                hub.drop("start while running")
        elif isinstance(msg, Abort):
            session.abort()
        elif isinstance(msg, Answers):
            if not session.answer(msg.step, list(msg.values)):
                hub.drop("answers: none asked")
        elif isinstance(msg, Next):
            if not session.proceed(msg.step):
                hub.drop("next: nothing to go on to")

    async def _send(client: _Client) -> None:
        ws = client.websocket
        gap = 0.0 if frame_rate is None else 1.0 / frame_rate
        next_frame = 0.0
        try:
            while True:
                await client.wake.wait()
                client.wake.clear()
                while client.queue:
                    await ws.send_text(json.dumps(client.queue.popleft()))
                if gap and client.frame is not None:
                    now = time.monotonic()
                    if now < next_frame:
                        await asyncio.sleep(next_frame - now)
                    next_frame = max(now, next_frame) + gap
                frame, client.frame = client.frame, None
                if frame is not None:
                    await ws.send_text(json.dumps(hub._stamp(frame)))
        except (WebSocketDisconnect, RuntimeError, OSError):  # the page is gone; the receiver cleans up
            return

    app = Starlette(
        routes=[
            Route("/", index),
            Mount("/static", app=StaticFiles(directory=str(static)), name="static"),
            WebSocketRoute("/ws", ws_endpoint),
        ]
    )
    app.state.hub = hub
    return app


def bind_page_socket(host: str, port: int) -> socket.socket:
    """The page's listening socket, bound to ``host:port`` (0: a free port); ValueError in one line where it cannot
    be (the port taken). Bound before anything is recorded (a study's participant), and handed to
    :class:`PlayServer` (``sock=``)."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise ValueError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
    return sock


class PlayServer:
    """uvicorn serving :func:`create_app` on ``host:port`` (port 0: any free one).

    ``run()`` serves in this thread until interrupted (the CLI); ``start()`` serves in a
    background thread and returns once it listens (tests, the benchmark); ``stop()``
    aborts a running trial and shuts down. ``sock``: a socket :func:`bind_page_socket` bound already to
    ``host:port`` (a study binds it before it registers the participant); None: bound here.
    """

    def __init__(
        self,
        session: PlaySession,
        host: str = "127.0.0.1",
        port: int = 8765,
        token: str | None = None,
        frame_rate: float | None = None,
        ping: tuple[float, float] = (WS_PING_INTERVAL, WS_PING_TIMEOUT),
        sock: socket.socket | None = None,
    ) -> None:
        import uvicorn

        check_token(token, host)
        if len(ping) != 2 or not all(isinstance(v, (int, float)) and math.isfinite(v) and v > 0 for v in ping):
            raise ValueError(f"ping must be (interval, timeout), two numbers > 0 [s], got {ping!r}")
        self.ping = (float(ping[0]), float(ping[1]))  # [s] the keepalive's interval and timeout (WS_PING_INTERVAL)
        self.session, self.host, self.token = session, host, token
        if sock is None:
            sock = bind_page_socket(host, port)
        elif sock.getsockname()[1] != port and port != 0:
            raise ValueError(f"sock is bound to port {sock.getsockname()[1]}, not {port}")
        self._sock = sock
        self.port = int(self._sock.getsockname()[1])
        self.app = create_app(session, bind=(host, self.port), token=token, frame_rate=frame_rate)
        config = uvicorn.Config(
            self.app,
            log_level="warning",
            access_log=False,
            ws="websockets-sansio",
            ws_max_size=WS_MAX_SIZE,
            ws_per_message_deflate=False,
            # a link that goes silent without closing (Wi-Fi lost, a laptop asleep) is a hand that left: pinged and
            # closed within WS_PING_INTERVAL + WS_PING_TIMEOUT (uvicorn's own 20 s + 20 s kept such a trial running
            # to its end with nobody in it, and the person's page a watcher)
            ws_ping_interval=self.ping[0],
            ws_ping_timeout=self.ping[1],
            lifespan="off",
        )
        self._server = uvicorn.Server(config)
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        host = f"[{self.host}]" if ":" in self.host else self.host
        query = f"?token={self.token}" if self.token else ""
        return f"http://{host}:{self.port}/{query}"

    @property
    def hub(self) -> Hub:
        return self.app.state.hub

    def run(self) -> None:
        try:
            self._server.run(sockets=[self._sock])
        finally:
            self._shutdown_session()

    def start(self, timeout: float = 10.0) -> PlayServer:
        self._thread = threading.Thread(
            target=lambda: asyncio.run(self._server.serve(sockets=[self._sock])),
            name="coassist-play-server",
            daemon=True,
        )
        self._thread.start()
        t_end = time.monotonic() + timeout
        while not self._server.started:
            if time.monotonic() > t_end or not self._thread.is_alive():
                raise RuntimeError("the play server did not start")
            time.sleep(0.01)
        return self

    def stop(self) -> None:
        self._server.should_exit = True
        if self._thread is not None:
            self._thread.join(10.0)
        self._shutdown_session()

    def _shutdown_session(self) -> None:
        if self.session.running:
            self.session.abort("server_stopped")
            self.session.wait(10.0)
        self.session.close()
        self._sock.close()

    def __enter__(self) -> PlayServer:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def new_token() -> str:
    """A random token for a non-local bind (128 bits, URL-safe)."""
    return secrets.token_urlsafe(16)


def check_token(token: str | None, host: str) -> None:
    """Refuse a token that cannot guard a bind to ``host`` (ValueError, one line naming ``--token``).

    Any bind: a given token holds only URL-safe characters (:data:`_TOKEN_CHARS`). A
    non-loopback bind needs a token of at least :data:`MIN_TOKEN_CHARS` characters and
    ``len(token) · log2(distinct characters) >= MIN_TOKEN_BITS`` (so ``"x"``, a short
    word and ``"aaaa…"`` are refused; a 16-character token needs 16 distinct characters).
    A loopback bind needs no token: only this machine reaches it.
    """
    if token is not None:
        if not isinstance(token, str):
            raise ValueError(f"--token must be a string, got {type(token).__name__}")
        odd = sorted(set(token) - _TOKEN_CHARS)
        if odd:
            raise ValueError(
                f"--token may hold only letters, digits and - . _ ~ (it travels in the page's URL), got {odd[0]!r}"
            )
    if is_loopback(host):
        return
    if not token:
        raise ValueError(f"binding {host} (not this machine only) needs a token: pass --token or let coassist make one")
    bits = len(token) * math.log2(len(set(token))) if len(set(token)) > 1 else 0.0
    if len(token) < MIN_TOKEN_CHARS or bits < MIN_TOKEN_BITS:
        raise ValueError(
            f"--token is too weak for --host {host} (anyone on the network may guess it): at least "
            f"{MIN_TOKEN_CHARS} characters and {MIN_TOKEN_BITS:g} bits (length x log2 of distinct "
            f"characters), got {len(token)} characters, {bits:.0f} bits; leave --token out and "
            "coassist makes a 128-bit one"
        )
