"""sorocontrol: the pneumatic board protocol and client, the real-time loop, vision and shape estimation.

Runs without DOLFINx.
"""
__all__: list[str] = []
