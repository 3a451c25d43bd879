r"""The host-side client of the pneumatic board, and its real-time loop.

>>> from sorocontrol import Board
>>> with Board.simulated(channels=2) as brd:          # a simulated board in its own process, on loopback
...     for t in brd.loop(duration=0.05, rate=100):
...         state = brd.set_pressure([10e3 * t / 0.05, 0.0])
>>> brd.loop_stats.iterations
5

:meth:`Board.connect` logs in to a board (``tcp://host:port`` and the shared secret), :meth:`Board.simulated`
starts a :class:`~sorocontrol.server.BoardServer` with a :class:`~sorocontrol.drivers.SimulatedPlant` in a
child process and connects to it. Every command is answered by the board's :class:`~sorocontrol.protocol.State`
(requested, applied and measured pressures [Pa], per-channel flags: clamped, rate-limited, vented, sensor
fault). Leaving the ``with`` block, normally or by an exception, vents the board and closes the connection.

After the login every frame is authenticated (a MAC under a session key and a sequence number, see
:mod:`sorocontrol.protocol`). The board vents when it hears nothing valid for its watchdog time (0.5 s by
default). Two ways to keep the session:

* ``keepalive=True`` (the default): a background thread sends a heartbeat whenever the connection has been
  quiet for a quarter of the watchdog time, so a person can pause at a Python prompt. The board still vents
  when the client process dies, hangs as a whole (SIGSTOP) or loses its network: the heartbeats stop.
  Inside :meth:`Board.loop` the thread stands aside (strict mode for the loop's duration).
* ``keepalive=False`` (strict, for control code): only commands and :meth:`Board.loop`'s heartbeats feed the
  watchdog, so a control loop that stalls is vented.

:meth:`Board.loop` paces a control loop without drift: iteration k is released at :math:`t_0 + k/f`
(sleep until ~0.3 ms before, then spin), so delays do not accumulate; iterations whose release time has
already passed by a whole period are skipped and counted as missed. After the loop, :attr:`Board.loop_stats`
has the achieved rate, the period jitter :math:`|T_k - 1/f|` (median, 99th percentile, maximum) and the
number of missed deadlines (iterations + missed = duration x rate).
"""
import logging
import math
import os
import socket
import threading
import time
from dataclasses import dataclass
from urllib.parse import urlparse

import numpy as np

from sorofem.errors import ParameterError, ProtocolError

from . import protocol as P

log = logging.getLogger(__name__)

__all__ = ["Board", "LoopStats"]


@dataclass
class LoopStats:
    """Figures of the last :meth:`Board.loop`: ``iterations``, ``duration`` [s], ``rate`` achieved [Hz],
    period jitter ``jitter_p50``/``jitter_p99``/``jitter_max`` [s] (:math:`|T_k - 1/f|`), ``lateness_p99``
    [s] (release time minus deadline), ``missed`` deadlines and the ``periods`` [s] themselves."""
    iterations: int
    duration: float
    rate: float
    target_rate: float
    jitter_p50: float
    jitter_p99: float
    jitter_max: float
    lateness_p99: float
    missed: int
    periods: np.ndarray

    def __str__(self):
        return (f"{self.iterations} iterations in {self.duration:.3f} s: {self.rate:.1f} Hz (target "
                f"{self.target_rate:g}), period jitter p50 {self.jitter_p50 * 1e6:.0f} us, p99 "
                f"{self.jitter_p99 * 1e6:.0f} us, max {self.jitter_max * 1e6:.0f} us, {self.missed} missed")


class Board:
    """A connection to a pneumatic board (use :meth:`connect` or :meth:`simulated`).

    Attributes
    ----------
    channels : int
    p_min, p_max, rate : ndarray [Pa], [Pa/s]
        The board's per-channel limits, announced at login.
    watchdog : float [s]
        The board vents when it hears nothing valid for this long.
    state : sorocontrol.protocol.State
        The last state received.
    """

    def __init__(self, sock, secret, process=None, timeout=1.0, keepalive=True, server_log=None):
        self._sock = sock
        self._process = process
        self._server_log = server_log        # a simulated board's log (its stderr), read when the board is lost
        self._lost = None                    # why the session ended, once it has
        self._seq = 0
        self._closed = False
        self._session = None
        self._io = threading.Lock()          # one command (frame out, answer in) at a time
        self._last_io = time.monotonic()
        self._keepalive = None
        self._ka_stop = threading.Event()
        self._ka_paused = False
        self.loop_stats = None
        self.state = None
        self._sock.settimeout(timeout)
        try:
            self._login(P.secret_bytes(secret))
        except BaseException:
            self._shutdown_process()
            sock.close()
            raise
        if keepalive:
            self._keepalive = threading.Thread(target=self._keepalive_run, daemon=True, name="soro-board-keepalive")
            self._keepalive.start()

    # ---- constructors -------------------------------------------------------------------------------
    @classmethod
    def connect(cls, url="tcp://127.0.0.1:8888", secret=None, *, secret_file=None, timeout=1.0, keepalive=True):
        """Connect and log in to the board at ``url`` (``tcp://host:port``).

        Parameters
        ----------
        secret : bytes or str, optional
            The shared secret (whitespace at both ends is ignored, as on the board); default the file
            ``secret_file``, else the environment variable ``SORO_BOARD_SECRET``.
        secret_file : path, optional
            A file holding the secret (the same file as the board's ``--secret-file``).
        timeout : float [s]
            How long to wait for each answer of the board.
        keepalive : bool
            Heartbeats from a background thread when the connection is quiet (see the module docstring);
            False for strict control code.
        """
        parsed = urlparse(url)
        if parsed.scheme != "tcp" or not parsed.hostname or not parsed.port:
            raise ParameterError(f"board url must look like tcp://host:port, got {url!r}")
        try:
            if secret is None and secret_file is not None:
                secret = P.read_secret_file(secret_file)
            secret = secret if secret is not None else os.environ.get("SORO_BOARD_SECRET")
            if secret is None:
                raise ProtocolError("no shared secret: pass Board.connect(url, secret=... or secret_file=...) or "
                                    "set SORO_BOARD_SECRET")
            secret = P.secret_bytes(secret)
        except ProtocolError as e:
            raise ParameterError(str(e)) from None
        try:
            sock = socket.create_connection((parsed.hostname, parsed.port), timeout=timeout)
        except OSError as e:
            raise ProtocolError(f"cannot reach the board at {url}: {e}; is the server running "
                                "(python -m sorocontrol.server, or the soro-board service on the Pi)?") from e
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return cls(sock, secret, timeout=timeout, keepalive=keepalive)

    @classmethod
    def simulated(cls, channels=4, *, p_min=-100e3, p_max=100e3, rate=1e6, watchdog=0.5, board_rate=400.0,
                  volume=20e-6, time_constant=0.03, max_flow=2e-3, beam=None, timeout=5.0, keepalive=True,
                  network=None, network_dt=2e-3):
        """Start a simulated board (:class:`~sorocontrol.drivers.SimulatedPlant` behind a
        :class:`~sorocontrol.server.BoardServer`, same limits and watchdog as a real one) in a child process
        (``python -m sorocontrol.server --driver simulated --plant-from-parent``) on loopback and connect to
        it; closing the board stops the process. ``beam``: a :class:`soroshapes.Shapes` with one chamber input
        per channel, simulated as the robot (its tip position and coordinates are the state's ``sensors``).
        ``network``: instead, a :class:`~sorocontrol.drivers.NetworkRecipe` of a network plant (an arm and an
        object, ...), built in the child (:class:`~sorocontrol.drivers.SimulatedPlant`).

        The plant goes to the child over its stdin pipe (no file), and the child watches that pipe: when
        this process ends, whatever way (SIGKILL included), the simulated board vents and exits."""
        import subprocess
        import sys
        import tempfile

        from .server import send_plant

        secret = os.urandom(32).hex()
        plant = dict(volume=volume, time_constant=time_constant, max_flow=max_flow, beam=beam)
        if network is not None:
            plant.update(network=network, network_dt=network_dt)
        cmd = [sys.executable, "-m", "sorocontrol.server", "--driver", "simulated", "--channels", str(channels),
               "--port", "0", "--p-min", repr(p_min), "--p-max", repr(p_max), "--rate", repr(rate),
               "--watchdog", repr(watchdog), "--board-rate", repr(board_rate), "--plant-from-parent"]
        env = dict(os.environ, SORO_BOARD_SECRET=secret)   # not on the command line (visible to ps)
        errors = tempfile.TemporaryFile("w+")   # the server's log: said when it fails to start or drops us
        proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=errors, env=env)
        try:
            send_plant(proc.stdin, plant)
            line = proc.stdout.readline().decode()      # "listening HOST PORT" once ready
            if not line.startswith("listening"):
                proc.wait(10)
                errors.seek(0)
                raise ParameterError(f"the simulated board did not start: {errors.read().strip()[-2000:]}")
            port = int(line.split()[2])
            sock = socket.create_connection(("127.0.0.1", port), timeout=timeout)
        except BaseException:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            for stream in (proc.stdin, proc.stdout, errors):
                stream.close()
            raise
        proc.stdout.close()
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        try:
            return cls(sock, secret, process=proc, timeout=timeout, keepalive=keepalive, server_log=errors)
        except BaseException:
            errors.close()
            raise

    @property
    def server_process(self):
        """The :class:`subprocess.Popen` of a simulated board's server (None for a board reached by url)."""
        return self._process

    # ---- protocol -----------------------------------------------------------------------------------
    def _login(self, secret):
        mtype, payload = self._receive()
        if mtype != P.MessageType.HELLO:
            raise ProtocolError(f"expected HELLO from the board, got {mtype.name}")
        hello = P.unpack_hello(payload)
        client_nonce = P.new_nonce()
        P.send_frame(self._sock, P.encode(P.MessageType.AUTH, P.pack_auth(
            client_nonce, P.client_proof(secret, hello.nonce, client_nonce))))
        mtype, payload = self._receive()
        if mtype != P.MessageType.READY:
            raise ProtocolError(f"expected READY from the board, got {mtype.name}")
        if not P.hmac.compare_digest(payload, P.server_proof(secret, hello.nonce, client_nonce)):
            raise ProtocolError("the board could not prove it knows the secret: wrong board or a "
                                "man-in-the-middle")
        self._session = P.Session(secret, hello.nonce, client_nonce, "client")
        self.hello = hello
        self.channels = hello.channels
        self.p_min, self.p_max, self.rate, self.watchdog = hello.p_min, hello.p_max, hello.rate, hello.watchdog

    def _receive(self):
        try:
            mtype, payload = P.read_frame(self._sock)
        except socket.timeout:
            raise ProtocolError("the board did not answer within the timeout") from None
        except ConnectionError as e:
            raise self._loss(f"the board closed the connection ({e})") from None
        except OSError as e:
            raise self._loss(f"lost the board: {e}") from None
        if self._session is not None:
            payload = self._session.open(mtype, payload)
        if mtype == P.MessageType.ERROR:
            code, message = P.unpack_error(payload)
            name = P.ErrorCode(code).name if code in P.ErrorCode._value2member_map_ else str(code)
            text = f"board refused: {name}: {message}"
            if self._session is not None:     # after the login the board closes the connection after an ERROR
                self._lost = text
            raise ProtocolError(text)
        return mtype, payload

    def _loss(self, text):
        """The ProtocolError for a connection that broke (``text``: how), saying why when it can: the ERROR
        frame the board sent before closing (e.g. its watchdog's), else the last lines of a simulated board's
        log. The session is over: later commands raise the same reason."""
        why = None
        if self._session is not None:
            try:                              # the board may have said why before closing: read it
                self._sock.settimeout(0.2)
                mtype, payload = P.read_frame(self._sock)
                if mtype == P.MessageType.ERROR:
                    code, message = P.unpack_error(self._session.open(mtype, payload))
                    name = P.ErrorCode(code).name if code in P.ErrorCode._value2member_map_ else str(code)
                    why = f"the board said: {name}: {message}"
            except (OSError, ProtocolError, ValueError):
                pass
        if why is None:
            why = self._server_log_tail()
        self._lost = f"{text}; {why}" if why else text
        return ProtocolError(self._lost)

    def _server_log_tail(self, lines=6):
        """The last warnings and errors of a simulated board's server (its stderr), or None."""
        log_file = self._server_log
        if log_file is None or self._process is None:
            return None
        try:
            log_file.seek(0)
            said = [ln.strip() for ln in log_file.read().splitlines() if " WARNING " in ln or " ERROR " in ln
                    or "Traceback" in ln or "Error" in ln]
        except (OSError, ValueError):
            return None
        try:                       # a server that died closed its sockets just before it could be waited for
            state = f"exited with status {self._process.wait(0.5)}"
        except Exception:  # noqa: BLE001 - TimeoutExpired: still running
            state = "running"
        tail = " | ".join(said[-lines:]) if said else "no warnings"
        return f"the simulated board's server ({state}) logged: {tail}"

    def _command(self, mtype, payload):
        with self._io:
            if self._closed:
                raise ProtocolError("the board connection is closed")
            if self._lost is not None:
                raise ProtocolError(f"the board connection was lost: {self._lost}")
            try:
                P.send_frame(self._sock, self._session.seal(mtype, payload))
            except OSError as e:
                raise self._loss(f"lost the board: {e}") from e
            rtype, rpayload = self._receive()
            if rtype != P.MessageType.STATE:
                raise ProtocolError(f"expected STATE from the board, got {rtype.name}")
            self.state = P.unpack_state(rpayload)
            self._last_io = time.monotonic()
            self._sent = True
            return self.state

    def _next(self):
        with self._io:
            self._seq = (self._seq + 1) & 0xFFFFFFFF
            return self._seq

    def _keepalive_run(self):
        period = self.watchdog / 4
        while not self._ka_stop.wait(period / 4):
            if self._ka_paused or self._closed or time.monotonic() - self._last_io < period:
                continue
            try:
                self.heartbeat()
            except ProtocolError as e:
                if not self._closed:
                    log.warning("keepalive: %s; the next command will fail", e)
                return

    def _stop_keepalive(self):
        self._ka_stop.set()
        th, self._keepalive = self._keepalive, None
        if th is not None and th is not threading.current_thread():
            th.join()

    # ---- commands -----------------------------------------------------------------------------------
    def set_pressure(self, pressures):
        """Request gauge pressures [Pa] (one per channel; a scalar sets all). The board clamps them to its
        limits and slews at its rate limit; the returned state says so (``state.flagged(Flag.CLAMPED)``)."""
        values = np.broadcast_to(np.asarray(pressures, float), (self.channels,)) if np.ndim(pressures) == 0 \
            else np.asarray(pressures, float)
        if values.shape != (self.channels,):
            raise ParameterError(f"set_pressure needs {self.channels} values (one per channel), got shape "
                                 f"{values.shape}")
        if not np.all(np.isfinite(values)):
            raise ParameterError(f"non-finite pressure on channel(s) {np.flatnonzero(~np.isfinite(values)).tolist()}")
        state = self._command(P.MessageType.SET, P.pack_pressures(self._next(), values))
        clamped = state.flagged(P.Flag.CLAMPED)
        if clamped.size:
            log.warning("board clamped channel(s) %s to its limits", clamped.tolist())
        return state

    def read(self):
        """The board's state now (pressures [Pa], flags, sensors)."""
        return self._command(P.MessageType.READ, P.pack_sequence(self._next()))

    def heartbeat(self):
        """Feed the watchdog without changing set-points; returns the state."""
        return self._command(P.MessageType.HEARTBEAT, P.pack_sequence(self._next()))

    def vent(self):
        """All channels to 0 Pa at once (no rate limit)."""
        return self._command(P.MessageType.VENT, P.pack_sequence(self._next()))

    def close(self):
        """Vent, say goodbye and close (idempotent); stops a simulated board's process."""
        if self._closed:
            return
        self._stop_keepalive()
        try:
            self.vent()
            with self._io:
                P.send_frame(self._sock, self._session.seal(P.MessageType.BYE))
            while self._sock.recv(4096):    # until the board closes: then it is free for the next client
                pass
        except (ProtocolError, OSError) as e:
            log.warning("could not vent the board on close (%s); its watchdog vents it", e)
        finally:
            self._closed = True
            self._sock.close()
            self._shutdown_process()

    def _shutdown_process(self):
        proc, self._process = self._process, None
        if proc is not None:
            if proc.stdin is not None:
                proc.stdin.close()      # the server sees its parent's pipe close: it vents and exits
            try:
                proc.wait(2.0)
            except Exception:  # noqa: BLE001 - TimeoutExpired: ask it with a signal
                pass
            proc.terminate()
            try:
                proc.wait(5.0)
            except Exception:  # noqa: BLE001 - TimeoutExpired: it must go anyway
                proc.kill()
                proc.wait()
            for stream in (proc.stdout, proc.stderr):
                if stream is not None:
                    stream.close()
        log_file, self._server_log = self._server_log, None
        if log_file is not None:
            log_file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    # ---- real-time loop -----------------------------------------------------------------------------
    def loop(self, duration, rate, spin=3e-4):
        """Yield the loop time t [s] at ``rate`` [Hz] for ``duration`` [s], paced without drift.

        When an iteration sends no command, the loop sends a heartbeat so that a slow-but-alive controller
        is not vented (a hung one still is: the loop cannot send while the body runs, and the keepalive
        thread stands aside while the loop runs). ``spin`` [s]: busy-wait window before each release, for
        sub-millisecond jitter. Figures in :attr:`loop_stats` afterwards.
        """
        duration, rate = float(duration), float(rate)
        if not (duration > 0 and rate > 0 and math.isfinite(duration) and math.isfinite(rate)):
            raise ParameterError(f"loop needs positive duration [s] and rate [Hz], got {duration!r}, {rate!r}")
        period = 1.0 / rate
        count = int(round(duration * rate))
        releases, missed = [], 0
        t0 = time.perf_counter()
        k = 0
        self._ka_paused = True
        try:
            while k < count:
                deadline = t0 + k * period
                while True:
                    left = deadline - time.perf_counter()
                    if left <= 0:
                        break
                    if left > spin:
                        time.sleep(left - spin)
                now = time.perf_counter()
                releases.append((deadline, now))
                self._sent = False
                yield k * period
                if not self._sent and not self._closed:
                    self.heartbeat()
                k += 1
                late = time.perf_counter() - (t0 + k * period)
                if late > period:     # skip the deadlines already gone: no burst to catch up
                    skip = min(int(late // period), count - k)
                    missed += skip
                    k += skip
        finally:
            self._ka_paused = False
            self.loop_stats = self._stats(releases, missed, period, rate)

    @staticmethod
    def _stats(releases, missed, period, rate):
        if not releases:
            return LoopStats(0, 0.0, 0.0, rate, 0.0, 0.0, 0.0, 0.0, missed, np.zeros(0))
        d = np.array(releases)
        periods = np.diff(d[:, 1])
        jitter = np.abs(periods - period) if periods.size else np.zeros(1)
        span = d[-1, 1] - d[0, 1]
        return LoopStats(len(d), float(span + period), float((len(d) - 1) / span) if span > 0 else 0.0, rate,
                         float(np.median(jitter)), float(np.percentile(jitter, 99)), float(jitter.max()),
                         float(np.percentile(d[:, 1] - d[:, 0], 99)), int(missed), periods)
