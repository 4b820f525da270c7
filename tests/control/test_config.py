"""Controller configuration: the YAML file, defaults and validation errors naming the key."""

from __future__ import annotations

from pathlib import Path

import pytest

from control.config import ControllerConfig, load_config, resolve_urdf_path
from control.errors import ControlConfigError

DEFAULT_YAML = Path(__file__).parents[2] / "control" / "config" / "default.yaml"


def _write(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "controller.yaml"
    path.write_text("controller:\n  ros__parameters:\n" + body, encoding="utf-8")
    return path


def test_default_yaml_matches_dataclass_defaults() -> None:
    config = load_config(DEFAULT_YAML)
    assert config == ControllerConfig()
    assert config.robot.gripper_max_opening_m == 0.08
    assert config.bins["rubber"] == (0.60, 0.07, 0.15)
    assert resolve_urdf_path(config.robot.urdf_path).is_file()


def test_partial_file_keeps_other_defaults(tmp_path: Path) -> None:
    path = _write(tmp_path, "    pick:\n      dwell_s: 0.4\n")
    config = load_config(path)
    assert config.pick.dwell_s == 0.4
    assert config.motion == ControllerConfig().motion


@pytest.mark.parametrize(
    ("body", "match"),
    [
        ("    pick:\n      dwell_s: fast\n", r"pick\.dwell_s: expected a number"),
        ("    pick:\n      dwel_s: 0.4\n", r"unknown key\(s\) \['dwel_s'\]"),
        ("    belt:\n      pick_window_x_m: [0.3, -0.3]\n", r"belt\.pick_window_x_m"),
        ("    motion:\n      max_jerk: [1, 2, 3]\n", r"motion\.max_jerk: expected 4 numbers"),
        ("    tracking:\n      confirm_hits: 0\n", r"tracking\.confirm_hits"),
        ("    bins:\n      concrete: [0, 0, .nan]\n", r"bins\.concrete\[2\]"),
        ("    robot:\n      urdf_path: 3\n", r"robot\.urdf_path: expected a string"),
        ("    scheduler:\n      class_priorities: {concrete: 1.0}\n", r"no priority for class"),
        ("    pick:\n      approach_space: diagonal\n", r"pick\.approach_space: 'diagonal'"),
        (
            "    pick:\n      close_overlap_s: 0.3\n",
            r"pick\.close_overlap_s: 0\.3 is invalid, must not exceed dwell_s",
        ),
    ],
)
def test_bad_values_name_file_and_key(tmp_path: Path, body: str, match: str) -> None:
    path = _write(tmp_path, body)
    with pytest.raises(ControlConfigError, match=match) as info:
        load_config(path)
    assert str(path) in str(info.value)


def test_invalid_yaml_names_line(tmp_path: Path) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text("controller:\n  ros__parameters:\n    pick: [1, 2\n", encoding="utf-8")
    with pytest.raises(ControlConfigError, match=r"broken\.yaml: line \d+"):
        load_config(path)


def test_missing_file_and_missing_node(tmp_path: Path) -> None:
    with pytest.raises(ControlConfigError, match="cannot read"):
        load_config(tmp_path / "absent.yaml")
    other = tmp_path / "other.yaml"
    other.write_text("twin:\n  ros__parameters: {}\n", encoding="utf-8")
    with pytest.raises(ControlConfigError, match="top-level key 'controller'"):
        load_config(other)


def test_unknown_urdf_is_reported() -> None:
    with pytest.raises(ControlConfigError, match=r"robot\.urdf_path: 'no/such\.urdf'"):
        resolve_urdf_path("no/such.urdf")
