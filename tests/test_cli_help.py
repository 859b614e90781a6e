"""Every command's --help reads well in an 80-column terminal; errors name the flag and print nothing before."""

from __future__ import annotations

import re

import pytest
import typer.main
from typer.testing import CliRunner

from adaptenv.cli import app
from adaptenv.errors import ConfigError

runner = CliRunner()


def command_paths(cmd, path: tuple[str, ...] = ()) -> list[tuple[str, ...]]:
    """Every command below ``cmd`` (a click command or group) as the words one types after ``adaptenv``."""
    out = [path]
    if hasattr(cmd, "commands"):
        for name, sub in cmd.commands.items():
            out += command_paths(sub, (*path, name))
    return out


PATHS = command_paths(typer.main.get_command(app))


def test_every_command_is_listed():
    assert ("train",) in PATHS and ("houses", "generate") in PATHS and ("bench", "adapt") in PATHS


@pytest.mark.parametrize("path", PATHS, ids=lambda p: " ".join(p) or "adaptenv")
def test_help_fits_80_columns_without_type_noise(path):
    result = runner.invoke(app, [*path, "--help"], env={"COLUMNS": "80"})
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[0].startswith("Usage: ")
    assert max(len(line) for line in lines) <= 80
    assert "<bool>" not in result.output
    # the help text uses the width: every description starts within the first 34 columns (click's layout)
    starts = [m.start(2) for line in lines if (m := re.match(r"^  (-\S.*?)\s{2,}(\S.*)$", line))]
    assert all(start <= 34 for start in starts), starts


def test_train_help_is_short():
    result = runner.invoke(app, ["train", "--help"], env={"COLUMNS": "80"})
    lines = result.output.splitlines()
    options = sum(line.lstrip().startswith("--") for line in lines)
    assert options > 30 and len(lines) < 3 * options  # under 3 lines an option; was 181 lines with the rich option table


@pytest.mark.parametrize(("args", "flag"), [(["--preset", "nope"], "--preset"), (["--rooms", "11"], "--rooms"),
                                            (["--n", "0"], "--n")])
def test_houses_generate_errors_name_the_flag_and_print_nothing_first(args, flag, tmp_path):
    result = runner.invoke(app, ["houses", "generate", *args, "-o", str(tmp_path / "h")])
    assert isinstance(result.exception, ConfigError)
    assert str(result.exception).startswith(flag + ":")
    assert result.output == ""


def test_houses_generate_help_names_every_preset():
    from adaptenv.scene.procedural import PRESETS

    result = runner.invoke(app, ["houses", "generate", "--help"], env={"COLUMNS": "80"})
    assert result.exit_code == 0, result.output
    listed = set(re.findall(r"[\w-]+", result.output))
    assert set(PRESETS) <= listed, sorted(set(PRESETS) - listed)


def test_a_group_without_its_command_still_prints_its_help():
    result = runner.invoke(app, ["houses"], env={"COLUMNS": "80"})
    lines = result.output.splitlines()
    assert lines[0] == "Usage: adaptenv houses [OPTIONS] COMMAND [ARGS]..." and "generate" in result.output, result.output


def test_a_usage_error_is_one_line_naming_the_flag_not_the_usage():
    result = runner.invoke(app, ["render", "--size", "12"])
    assert result.exit_code == 2
    assert result.stderr.splitlines() == ["error: --size 12: must be a whole number from 256 to 8192; pass a number in "
                                          "that range"], result.stderr
