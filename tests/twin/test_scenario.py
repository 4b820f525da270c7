"""Scenarios round-trip through YAML and reject bad keys and values by name."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from twin.errors import ConfigError
from twin.perception_config import PerceptionConfig
from twin.scenario import (
    FaultLevel,
    ObjectLevel,
    PerturbationLevel,
    Scenario,
    SystemLevel,
    seed_tree,
)


def test_round_trip_through_a_file(tmp_path: Path) -> None:
    scenario = Scenario(
        name="dense",
        seed=4,
        duration_s=30.0,
        objects=ObjectLevel(
            images=("a", "b"),
            max_objects=9,
            resample_heights=True,
            height_ranges_m={"wood": (0.02, 0.05)},
            orientation_jitter_rad=0.3,
            max_width_m=0.065,
        ),
        system=SystemLevel(
            belt_speed_mps=0.6,
            object_order="shuffled",
            perturbation=PerturbationLevel(enabled=True, force_std_N=20.0),
            speed_schedule=((10.0, 0.2),),
            prefill_m=0.5,
        ),
    )
    path = tmp_path / "s.yaml"
    scenario.save(path)
    assert Scenario.load(path) == scenario
    assert not list(tmp_path.glob("*.tmp"))


@pytest.mark.parametrize("text", ["", "# only a comment\n", "---\n"])
def test_an_empty_file_is_refused_rather_than_running_the_defaults(
    tmp_path: Path, text: str
) -> None:
    path = tmp_path / "empty.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=r"empty\.yaml: the scenario is empty"):
        Scenario.load(path)


def test_an_explicit_empty_mapping_gives_the_defaults(tmp_path: Path) -> None:
    path = tmp_path / "defaults.yaml"
    path.write_text("{}\n", encoding="utf-8")
    assert Scenario.load(path) == Scenario()


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        ("speed: 3", r"unknown key 'speed'"),
        ("system: {belt_speeed_mps: 0.3}", r"system: unknown key 'belt_speeed_mps'"),
        ("system: {belt_speed_mps: 5}", r"system\.belt_speed_mps = 5\.0: must be in \[0, 2\]"),
        ("system: {belt_speed_mps: fast}", r"system\.belt_speed_mps = 'fast': expected a number"),
        ("system: {object_order: random}", r"object_order = 'random': must be one of"),
        ("duration_s: -1", r"duration_s = -1\.0"),
        ("physics: {friction: {wood: [0.9, 0.1]}}", r"physics\.friction\.wood = \[0\.9, 0\.1\]"),
        ("[1, 2]", r"top level must be a mapping"),
        ("a: [", r"not valid YAML"),
        ("objects: {max_width_m: 0}", r"objects\.max_width_m = 0\.0: must be > 0"),
        ("objects: {min_height_m: 0}", r"objects\.min_height_m = 0\.0: must be in \(0, 1\)"),
    ],
)
def test_bad_scenarios_name_the_key(tmp_path: Path, text: str, pattern: str) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=pattern) as info:
        Scenario.load(path)
    assert str(path) in str(info.value)


def test_seed_tree_is_reproducible_and_independent() -> None:
    a, b, c = seed_tree(3), seed_tree(3), seed_tree(4)
    assert a.fmu_seed == b.fmu_seed != c.fmu_seed
    assert np.array_equal(a.objects.random(5), b.objects.random(5))
    assert not np.array_equal(seed_tree(3).objects.random(5), seed_tree(3).physics.random(5))


def test_perception_and_faults_round_trip_and_default_to_the_camera_model(tmp_path: Path) -> None:
    scenario = Scenario(
        perception=PerceptionConfig(position_noise_m=0.01, drop_rate=0.1, rate_hz=15.0),
        faults=FaultLevel(
            detection_dropout=((1.0, 2.0), (5.0, 6.5)),
            belt_stall=((3.0, 4.0),),
            controller_restart_at_s=(2.5,),
        ),
    )
    path = tmp_path / "faults.yaml"
    scenario.save(path)
    assert Scenario.load(path) == scenario
    assert Scenario().perception == PerceptionConfig()
    assert scenario.faults.stalled(3.0)
    assert scenario.faults.stalled(3.99)
    assert not scenario.faults.stalled(4.0)
    assert not scenario.faults.stalled(2.99)


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        ("perception: {rate_hz: 0}", r"perception\.rate_hz = 0\.0"),
        ("perception: {drop_rate: 1.5}", r"perception\.drop_rate = 1\.5"),
        ("perception: {noise: 0.1}", r"perception: unknown key 'noise'"),
        ("faults: {belt_stall: [[4, 3]]}", r"faults\.belt_stall\[0\] = \[4\.0, 3\.0\]"),
        ("faults: {detection_dropout: [[-1, 3]]}", r"faults\.detection_dropout\[0\]"),
        ("faults: {detection_dropout: [[1, 2, 3]]}", r"faults\.detection_dropout\[0\].*2 values"),
        ("faults: {controller_restart_at_s: [0]}", r"faults\.controller_restart_at_s\[0\] = 0\.0"),
        ("faults: {crash: true}", r"faults: unknown key 'crash'"),
    ],
)
def test_bad_perception_and_fault_values_name_the_key(
    tmp_path: Path, text: str, pattern: str
) -> None:
    path = tmp_path / "bad.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=pattern):
        Scenario.load(path)


def test_max_width_lets_only_narrow_objects_onto_the_belt() -> None:
    from interfaces.cell import default_cell
    from twin.builtin import builtin_dataset
    from twin.objects import load_dataset
    from twin.stream import Stream

    layouts = load_dataset(builtin_dataset(), ("concrete", "brick", "wood", "rubber"))
    narrow = sum(1 for lay in layouts for o in lay.objects if min(o.width_m, o.length_m) <= 0.065)
    assert 0 < narrow < sum(len(lay.objects) for lay in layouts)
    scenario = Scenario(
        objects=ObjectLevel(max_width_m=0.065), system=SystemLevel(repeat_images=False)
    )
    stream = Stream(layouts, scenario, default_cell().belt, seed_tree(0))
    widths = [min(p.spec.width_m, p.spec.length_m) for b in stream for p in b.placements]
    assert len(widths) == narrow
    assert max(widths) <= 0.065


def test_min_height_lets_only_tall_enough_objects_onto_the_belt() -> None:
    from interfaces.cell import default_cell
    from twin.builtin import builtin_dataset
    from twin.objects import load_dataset
    from twin.stream import Stream

    layouts = load_dataset(builtin_dataset(), ("concrete", "brick", "wood", "rubber"))
    tall = sum(1 for lay in layouts for o in lay.objects if o.height_m >= 0.02)
    assert 0 < tall < sum(len(lay.objects) for lay in layouts)
    scenario = Scenario(
        objects=ObjectLevel(min_height_m=0.02), system=SystemLevel(repeat_images=False)
    )
    stream = Stream(layouts, scenario, default_cell().belt, seed_tree(0))
    heights = [p.height_m for b in stream for p in b.placements]
    assert len(heights) == tall
    assert min(heights) >= 0.02


@pytest.mark.parametrize(
    ("text", "pattern"),
    [
        ("name: a\nseed: 1\nname: b\n", r":3: duplicate key 'name' \(first on line 1\)"),
        (
            "system:\n  belt_speed_mps: 0.3\n  prefill_m: 1.0\n  belt_speed_mps: 0.5\n",
            r":4: duplicate key 'belt_speed_mps' \(first on line 2\)",
        ),
        (
            "physics: {friction: {wood: [0.4, 0.5], wood: [0.5, 0.6]}}",
            r":1: duplicate key 'wood' \(first on line 1\)",
        ),
        ("faults:\n  belt_stall: [[1, 2]]\nfaults: {}\n", r":3: duplicate key 'faults'"),
    ],
)
def test_duplicate_keys_are_refused_with_key_and_line(
    tmp_path: Path, text: str, pattern: str
) -> None:
    path = tmp_path / "dup.yaml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=re.escape(str(path)) + pattern):
        Scenario.load(path)


def test_a_key_repeated_in_different_mappings_is_fine() -> None:
    text = (
        "objects: {height_ranges_m: {wood: [0.02, 0.05]}}\n"
        "physics: {friction: {wood: [0.4, 0.5]}}\n"
    )
    scenario = Scenario.from_yaml(text)
    assert scenario.objects.height_ranges_m == {"wood": (0.02, 0.05)}
    assert scenario.physics.friction == {"wood": (0.4, 0.5)}


@pytest.mark.parametrize(
    "name", ["", ".", "..", "...", "../escape", "a/../../b", "/tmp/abs", "a/b", "a\\b", "a\0b"]
)
def test_a_name_that_would_leave_the_runs_folder_is_refused(name: str) -> None:
    with pytest.raises(ConfigError, match=r"name = .*: must be a plain folder name"):
        Scenario(name=name)
    text = "name: " + json.dumps(name)
    with pytest.raises(ConfigError, match=r"where\.yaml: name = .*: must be a plain folder name"):
        Scenario.from_yaml(text, where="where.yaml")


@pytest.mark.parametrize("name", ["dense", "speed_0.4", "v1..2", ".hidden", "run 2"])
def test_plain_names_are_accepted(name: str) -> None:
    assert Scenario(name=name).name == name
