r"""The board server: runs on the Raspberry Pi (or, simulated, on the host), enforces the safety rules.

One thread runs the board loop at ``board_rate`` [Hz]: the applied set-point of each channel slews toward
the requested one at most at the channel's rate limit, :math:`p_a \leftarrow p_a + \mathrm{clip}(p_r - p_a,
-r\,\Delta t, r\,\Delta t)`, and is sent to the driver, which returns the measured pressures. Another thread
accepts connections; one client at a time controls the board (a second is refused with ``ERROR BUSY``).

Safety rules (all enforced here, whatever the client does):

* set-points outside ``[p_min, p_max]`` are clamped (flag ``CLAMPED`` in the answer), non-finite ones are an
  error;
* the slew rate limit above (flag ``RATE_LIMITED`` while slewing);
* the watchdog: when the controlling client sends no valid frame within ``watchdog`` seconds, every channel
  is vented to 0 Pa (flag ``VENTED``) and the connection is dropped;
* venting on a client's disconnect, on any protocol error, on a driver exception and on shutdown
  (``stop()``, SIGTERM, SIGINT).

Run it with ``python -m sorocontrol.server`` (``--help``; on the Pi with ``--driver i2c``, see
``hardware/README.md``) or from Python with :class:`BoardServer`.
"""
import argparse
import logging
import math
import os
import signal
import socket
import sys
import threading
import time

import numpy as np

from sorofem.errors import ParameterError, ProtocolError

from . import protocol as P
from .drivers import Driver, MockDriver, SimulatedPlant

log = logging.getLogger(__name__)

__all__ = ["BoardServer", "main"]


class BoardServer:
    """A board: a driver behind the protocol, with limits, rate limits and a watchdog.

    Parameters
    ----------
    driver : sorocontrol.drivers.Driver
    secret : bytes or str
        Shared secret for the challenge-response login.
    host, port : str, int
        Where to listen (port 0 picks a free one: see :attr:`address`). Default loopback:8888.
    p_min, p_max : float or array [Pa]
        Per-channel pressure limits (default -100 kPa / 100 kPa, the VEAB range).
    rate : float or array [Pa/s]
        Per-channel slew-rate limit of the applied set-point (default 1 MPa/s: 100 kPa in 0.1 s).
    watchdog : float [s]
        Vent when the controlling client is silent this long (default 0.5 s, Sorotoki's socket timeout).
    board_rate : float [Hz]
        Board loop rate (default 400 Hz, Sorotoki's Pi loop).
    auth_timeout : float [s]
        Time a new connection has to log in.
    """

    def __init__(self, driver, secret, host="127.0.0.1", port=8888, p_min=-100e3, p_max=100e3, rate=1e6,
                 watchdog=0.5, board_rate=400.0, auth_timeout=2.0):
        if not isinstance(driver, Driver):
            raise ParameterError("driver must be a sorocontrol.drivers.Driver (I2CDriver, MockDriver or "
                                 "SimulatedPlant)")
        self.driver = driver
        n = self.channels = driver.channels
        self.secret = P._secret(secret)
        self.p_min, self.p_max, self.rate = (np.broadcast_to(np.asarray(v, float), (n,)).copy()
                                             for v in (p_min, p_max, rate))
        if not (np.all(np.isfinite(self.p_min)) and np.all(np.isfinite(self.p_max))
                and np.all(self.p_min <= 0) and np.all(self.p_max >= 0)):
            raise ParameterError("pressure limits must be finite with p_min <= 0 <= p_max [Pa] (0 Pa, the "
                                 "vent pressure, must be allowed)")
        if not np.all(self.rate > 0):
            raise ParameterError("rate limits must be positive [Pa/s]")
        for what, v in (("watchdog", watchdog), ("board_rate", board_rate), ("auth_timeout", auth_timeout)):
            if not (math.isfinite(v) and v > 0):
                raise ParameterError(f"{what} must be positive, got {v!r}")
        self.watchdog, self.board_rate, self.auth_timeout = float(watchdog), float(board_rate), float(auth_timeout)
        self.requested = np.zeros(n)
        self.applied = np.zeros(n)
        self.flags = np.zeros(n, np.int64)
        measured, sensors, faults = driver.apply(np.zeros(n), 0.0)   # a first reading: states are never empty
        self.measured, self.sensors, self.faults = (np.asarray(a, float) for a in (measured, sensors, faults))
        self.faults = self.faults.astype(bool)
        self.events = []                   # (board time, text) of vents, refusals and errors, newest last
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._client = None                # the controlling connection's socket
        self._fault = None                 # a driver failure: commands are refused until the next login
        self._last_valid = 0.0
        self._t0 = time.monotonic()
        self._sock = socket.create_server((host, int(port)), reuse_port=False)
        self._sock.settimeout(0.1)
        self.address = self._sock.getsockname()[:2]
        self._threads = []

    # ---- life cycle ---------------------------------------------------------------------------------
    def start(self):
        """Start the board loop and the accept loop in background threads; returns ``self``."""
        for target in (self._board_loop, self._accept_loop):
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
        self._vent("shutdown")
        self._drop_client()
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
        return time.monotonic() - self._t0

    # ---- board loop ---------------------------------------------------------------------------------
    def _event(self, text):
        self.events.append((round(self.now(), 6), text))
        del self.events[:-200]
        log.warning("board: %s", text)

    def _vent(self, why):
        with self._lock:
            self.requested[:] = 0.0
            self.applied[:] = 0.0
            self.flags |= P.Flag.VENTED
            self.flags &= ~(P.Flag.RATE_LIMITED | P.Flag.CLAMPED)
        try:
            self.driver.vent()
        except Exception as e:  # noqa: BLE001 - a vent must not raise; say it loudly
            log.error("driver vent failed: %s", e)
        self._event(f"vented ({why})")

    def _board_loop(self):
        dt = 1.0 / self.board_rate
        next_t = time.monotonic()
        while not self._stop.is_set():
            t = self.now()
            with self._lock:
                step = self.rate * dt
                delta = np.clip(self.requested - self.applied, -step, step)
                self.applied += delta
                slewing = np.abs(self.requested - self.applied) > 1e-9 * np.maximum(1.0, np.abs(self.requested))
                self.flags = np.where(slewing, self.flags | P.Flag.RATE_LIMITED, self.flags & ~P.Flag.RATE_LIMITED)
                applied = self.applied.copy()
                silent = self._client is not None and t - self._last_valid > self.watchdog
            if silent:
                self._event(f"watchdog: no valid command for {t - self._last_valid:.3f} s "
                            f"(timeout {self.watchdog} s)")
                self._drop_client()
                self._vent("watchdog")
                continue
            try:
                measured, sensors, faults = self.driver.apply(applied, t)
            except Exception as e:  # noqa: BLE001 - any driver failure vents the board
                self._fault = f"driver error: {type(e).__name__}: {e}"
                self._event(self._fault)
                self._vent("driver error")
                time.sleep(dt)
                continue
            with self._lock:
                self.measured = np.asarray(measured, float)
                self.sensors = np.asarray(sensors, float)
                self.faults = np.asarray(faults, bool)
                self.flags = np.where(self.faults, self.flags | P.Flag.SENSOR_FAULT,
                                      self.flags & ~P.Flag.SENSOR_FAULT)
            next_t += dt
            delay = next_t - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            else:
                next_t = time.monotonic()   # overrun: do not try to catch up with a burst

    # ---- connections --------------------------------------------------------------------------------
    def _accept_loop(self):
        while not self._stop.is_set():
            try:
                conn, peer = self._sock.accept()
            except (socket.timeout, OSError):
                continue
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            with self._lock:
                busy = self._client is not None
                if not busy:
                    self._client = conn
                    self._last_valid = self.now()
            if busy:
                self._event(f"refused {peer[0]}:{peer[1]}: another client controls the board")
                self._send_error(conn, P.ErrorCode.BUSY, "another client controls the board; one at a time")
                conn.close()
                continue
            th = threading.Thread(target=self._serve_client, args=(conn, peer), daemon=True,
                                  name="soro-board-client")
            th.start()

    def _drop_client(self):
        with self._lock:
            conn, self._client = self._client, None
        if conn is not None:
            try:
                conn.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            conn.close()

    @staticmethod
    def _send_error(conn, code, message):
        try:
            conn.sendall(P.encode(P.MessageType.ERROR, P.pack_error(code, message)))
        except OSError:
            pass

    def _hello(self, nonce):
        return P.Hello(P.PROTOCOL_VERSION, self.channels, self.watchdog, self.board_rate, self.p_min, self.p_max,
                       self.rate, nonce)

    def _state(self, sequence):
        with self._lock:
            s = P.State(self.now(), sequence, self.requested.copy(), self.applied.copy(), self.measured.copy(),
                        self.flags.copy(), self.sensors.copy())
        return P.encode(P.MessageType.STATE, P.pack_state(s))

    def _login(self, conn):
        nonce = P.new_nonce()
        conn.sendall(P.encode(P.MessageType.HELLO, P.pack_hello(self._hello(nonce))))
        conn.settimeout(self.auth_timeout)
        mtype, payload = P.read_frame(conn)
        if mtype != P.MessageType.AUTH:
            raise ProtocolError(f"expected AUTH, got {mtype.name}")
        client_nonce, proof = P.unpack_auth(payload)
        if not P.hmac.compare_digest(proof, P.client_proof(self.secret, nonce, client_nonce)):
            raise PermissionError("bad secret")
        conn.sendall(P.encode(P.MessageType.READY, P.server_proof(self.secret, nonce, client_nonce)))

    def _handle(self, mtype, payload, who):
        """Carry out one command frame; returns the STATE frame that answers it."""
        if self._fault:
            raise ProtocolError(f"board fault, vented: {self._fault}; reconnect to clear it once fixed")
        if mtype == P.MessageType.SET:
            seq, values = P.unpack_pressures(payload, self.channels)
            if not np.all(np.isfinite(values)):
                raise ProtocolError(f"non-finite set-point on channel(s) "
                                    f"{np.flatnonzero(~np.isfinite(values)).tolist()}")
            clamped = np.clip(values, self.p_min, self.p_max)
            with self._lock:
                self.requested = clamped
                self.flags &= ~(P.Flag.VENTED | P.Flag.CLAMPED)
                self.flags |= np.where(clamped != values, int(P.Flag.CLAMPED), 0)
        elif mtype == P.MessageType.VENT:
            seq = P.unpack_sequence(payload)
            self._vent(f"requested by {who}")
        elif mtype in (P.MessageType.READ, P.MessageType.HEARTBEAT):
            seq = P.unpack_sequence(payload)
        else:
            raise ProtocolError(f"unexpected {mtype.name} from a client")
        self._last_valid = self.now()
        return self._state(seq)

    def _serve_client(self, conn, peer):
        who = f"{peer[0]}:{peer[1]}"
        try:
            self._login(conn)
            self._fault = None
            self._last_valid = self.now()
            log.info("client %s logged in", who)
            conn.settimeout(0.05)
            reader = P.FrameReader()
            while not self._stop.is_set() and self._client is conn:
                try:
                    data = conn.recv(65536)
                except socket.timeout:
                    continue
                if not data:
                    raise ConnectionError("closed by the client")
                for mtype, payload in reader.feed(data):
                    if mtype == P.MessageType.BYE:
                        self._event(f"client {who} said bye")
                        return
                    conn.sendall(self._handle(mtype, payload, who))
        except PermissionError:
            self._event(f"refused {who}: authentication failed")
            self._send_error(conn, P.ErrorCode.AUTH, "authentication failed: wrong shared secret")
        except ProtocolError as e:
            self._event(f"protocol error from {who}: {e}")
            text = str(e)
            code = (P.ErrorCode.VERSION if "protocol version" in text else P.ErrorCode.SIZE if "MAX_PAYLOAD" in text
                    else P.ErrorCode.UNEXPECTED if text.startswith(("unexpected", "expected AUTH"))
                    else P.ErrorCode.MALFORMED)
            self._send_error(conn, code, text)
        except (ConnectionError, socket.timeout, OSError) as e:
            if self._client is conn:
                self._event(f"client {who} lost: {e}")
        except Exception as e:  # noqa: BLE001 - the server must survive anything a client sends
            self._event(f"internal error serving {who}: {type(e).__name__}: {e}")
            self._send_error(conn, P.ErrorCode.INTERNAL, f"{type(e).__name__}: {e}")
        finally:
            mine = self._client is conn
            if mine:
                self._drop_client()
                self._vent(f"client {who} disconnected")
            else:
                conn.close()


def _read_secret(args):
    if args.secret_file:
        with open(args.secret_file, "rb") as f:
            return f.read().strip()
    if args.secret:
        return args.secret
    if os.environ.get("SORO_BOARD_SECRET"):
        return os.environ["SORO_BOARD_SECRET"]
    raise SystemExit("give the shared secret with --secret-file PATH (on the Pi: /etc/soro-board/secret, "
                     "mode 600), the environment variable SORO_BOARD_SECRET, or --secret TEXT (tests only)")


def main(argv=None):
    """``python -m sorocontrol.server``: run a board. Prints ``listening HOST PORT`` once ready."""
    ap = argparse.ArgumentParser(prog="python -m sorocontrol.server", description=__doc__.split("\n")[0])
    ap.add_argument("--driver", choices=["simulated", "mock", "i2c"], default="simulated")
    ap.add_argument("--channels", type=int, default=12)
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=8888)
    ap.add_argument("--secret-file")
    ap.add_argument("--secret")
    ap.add_argument("--p-min", type=float, default=-100e3, help="Pa")
    ap.add_argument("--p-max", type=float, default=100e3, help="Pa")
    ap.add_argument("--rate", type=float, default=1e6, help="slew-rate limit, Pa/s")
    ap.add_argument("--watchdog", type=float, default=0.5, help="s")
    ap.add_argument("--board-rate", type=float, default=400.0, help="Hz")
    ap.add_argument("--plant", help="pickled dict of SimulatedPlant keyword arguments (Board.simulated)")
    ap.add_argument("--i2c-bus", type=int, default=1)
    ap.add_argument("--dacs", default="0x60,0x61", help="MCP4725 addresses, one per channel")
    ap.add_argument("--adcs", default="0x48:0,0x48:1", help="ADS1015 address:input, one per channel")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(message)s")
    # the board loop and the client thread share the GIL: hand it over within 0.2 ms (default 5 ms), so
    # that an answer never waits for a whole plant update
    sys.setswitchinterval(2e-4)
    secret = _read_secret(args)
    if args.driver == "i2c":
        from .drivers import I2CDriver
        dacs = [int(a, 0) for a in args.dacs.split(",")]
        adcs = [(int(a.split(":")[0], 0), int(a.split(":")[1])) for a in args.adcs.split(",")]
        driver = I2CDriver(dacs, adcs, p_range=(args.p_min, args.p_max), bus=args.i2c_bus)
    elif args.driver == "mock":
        driver = MockDriver(args.channels)
    else:
        plant = {}
        if args.plant:
            import pickle
            with open(args.plant, "rb") as f:
                plant = pickle.load(f)
        driver = SimulatedPlant(args.channels, **plant)
    server = BoardServer(driver, secret, host=args.host, port=args.port, p_min=args.p_min, p_max=args.p_max,
                         rate=args.rate, watchdog=args.watchdog, board_rate=args.board_rate)

    def _terminate(signum, frame):
        server._stop.set()
    signal.signal(signal.SIGTERM, _terminate)
    signal.signal(signal.SIGINT, _terminate)
    print(f"listening {server.address[0]} {server.address[1]}", flush=True)
    server.serve_forever()
    return 0


if __name__ == "__main__":
    sys.exit(main())
