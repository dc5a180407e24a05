"""The parser fuzzing of the robustness benchmark (hindrax_tools.benchmarks.robustness): its
checks run.

The benchmark's DVL check read the speed gate as ``section["max_speed_m_s"]`` after the configuration became typed
sections; every valid ``$DVPDL`` then counted as a parser crash (91 of 100,000 inputs in ``make bench``), in the
harness and not in the driver. These tests fail on that kind of harness error before a bench run does.
"""
from hindrax_drivers.dvl75.protocol import DvlPositionDelta, format_dvpdl

from hindrax_tools.benchmarks import robustness


def test_the_dvl_check_accepts_a_valid_position_delta_within_the_gates():
    """A well-formed ``$DVPDL`` (0.1 s, 1 mm / -2 mm / 3 mm: 0.037 m/s, well inside the vehicle file's gate)
    decodes, reaches the speed gate and is counted as accepted, without raising."""
    check = robustness._dvl_check_factory()
    line = format_dvpdl(DvlPositionDelta(12.345678, 0.1, 0.001, -0.002, 0.003, 0.0123, -0.0045, 0.0007, 87))
    assert check(line) is True
    assert check(line) is True


def test_twenty_thousand_fuzzed_inputs_per_parser_crash_none():
    """20,000 derandomised inputs per parser (a fifth of the benchmark's count; about 3 s here): every parser
    accepts some of them (the field decoders are reached) and none crashes. With the harness error above, this
    count drew 13 DVL crashes."""
    rows = robustness.fuzz_parsers(20_000)
    assert [r["name"] for r in rows] == ["DVL-75 sentences", "Ping1D frames", "MS5837 PROM/ADC conversion",
                                         "ICM-20948 register decoding"]
    for row in rows:
        assert row["inputs"] >= 20_000, row
        assert row["accepted"] > 0, row
        assert row["crashes"] == 0, row["first"]
