"""The board profile of a robot: a ``soro-board-profile`` TOML file (the format of ``hardware/README.md``, read
by :meth:`sorocontrol.drivers.BoardProfile.load`) with one channel per pneumatic network, and the seed's
pressure ranges as the board's safety limits.

Calibration is not a limit: each ``[[channels]]`` table holds the wiring, the regulator's ``signal_range``
(the calibration) and, apart from it, the channel's safety limits ``p_min``/``p_max`` [Pa], the seed's range
of that network. The board server enforces them per channel (a set-point beyond a channel's limit is clamped
to it); a ``--p-min/--p-max`` pair in ``board.env`` can only narrow them.

This module writes the text (the export needs no board package); the tests read it back with the board's own
loader.
"""
from __future__ import annotations

from sorofem.errors import GeometryError

__all__ = ["board_profile", "VEAB_SIGNAL_RANGE"]

#: Calibration of the seed's regulators (Festo VEAB, -100..100 kPa gauge over the DAC's range) [Pa].
VEAB_SIGNAL_RANGE = (-100e3, 100e3)


def _pa(v):
    return f"{v:.6g}"


def board_profile(design, signal_range=VEAB_SIGNAL_RANGE):
    """The TOML text of ``design``'s board profile.

    Channel ``i`` (in the order of ``design.channels``) is wired as on the seed's board: valve ``i % 2`` of
    VEAB board ``i // 2`` (DAC 0x60/0x61; boards beyond the first sit behind an I2C multiplexer), read back on
    ADS1015 ``0x48 + i // 4``, input ``i % 4``.

    Parameters
    ----------
    design : Design
    signal_range : (float, float)
        Gauge pressure [Pa] at DAC code 0 and at full scale; it must contain every channel's range.

    Returns
    -------
    str
    """
    lo_s, hi_s = (float(v) for v in signal_range)
    names = list(design.channels)
    if len(names) > 16:
        raise GeometryError(f"{design.robot} has {len(names)} channels; the board reads back at most 16")
    for name, (lo, hi) in design.channels.items():
        if not lo_s <= lo <= 0.0 <= hi <= hi_s:
            raise GeometryError(f"{design.robot}: channel {name!r} range [{lo:g}, {hi:g}] Pa is not inside the "
                                f"regulators' signal range [{lo_s:g}, {hi_s:g}] Pa: use regulators that cover it")
    lines = [
        f"# Board profile of the robot {design.robot!r} (written by `soro robot export`; hardware/README.md).",
        "# Copy to /etc/soro-board/profile.toml; check the wiring against your board (channel i: valve i % 2 of",
        "# VEAB board i // 2, boards beyond the first behind an I2C multiplexer; ADS1015 0x48 + i // 4, input i % 4).",
        "# p_min/p_max: each channel's safety limits, the seed's pressure range of its network; the board server",
        "# clamps every set-point to them. Drop --p-min/--p-max from board.env's SORO_BOARD_ARGS (a pair there",
        "# only narrows these limits, on every channel).",
        'format = "soro-board-profile"',
        "version = 1",
        f'name = "{design.robot}: {len(names)} channel(s)"',
        "i2c_bus = 1",
    ]
    for i, name in enumerate(names):
        lo, hi = design.channels[name]
        lines += [
            "",
            "[[channels]]",
            f'name = "{name}"',
            f"dac = 0x{0x60 + i % 2:02x}                          # MCP4725 of valve {i % 2 + 1} on VEAB board {i // 2 + 1}",
            f"adc = [0x{0x48 + i // 4:02x}, {i % 4}]",
            f"signal_range = [{_pa(lo_s)}, {_pa(hi_s)}]      # gauge pressure [Pa] at DAC code 0 and 4095",
            "sensor_gain = 20e3",
            "sensor_offset = 5.0",
            "divider = 3.0",
            f"p_min = {_pa(lo)}                      # safety limits [Pa]: the seed's range of this network",
            f"p_max = {_pa(hi)}",
        ]
    return "\n".join(lines) + "\n"
