"""InkSlice: slice a part with a rising liquid level, rebuild its surface, mill it."""

__version__ = "0.1.0"
