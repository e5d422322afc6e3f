"""Every setting once (settings.py), reaching the node's parameters and tof_calib's options alike."""
from __future__ import annotations

import argparse

import pytest

from tof_calib_ros.offline import cli
from tof_calib_ros.settings import SETTINGS, calibration_options, collector_config, defaults, refusal


def _options(command: str) -> dict[str, argparse.Action]:
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))   # noqa: SLF001
    return {flag: action for action in sub.choices[command]._actions for flag in action.option_strings}   # noqa: SLF001


@pytest.mark.parametrize("command", ["bag", "images"])
def test_every_setting_with_a_flag_is_an_option_with_the_same_default(command):
    options = _options(command)
    for s in SETTINGS.values():
        if s.flag is None or (command == "images" and s.name.startswith(("bag.", "sync."))):
            continue
        assert s.flag in options, f"{s.name}: {s.flag} missing from tof_calib {command}"
        action = options[s.flag]
        if s.name != "board.square":   # required on the command line: a board has no default size
            assert action.default == s.default, (s.name, action.default, s.default)
        assert s.text in action.help


def test_the_node_declares_every_setting_with_its_range():
    pytest.importorskip("rclpy", reason="the ROS 2 wheels are not installed")
    from tof_calib_ros.ros.node import PARAMETERS

    assert list(PARAMETERS) == list(SETTINGS)
    for name, (default, descriptor) in PARAMETERS.items():
        s = SETTINGS[name]
        assert default == s.default and descriptor.description == s.text and descriptor.read_only == s.read_only
        ranges = list(descriptor.integer_range) + list(descriptor.floating_point_range)
        assert (s.low is None) == (not ranges), name
        if ranges:
            assert (ranges[0].from_value, ranges[0].to_value) == (s.low, s.high), name


@pytest.mark.parametrize("name, value, reason, on_the_command_line", [
    ("views.min", 2, "views.min must be at least 3, got 2", True),
    ("depth.bias", "offset+wobble", "depth.bias: depth_bias must be 'none' or terms", True),
    ("calibration.loss", "l2", "calibration.loss must be one of 'none', 'huber', 'cauchy', got 'l2'", True),
    ("camera_name", "my camera", "camera_name: camera name 'my camera' must be letters, digits and '_'", True),
    ("sync.slop", "0.1", "sync.slop must be float, got '0.1'", False),   # a node parameter of the wrong type
])
def test_one_refusal_in_the_same_words_for_node_and_cli(name, value, reason, on_the_command_line, capsys):
    assert refusal({name: value}).startswith(reason)
    flag = SETTINGS[name].flag
    if on_the_command_line:
        with pytest.raises(SystemExit):
            cli.main(["bag", "x", "--size", "5x7", "--square", "0.03", "--output", "o", flag, str(value)])
        assert reason in capsys.readouterr().err
    assert refusal({"views.min": 20, "views.max": 10}).startswith("views.min (20) must not exceed views.max (10)")


def test_the_wiggle_term_is_refused_without_the_modulation_frequency(capsys):
    needs = "depth.bias 'offset+wiggle' with depth.modulation_mhz 0.0: the wiggle term needs the camera's modulation"
    assert refusal({"depth.bias": "offset+wiggle", "depth.modulation_mhz": 0.0}).startswith(needs)
    assert refusal({"depth.bias": "offset+wiggle", "depth.modulation_mhz": 20.0}) is None
    # within the setting's range, but no ToF camera's: refused up front, not at the calibration
    assert "modulation_hz must be a frequency" in refusal({"depth.bias": "auto", "depth.modulation_mhz": 0.01})
    with pytest.raises(SystemExit):
        cli.main(["bag", "x", "--size", "5x7", "--square", "0.03", "--output", "o", "--depth-bias", "offset+wiggle"])
    assert needs in capsys.readouterr().err
    assert calibration_options(defaults() | {"depth.modulation_mhz": 20.0})["modulation_hz"] == 20e6


def test_the_radial_term_is_refused_for_radial_depth():
    """An offset in the light's path is the depth offset where the depth is the light's path."""
    assert "the radial term is for z-depth" in refusal({"depth.bias": "offset+radial", "depth.convention": "radial"})
    # the data might choose radial depth, where the term has no meaning: asked for, z must be said
    assert "the radial term is for z-depth" in refusal({"depth.bias": "offset+radial", "depth.convention": "auto"})
    assert refusal({"depth.bias": "offset+radial", "depth.convention": "z"}) is None


def test_the_settings_reach_calibrate_and_the_collector():
    values = defaults() | {"calibration.loss": "huber", "depth.bias": "offset+tilt", "views.max": 30}
    assert calibration_options(values) == {"depth_convention": "auto", "depth_bias": "offset+tilt",
                                           "distortion": "auto", "loss": "huber", "plane_squares": "auto",
                                           "modulation_hz": None}
    assert calibration_options(defaults())["loss"] is None
    config = collector_config(values, stills=True)
    assert (config.max_views, config.min_views, config.stills) == (30, 8, True)
