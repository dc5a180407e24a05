"""``outputs_off``: silence the PCA9685 from outside the stack, after its unit stopped or was killed (issue 71.6).

The systemd units run it as ``ExecStopPost=`` (docker/hindrax*.service): the PCA9685 keeps its last pulses on its
own, and a Raspberry Pi kernel without ``strict_gpiod`` keeps a freed /OE low (docs/threat_model.md §6). It drives
/OE (``esc.output_enable_gpio``) high and releases it, then writes the chip's ALL_LED_OFF_H full-OFF bit and MODE1
SLEEP (:func:`silence_chip`), each step tried even when the other fails, one line each on stdout; exit status 0
when both worked (or /OE is not wired), else 1. No ROS: it must run when the ROS installation is what broke. The
vehicle file: ``HINDRAX_CONFIG``, else the installed one (:func:`hindrax_common.config.default_config_path`)."""
from __future__ import annotations

import sys
from typing import Any, Sequence

from hindrax_common.config import ConfigError, default_config_path, load_config, output_enable_gpio
from hindrax_drivers.pca9685 import protocol as p
from hindrax_common.transport.gpio import GpiodLine
from hindrax_common.transport.i2c import I2CDevice, I2CError, open_smbus
from hindrax_common.transport.shared_emulation import open_shared_bus, open_shared_line

__all__ = ["open_output_enable", "silence_chip", "main"]


def open_output_enable(chip: str, line: int) -> Any:
    """The /OE line, requested HIGH (outputs off): the emulation server's line when
    ``HINDRAX_EMULATION_SOCKET`` is set (tests, benchmarks), else libgpiod. Raises OSError/ImportError."""
    shared = open_shared_line("oe", True)
    if shared is not None:
        return shared
    return GpiodLine(chip, line, initial_high=True)


def silence_chip(dev: Any) -> None:
    """Every output full OFF, then SLEEP (datasheet §7.3.4, §7.3.1) on ``dev`` (an I2CDevice of the PCA9685).
    Raises OSError/I2CError."""
    dev.write_byte_data(p.ALL_LED_OFF_H, p.FULL_BIT)
    dev.write_byte_data(p.MODE1, p.MODE1_SLEEP | p.MODE1_AI | p.MODE1_ALLCALL)


def main(args: Sequence[str] | None = None) -> int:
    """Process entry point (module docstring). No arguments."""
    del args
    try:
        cfg = load_config(default_config_path())
    except (OSError, ConfigError) as exc:
        print(f"outputs_off: vehicle file: {exc}", flush=True)
        return 1
    ok = True
    gpio = output_enable_gpio(cfg)
    if gpio is None:
        print("outputs_off: /OE not wired (esc.output_enable_gpio): registers only", flush=True)
    else:
        try:
            line = open_output_enable(*gpio)
            line.set_high(True)
            line.release()
            print(f"outputs_off: /OE {gpio[0]}:{gpio[1]} driven high (outputs off) and released", flush=True)
        except (OSError, ImportError) as exc:
            ok = False
            print(f"outputs_off: /OE {gpio[0]}:{gpio[1]}: {exc}", flush=True)
    bus_number, address = int(cfg.esc.i2c_bus), int(cfg.esc.i2c_address)
    try:
        silence_chip(I2CDevice(open_shared_bus() or open_smbus(bus_number), address, "pca9685-off", retries=2))
        print(f"outputs_off: PCA9685 i2c-{bus_number}@0x{address:02x}: all outputs full off, asleep", flush=True)
    except (OSError, I2CError, ImportError) as exc:
        ok = False
        print(f"outputs_off: PCA9685 i2c-{bus_number}@0x{address:02x}: {exc}", flush=True)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
