"""``esc.*``: the PCA9685 ESC output, its safety timeouts, the /OE line and the hardware watchdog's feed
(docs/devices.md §5.1-5.2, docs/watchdog.md)."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

from ...base.hardware_limits import PCA9685_OSCILLATOR_MAX_HZ, PCA9685_OSCILLATOR_MIN_HZ, Pca9685Error, esc_prescale
from ..spec import ConfigIssue, flag, integer, real, section, text

SCHEMA, OPTIONAL = section("esc", {
    "i2c_bus": integer("Linux I2C bus number (/dev/i2c-N)", 0, 31),
    "i2c_address": integer("PCA9685 7-bit address", 0x40, 0x7F),
    "pwm_frequency_hz": real("PWM frequency, Hz (Basic ESC max 400 Hz)", 24.0, 400.0),
    "oscillator_hz": real("calibrated PCA9685 internal oscillator frequency, Hz (25 MHz nominal, NXP PCA9685 "
                          "data sheet §7.3.5; parts measure 23-27 MHz, docs/devices.md §5.1)",
                          PCA9685_OSCILLATOR_MIN_HZ, PCA9685_OSCILLATOR_MAX_HZ),
    "arming_time_s": real("time at neutral before arming is accepted, s (docs/devices.md §5.2: BR holds 7 s)",
                          0.0, 60.0),
    "watchdog_timeout_s": real("no command for this long -> all neutral, s", 0.02, 10.0),
    "output_rate_hz": real("rate the outputs are refreshed and the watchdog checked, Hz", 1.0, 400.0),
    "slew_rate_us_per_s": real("max pulse-width change rate, us/s (0 = off)", 0.0, 1e6),
    "output_latency_s": real("delay from the ESC node's stamp of a written width (thrusters/pulse_width) to the "
                             "thrust starting to change, s: the identification's force timing", 0.0, 0.5),
    "oscillator_calibrated": flag("esc.oscillator_hz was measured on this board (`hindrax esc calibrate`); "
                                  "arming is refused while false"),
    "oscillator_measured_on": text("the record `hindrax esc calibrate --write` leaves: '<board id> <UTC date> "
                                   "<measured width> us' (board id: the Pi's serial number, or its machine id); "
                                   "absent, or another board's: `hindrax config check` and `hindrax health` warn "
                                   "(docs/devices.md §5.1)"),
    "readback_interval_s": real("MODE1, PRE_SCALE and the channel registers are read back this often; a "
                                "mismatch (chip reset) re-initialises the chip and disarms, s", 0.05, 10.0),
    "bus_call_timeout_s": real("a PCA9685 bus call (write or read-back) not returned after this long makes the "
                               "output state unknown: ESC heartbeat ERROR, the guard asserts /OE (a block write "
                               "takes 0.9 ms at 400 kHz; must be below esc.guard_heartbeat_timeout_s), s",
                               0.01, 1.0),
    "heartbeat_timeout_s": real("the ESC refuses to arm, and disarms, when supervisor/heartbeat or guard/heartbeat "
                                "is older than this (steady clock; docs/architecture.md §8), s", 0.05, 1.0),
    "guard_heartbeat_timeout_s": real("the output guard asserts /OE (or silences the chip over I2C) when "
                                      "esc/heartbeat or supervisor/heartbeat is older than this (steady clock; "
                                      "docs/architecture.md §8), s", 0.05, 1.0),
    "output_enable_gpio.chip": text("gpiochip of the PCA9685 /OE line, e.g. /dev/gpiochip0 (absent or null: /OE "
                                    "not wired, the guard writes the chip's all-off and sleep registers instead)"),
    "output_enable_gpio.line": integer("line offset of the PCA9685 /OE on esc.output_enable_gpio.chip (BCM GPIO number "
                                       "on a Pi 4)", 0, 1023),
    "output_enable_feed_gpio.chip": text("gpiochip of the hardware watchdog's feed line (docs/watchdog.md: a "
                                         "retriggerable monostable that holds /OE high unless it sees rising "
                                         "edges); absent or null: no hardware watchdog"),
    "output_enable_feed_gpio.line": integer("line offset of the watchdog feed on esc.output_enable_feed_gpio.chip (BCM "
                                            "GPIO number on a Pi 4)", 0, 1023),
    "output_enable_feed_rate_hz": real("rising edges per second the output guard puts on the watchdog feed while "
                                       "the ESC heartbeat is fresh and nothing is tripped, Hz", 2.0, 50.0),
    "output_enable_feed_timeout_s": real("the hardware watchdog's timeout: its monostable's pulse width "
                                         "t_W = R_EXT * C_EXT (docs/watchdog.md); the outputs stop this long after "
                                         "the last rising edge, s", 0.05, 2.0),
}, optional=("output_enable_gpio.", "output_enable_feed", "oscillator_measured_on"))


#: keys whose YAML value may be null, meaning "absent" (their sub-keys are optional)
NULLABLE: tuple[str, ...] = ("esc.output_enable_gpio", "esc.output_enable_feed_gpio")

# The safety timeouts a node parameter outside the vehicle file widens (read-only, validated like the keys above:
# config.node_parameters.declare_node_parameter); each defaults to the key it names, and only the graph in one process
# sets them (hindrax bringup: the three safety nodes share one executor thread, its simulator holds time on purpose).
#: the ESC's ``heartbeat_timeout_s``
ESC_HEARTBEAT_TIMEOUT = real("the ESC refuses to arm, and disarms, when supervisor/heartbeat or guard/heartbeat is "
                             "older than this (steady clock), s; default esc.heartbeat_timeout_s", 0.05, 10.0)
#: the ESC's ``steady_watchdog_timeout_s``: it covers a ROS clock that stops (use_sim_time with a dead /clock), where
#: the ROS-time watchdog stands still
STEADY_WATCHDOG_TIMEOUT = real("no command for this long of steady-clock time (the executor running) -> all "
                               "neutral, s; default esc.watchdog_timeout_s", 0.02, 60.0)
#: the output guard's ``heartbeat_timeout_s``
GUARD_HEARTBEAT_TIMEOUT = real("the ESC's and the supervisor's heartbeats count as silent when older than this "
                               "(steady clock), s; default esc.guard_heartbeat_timeout_s", 0.05, 10.0)


def output_enable_gpio(cfg: Any, key: str = "esc.output_enable_gpio") -> tuple[str, int] | None:
    """``(chip, line)`` of the PCA9685 /OE line from ``esc.output_enable_gpio`` (or of another GPIO key, e.g.
    ``esc.output_enable_feed_gpio``), or None when it is not wired. ``cfg``: a VehicleConfig or a flat mapping."""
    flat = cfg.flat if hasattr(cfg, "flat") else cfg
    chip = flat.get(f"{key}.chip")
    if not chip:
        return None
    return str(chip), int(flat[f"{key}.line"])


def board_id() -> str:
    """This machine's board: the Raspberry Pi's serial number (device tree), else ``/etc/machine-id``, else
    ``unknown``."""
    for path in ("/sys/firmware/devicetree/base/serial-number", "/etc/machine-id"):
        try:
            text = Path(path).read_text().strip("\x00\n ")
        except OSError:
            continue
        if text:
            return text
    return "unknown"


def oscillator_problem(cfg: Any, board: str) -> str:
    """One line when ``esc.oscillator_calibrated`` is true but no measurement on ``board`` is recorded
    (``esc.oscillator_measured_on`` absent, or naming another board: a vehicle file copied from another vehicle, or
    the flag set by hand); "" otherwise (false is refused by the ESC itself). Issue 71.8: a mis-set oscillator
    marked calibrated put 1559-1631 us on the wire as "neutral"."""
    flat = cfg.flat if hasattr(cfg, "flat") else cfg
    if not flat.get("esc.oscillator_calibrated"):
        return ""
    record = str(flat.get("esc.oscillator_measured_on") or "")
    check = ("check with a scope that a disarmed thruster channel carries 1500 us (or run `hindrax esc calibrate "
             "--measured-us X --write` on this vehicle)")
    if not record:
        return f"esc.oscillator_calibrated is true but no measurement is recorded (esc.oscillator_measured_on): {check}"
    if record.split()[0] != board:
        return f"esc.oscillator_hz was measured on board {record.split()[0]}, not this one ({board}): {check}"
    return ""


def cross_checks(c: Mapping[str, Any]) -> list[ConfigIssue]:
    """Checks of the ESC output's safety settings (docs/architecture.md §8), one issue (one line) each: the ACTUAL
    PWM rate after prescale rounding within the ESC's 50-400 Hz; an /OE chip with its line; the hardware watchdog's
    feed (docs/watchdog.md) with its line, rate and the circuit's timeout, and at least three rising edges per
    timeout, so that one late guard tick does not stop the outputs; the ESC's and the guard's heartbeat timeouts
    long enough for two supervisor heartbeats (one per supervisor check). The oscillator's range (23-27 MHz,
    :data:`~.hardware_limits.PCA9685_OSCILLATOR_MIN_HZ`) is the key's own range in :data:`SCHEMA`."""
    issues: list[ConfigIssue] = []
    if "esc.pwm_frequency_hz" in c and "esc.oscillator_hz" in c:
        try:
            esc_prescale(c["esc.pwm_frequency_hz"], c["esc.oscillator_hz"])
        except Pca9685Error as exc:
            issues.append(ConfigIssue("esc.pwm_frequency_hz", c["esc.pwm_frequency_hz"],
                                      f"an actual rate within the ESC's 50-400 Hz ({exc})"))
    if "esc.output_enable_gpio.chip" in c and "esc.output_enable_gpio.line" not in c:
        issues.append(ConfigIssue("esc.output_enable_gpio.line", "<missing>", "a line offset with "
                                  "esc.output_enable_gpio.chip"))
    if c.get("esc.output_enable_feed_gpio.chip"):
        for key in ("esc.output_enable_feed_gpio.line", "esc.output_enable_feed_rate_hz",
                    "esc.output_enable_feed_timeout_s"):
            if key not in c:
                issues.append(ConfigIssue(key, "<missing>", "a value with esc.output_enable_feed_gpio.chip"))
        if "esc.output_enable_feed_rate_hz" in c and "esc.output_enable_feed_timeout_s" in c:
            low = 3.0 / c["esc.output_enable_feed_timeout_s"]
            if c["esc.output_enable_feed_rate_hz"] < low:
                issues.append(ConfigIssue("esc.output_enable_feed_rate_hz", c["esc.output_enable_feed_rate_hz"],
                                          f">= {low:g} Hz: three rising edges per esc.output_enable_feed_timeout_s"))
    for key in ("esc.heartbeat_timeout_s", "esc.guard_heartbeat_timeout_s"):
        if key in c and "supervisor.check_rate_hz" in c:
            period = 1.0 / c["supervisor.check_rate_hz"]
            if c[key] < 2.0 * period:
                issues.append(ConfigIssue(key, c[key], f"at least two supervisor heartbeats (2 / "
                                                       f"supervisor.check_rate_hz = {2.0 * period:g} s)"))
    # an unreturned bus call must be reported (ERROR heartbeat) before the guard would notice the silence anyway
    if "esc.bus_call_timeout_s" in c and "esc.guard_heartbeat_timeout_s" in c:
        if c["esc.bus_call_timeout_s"] >= c["esc.guard_heartbeat_timeout_s"]:
            issues.append(ConfigIssue("esc.bus_call_timeout_s", c["esc.bus_call_timeout_s"],
                                      f"< esc.guard_heartbeat_timeout_s = {c['esc.guard_heartbeat_timeout_s']:g} s"))
    return issues
