"""``hindrax config check FILE``: validate a vehicle configuration before a pool test.

Prints each error as one line (key, value, allowed range) on stdout and exits 1, or prints a short
summary of the vehicle and exits 0. Validation rules: :mod:`hindrax_common.config`."""
from __future__ import annotations

import argparse


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Add the command's options and arguments to ``parser``."""
    parser.add_argument("file", nargs="?", default=None,
                        help="vehicle configuration YAML (ros-args params-file layout); default: the "
                             "installed share/hindrax_common/config/hindrax.yaml, or the repository's "
                             "ros_ws/config/hindrax.yaml in a checkout")


def run(args: argparse.Namespace) -> int:
    """Run the command with the parsed ``args``; returns the process exit code."""
    from hindrax_common.config import ConfigError, default_config_path, load_config, output_enable_gpio
    from hindrax_common.config.sections.esc import board_id, oscillator_problem
    from hindrax_drivers.pca9685.protocol import REFERENCE_CHANNEL

    if args.file is None:
        try:
            args.file = str(default_config_path())
        except FileNotFoundError as exc:
            print(exc)
            return 1
    try:
        cfg = load_config(args.file)
    except ConfigError as exc:
        for line in exc.lines():
            print(f"{args.file}: {line}")
        return 1
    print(f"{args.file}: OK")
    print(cfg.summary())
    if not cfg.esc.oscillator_calibrated:
        print(f"warning: esc.oscillator_calibrated is false: esc.oscillator_hz {cfg.esc.oscillator_hz:g} Hz is not "
              f"measured (parts run at 23-27 MHz), so no width is known to be neutral: the ESC node keeps the "
              f"thruster outputs off (no pulses) and refuses to arm. Start the stack (hindrax bringup), measure the "
              f"reference pulse on PCA9685 channel {REFERENCE_CHANNEL} with a scope, then run `hindrax esc calibrate "
              f"--measured-us X --config {args.file} --write` (sets esc.oscillator_hz and the flag).")
    if problem := oscillator_problem(cfg, board_id()):
        print(f"warning: {problem}")
    if output_enable_gpio(cfg) is None:
        print("warning: esc.output_enable_gpio is not wired: the vehicle has no hardware cut-off. The output guard "
              "silences the PCA9685 over the I2C bus (all-off + sleep), which an I2C outage defeats "
              "(docs/architecture.md §8).")
    if output_enable_gpio(cfg, "esc.output_enable_feed_gpio") is None:
        print("warning: esc.output_enable_feed_gpio is not wired: no hardware watchdog on /OE. A frozen launch or Pi "
              "keeps the last widths on the wire until systemd's WatchdogSec restarts the unit (docs/watchdog.md).")
    return 0
