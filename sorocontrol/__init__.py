"""sorocontrol: the pneumatic board protocol and client, the real-time loop, vision and shape estimation.

Runs without DOLFINx. Submodules: :mod:`~sorocontrol.protocol` (the wire format, spec in
``docs/board-protocol.md``), :mod:`~sorocontrol.server` (the board server that runs on the Raspberry Pi),
:mod:`~sorocontrol.drivers` (I2C hardware, mock, simulated plant), :mod:`~sorocontrol.board` (the host
client :class:`Board` and its real-time loop). They load on first attribute access.
"""
import importlib

_SUBMODULES = ("protocol", "server", "drivers", "board")
_CLASSES = {"Board": "board", "LoopStats": "board", "BoardServer": "server", "MockDriver": "drivers",
            "SimulatedPlant": "drivers", "I2CDriver": "drivers"}

__all__: list[str] = [*_SUBMODULES, *_CLASSES]


def __getattr__(name):
    """Import the submodule ``name`` (or the module of the class ``name``) on first access (PEP 562)."""
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    if name in _CLASSES:
        return getattr(importlib.import_module(f"{__name__}.{_CLASSES[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
