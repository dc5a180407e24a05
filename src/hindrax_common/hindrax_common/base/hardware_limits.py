"""The PWM hardware's limits that both the ESC driver and the configuration check: pure, standard library only.

NXP PCA9685 (docs/devices.md §5.1; product data sheet Rev. 4 [PCA9685] in docs/references.md): 4096 counts per
period, PRE_SCALE 3..255 (§7.3.5), ``prescale = round(osc_clock / (4096 f)) - 1``, internal oscillator 25 MHz
nominal, 23-27 MHz measured on individual parts. Blue Robotics Basic ESC (docs/devices.md §5.2): 1100-1900 us,
1500 us stop, deadband 1500 +- 25 us, update rate 50-400 Hz, neutral held 7 s to arm.

The driver (:mod:`hindrax_drivers.pca9685.protocol`) re-exports these names; the configuration
(:mod:`hindrax_common.config`) imports them from here, so it imports no driver package."""
from __future__ import annotations

import math

__all__ = ["Pca9685Error", "COUNTS_PER_PERIOD", "PRESCALE_MIN", "PRESCALE_MAX", "INTERNAL_OSCILLATOR_HZ",
           "PCA9685_OSCILLATOR_MIN_HZ", "PCA9685_OSCILLATOR_MAX_HZ", "ESC_MIN_US", "ESC_NEUTRAL_US", "ESC_MAX_US",
           "ESC_DEADBAND_US", "ESC_MIN_FREQUENCY_HZ", "ESC_MAX_FREQUENCY_HZ", "ESC_ARMING_HOLD_S",
           "prescale_for_frequency", "frequency_for_prescale", "esc_prescale"]


class Pca9685Error(ValueError):
    """Bad PCA9685/ESC input: channel, frequency, prescale, pulse width or register bytes."""


# ------------------------------------------------------------------------------ PCA9685 (§5.1)
COUNTS_PER_PERIOD = 4096
PRESCALE_MIN = 3
PRESCALE_MAX = 255
#: Nominal internal oscillator; real parts measure 23-27 MHz: calibrate (docs/devices.md §0 item 8, §5.1).
INTERNAL_OSCILLATOR_HZ = 25_000_000.0
#: Range of the PCA9685's internal oscillator, Hz: 25 MHz nominal (data sheet §7.3.5, osc_clock 25 MHz); individual
#: parts measure 23-27 MHz (docs/devices.md §5.1). A calibration outside it is a wrong reading (channel, trigger, unit),
#: not a part: with 28.85 MHz assumed, a commanded 1500 us neutral puts 1732 us on a 25 MHz part's wire.
PCA9685_OSCILLATOR_MIN_HZ = 23e6
PCA9685_OSCILLATOR_MAX_HZ = 27e6

# ------------------------------------------------------------------------------ Basic ESC (§5.2)
ESC_MIN_US = 1100.0
ESC_NEUTRAL_US = 1500.0
ESC_MAX_US = 1900.0
ESC_DEADBAND_US = 25.0  # [UNVERIFIED directly, §5.2]
ESC_MAX_FREQUENCY_HZ = 400.0
ESC_MIN_FREQUENCY_HZ = 50.0
#: Blue Robotics' minimal example holds neutral 7 s before other commands (arming, §5.2 [E1]).
ESC_ARMING_HOLD_S = 7.0


def check_oscillator(oscillator_hz: float) -> float:
    """``oscillator_hz`` as a float; raises :class:`Pca9685Error` unless finite and > 0."""
    if not (math.isfinite(oscillator_hz) and oscillator_hz > 0.0):
        raise Pca9685Error(f"oscillator_hz must be finite and > 0, got {oscillator_hz}")
    return float(oscillator_hz)


def check_prescale(prescale: int) -> int:
    """``prescale``; raises :class:`Pca9685Error` unless an int in 3..255 (data sheet §7.3.5)."""
    if not isinstance(prescale, int) or not PRESCALE_MIN <= prescale <= PRESCALE_MAX:
        raise Pca9685Error(f"prescale must be an int {PRESCALE_MIN}..{PRESCALE_MAX}, got {prescale!r}")
    return prescale


def prescale_for_frequency(frequency_hz: float, oscillator_hz: float = INTERNAL_OSCILLATOR_HZ) -> int:
    """PRE_SCALE = round(f_osc / (4096 f)) - 1 (docs/devices.md §5.1 [Q1 §7.3.5]).

    Rounding is half-up (``floor(x + 0.5)``, as Adafruit's "+0.5 then truncate" [Q3]), not Python's banker's rounding.

    Raises ``Pca9685Error``: non-finite/non-positive inputs, or a result outside 3..255 (about 24..1526 Hz at 25 MHz).
    """
    osc = check_oscillator(oscillator_hz)
    if not (math.isfinite(frequency_hz) and frequency_hz > 0.0):
        raise Pca9685Error(f"frequency_hz must be finite and > 0, got {frequency_hz}")
    prescale = math.floor(osc / (COUNTS_PER_PERIOD * frequency_hz) + 0.5) - 1
    if not PRESCALE_MIN <= prescale <= PRESCALE_MAX:
        raise Pca9685Error(
            f"{frequency_hz:g} Hz needs prescale {prescale}, outside {PRESCALE_MIN}..{PRESCALE_MAX} "
            f"({frequency_for_prescale(PRESCALE_MAX, osc):.1f}..{frequency_for_prescale(PRESCALE_MIN, osc):.1f} Hz)")
    return prescale


def frequency_for_prescale(prescale: int, oscillator_hz: float = INTERNAL_OSCILLATOR_HZ) -> float:
    """Actual PWM frequency f = f_osc / (4096 (PRE_SCALE + 1)) in Hz (docs/devices.md §5.1)."""
    return check_oscillator(oscillator_hz) / (COUNTS_PER_PERIOD * (check_prescale(prescale) + 1))


def esc_prescale(frequency_hz: float, oscillator_hz: float = INTERNAL_OSCILLATOR_HZ) -> int:
    """Prescale for an ESC update rate, checking the ACTUAL rate is within 50..400 Hz (§5.1, §5.2).

    E.g. 400 Hz rounds to prescale 14 = 406.9 Hz at 25 MHz, above the Basic ESC's 400 Hz maximum,
    and is rejected; use 381.5 Hz (prescale 15) or 200 Hz.

    Raises ``Pca9685Error``: the actual frequency is outside 50..400 Hz."""
    prescale = prescale_for_frequency(frequency_hz, oscillator_hz)
    actual_hz = frequency_for_prescale(prescale, oscillator_hz)
    if not ESC_MIN_FREQUENCY_HZ <= actual_hz <= ESC_MAX_FREQUENCY_HZ:
        raise Pca9685Error(f"{frequency_hz:g} Hz gives an actual {actual_hz:.1f} Hz (prescale {prescale}), "
                           f"outside the ESC range {ESC_MIN_FREQUENCY_HZ:g}..{ESC_MAX_FREQUENCY_HZ:g} Hz")
    return prescale
