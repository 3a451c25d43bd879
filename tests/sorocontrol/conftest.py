"""The stub I²C bus is a stand-in module for child processes and for ``sys.modules``, not a test module:
pytest must not import it (as ``smbus2``) while collecting doctests."""
collect_ignore = ["stub_i2c"]
