"""The shared progress bar: counts and time left on a terminal, nothing at all in logs."""

from __future__ import annotations

import io

from rich.console import Console

from adaptenv.progress import ProgressBar


def test_bar_draws_counts_and_time_left_on_a_terminal():
    out = io.StringIO()
    console = Console(file=out, force_terminal=True, width=100)
    with ProgressBar("rollouts", 5, console=console) as bar:
        assert bar.active
        for _ in range(3):
            bar.advance()
        bar._bar.refresh()
    text = out.getvalue()
    assert "rollouts" in text and "3/5" in text and "left" in text


def test_bar_is_silent_when_not_a_terminal(capsys):
    with ProgressBar("rollouts", 5) as bar:  # stderr is captured: not a terminal
        assert not bar.active
        bar.advance(5)
        bar.update(5, description="done")
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err == ""


def test_no_description_or_empty_total_means_no_bar():
    console = Console(file=io.StringIO(), force_terminal=True)
    assert not ProgressBar(None, 5, console=console).active
    assert not ProgressBar("x", 0, console=console).active
    assert ProgressBar("x", None, console=console).active  # indeterminate: elapsed time only
