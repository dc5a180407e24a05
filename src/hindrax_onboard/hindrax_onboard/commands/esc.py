"""``hindrax esc calibrate --measured-us X [--commanded-us 1500] [--config FILE] [--write]``.

Calibrates the PCA9685's internal oscillator (``esc.oscillator_hz``) from one oscilloscope reading, so that
"neutral" on the wire is really neutral: real parts run at 23-27 MHz (docs/devices.md §5.1), and with the
nominal 25 MHz a 24.06 MHz part puts 1559 us on the wire for 1500 us, outside the ESC deadband. Until
``esc.oscillator_calibrated`` is true the ESC node keeps every thruster channel off (no pulses) and refuses to arm.

Procedure: start the stack (``hindrax bringup``; while not calibrated the ESC node puts the reference pulse,
``thrusters.pulse_width_neutral_us``, on PCA9685 channel 15, which no ESC is on), measure its high time with a
scope, and run this command with the reading. It prints one JSON
object (assumed and calibrated oscillator, prescale, counts, the pulse width the calibrated value gives);
``--write`` sets ``esc.oscillator_hz``, ``esc.oscillator_calibrated: true`` and ``esc.oscillator_measured_on`` (this
board's id, the date, the reading) in the configuration file (comments
kept, validated, the original restored if the result is invalid). A reading that gives an oscillator outside the
part's 23-27 MHz (``esc.oscillator_hz``'s range) is refused, written or not: it is a wrong reading. Arithmetic:
:func:`hindrax_drivers.pca9685.protocol.oscillator_from_measurement`."""
from __future__ import annotations

import argparse
import json
import time

from .common import CommandError, add_config_argument, load_vehicle, update_vehicle_file

__all__ = ["add_arguments", "run"]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the command's options and arguments to ``parser``."""
    parser.add_argument("--measured-us", type=float, required=True,
                        help="high time of the pulse measured on the scope, us")
    parser.add_argument("--commanded-us", type=float, default=None,
                        help="pulse width the ESC node commanded on that channel, us "
                             "(default thrusters.pulse_width_neutral_us, the reference pulse on channel 15)")
    add_config_argument(parser)
    parser.add_argument("--write", action="store_true",
                        help="write esc.oscillator_hz and esc.oscillator_calibrated: true into --config")


def run(args: argparse.Namespace) -> int:
    """Run the command with the parsed ``args``; returns the process exit code."""
    from hindrax_common.config import ConfigError, default_config_path
    from hindrax_common.base.hardware_limits import PCA9685_OSCILLATOR_MAX_HZ, PCA9685_OSCILLATOR_MIN_HZ
    from hindrax_drivers.pca9685 import protocol as p

    path = args.config or str(default_config_path())
    cfg = load_vehicle(path)
    assumed = float(cfg.esc.oscillator_hz)
    commanded = float(args.commanded_us if args.commanded_us is not None else cfg.thrusters.pulse_width_neutral_us)
    try:
        prescale = p.esc_prescale(cfg.esc.pwm_frequency_hz, assumed)
        f_true = p.oscillator_from_measurement(args.measured_us, commanded, prescale, assumed)
        new_prescale = p.esc_prescale(cfg.esc.pwm_frequency_hz, f_true)
        counts = p.pulse_width_to_counts(commanded, new_prescale, f_true)
    except p.Pca9685Error as exc:
        raise CommandError(f"esc calibrate: {exc}") from None
    if not PCA9685_OSCILLATOR_MIN_HZ <= f_true <= PCA9685_OSCILLATOR_MAX_HZ:
        # not a part (23-27 MHz, esc.oscillator_hz's range): a wrong reading; nothing written, the flag stays false
        raise CommandError(f"esc calibrate: {args.measured_us:g} us measured for {commanded:g} us commanded gives "
                           f"esc.oscillator_hz = {f_true:.1f}: allowed {PCA9685_OSCILLATOR_MIN_HZ / 1e6:g}-"
                           f"{PCA9685_OSCILLATOR_MAX_HZ / 1e6:g} MHz (the PCA9685's range); check channel, trigger and "
                           f"units; {path} left unchanged")
    result = {
        "assumed_oscillator_hz": assumed,
        "commanded_us": commanded,
        "measured_us": float(args.measured_us),
        "prescale_used": prescale,
        "oscillator_hz": round(f_true, 1),
        "calibrated_prescale": new_prescale,
        "calibrated_pwm_frequency_hz": p.frequency_for_prescale(new_prescale, f_true),
        "calibrated_pulse_us": p.counts_to_pulse_width_us(counts, new_prescale, f_true),
        "written": False,
    }
    if args.write:
        from hindrax_common.config.sections.esc import board_id

        try:
            record = f"{board_id()} {time.strftime('%Y-%m-%d', time.gmtime())} {float(args.measured_us):g} us"
            update_vehicle_file(path, {"esc.oscillator_hz": round(f_true, 1), "esc.oscillator_calibrated": True,
                                       "esc.oscillator_measured_on": record},
                                new_keys={"esc.oscillator_measured_on": (
                                    "oscillator_calibrated", "board, date, scope reading (hindrax esc calibrate)")})
        except (ValueError, ConfigError) as exc:
            raise CommandError(f"esc calibrate: {path} left unchanged: {exc}") from None
        result["written"] = True
    print(json.dumps(result))
    return 0
