"""The HTTP server of ``soro play`` (standard library only): the page, the scene, a stream of frames and the
commands.

Routes: ``GET /`` the page (:mod:`soro.play._page`), ``GET /scene`` the static scene (JSON), ``GET /events``
the frames as server-sent events, ``GET /state`` the latest frame (JSON), ``POST /cmd`` one command (JSON, see
:meth:`soro.play.backends.Backend.command`), ``POST /close`` the page is closing (vents the back end).
When the last page that listened to ``/events`` goes away, the back end is vented as well; closing the server
closes the back end (a board is vented and released).
"""
from __future__ import annotations

import errno
import json
import logging
import socket
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

from sorofem.errors import ParameterError, SoroError

from ._page import PAGE
from .backends import scene_geometry

__all__ = ["PlayServer", "ServeError", "DEFAULT_PORT"]

log = logging.getLogger(__name__)

DEFAULT_PORT = 8765


class ServeError(SoroError):
    """The server could not start (the port is taken, the address is not local, ...)."""


class _Http(ThreadingHTTPServer):
    daemon_threads = True
    allow_reuse_address = False      # a port in use must fail, not be shared


class PlayServer:
    """Serve a scene's page on ``http://host:port/`` with a back end.

    Parameters
    ----------
    scene : soro.play.Scene
    backend : soro.play.backends.Backend or callable () -> Backend
        Not yet started; the server starts and closes it. A callable is called after the port is bound, so a
        taken port fails before a board is started or reached.
    host : str
        Interface to bind, ``127.0.0.1`` by default (only this machine can open the page).
    port : int
        TCP port; 0 picks a free one (see :attr:`url`).
    """

    def __init__(self, scene, backend, host="127.0.0.1", port=DEFAULT_PORT):
        self.scene = scene
        self.clients = 0
        self._clients_lock = threading.Lock()
        self.closed_by_page = 0
        self._geometry = json.dumps(scene_geometry(scene)).encode()
        try:
            self.httpd = _Http((host, int(port)), self._handler())
        except OSError as e:
            if e.errno == errno.EADDRINUSE:
                raise ServeError(f"port {port} on {host} is in use (another soro play?): choose another with "
                                 f"--port N, or --port 0 for any free port") from None
            raise ServeError(f"cannot listen on {host}:{port}: {e.strerror or e}") from None
        self.thread = None
        try:
            self.backend = backend() if callable(backend) else backend
        except BaseException:
            self.httpd.server_close()
            raise

    @property
    def url(self):
        host, port = self.httpd.server_address[:2]
        return f"http://{host}:{port}/"

    def start(self):
        """Start the back end and serve in a background thread; returns self."""
        self.backend.start()
        self.thread = threading.Thread(target=self.httpd.serve_forever, kwargs={"poll_interval": 0.1}, daemon=True,
                                       name="soro-play-http")
        self.thread.start()
        return self

    def close(self):
        """Stop serving and close the back end (vents a board). Idempotent."""
        httpd, self.httpd = self.httpd, None
        if httpd is not None:
            if self.thread is not None:
                httpd.shutdown()
            httpd.server_close()
        self.backend.close()

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.close()

    # -- connections of the event stream ------------------------------------------------------------------
    def _listener(self, delta):
        with self._clients_lock:
            self.clients += delta
            last_left = delta < 0 and self.clients == 0
        if last_left:
            log.info("soro play: the last page closed; venting")
            self.backend.vent()

    def _handler(self):
        server = self

        class Handler(BaseHTTPRequestHandler):
            def log_message(self, fmt, *args):     # quiet: the CLI prints what matters
                log.debug("http: " + fmt, *args)

            def _send(self, code, body, ctype="application/json"):
                self.send_response(code)
                self.send_header("Content-Type", ctype)
                self.send_header("Content-Length", str(len(body)))
                self.send_header("Cache-Control", "no-store")
                self.end_headers()
                self.wfile.write(body)

            def do_GET(self):   # noqa: N802 - http.server's name
                if self.path in ("/", "/index.html"):
                    self._send(200, PAGE.encode(), "text/html; charset=utf-8")
                elif self.path == "/scene":
                    self._send(200, server._geometry)
                elif self.path == "/state":
                    self._send(200, json.dumps(server.backend.frame()).encode())
                elif self.path == "/events":
                    self._events()
                else:
                    self._send(404, b'{"ok": false, "error": "not found"}')

            def _events(self):
                self.send_response(200)
                self.send_header("Content-Type", "text/event-stream")
                self.send_header("Cache-Control", "no-store")
                self.end_headers()
                self.connection.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
                server._listener(+1)
                seq = -1
                try:
                    while server.httpd is not None:
                        f = server.backend.wait_frame(seq, 1.0)
                        if f is None:
                            self.wfile.write(b": idle\n\n")
                        else:
                            seq = f["seq"]
                            self.wfile.write(b"data: " + json.dumps(f).encode() + b"\n\n")
                        self.wfile.flush()
                except (BrokenPipeError, ConnectionResetError, ConnectionAbortedError, OSError):
                    pass
                finally:
                    server._listener(-1)

            def do_POST(self):   # noqa: N802
                n = int(self.headers.get("Content-Length") or 0)
                body = self.rfile.read(n) if n else b""
                if self.path == "/close":
                    server.closed_by_page += 1
                    server.backend.vent()
                    self._send(200, b'{"ok": true}')
                    return
                if self.path != "/cmd":
                    self._send(404, b'{"ok": false, "error": "not found"}')
                    return
                try:
                    cmd = json.loads(body or b"{}")
                    if not isinstance(cmd, dict):
                        raise ParameterError("a command is a JSON object")
                    answer = server.backend.command(cmd)
                    self._send(200, json.dumps(answer).encode())
                except (ValueError, TypeError, SoroError) as e:
                    self._send(400, json.dumps({"ok": False, "error": str(e)}).encode())

        return Handler
