"""The board profile of a robot: a ``soro-board-profile`` TOML file (the format of ``hardware/README.md``, read
by :meth:`sorocontrol.drivers.BoardProfile.load`) with one channel per pneumatic network, and the seed's
pressure ranges as the board's safety limits.

The profile format keeps calibration and limits apart (calibration is not a limit): each ``[[channels]]``
table holds only the wiring and the regulator's ``signal_range``. The safety limits are written twice:
per channel in a top-level ``[safety_limits]`` table (``name = [lo, hi]`` in Pa; the data a server with
per-channel limits takes, :class:`sorocontrol.server.BoardServer` ``p_min``/``p_max`` arrays), and as the
``--p-min/--p-max`` pair of ``board.env`` that every channel can live with: the tightest common range
(intersection), never wider than any channel's own range.

``sorofem`` does not import ``sorocontrol`` (layering): this module writes text; the tests read it back with
the board's own loader.
"""
from __future__ import annotations

from ..errors import GeometryError

__all__ = ["board_profile", "board_limits", "VEAB_SIGNAL_RANGE"]

#: Calibration of the seed's regulators (Festo VEAB, -100..100 kPa gauge over the DAC's range) [Pa].
VEAB_SIGNAL_RANGE = (-100e3, 100e3)


def board_limits(design):
    """The ``--p-min``/``--p-max`` pair [Pa] that is safe for every channel of ``design``: the intersection
    of the channels' ranges (it contains 0 Pa, the vent pressure)."""
    lo = max(r[0] for r in design.channels.values())
    hi = min(r[1] for r in design.channels.values())
    if not lo <= 0.0 <= hi:
        raise GeometryError(f"{design.robot}: the channels' pressure ranges have no common range around 0 Pa")
    return float(lo), float(hi)


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
    p_min, p_max = board_limits(design)
    lines = [
        f"# Board profile of the robot {design.robot!r} (written by `soro robot export`; hardware/README.md).",
        "# Copy to /etc/soro-board/profile.toml; check the wiring against your board (channel i: valve i % 2 of",
        "# VEAB board i // 2, boards beyond the first behind an I2C multiplexer; ADS1015 0x48 + i // 4, input i % 4).",
        "# The safety limits are the seed's pressure ranges: [safety_limits] per channel (the board server's",
        "# command line takes one pair for all channels, so this table is data for a server with per-channel",
        "# limits), and for board.env the range every channel can live with (put it there):",
        f"#   SORO_BOARD_ARGS=--p-min {_pa(p_min)} --p-max {_pa(p_max)}",
        'format = "soro-board-profile"',
        "version = 1",
        f'name = "{design.robot}: {len(names)} channel(s)"',
        "i2c_bus = 1",
        "",
        "[safety_limits]                     # [Pa] per channel: the seed's pressure range (lo, hi)",
    ]
    lines += [f'"{n}" = [{_pa(lo)}, {_pa(hi)}]' for n, (lo, hi) in design.channels.items()]
    for i, name in enumerate(names):
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
        ]
    return "\n".join(lines) + "\n"
