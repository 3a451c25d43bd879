"""``python -m sorocontrol.vent --profile FILE``: write the 0 kPa code of every channel straight to its DAC.

The fail-safe outside the board server. The systemd unit (``hardware/soro-board.service``) runs it as
``ExecStopPost=``, i.e. after the server has stopped for any reason: a normal stop, a crash, SIGKILL, the OOM
killer, or systemd's own watchdog killing a hung server (``WatchdogSec=``). It needs nothing but the board
profile (the calibration gives each channel's 0 kPa code, :attr:`ChannelCalibration.vent_code`) and the I²C
bus, and goes through the same :meth:`I2CDriver.vent` as the server. A write that fails is retried, and the
exit status says whether every channel was vented (systemd logs the message).

``--eeprom`` also stores the 0 kPa code in each MCP4725's EEPROM, the value the DAC outputs at power-up: run
it once at installation so that a board that powers up, or a Pi that resets, starts vented.
"""
import argparse
import logging
import sys
import time

from sorofem.errors import SoroError

__all__ = ["main"]

log = logging.getLogger(__name__)


def main(argv=None):
    """Vent every channel of the board described by ``--profile``; returns the exit status (0: vented)."""
    ap = argparse.ArgumentParser(prog="python -m sorocontrol.vent", description=__doc__.split("\n")[0])
    ap.add_argument("--profile", required=True, help="the board profile (TOML) the server uses")
    ap.add_argument("--eeprom", action="store_true", help="also store the 0 kPa codes as the DACs' power-up value")
    ap.add_argument("--attempts", type=int, default=5, help="tries per vent when the bus fails")
    args = ap.parse_args(argv)
    from .drivers import I2CDriver

    try:
        driver = I2CDriver(args.profile)
    except SoroError as e:
        print(f"python -m sorocontrol.vent: {e}", file=sys.stderr)
        return 2
    try:
        for attempt in range(1, max(args.attempts, 1) + 1):
            try:
                driver.vent()
                if args.eeprom:
                    driver.store_power_on_vent()
                break
            except OSError as e:
                print(f"python -m sorocontrol.vent: attempt {attempt}: {e}", file=sys.stderr)
                time.sleep(0.05)
        else:
            print("python -m sorocontrol.vent: NOT VENTED: the I2C bus refused the writes; cut the regulators' "
                  "supply", file=sys.stderr)
            return 1
    finally:
        driver.bus.close()
    codes = ", ".join(f"{c.dac:#x}={c.vent_code}" for c in driver.calibration)
    print(f"vented {driver.channels} channel(s) to 0 kPa (DAC codes {codes})"
          f"{'; stored as power-up values' if args.eeprom else ''}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
