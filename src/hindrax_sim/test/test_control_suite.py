"""The scenario suite's table says where the heave model came from (hindrax_sim.control_suite)."""
from hindrax_sim.control_suite import format_suite


def _row(name, sources):
    return {"scenario": name, "cases": {}, "ratios": {}, "model_sources": {"heave": sources}}


def test_heave_column_names_a_fallback_of_the_force_terms():
    force = "vehicle file (identified value suspect: bias -0.0143 N is -0.02 x the file's +0.785 N ...: a force error)"
    rows = [_row("all", {"inertia": "identified", "damping": "identified", "bias": "identified"}),
            _row("forces", {"inertia": "identified", "damping": force, "bias": force}),
            _row("white", {"inertia": "vehicle file (identified value suspect: residuals not white (lag-1 0.4))",
                           "damping": "vehicle file", "bias": "vehicle file"})]
    cells = {line.split(" | ")[0].lstrip("| "): line.split(" | ")[1] for line in format_suite(rows).splitlines()[2:]}
    assert cells["all"] == "identified"
    assert cells["forces"].startswith("inertia identified") and "force error" in cells["forces"]
    assert cells["white"].startswith("file: residuals not white")
