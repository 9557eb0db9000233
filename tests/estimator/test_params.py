from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import pytest

from estimator.errors import ConfigError
from estimator.params import (
    ExtensionParams,
    Params,
    coerce_value,
    for_method,
    get_param,
    load_params,
    param_specs,
    params_to_toml,
    parse_assignments,
    save_params,
    with_values,
)


def _changed(params: Params) -> dict[str, object]:
    """A new in-bounds value for every numeric and boolean parameter."""
    out: dict[str, object] = {}
    for spec in param_specs():
        value = get_param(params, spec.name)
        if isinstance(value, bool):
            out[spec.name] = not value
        elif isinstance(value, float) and spec.lo is not None and spec.hi is not None:
            out[spec.name] = (
                (spec.lo + spec.hi) / 2 if value != (spec.lo + spec.hi) / 2 else spec.lo
            )
        elif isinstance(value, tuple):
            out[spec.name] = tuple(v + 0.5 for v in value)
    return out


def test_defaults_respect_their_own_bounds() -> None:
    specs = list(param_specs())
    assert len(specs) == len({s.name for s in specs}) > 10
    for spec in specs:
        assert spec.doc, spec.name
        if spec.default is not None:
            assert coerce_value(spec, spec.default) == spec.default, spec.name


def test_toml_round_trip_of_defaults_and_of_every_changed_value(tmp_path: Path) -> None:
    path = tmp_path / "p.toml"
    save_params(Params(), path)
    assert load_params(path) == Params()
    values = _changed(Params())
    changed = with_values(Params(), values)
    for name, value in values.items():
        assert get_param(changed, name) == value
    assert changed != Params()
    path.write_text(params_to_toml(changed))
    assert load_params(path) == changed


def test_cli_strings_are_converted() -> None:
    p = with_values(
        Params(), parse_assignments(["sensors.imu_yaw_deg=-90", "sensors.gnss_lever_arm_m=1,0,1.5"])
    )
    assert p.sensors.imu_yaw_deg == -90.0
    assert p.sensors.gnss_lever_arm_m == (1.0, 0.0, 1.5)
    p = with_values(p, {"sensors.initial_heading_deg": "none"})
    assert p.sensors.initial_heading_deg is None


@pytest.mark.parametrize(
    ("values", "problem"),
    [
        ({"sensors.imu_yaw_deg": 400}, "sensors.imu_yaw_deg=400.0 is outside [-180, 180]"),
        ({"sensors.imu_yaw_deg": "east"}, "invalid value 'east'"),
        ({"sensors.imu_yaw_deg": "nan"}, "NaN is not a valid value"),
        ({"sensors.gnss_lever_arm_m": "1,2"}, "expected 3 numbers"),
        ({"sensors.no_such": 1}, "unknown parameter 'sensors.no_such'"),
    ],
)
def test_bad_values_are_config_errors(values: dict, problem: str) -> None:
    with pytest.raises(ConfigError) as err:
        with_values(Params(), values, "cmdline")
    assert problem in str(err.value) and "\n" not in str(err.value)


def test_bad_bool_is_refused() -> None:
    name = next(s.name for s in param_specs() if s.type is bool)
    with pytest.raises(ConfigError, match="invalid value 'maybe'"):
        with_values(Params(), {name: "maybe"})


@pytest.mark.parametrize("value", [3, 0.5, [1], {"on": True}, None])
def test_a_switch_takes_true_or_false_not_whatever_python_calls_truthy(value: object) -> None:
    """A TOML or JSON ``map_bias = 3`` is a mistake to report, not a switch turned on."""
    with pytest.raises(ConfigError, match="true or false is required") as caught:
        with_values(Params(), {"extensions.map_bias": value})
    assert str(caught.value).count("extensions.map_bias") == 1


@pytest.mark.parametrize("value", [1, 0, True, False, "on", "0"])
def test_a_switch_takes_its_spellings(value: object) -> None:
    assert with_values(Params(), {"extensions.map_bias": value}).extensions.map_bias is bool(
        value if not isinstance(value, str) else value in ("on", "1")
    )


@pytest.mark.parametrize("value", [2.5, True])
def test_a_count_is_not_rounded_from_a_fraction_or_a_switch(value: object) -> None:
    with pytest.raises(ConfigError, match="a whole number is required"):
        with_values(Params(), {"gates.min_pairs": value})


def test_a_count_takes_a_whole_float() -> None:
    assert with_values(Params(), {"gates.min_pairs": 4.0}).gates.min_pairs == 4


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("[sensors]\nimu_yaw_deg = 1000.0\n", "is outside"),
        ("[sensors]\nimu_yaw = 1.0\n", "unknown parameter 'sensors.imu_yaw'"),
        ("[sensors\nimu_yaw_deg = 1\n", "not valid TOML"),
        pytest.param(
            f"[window]\nlength_m = {'9' * 400}\n",
            "window.length_m: invalid value 999",
            id="float-400-digits",
        ),
        pytest.param(
            f"[gates]\nmin_pairs = {'9' * 400}\n", "gates.min_pairs=999", id="int-400-digits"
        ),
        pytest.param(
            f"[window]\nlength_m = {'9' * 5000}\n",
            "an integer of more than 4300 digits",
            id="int-5000-digits",
        ),
        pytest.param(
            "a = " + "[" * 100_000 + "]" * 100_000 + "\n", "nested too deeply", id="deep-array"
        ),
        pytest.param(
            "[" + ".".join(["a"] * 5000) + "]\nx = 1\n",
            "a key of more than 32 dotted parts",
            id="deep-table",
        ),
        pytest.param(
            ".".join(['"a"'] * 40) + " = 1\n",
            "a key of more than 32 dotted parts",
            id="deep-quoted-key",
        ),
        pytest.param(
            "[" + ".".join(["a"] * 20) + "]\nx = 1\n",
            "unknown parameter 'a.a.a.a.a.a.a",
            id="table-20-deep",
        ),
    ],
)
def test_bad_toml_files(tmp_path: Path, text: str, problem: str) -> None:
    """Each is one line naming the file: numbers too large for a float or for Python's integer
    conversion, arrays nested past the recursion limit, keys deeper than any parameter's."""
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_params(path)
    message = str(err.value)
    assert message.startswith(str(path)) and problem in message
    assert "\n" not in message and len(message) < 300


def test_a_key_half_a_megabyte_deep_is_refused_at_once(tmp_path: Path) -> None:
    """tomllib's time grows with the square of a key's parts: 17 s at 100 000 parts."""
    path = tmp_path / "deep.toml"
    path.write_text("[" + ".".join(["a"] * 490_000) + "]\n")
    started = time.perf_counter()
    with pytest.raises(ConfigError, match="a key of more than 32 dotted parts"):
        load_params(path)
    assert time.perf_counter() - started < 2.0


@pytest.mark.parametrize(
    "text",
    [
        "# see a.b.c.d.e.f.g.h for more\n[gates]\nmin_pairs = 4\n",
        "[gates]\nmin_pairs = 4\n[sensors]\ngnss_lever_arm_m = [0.5, 1.5, 2.5]\n",
        "gates.min_pairs = 4\n",
    ],
)
def test_dotted_words_short_of_the_limit_are_read(tmp_path: Path, text: str) -> None:
    path = tmp_path / "ok.toml"
    path.write_text(text)
    assert load_params(path).gates.min_pairs == 4


def test_missing_config_and_bad_assignment(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match="cannot read config"):
        load_params(tmp_path / "none.toml")
    with pytest.raises(ConfigError, match="--set expects NAME=VALUE"):
        parse_assignments(["sensors.imu_yaw_deg"])


def test_paper_method_switches_every_extension_off() -> None:
    paper = for_method(Params(), "paper")
    assert all(v is False for v in dataclasses.asdict(paper.extensions).values())
    assert for_method(Params(), "proposed") == Params()
    assert paper.noise == Params().noise
    assert dataclasses.fields(ExtensionParams)
