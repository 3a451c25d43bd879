r"""The board server: runs on the Raspberry Pi (or, simulated, on the host), enforces the safety rules.

One thread runs the board loop at ``board_rate`` [Hz] (:meth:`BoardServer.tick`): the applied set-point of
each channel slews toward the requested one at most at the channel's rate limit, :math:`p_a \leftarrow p_a +
\mathrm{clip}(p_r - p_a, -r\,\Delta t, r\,\Delta t)`, and is sent to the driver, which returns the measured
pressures. Another thread accepts connections and runs their logins; the connection that logs in first takes
the control slot and is served by its own thread.

Safety rules (all enforced here, whatever the client does):

* no client logged in (or a fault) ⇒ the requested and applied pressures are 0 Pa on every channel, enforced
  by the board loop at every tick; a command from a connection that is no longer the client is refused;
* set-points outside ``[p_min, p_max]`` are clamped per channel (flag ``CLAMPED``), non-finite ones are an
  error; a channel's limits are the tighter of those the server is given and those of the board profile
  (:attr:`Driver.safety_limits`), so a profile's limit is never widened;
* the slew rate limit above (flag ``RATE_LIMITED`` while slewing);
* the measured pressure of every channel is checked against ``[p_min - tolerance, p_max + tolerance]`` at
  each tick: a channel outside for ``excursion_time`` vents the board and refuses commands until the next
  login, with an event that names the channel (a regulator fault or a wrong calibration in the profile);
* the watchdog: when the client sends no valid frame within ``watchdog`` seconds, every channel is vented
  (flag ``VENTED``), the client is told why (a sealed ``ERROR`` with code ``WATCHDOG``) and dropped. The
  silence measured is the client's, not the server's: it counts from the server's answer to the client's last
  valid command (a client waits for that answer before it sends again), and the board loop drops the client
  only when nothing it sent waits unread (in the socket, or in the hands of the thread that serves it), so a
  server that was slow to read or to answer (a long driver step, a busy machine) does not drop a healthy client. A client whose frames the
  server cannot read for the hard limit (four watchdog times, at least one second more than the watchdog) is
  dropped anyway: the server is overloaded or stuck;
* venting on a client's disconnect, on any protocol error (including a frame with a bad MAC or an old
  sequence number), on a driver exception and on shutdown (``stop()``, SIGTERM, SIGINT);
* connections that have not logged in never hold the control slot: at most ``max_pending`` wait, each for
  ``auth_timeout`` seconds (the oldest is dropped when a new one comes and they are all taken); failed logins
  back off per source address (``backoff``: the first wait, doubling up to the second).

Outside this process (``hardware/README.md``): the systemd unit's ``ExecStopPost`` runs
``python -m sorocontrol.vent`` when the server stops or dies, and the server pets systemd's watchdog
(``WatchdogSec``, ``sd_notify``) from the board loop, so a hung server is killed, vented and restarted.

Run it with ``python -m sorocontrol.server`` (``--help``; on the Pi with ``--driver i2c --profile FILE``, see
``hardware/README.md``) or from Python with :class:`BoardServer`.
"""
import argparse
import collections
import importlib
import logging
import math
import os
import select
import selectors
import signal
import socket
import struct
import sys
import threading
import time

import numpy as np

from sorofem.errors import ParameterError, ProtocolError

from . import protocol as P
from .drivers import Driver, MockDriver, SimulatedPlant

log = logging.getLogger(__name__)

__all__ = ["BoardServer", "main"]


class _NotClient(Exception):
    """A command arrived from a connection that no longer holds the control slot."""


class _Pending:
    """A connection that has not logged in yet."""
    __slots__ = ("peer", "nonce", "deadline", "reader")

    def __init__(self, peer, nonce, deadline):
        self.peer, self.nonce, self.deadline, self.reader = peer, nonce, deadline, P.FrameReader()


class BoardServer:
    """A board: a driver behind the protocol, with limits, rate limits, read-back checks and a watchdog.

    Parameters
    ----------
    driver : sorocontrol.drivers.Driver
    secret : bytes or str
        Shared secret for the login and the session keys (at least 16 bytes of entropy, see
        :func:`sorocontrol.protocol.secret_bytes`).
    host, port : str, int
        Where to listen (port 0 picks a free one: see :attr:`address`). Default loopback:8888.
    p_min, p_max : float or array [Pa], optional
        Safety limits, one for all channels or one per channel. When the driver has safety limits of its own
        (:attr:`Driver.safety_limits`: the ``p_min``/``p_max`` of each channel of the board profile), each
        channel gets the tighter of the two (the intersection; without these arguments, the profile's);
        otherwise these (default -100 kPa / 100 kPa). They must lie inside the driver's calibrated range
        (:attr:`Driver.p_range`) and contain 0 Pa. The limits in force are :attr:`p_min`/:attr:`p_max`
        (announced to the client at login).
    rate : float or array [Pa/s]
        Per-channel slew-rate limit of the applied set-point (default 1 MPa/s: 100 kPa in 0.1 s).
    watchdog : float [s]
        Vent when the controlling client is silent this long (default 0.5 s, Sorotoki's socket timeout).
    board_rate : float [Hz]
        Board loop rate (default 400 Hz, Sorotoki's Pi loop).
    auth_timeout : float [s]
        Time each new connection has to log in (default 2 s).
    tolerance : float or array [Pa], optional
        How far a measured pressure may leave ``[p_min, p_max]`` (regulator overshoot, sensor noise) before
        the board vents; default 20 % of ``p_max - p_min`` plus 5 kPa.
    excursion_time : float [s]
        How long a channel must stay outside before it counts (default 20 ms, at least one tick).
    max_pending : int
        Connections that may wait to log in at once (default 16).
    backoff : (float, float) [s]
        After the k-th consecutive failed login from an address, its next attempt is refused for
        ``min(backoff[0] * 2**(k-1), backoff[1])`` (default 0.1 s ... 10 s).
    clock : callable, optional
        Monotonic time source [s] (default :func:`time.monotonic`); tests inject one and call :meth:`tick`.
    """

    def __init__(self, driver, secret, host="127.0.0.1", port=8888, p_min=None, p_max=None, rate=1e6,
                 watchdog=0.5, board_rate=400.0, auth_timeout=2.0, tolerance=None, excursion_time=0.02,
                 max_pending=16, backoff=(0.1, 10.0), clock=None):
        if not isinstance(driver, Driver):
            raise ParameterError("driver must be a sorocontrol.drivers.Driver (I2CDriver, MockDriver or "
                                 "SimulatedPlant)")
        self.driver = driver
        n = self.channels = driver.channels
        try:
            self.secret = P.secret_bytes(secret)
        except ProtocolError as e:
            raise ParameterError(str(e)) from None
        self.p_min, self.p_max = self._limits(driver, p_min, p_max)
        self.rate = np.broadcast_to(np.asarray(rate, float), (n,)).copy()
        lo, hi = driver.p_range
        outside = np.flatnonzero((self.p_min < lo) | (self.p_max > hi))
        if outside.size:
            c = outside[0]
            raise ParameterError(f"the limits of channel {c} [{self.p_min[c] / 1e3:g}, {self.p_max[c] / 1e3:g}] kPa "
                                 f"leave the regulator's calibrated range [{lo[c] / 1e3:g}, {hi[c] / 1e3:g}] kPa "
                                 "(board profile): narrow the limits or fix the profile")
        if not np.all(self.rate > 0):
            raise ParameterError("rate limits must be positive [Pa/s]")
        if tolerance is None:
            tolerance = 0.2 * (self.p_max - self.p_min) + 5e3
        self.tolerance = np.broadcast_to(np.asarray(tolerance, float), (n,)).copy()
        if not np.all(self.tolerance >= 0):
            raise ParameterError("tolerance must be >= 0 [Pa]")
        for what, v in (("watchdog", watchdog), ("board_rate", board_rate), ("auth_timeout", auth_timeout),
                        ("excursion_time", excursion_time), ("backoff[0]", backoff[0]),
                        ("backoff[1]", backoff[1])):
            if not (math.isfinite(v) and v > 0):
                raise ParameterError(f"{what} must be positive, got {v!r}")
        if int(max_pending) < 1:
            raise ParameterError(f"max_pending must be at least 1, got {max_pending!r}")
        self.watchdog, self.board_rate, self.auth_timeout = float(watchdog), float(board_rate), float(auth_timeout)
        self.max_pending, self.backoff = int(max_pending), (float(backoff[0]), float(backoff[1]))
        self._excursion_ticks = max(1, int(math.ceil(excursion_time * self.board_rate - 1e-9)))
        self._clock = clock or time.monotonic
        self._t0 = self._clock()
        self.requested = np.zeros(n)
        self.applied = np.zeros(n)
        self.flags = np.zeros(n, np.int64)
        self.events = []                   # (board time, text) of vents, refusals and errors, newest last
        self.counters = collections.Counter()   # logins, auth_failures, backoff_refusals, evicted, expired, ...
        self._lock = threading.Lock()          # the state below and the control slot
        self._driver_lock = threading.Lock()   # the driver (taken before _lock when both are needed)
        self._stop = threading.Event()
        self._client = None                # the logged-in connection's socket
        self._client_peer = None
        self._client_session = None        # its Session: sealed and opened only under _client_reading
        self._client_reading = None        # held by whoever reads, answers or ends that connection
        self._hard_watchdog = max(4.0 * self.watchdog, self.watchdog + 1.0)
        self._fault = None                 # a driver or read-back failure: commands refused until the next login
        self._out_ticks = np.zeros(n, int)
        self._tripped = False
        self._last_valid = 0.0
        self._failures = collections.OrderedDict()   # address -> (consecutive failures, refused until)
        self._accept_alive = time.monotonic()
        measured, sensors, faults = driver.apply(np.zeros(n), 0.0)   # a first reading: states are never empty
        self.measured, self.sensors = np.asarray(measured, float), np.asarray(sensors, float)
        self.faults = np.asarray(faults, bool)
        if not host:
            raise ParameterError("no address to listen on: give --host (on the Pi: the lab-network address of "
                                 "the board, SORO_BOARD_HOST in /etc/soro-board/board.env)")
        self._sock = socket.create_server((host, int(port)), reuse_port=False)
        self._sock.setblocking(False)
        self.address = self._sock.getsockname()[:2]
        if self.address[0] in ("0.0.0.0", "::"):
            log.warning("listening on every interface (%s): any host that reaches the Pi can try to log in; "
                        "prefer the lab-network address", self.address[0])
        self._threads = []

    @staticmethod
    def _limits(driver, p_min, p_max):
        """The per-channel limits in force [Pa]: the arguments (default -100/100 kPa), narrowed per channel to
        the driver's own safety limits (the board profile's) when it has them."""
        n = driver.channels

        def per_channel(v, what):
            try:
                return np.broadcast_to(np.asarray(v, float), (n,)).copy()
            except ValueError:
                raise ParameterError(f"{what} must be one value or one per channel ({n}), got {v!r}") from None
        given = {what: None if v is None else per_channel(v, what) for what, v in (("p_min", p_min),
                                                                                   ("p_max", p_max))}
        for what, v in given.items():
            if v is not None and not (np.all(np.isfinite(v)) and np.all(v <= 0 if what == "p_min" else v >= 0)):
                raise ParameterError("pressure limits must be finite with p_min <= 0 <= p_max [Pa] (0 Pa, the "
                                     "vent pressure, must be allowed)")
        own = driver.safety_limits
        if own is None:
            lo = given["p_min"] if given["p_min"] is not None else np.full(n, -100e3)
            hi = given["p_max"] if given["p_max"] is not None else np.full(n, 100e3)
            return lo, hi
        own_lo, own_hi = (per_channel(v, "the driver's safety limits") for v in own)
        if not (np.all(np.isfinite(own_lo)) and np.all(np.isfinite(own_hi)) and np.all(own_lo <= 0)
                and np.all(own_hi >= 0)):
            raise ParameterError("the driver's safety limits (board profile p_min/p_max) must be finite with "
                                 "p_min <= 0 <= p_max [Pa]: fix the profile")
        lo = own_lo if given["p_min"] is None else np.maximum(given["p_min"], own_lo)
        hi = own_hi if given["p_max"] is None else np.minimum(given["p_max"], own_hi)
        for what, arg, own_v, used in (("p_min", given["p_min"], own_lo, lo), ("p_max", given["p_max"], own_hi, hi)):
            if arg is None:
                continue
            wider = np.flatnonzero(used != arg)
            if wider.size:
                log.info("%s of channel(s) %s: the board profile's %s kPa applies (tighter than the %s kPa "
                         "given)", what, wider.tolist(), (own_v[wider] / 1e3).tolist(), (arg[wider] / 1e3).tolist())
        log.info("safety limits per channel [kPa]: %s",
                 ", ".join(f"{c}: [{a / 1e3:g}, {b / 1e3:g}]" for c, (a, b) in enumerate(zip(lo, hi))))
        return lo, hi

    # ---- life cycle ---------------------------------------------------------------------------------
    def start(self, loop=True):
        """Start the accept loop and (``loop``, default) the board loop in background threads; returns
        ``self``. Without ``loop`` the caller runs the board by calling :meth:`tick`."""
        targets = (self._board_loop, self._accept_loop) if loop else (self._accept_loop,)
        for target in targets:
            th = threading.Thread(target=target, daemon=True, name=f"soro-board-{target.__name__}")
            th.start()
            self._threads.append(th)
        log.info("board serving %d channels on %s:%d", self.channels, *self.address)
        return self

    def serve_forever(self):
        """Start and block until :meth:`stop` (or SIGINT/SIGTERM in the main thread)."""
        self.start()
        try:
            while not self._stop.wait(0.2):
                pass
        finally:
            self.stop()

    def stop(self):
        """Vent, close the client and the listening socket, release the driver."""
        if self._stop.is_set() and not self._threads:
            return
        self._stop.set()
        for th in self._threads:
            th.join(timeout=2.0)
        self._threads = []
        self._drop_client("shutdown")
        self._vent("shutdown")
        self._sock.close()
        try:
            self.driver.close()
        except Exception as e:  # noqa: BLE001 - report, the process is going down anyway
            log.error("driver close failed: %s", e)

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()

    def now(self):
        """Board time [s] since the server was created."""
        return self._clock() - self._t0

    @property
    def client(self):
        """``"host:port"`` of the logged-in client, or None."""
        with self._lock:
            return self._client_peer if self._client is not None else None

    @property
    def serving(self):
        """True while the thread that serves the client reads or answers its frames: time the watchdog does
        not count as the client's silence (tests stepping the board loop wait for it to end)."""
        reading = self._client_reading
        return reading is not None and reading.locked()

    @property
    def fault(self):
        """Why commands are refused until the next login (a driver or read-back failure), or None."""
        return self._fault

    def healthy(self, within=1.0):
        """True when the board loop ticked and the accept loop ran within ``within`` seconds (real time):
        what the systemd watchdog is petted on."""
        t = time.monotonic()
        return t - self._last_tick_real < within and t - self._accept_alive < within

    # ---- board loop ---------------------------------------------------------------------------------
    def _event(self, text):
        self.events.append((round(self.now(), 6), text))
        del self.events[:-200]
        log.warning("board: %s", text)

    def _vent(self, why, conn=None, release=None, fault=None):
        """All channels to 0 Pa at once and the driver's vent, in one critical section with the state, so
        that nobody sees the slot free and the DAC still pressurized. With ``conn``: only if it is still the
        client (else :class:`_NotClient`). With ``release``: that connection loses the slot in the same
        section (no vent if it did not hold it); returns whether it held it. With ``fault``: the board's fault
        is set in the same section after the outputs, so nobody sees the fault with them still pressurized."""
        with self._driver_lock:
            with self._lock:
                if conn is not None and self._client is not conn:
                    raise _NotClient
                if release is not None:
                    if self._client is not release:
                        return False
                    self._client = None
                self._zero_locked()
                try:
                    self.driver.vent()
                except Exception as e:  # noqa: BLE001 - a vent must not raise; say it loudly
                    log.error("driver vent failed: %s", e)
                if fault is not None:     # after the outputs are at 0 Pa: whoever sees the fault sees them vented
                    self._fault = fault
        self._event(f"vented ({why})")
        return True

    def _zero_locked(self):
        self.requested[:] = 0.0
        self.applied[:] = 0.0
        self.flags |= P.Flag.VENTED
        self.flags &= ~(P.Flag.RATE_LIMITED | P.Flag.CLAMPED)

    _last_tick_real = 0.0

    def tick(self):
        """One iteration of the board loop at the clock's time: watchdog, the no-client rule, slewing, the
        driver, the read-back check. The board loop thread calls it at ``board_rate``."""
        t = self.now()
        self._last_tick_real = time.monotonic()
        dt = 1.0 / self.board_rate
        dropped, forced = None, False
        with self._driver_lock:
            with self._lock:
                if self._client is not None and t - self._last_valid > self.watchdog:
                    dropped = self._silent_client(t - self._last_valid)
                    if dropped is not None:
                        self._client = None
                driver_error = None
                if self._client is None or self._fault:       # nobody may hold pressure
                    forced = bool(np.any(self.requested != 0) or np.any(self.applied != 0))
                    self.requested[:] = 0.0
                    self.applied[:] = 0.0
                    if forced or dropped:                     # vent before anyone sees the slot free
                        self._zero_locked()
                        try:
                            self.driver.vent()
                        except Exception as e:  # noqa: BLE001 - any driver failure vents the board
                            driver_error = f"driver error: {type(e).__name__}: {e}"
                else:
                    step = self.rate * dt
                    self.applied += np.clip(self.requested - self.applied, -step, step)
                slewing = np.abs(self.requested - self.applied) > 1e-9 * np.maximum(1.0, np.abs(self.requested))
                self.flags = np.where(slewing, self.flags | P.Flag.RATE_LIMITED, self.flags & ~P.Flag.RATE_LIMITED)
                applied = self.applied.copy()
            try:
                if driver_error is None:
                    measured, sensors, faults = self.driver.apply(applied, t)
            except Exception as e:  # noqa: BLE001 - any driver failure vents the board
                driver_error = f"driver error: {type(e).__name__}: {e}"
        if dropped is not None:
            conn, session, reading, why = dropped
            self._event(why)
            if reading is not None:         # we hold the connection: tell the client why, then close it
                try:
                    self._send_error(conn, P.ErrorCode.WATCHDOG, f"{why}; every channel vented, log in again",
                                     session)
                    self._close(conn)
                finally:
                    reading.release()
            else:
                self._close(conn)
            self._event("vented (watchdog)")
        elif forced:
            self._event("vented (no client logged in: every channel held at 0 Pa)")
        if driver_error is not None:
            if self._fault != driver_error:
                self._event(driver_error)
                self._vent("driver error", fault=driver_error)
            return
        measured, faults = np.asarray(measured, float), np.asarray(faults, bool)
        with self._lock:
            self.measured, self.sensors, self.faults = measured, np.asarray(sensors, float), faults
            self.flags = np.where(faults, self.flags | P.Flag.SENSOR_FAULT, self.flags & ~P.Flag.SENSOR_FAULT)
        self._check_readback(measured, faults)

    def _silent_client(self, silence):
        """Whether the logged-in client really was silent for ``silence`` [s] > the watchdog (called under
        ``_lock``): None when something it sent waits unread, in its socket or being served (the server was
        slow, not the client), until the hard limit. Otherwise ``(conn, session, reading, why)``: ``reading``
        is the connection's reading lock, acquired (the caller sends the reason and releases it), or None
        when the thread that serves it holds it past the hard limit."""
        conn, who, reading = self._client, self._client_peer, self._client_reading
        hard = silence > self._hard_watchdog
        held = reading.acquire(blocking=False)
        waiting = not held or self._readable(conn)
        if waiting and not hard:
            if held:
                reading.release()
            self.counters["watchdog_waits"] += 1      # ticks on which the client spoke but was not read yet
            return None
        if waiting:
            why = (f"watchdog: the frames of {who} were not read for {silence:.3f} s (hard limit "
                   f"{self._hard_watchdog:g} s): the board server is overloaded or stuck: dropped")
        else:
            why = f"watchdog: no valid command from {who} for {silence:.3f} s (timeout {self.watchdog} s): dropped"
        return conn, self._client_session if held else None, reading if held else None, why

    @staticmethod
    def _readable(conn):
        """True when ``conn`` has bytes (or its end) waiting to be read."""
        try:
            return bool(select.select([conn], [], [], 0)[0])
        except (ValueError, OSError):     # closed under us: its serving thread ends the session
            return False

    def _check_readback(self, measured, faults):
        out = ~faults & ((measured < self.p_min - self.tolerance) | (measured > self.p_max + self.tolerance))
        self._out_ticks = np.where(out, self._out_ticks + 1, 0)
        tripped = np.flatnonzero(self._out_ticks >= self._excursion_ticks)
        if not tripped.size:
            self._tripped = False
            return
        c = tripped[0]
        why = (f"channel {c} measures {measured[c] / 1e3:.1f} kPa, outside its limits [{self.p_min[c] / 1e3:g}, "
               f"{self.p_max[c] / 1e3:g}] kPa (tolerance {self.tolerance[c] / 1e3:g} kPa) with "
               f"{self.requested[c] / 1e3:g} kPa requested: check the regulator, its supply and the calibration "
               "in the board profile")
        if not self._tripped:
            self._tripped = True
            self._event(why)
            self._vent(f"read-back outside the limits on channel(s) {tripped.tolist()}", fault=why)
        else:
            self._fault = why

    def _board_loop(self):
        dt = 1.0 / self.board_rate
        next_t = time.monotonic()
        while not self._stop.is_set():
            self.tick()
            next_t += dt
            delay = next_t - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            else:
                next_t = time.monotonic()   # overrun: do not try to catch up with a burst

    # ---- connections and logins ---------------------------------------------------------------------
    def _backoff_left(self, addr):
        entry = self._failures.get(addr)
        return 0.0 if entry is None else max(entry[1] - self._clock(), 0.0)

    def _login_failed(self, addr):
        count = self._failures.pop(addr, (0, 0.0))[0] + 1
        wait = min(self.backoff[0] * 2.0 ** min(count - 1, 64), self.backoff[1])
        self._failures[addr] = (count, self._clock() + wait)
        while len(self._failures) > 4096:
            self._failures.popitem(last=False)
        return count, wait

    def _accept_loop(self):
        sel = selectors.DefaultSelector()
        sel.register(self._sock, selectors.EVENT_READ, None)
        pending = collections.OrderedDict()     # socket -> _Pending, oldest first
        try:
            while not self._stop.is_set():
                self._accept_alive = time.monotonic()
                for key, _ in sel.select(timeout=0.05):
                    try:
                        if key.data is None:
                            self._accept(sel, pending)
                        else:
                            self._login_step(sel, pending, key.fileobj)
                    except Exception as e:  # noqa: BLE001 - the accept loop must survive any peer
                        self._event(f"internal error in the accept loop: {type(e).__name__}: {e}")
                        if key.data is not None:
                            self._forget(sel, pending, key.fileobj, P.ErrorCode.INTERNAL, "internal error")
                now = self._clock()
                for conn in [c for c, pd in pending.items() if now > pd.deadline]:
                    self.counters["expired"] += 1
                    log.info("login of %s:%d timed out", *pending[conn].peer[:2])
                    self._forget(sel, pending, conn, P.ErrorCode.AUTH,
                                 f"no AUTH within {self.auth_timeout} s of HELLO")
        finally:
            for conn in list(pending):
                self._forget(sel, pending, conn)
            sel.close()

    def _forget(self, sel, pending, conn, code=None, message=""):
        pending.pop(conn, None)
        try:
            sel.unregister(conn)
        except (KeyError, ValueError):
            pass
        if code is not None:
            self._send_error(conn, code, message)
        conn.close()

    def _accept(self, sel, pending):
        try:
            conn, peer = self._sock.accept()
        except (BlockingIOError, OSError):
            return
        wait = self._backoff_left(peer[0])
        if wait > 0:
            self.counters["backoff_refusals"] += 1
            self._send_error(conn, P.ErrorCode.AUTH, f"too many failed logins from {peer[0]}: retry in {wait:.1f} s")
            conn.close()
            return
        if len(pending) >= self.max_pending:
            oldest = next(iter(pending))
            self.counters["evicted"] += 1
            log.info("%d connections waiting to log in: dropped the oldest (%s:%d)", len(pending),
                     *pending[oldest].peer[:2])
            self._forget(sel, pending, oldest, P.ErrorCode.BUSY, "too many connections waiting to log in")
        try:
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            nonce = P.new_nonce()
            P.send_frame(conn, P.encode(P.MessageType.HELLO, P.pack_hello(self._hello(nonce))))
            conn.setblocking(False)
        except OSError:
            conn.close()
            return
        pending[conn] = _Pending(peer, nonce, self._clock() + self.auth_timeout)
        sel.register(conn, selectors.EVENT_READ, True)

    def _login_step(self, sel, pending, conn):
        pd = pending.get(conn)
        if pd is None:
            return
        who = f"{pd.peer[0]}:{pd.peer[1]}"
        try:
            data = conn.recv(4096)
        except BlockingIOError:
            return
        except OSError:
            data = b""
        if not data:
            self._forget(sel, pending, conn)
            return
        try:
            frames = pd.reader.feed(data)
            if not frames:
                return
            mtype, payload = frames[0]
            if mtype != P.MessageType.AUTH:
                raise ProtocolError(f"expected AUTH, got {mtype.name}")
            client_nonce, proof = P.unpack_auth(payload)
        except ProtocolError as e:
            self._event(f"protocol error from {who} before login: {e}")
            self._forget(sel, pending, conn, P.error_code(e), str(e))
            return
        if not P.hmac.compare_digest(proof, P.client_proof(self.secret, pd.nonce, client_nonce)):
            count, wait = self._login_failed(pd.peer[0])
            self.counters["auth_failures"] += 1
            self._event(f"refused {who}: authentication failed ({count} in a row from {pd.peer[0]}; its next "
                        f"attempt is refused for {wait:.1f} s)")
            self._forget(sel, pending, conn, P.ErrorCode.AUTH, "authentication failed: wrong shared secret")
            return
        pending.pop(conn)
        sel.unregister(conn)
        self._failures.pop(pd.peer[0], None)
        session, reading = P.Session(self.secret, pd.nonce, client_nonce, "board"), threading.Lock()
        with self._lock:
            busy = self._client is not None
            if not busy:
                self._client, self._client_peer = conn, who
                self._client_session, self._client_reading = session, reading
                self._last_valid = self.now()
                self._fault = None
        if busy:
            self._event(f"refused {who}: another client controls the board")
            self._send_error(conn, P.ErrorCode.BUSY, "another client controls the board; one at a time")
            conn.close()
            return
        self.counters["logins"] += 1
        try:
            conn.setblocking(True)
            conn.settimeout(1.0)
            P.send_frame(conn, P.encode(P.MessageType.READY, P.server_proof(self.secret, pd.nonce, client_nonce)))
        except OSError as e:
            self._release(conn, who, f"client {who} lost at login: {e}")
            return
        log.info("client %s logged in", who)
        threading.Thread(target=self._serve_client, args=(conn, who, session, pd.reader, reading), daemon=True,
                         name="soro-board-client").start()

    @staticmethod
    def _close(conn):
        try:
            conn.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        conn.close()

    def _drop_client(self, why):
        with self._lock:
            conn, self._client = self._client, None
        if conn is not None:
            self._event(f"client dropped ({why})")
            self._close(conn)

    def _release(self, conn, who, why):
        """End the connection ``conn``; vent if it still held the slot."""
        self._vent(why or f"client {who} disconnected", release=conn)
        self._close(conn)

    @staticmethod
    def _send_error(conn, code, message, session=None):
        frame = P.pack_error(code, message)
        try:
            P.send_frame(conn, session.seal(P.MessageType.ERROR, frame) if session
                         else P.encode(P.MessageType.ERROR, frame))
        except OSError:
            pass

    def _hello(self, nonce):
        return P.Hello(P.PROTOCOL_VERSION, self.channels, self.watchdog, self.board_rate, self.p_min, self.p_max,
                       self.rate, nonce)

    def _state(self, sequence):
        return P.pack_state(P.State(self.now(), sequence, self.requested.copy(), self.applied.copy(),
                                    self.measured.copy(), self.flags.copy(), self.sensors.copy()))

    def _command(self, conn, mtype, body, who):
        """Carry out one command of the client ``conn``; returns the STATE payload that answers it. Refused
        (:class:`_NotClient`) when ``conn`` no longer holds the slot: checked under the lock that the board
        loop takes to drop a client, so a command never lands after the vent that ended its session."""
        if mtype == P.MessageType.SET:
            seq, values = P.unpack_pressures(body, self.channels)
            if not np.all(np.isfinite(values)):
                raise ProtocolError(f"non-finite set-point on channel(s) "
                                    f"{np.flatnonzero(~np.isfinite(values)).tolist()}")
        elif mtype in (P.MessageType.READ, P.MessageType.HEARTBEAT, P.MessageType.VENT):
            seq = P.unpack_sequence(body)
        else:
            raise ProtocolError(f"unexpected {mtype.name} from a client")
        if mtype == P.MessageType.VENT:
            self._vent(f"requested by {who}", conn=conn)
        with self._lock:
            if self._client is not conn:
                raise _NotClient
            if self._fault:
                raise ProtocolError(f"board fault, vented: {self._fault}; reconnect to clear it once fixed")
            if mtype == P.MessageType.SET:
                clamped = np.clip(values, self.p_min, self.p_max)
                self.requested = clamped
                self.flags &= ~(P.Flag.VENTED | P.Flag.CLAMPED)
                self.flags |= np.where(clamped != values, int(P.Flag.CLAMPED), 0)
            self._last_valid = self.now()
            return self._state(seq)

    def _serve_client(self, conn, who, session, reader, reading):
        """Serve the logged-in connection ``conn`` until it ends: wait for its bytes, then read and answer them
        holding ``reading`` (so the board loop's watchdog sees them either waiting in the socket or being
        served, never lost in between: :meth:`_silent_client`)."""
        why = None
        poll = selectors.DefaultSelector()
        try:
            conn.settimeout(0.05)
            poll.register(conn, selectors.EVENT_READ)
            while not self._stop.is_set() and self._client is conn:
                if not poll.select(timeout=0.05):
                    continue
                with reading:
                    if self._client is not conn:
                        break
                    why = self._serve_frames(conn, who, session, reader)
                if why is not None:
                    break
        except (ValueError, OSError) as e:     # closed under us (shutdown, hard watchdog)
            why = f"client {who} lost: {e}"
        finally:
            poll.close()
            self._release(conn, who, why)

    def _serve_frames(self, conn, who, session, reader):
        """Read what ``conn`` sent and answer each complete frame; None, or why the connection ends (it was
        answered with an ERROR frame when the client is at fault)."""
        try:
            try:
                data = conn.recv(65536)
            except socket.timeout:       # readable, then nothing after all: wait again
                return None
            if not data:
                raise ConnectionError("closed by the client")
            for mtype, payload in reader.feed(data):
                body = session.open(mtype, payload)
                if mtype == P.MessageType.BYE:
                    return f"client {who} said bye"
                P.send_frame(conn, session.seal(P.MessageType.STATE, self._command(conn, mtype, body, who)))
                with self._lock:       # answered: the client waited for this answer, so its silence starts now
                    if self._client is conn:
                        self._last_valid = self.now()
        except _NotClient:
            self.counters["late_commands"] += 1
            self._event(f"refused a command from {who}: it no longer controls the board")
            return f"client {who} no longer controls the board"
        except ProtocolError as e:
            self._send_error(conn, P.error_code(e), str(e), session)
            return f"protocol error from {who}: {e}"
        except (ConnectionError, socket.timeout, OSError) as e:
            return f"client {who} lost: {e}"
        except Exception as e:  # noqa: BLE001 - the server must survive anything a client sends
            self._send_error(conn, P.ErrorCode.INTERNAL, f"{type(e).__name__}: {e}", session)
            return f"internal error serving {who}: {type(e).__name__}: {e}"
        return None


# ---- command line ---------------------------------------------------------------------------------------

def _read_secret(args):
    try:
        if args.secret_file:
            return P.read_secret_file(args.secret_file)
        if args.secret:
            return P.secret_bytes(args.secret, "--secret")
        if os.environ.get("SORO_BOARD_SECRET") is not None:
            return P.secret_bytes(os.environ["SORO_BOARD_SECRET"], "SORO_BOARD_SECRET")
    except ProtocolError as e:
        raise SystemExit(f"python -m sorocontrol.server: {e}") from None
    raise SystemExit("give the shared secret with --secret-file PATH (on the Pi: /etc/soro-board/secret, "
                     f"mode 600; make one with `{P.MAKE_SECRET}`), the environment variable SORO_BOARD_SECRET, "
                     "or --secret TEXT (tests only)")


def _import_plant(spec):
    """``module:attribute`` -> SimulatedPlant keyword arguments (a dict, or a callable returning one)."""
    module, _, attr = spec.partition(":")
    if not module or not attr:
        raise SystemExit(f"--plant takes a Python import path MODULE:NAME (a dict of SimulatedPlant keyword "
                         f"arguments or a function returning one), got {spec!r}")
    obj = getattr(importlib.import_module(module), attr)
    kw = obj() if callable(obj) else obj
    if not isinstance(kw, dict):
        raise SystemExit(f"--plant {spec} gave {type(kw).__name__}, expected a dict of SimulatedPlant arguments")
    return kw


_LENGTH = struct.Struct("<Q")


def send_plant(stream, plant):
    """Write the SimulatedPlant keyword arguments ``plant`` (dict; may hold a picklable beam) to a child
    server's stdin (``--plant-from-parent``): a length-prefixed pickle over the private pipe."""
    import pickle

    data = pickle.dumps(plant, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_LENGTH.pack(len(data)) + data)
    stream.flush()


def _receive_plant(stream):
    import pickle

    if os.isatty(stream.fileno()) or not _is_pipe(stream.fileno()):
        raise SystemExit("--plant-from-parent reads the plant from a pipe that the parent process "
                         "(Board.simulated) holds, never from a file or a terminal")
    head = stream.read(_LENGTH.size)
    if len(head) != _LENGTH.size:
        raise SystemExit("--plant-from-parent: the parent closed the pipe before sending the plant")
    data = stream.read(_LENGTH.unpack(head)[0])
    return pickle.loads(data)


def _is_pipe(fd):
    import stat
    return stat.S_ISFIFO(os.fstat(fd).st_mode)


def _watch_parent(stream, stop, parent):
    """Set ``stop`` when the parent process is gone: its end of our stdin pipe closes (at once, whatever way
    it ended, SIGKILL included) or we are re-parented (a fork of the parent kept the pipe open)."""
    sel = selectors.DefaultSelector()
    sel.register(stream, selectors.EVENT_READ)
    while not stop.is_set():
        if sel.select(timeout=0.2):
            if not os.read(stream.fileno(), 4096):
                log.warning("board: the parent process closed its pipe: vent and exit")
                break
        if os.getppid() != parent:
            log.warning("board: the parent process %d is gone: vent and exit", parent)
            break
    stop.set()


def _sd_notify(message):
    """Send ``message`` to systemd's notification socket (``Type=notify``, ``WatchdogSec=``), if any."""
    path = os.environ.get("NOTIFY_SOCKET")
    if not path:
        return False
    if path.startswith("@"):
        path = "\0" + path[1:]
    try:
        with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as s:
            s.connect(path)
            s.sendall(message.encode())
        return True
    except OSError as e:
        log.error("sd_notify(%r) failed: %s", message, e)
        return False


def _petting(server, stop, period):
    """Pet systemd's watchdog every ``period`` seconds while the board loop and the accept loop run."""
    while not stop.wait(period):
        if server.healthy(within=max(4 * period, 0.5)):
            _sd_notify("WATCHDOG=1")


def main(argv=None):
    """``python -m sorocontrol.server``: run a board. Prints ``listening HOST PORT`` once ready."""
    ap = argparse.ArgumentParser(prog="python -m sorocontrol.server", description=__doc__.split("\n")[0])
    ap.add_argument("--driver", choices=["simulated", "mock", "i2c"], default="simulated")
    ap.add_argument("--profile", help="board profile (TOML: wiring, regulator calibration and the channels' "
                                      "safety limits), --driver i2c")
    ap.add_argument("--channels", type=int, default=12, help="simulated/mock boards")
    ap.add_argument("--host", default="127.0.0.1", help="address to listen on (the Pi's lab-network address)")
    ap.add_argument("--port", type=int, default=8888)
    ap.add_argument("--secret-file")
    ap.add_argument("--secret")
    ap.add_argument("--p-min", type=float, help="safety limit of every channel, Pa (default: the profile's "
                                                "per-channel limits, else -100e3; with both, the tighter applies)")
    ap.add_argument("--p-max", type=float, help="safety limit of every channel, Pa (default: the profile's "
                                                "per-channel limits, else 100e3; with both, the tighter applies)")
    ap.add_argument("--tolerance", type=float, help="read-back margin beyond the limits before venting, Pa")
    ap.add_argument("--rate", type=float, default=1e6, help="slew-rate limit, Pa/s")
    ap.add_argument("--watchdog", type=float, default=0.5, help="s")
    ap.add_argument("--board-rate", type=float, default=400.0, help="Hz")
    ap.add_argument("--auth-timeout", type=float, default=2.0, help="time to log in, s")
    ap.add_argument("--plant", help="simulated board: MODULE:NAME, a dict of SimulatedPlant keyword arguments")
    ap.add_argument("--plant-from-parent", action="store_true",
                    help="simulated board started by Board.simulated: read the plant from the stdin pipe, then "
                         "vent and exit as soon as the parent process is gone")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s")
    # the board loop and the client thread share the GIL: hand it over within 0.2 ms (default 5 ms), so
    # that an answer never waits for a whole plant update
    sys.setswitchinterval(2e-4)
    secret = _read_secret(args)
    stop = threading.Event()
    if args.plant_from_parent:
        plant = _receive_plant(sys.stdin.buffer)
        threading.Thread(target=_watch_parent, args=(sys.stdin.buffer, stop, os.getppid()), daemon=True,
                         name="soro-board-parent").start()
    elif args.plant:
        plant = _import_plant(args.plant)
    else:
        plant = {}
    try:
        if args.driver == "i2c":
            from .drivers import I2CDriver
            if not args.profile:
                raise SystemExit("--driver i2c needs --profile FILE: the board profile with the wiring and the "
                                 "regulators' calibration (hardware/README.md)")
            driver = I2CDriver(args.profile)
        elif args.profile:
            raise SystemExit(f"--profile is the board profile of the real board (--driver i2c); the {args.driver} "
                             "board does not read it: drop --profile or use --driver i2c")
        elif args.driver == "mock":
            driver = MockDriver(args.channels)
        else:
            driver = SimulatedPlant(args.channels, **plant)
        server = BoardServer(driver, secret, host=args.host, port=args.port, p_min=args.p_min, p_max=args.p_max,
                             rate=args.rate, watchdog=args.watchdog, board_rate=args.board_rate,
                             auth_timeout=args.auth_timeout, tolerance=args.tolerance)
    except (ParameterError, ProtocolError) as e:
        raise SystemExit(f"python -m sorocontrol.server: {e}") from None

    def _terminate(signum, frame):
        stop.set()
    signal.signal(signal.SIGTERM, _terminate)
    signal.signal(signal.SIGINT, _terminate)
    server.start()
    try:
        print(f"listening {server.address[0]} {server.address[1]}", flush=True)
        _sd_notify("READY=1")
        usec = os.environ.get("WATCHDOG_USEC")
        if usec:
            threading.Thread(target=_petting, args=(server, stop, int(usec) / 4e6), daemon=True,
                             name="soro-board-sd-watchdog").start()
        while not stop.wait(0.2) and not server._stop.is_set():
            pass
    finally:
        _sd_notify("STOPPING=1")
        server.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
