"""``cdw-twin bench render`` times both renderers and says which one this machine uses."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from twin.cli import main


def test_the_render_benchmark_prints_its_figures_per_renderer(
    builtin_meshes: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["bench", "render", "--json", "--rounds", "2", "--objects", "8"]
    assert main([*args, "--dataset", str(builtin_meshes), "--renderers", "tiny,gl"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["default_renderer"] in ("gl", "tiny")
    renderers = set(result["figures"]) | set(result.get("unavailable", {}))
    assert renderers == {"gl", "tiny"}
    for cameras in result["figures"].values():
        assert set(cameras) == {"reference", "wide"}
        for sizes in cameras.values():
            assert set(sizes["640x480"]) == {"render_ms", "capture_ms"}
            assert set(sizes["320x240"]) == {"render_ms"}
            for stats in (*sizes["640x480"].values(), sizes["320x240"]["render_ms"]):
                assert 0.0 < stats["min"] <= stats["median"] <= stats["p90"]
    if "gl" in result["figures"]:
        assert result["gl_renderer"]
        assert result["objects_in_view"]["wide"] >= 1


def test_an_unknown_renderer_is_refused_naming_it(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["bench", "render", "--renderers", "gl,vulkan"]) == 2
    assert "'vulkan'" in capsys.readouterr().err
