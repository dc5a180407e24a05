"""Fixtures the simulator's tests share: the DVL-75 emulator's reports through the virtual hardware's pty
(test_sim_hardware.py, test_sloped_floor.py)."""
import pytest
import serial

from hindrax_common.testing import wait_until
from hindrax_drivers.dvl75 import protocol as dvl


@pytest.fixture
def dvl_reports():
    """``dvl_reports(sim, vh, until, what, send=b"")``: the DVL-75 emulator's records (the driver's framer and parser)
    read from the pty of the virtual hardware ``vh`` while the simulator ``sim`` advances 20 ms per read, until
    ``until(records)`` (``what`` names it; 20 s of wall time at most); ``send`` is written to the device first."""
    def read(sim, vh, until, what, send=b""):
        port = serial.serial_for_url(vh.ports["dvl75"], baudrate=115200, timeout=0.05)
        framer, records = dvl.DvlLineFramer(), []

        def poll():
            sim.advance(0.02)
            for line in framer.feed(port.read(4096)):
                try:
                    records.append(dvl.parse_line(line))
                except dvl.DvlParseError:
                    pass
        try:
            port.write(send)
            wait_until(lambda: until(records), 20, poll, what)
        finally:
            port.close()
        return records
    return read
