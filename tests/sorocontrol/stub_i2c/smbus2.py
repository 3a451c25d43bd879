"""A stand-in for ``smbus2`` that records every MCP4725 DAC code and answers ADS1015 reads from a model of
the regulators (tests only).

In a test process it is put in ``sys.modules["smbus2"]``; in a child process (the board server, the vent
command) its folder is put on ``PYTHONPATH``. Configuration, from the environment or set directly:

* ``STUB_SMBUS_LOG`` (path): every DAC write is appended as a line ``address code`` (``e`` for an EEPROM
  write), so a parent can read what a killed child wrote.
* ``STUB_SMBUS_REGULATORS`` (JSON): ``{"<dac address>": [adc address, input, p_lo, p_hi, gain, offset,
  divider]}``: the *true* regulator behind each DAC (gauge pressure p_lo [Pa] at code 0, p_hi at 4095) and
  its sensor (V = p/gain + offset, divided by ``divider`` before the ADC). The pressure follows the code at
  once.

``WRITES`` holds ``(address, code)`` of this process, ``CODES`` the current code of each DAC.
"""
import json
import os

WRITES = []
CODES = {}
REGULATORS = {int(k, 0): v for k, v in json.loads(os.environ.get("STUB_SMBUS_REGULATORS", "{}")).items()}
_config = {}     # ADS1015 address -> selected input


def reset(regulators=None):
    WRITES.clear()
    CODES.clear()
    _config.clear()
    REGULATORS.clear()
    REGULATORS.update(regulators or {})


def _log(address, code, eeprom=False):
    WRITES.append((address, code))
    CODES[address] = code
    path = os.environ.get("STUB_SMBUS_LOG")
    if path:
        with open(path, "a") as f:
            f.write(f"{address} {code}{' e' if eeprom else ''}\n")
            f.flush()


class SMBus:
    def __init__(self, bus=None):
        self.bus = bus
        self.closed = False

    def write_byte_data(self, address, register, value):
        """MCP4725 fast write: (power-down bits, code high nibble), code low byte."""
        if register & 0x30:
            raise OSError("stub: power-down bits set in a fast write")
        _log(address, ((register & 0x0F) << 8) | (value & 0xFF))

    def write_i2c_block_data(self, address, register, data):
        if register == 0x60:                       # MCP4725 write DAC register and EEPROM
            _log(address, (data[0] << 4) | (data[1] >> 4), eeprom=True)
        elif register == 0x01:                     # ADS1015 config: remember the selected input
            _config[address] = ((data[0] >> 4) & 0x7) - 4
        else:
            raise OSError(f"stub: unexpected block write to {address:#x} register {register:#x}")

    def read_i2c_block_data(self, address, register, length):
        if register == 0x01:
            return [0x80, 0x00]                    # conversion done
        inp = _config.get(address, 0)
        for dac, (adc, channel, lo, hi, gain, offset, divider) in REGULATORS.items():
            if adc == address and channel == inp:
                p = lo + (hi - lo) * CODES.get(dac, 0) / 4095
                volts = (p / gain + offset) / divider
                raw = max(min(int(round(volts / (6.144 / 2048))), 2047), -2048) & 0xFFF
                return [(raw << 4) >> 8, (raw << 4) & 0xFF]
        raise OSError(f"stub: no device at {address:#x} input {inp}")

    def close(self):
        self.closed = True
