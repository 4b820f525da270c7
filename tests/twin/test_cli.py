"""The ``cdw-twin`` entry point: every subcommand listed, only the one run is imported."""

from __future__ import annotations

import subprocess
import sys

import pytest

from twin.cli import COMMANDS, build_parser, selected_command


def test_selected_command_takes_the_longest_words_argv_starts_with() -> None:
    assert selected_command(["bench", "sweep", "--json"]) == ("bench", "sweep")
    assert selected_command(["twin-node", "--mode", "lockstep"]) == ("twin-node",)
    assert selected_command(["bench"]) is None
    assert selected_command(["--help"]) is None
    assert selected_command(["sweeps"]) is None


def test_selected_command_prefers_the_longest_match(monkeypatch: pytest.MonkeyPatch) -> None:
    longer = (("fmu",), "twin.bench_fmu", "a shorter command listed first")
    monkeypatch.setattr("twin.cli.COMMANDS", (longer, *COMMANDS))
    assert selected_command(["fmu", "build", "--help"]) == ("fmu", "build")
    assert selected_command(["fmu", "--help"]) == ("fmu",)


def test_a_process_imports_only_the_module_of_its_subcommand() -> None:
    code = (
        "import sys\n"
        "from twin.cli import COMMANDS, build_parser\n"
        "args = build_parser(('sample',)).parse_args(['sample', '--out', 'x'])\n"
        "print(args._module)\n"
        "print(sorted(m for _, m, _ in COMMANDS if m in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], check=True, capture_output=True, text=True
    ).stdout.splitlines()
    assert out == ["meshgen.cmd_sample", "['meshgen.cmd_sample']"]


def test_every_subcommand_is_listed_and_the_selected_one_keeps_its_options(
    capsys: pytest.CaptureFixture[str],
) -> None:
    with pytest.raises(SystemExit):
        build_parser(("sample",)).parse_args(["--help"])
    listing = capsys.readouterr().out
    for words, _, _ in COMMANDS:
        assert words[0] in listing
    with pytest.raises(SystemExit) as exc:
        build_parser(("sample",)).parse_args(["sample", "--out", "x", "--no-such-option"])
    assert exc.value.code == 2
    assert "--no-such-option" in capsys.readouterr().err
    full = build_parser().parse_args(["run", "scenario.yaml", "--episodes", "2"])
    lazy = build_parser(("run",)).parse_args(["run", "scenario.yaml", "--episodes", "2"])
    assert vars(full) == vars(lazy)
