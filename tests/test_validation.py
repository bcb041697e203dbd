"""The one validation module: one template, one rule per kind of value, for every caller."""

import math

import numpy as np
import pytest

from imu_square.errors import ConfigError, ImuSquareError
from imu_square.validation import (
    TomlTable,
    check_bool,
    check_int,
    check_number,
    check_option,
    check_text,
    interval,
)


def test_the_template_names_where_the_field_what_is_allowed_and_what_came():
    with pytest.raises(ConfigError) as info:
        check_number(
            "[sensor] range_g", -1, 0, math.inf, lo_open=True, where="s.toml", error=ConfigError
        )
    assert str(info.value) == "s.toml: [sensor] range_g must be in (0, inf], got -1.0"
    with pytest.raises(ImuSquareError) as info:
        check_option("dialect", "heidenhain", ("linuxcnc", "fanuc"))
    assert str(info.value) == "dialect must be one of ('linuxcnc', 'fanuc'), got 'heidenhain'"


@pytest.mark.parametrize("value", [True, np.bool_(False), "1.0", None, [1.0], 1j])
def test_a_bool_or_anything_else_is_not_a_number(value):
    with pytest.raises(ImuSquareError, match=r"x must be a number in \[0, 1\], got"):
        check_number("x", value, 0, 1)
    with pytest.raises(ImuSquareError, match=r"x must be a number, got"):
        check_number("x", value)


@pytest.mark.parametrize(
    "value", [np.float32(0.5), np.float64(0.5), np.int8(0), np.array(0.25), 1, 0.5]
)
def test_numpy_scalars_and_0d_arrays_are_numbers(value):
    got = check_number("x", value, 0, 1)
    assert type(got) is float and got == float(value)


def test_infinity_passes_only_as_a_closed_bound_and_nan_never():
    assert check_number("x", math.inf, 0, math.inf) == math.inf
    for bad, message in [
        (math.inf, r"x must be finite, got inf"),
        (-math.inf, r"x must be finite, got -inf"),
        (math.nan, r"x must be finite, got nan"),
    ]:
        with pytest.raises(ImuSquareError, match=message):
            check_number("x", bad, 0, 10)
        with pytest.raises(ImuSquareError, match=message):
            check_number("x", bad)  # no bound: finite all the same
    with pytest.raises(ImuSquareError, match=r"x must be finite, got inf"):
        check_number("x", math.inf, 0, math.inf, lo_open=True, hi_open=True)
    with pytest.raises(ImuSquareError, match=r"x must be in \[0, inf\], got nan"):
        check_number("x", math.nan, 0, math.inf)


def test_open_and_closed_bounds():
    assert check_number("x", 0, 0, 1) == 0.0
    with pytest.raises(ImuSquareError, match=r"x must be in \(0, 1\], got 0\.0"):
        check_number("x", 0, 0, 1, lo_open=True)
    with pytest.raises(ImuSquareError, match=r"x must be in \[0, 1\), got 1\.0"):
        check_number("x", 1, 0, 1, hi_open=True)


def test_a_whole_number_is_an_integer_not_a_float():
    assert check_int("n", np.int64(3), 1, 10) == 3
    assert type(check_int("n", np.int64(3))) is int
    for bad in (3.0, True, "3"):
        with pytest.raises(ImuSquareError, match=r"n must be a whole number in \[1, 10\], got"):
            check_int("n", bad, 1, 10)
    with pytest.raises(ImuSquareError, match=r"n must be a whole number in \[1, 10\], got 0$"):
        check_int("n", 0, 1, 10)


def test_bools_and_text():
    assert check_bool("b", np.bool_(True)) is True
    with pytest.raises(ImuSquareError, match=r"b must be True or False, got 1"):
        check_bool("b", 1)
    for bad in ("", "  ", "a\tb", "a\nb", "a\u2028b", 3):
        with pytest.raises(ImuSquareError, match=r"t must be a non-empty string on one line"):
            check_text("t", bad)
    assert check_text("t", "", empty=True) == ""
    assert check_text("t", "a\tb", controls=True) == "a\tb"
    with pytest.raises(ImuSquareError, match=r"t must be one line of text, got 'a\\rb'"):
        check_text("t", "a\rb", controls=True)


def test_interval_writes_ints_in_full_and_floats_short():
    assert interval(1, 20_000_000) == "[1, 20000000]"
    assert interval(0.0, 1e6, lo_open=True) == "(0, 1e+06]"
    assert interval(None, 5.0) == "(-inf, 5]"


def test_a_toml_table_refuses_unknown_fields_and_takes_defaults_from_its_layout():
    with pytest.raises(ConfigError, match=r"^f: \[s\] has unknown field 'b'; allowed: \['a'\]$"):
        TomlTable({"b": 1}, "[s]", ("a",), "f", error=ConfigError)
    with pytest.raises(ConfigError, match=r"^f: \[s\] must be a table, got 3$"):
        TomlTable(3, "[s]", ("a",), "f", error=ConfigError)
    t = TomlTable({}, "[s]", {"a": 2.5}, "f", error=ConfigError)
    assert t.number("a", 0, 10) == 2.5
    with pytest.raises(ConfigError, match=r"^f: \[s\] is missing the required field 'c'$"):
        TomlTable({}, "[s]", ("c",), "f", error=ConfigError).text("c")
