"""fabwire: native wire protocols of maker machines, from the host side and the device side."""

__version__ = "0.1.0"
