"""twin.infra.tables: the Markdown tables the reports are built with."""
import math

import numpy as np
import pytest

from twin.infra.tables import markdown_table


def test_a_table_with_units_formats_and_alignment():
    text = markdown_table([("Z", -40.2049, 1.98333, 12), ("Y_top", 15.9, 2.0, 3)],
                          ["channel", "peak drift (µm)", "at (h)", "samples"],
                          align=[None, "right", "center", "left"], formats=[None, ".2f", ".1f", ".2f"])
    assert text == ("| channel | peak drift (µm) | at (h) | samples |\n"
                    "|---|---:|:---:|:---|\n"
                    "| Z | -40.20 | 2.0 | 12 |\n"          # integers are not float-formatted
                    "| Y_top | 15.90 | 2.0 | 3 |")


def test_missing_numbers_numpy_floats_and_pipes():
    text = markdown_table([(math.nan, np.float64(0.1234), "max |Z|", math.inf)], list("abcd"), formats=".2g")
    assert text.splitlines()[-1] == r"| – | 0.12 | max \|Z\| | – |"


def test_a_callable_format_sees_every_value():
    assert markdown_table([(1, "x")], ["n", "s"], formats=lambda v: f"<{v}>").endswith("| <1> | <x> |")


@pytest.mark.parametrize("kwargs, message", [
    (dict(rows=[(1, 2, 3)]), "row 0 has 3 values for 2 columns"),
    (dict(rows=[], formats=[".2f"]), "formats has 1 entries for 2 columns"),
    (dict(rows=[], align="middle"), "unknown alignment 'middle'"),
])
def test_a_malformed_table_is_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        markdown_table(headers=["a", "b"], **kwargs)
