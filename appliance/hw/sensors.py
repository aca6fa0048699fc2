"""An optional liquid-level sensor on I2C, used to cross-check the
displacement model (the ink drops as the part emerges).

The supported part is a VL6180X time-of-flight ranger looking down at the
ink from a fixed height: level = mount height - range. Readings are in whole
millimetres, so it checks the model (a few tenths of a mm over a scan), it
never replaces the stage's position.
"""

from __future__ import annotations

import time

from ..errors import DeviceError

_SYSRANGE_START = 0x018
_RESULT_INTERRUPT_STATUS = 0x04F
_RESULT_RANGE_VAL = 0x062
_SYSTEM_INTERRUPT_CLEAR = 0x015
_IDENTIFICATION_MODEL_ID = 0x000


class Vl6180xLevel:
    def __init__(self, mount_height_mm: float, bus: int = 1, address: int = 0x29):
        from smbus2 import SMBus, i2c_msg

        self._msg = i2c_msg
        self.where = f"level sensor i2c-{bus} 0x{address:02x}"
        self.address, self.mount = address, float(mount_height_mm)
        try:
            self._bus = SMBus(bus)
            model = self._read(_IDENTIFICATION_MODEL_ID)
        except OSError as e:
            raise DeviceError(self.where, f"no VL6180X answers: {e}") from None
        if model != 0xB4:
            raise DeviceError(self.where, f"model id 0x{model:02x} is not a VL6180X (0xb4)")

    def _read(self, reg):
        w = self._msg.write(self.address, [reg >> 8, reg & 0xFF])
        r = self._msg.read(self.address, 1)
        self._bus.i2c_rdwr(w, r)
        return list(r)[0]

    def _write(self, reg, value):
        self._bus.i2c_rdwr(self._msg.write(self.address, [reg >> 8, reg & 0xFF, value]))

    def read_mm(self, timeout: float = 0.5) -> float:
        try:
            self._write(_SYSRANGE_START, 0x01)
            end = time.monotonic() + timeout
            while (self._read(_RESULT_INTERRUPT_STATUS) & 0x07) != 0x04:
                if time.monotonic() > end:
                    raise DeviceError(self.where, "no range reading in time")
                time.sleep(0.005)
            rng = self._read(_RESULT_RANGE_VAL)
            self._write(_SYSTEM_INTERRUPT_CLEAR, 0x07)
        except OSError as e:
            raise DeviceError(self.where, f"read failed: {e}") from None
        return self.mount - rng

    def close(self):
        self._bus.close()
