"""sorocontrol: the pneumatic board protocol and client, the real-time loop, vision and shape estimation.

Runs without DOLFINx. Submodules: :mod:`~sorocontrol.protocol` (the wire format, spec in
``docs/board-protocol.md``), :mod:`~sorocontrol.server` (the board server that runs on the Raspberry Pi),
:mod:`~sorocontrol.drivers` (I2C hardware, mock, simulated plant), :mod:`~sorocontrol.board` (the host
client :class:`Board` and its real-time loop), :mod:`~sorocontrol.camera` (camera models and sources: OpenCV,
RealSense, a synthetic camera that renders markers on a beam), :mod:`~sorocontrol.vision` (colour-marker
detection, ArUco calibration of the world frame, pixels to 3D) and :mod:`~sorocontrol.estimation` (shape
estimation: markers to beam coordinates by IK with the quasi-static prior); ``python -m sorocontrol.vent``
(:mod:`~sorocontrol.vent`) vents a real board's DACs from outside the server. They load on first attribute
access.
"""
from sorofem._lazy import lazy_attributes

_SUBMODULES = ("protocol", "server", "drivers", "board", "camera", "vision", "estimation", "vent")
_CLASSES = {"Board": "board", "LoopStats": "board", "BoardServer": "server", "MockDriver": "drivers",
            "SimulatedPlant": "drivers", "I2CDriver": "drivers", "BoardProfile": "drivers",
            "ChannelCalibration": "drivers",
            "CameraModel": "camera", "SyntheticCamera": "camera", "OpenCVCamera": "camera",
            "RealSenseCamera": "camera", "ArucoTarget": "camera", "Frame": "camera",
            "MarkerDetector": "vision", "HsvRange": "vision", "calibrate_world": "vision",
            "calibrate_intrinsics": "vision",
            "ShapeEstimator": "estimation", "Estimate": "estimation", "EstimatorThread": "estimation",
            "run_sensing": "estimation"}

__all__: list[str] = [*_SUBMODULES, *_CLASSES]


__getattr__ = lazy_attributes(__name__, _SUBMODULES, _CLASSES)
