"""sorocontrol: the pneumatic board protocol and client, the real-time loop, vision and shape estimation.

Runs without DOLFINx. Submodules: :mod:`~sorocontrol.protocol` (the wire format, spec in
``docs/board-protocol.md``), :mod:`~sorocontrol.server` (the board server that runs on the Raspberry Pi),
:mod:`~sorocontrol.drivers` (I2C hardware, mock, simulated plant), :mod:`~sorocontrol.board` (the host
client :class:`Board` and its real-time loop), :mod:`~sorocontrol.camera` (camera models and sources: OpenCV,
RealSense, a synthetic camera that renders markers on a beam), :mod:`~sorocontrol.vision` (colour-marker
detection, ArUco calibration of the world frame, pixels to 3D) and :mod:`~sorocontrol.estimation` (shape
estimation: markers to beam coordinates by IK with the quasi-static prior). They load on first attribute
access.
"""
import importlib

_SUBMODULES = ("protocol", "server", "drivers", "board", "camera", "vision", "estimation")
_CLASSES = {"Board": "board", "LoopStats": "board", "BoardServer": "server", "MockDriver": "drivers",
            "SimulatedPlant": "drivers", "I2CDriver": "drivers",
            "CameraModel": "camera", "SyntheticCamera": "camera", "OpenCVCamera": "camera",
            "RealSenseCamera": "camera", "ArucoTarget": "camera", "Frame": "camera",
            "MarkerDetector": "vision", "HsvRange": "vision", "calibrate_world": "vision",
            "ShapeEstimator": "estimation", "Estimate": "estimation", "run_sensing": "estimation"}

__all__: list[str] = [*_SUBMODULES, *_CLASSES]


def __getattr__(name):
    """Import the submodule ``name`` (or the module of the class ``name``) on first access (PEP 562)."""
    if name in _SUBMODULES:
        return importlib.import_module(f"{__name__}.{name}")
    if name in _CLASSES:
        return getattr(importlib.import_module(f"{__name__}.{_CLASSES[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
