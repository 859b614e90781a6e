"""Progress bars for every step longer than a couple of seconds: a rich bar on a terminal, nothing in logs.

One bar shows what is running, a bar, the count done of the total, the time elapsed and the time
left. When stderr is not a terminal (a log file, a pipe, CI) the bar draws nothing at all, so logs
keep only the lines commands print on purpose.

Example:
    >>> with ProgressBar("rollouts", total=len(jobs)) as bar:  # doctest: +SKIP
    ...     for job in jobs:
    ...         run(job)
    ...         bar.advance()
"""

from __future__ import annotations

from types import TracebackType

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)


class ProgressBar:
    """A context manager around one rich progress bar on stderr (or ``console``), silent when not a terminal.

    Args:
        desc: what is running; None disables the bar (handy for library calls that take an optional label).
        total: how many units of work; None shows an indeterminate bar with the elapsed time only.
        console: where to draw (default: stderr).
        transient: erase the bar when done (True) or leave the finished bar on screen.
    """

    def __init__(self, desc: str | None, total: float | None = None, *, console: Console | None = None,
                 transient: bool = True):
        self._bar: Progress | None = None
        self._task: TaskID | None = None
        console = console or Console(stderr=True)
        if desc is None or (total is not None and total <= 0) or not console.is_terminal:
            return
        self._bar = Progress(TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
                             TimeElapsedColumn(), TextColumn("left"), TimeRemainingColumn(),
                             console=console, transient=transient)
        self._task = self._bar.add_task(desc, total=total)

    @property
    def active(self) -> bool:
        """Whether a bar is drawn (a terminal and a description)."""
        return self._bar is not None

    def start(self) -> ProgressBar:
        """Start drawing (``with ProgressBar(...)`` does this); returns the bar."""
        if self._bar is not None:
            self._bar.start()
        return self

    def stop(self) -> None:
        """Stop drawing (idempotent)."""
        if self._bar is not None:
            self._bar.stop()

    def __enter__(self) -> ProgressBar:
        return self.start()

    def advance(self, n: float = 1) -> None:
        """Count ``n`` more units done."""
        if self._bar is not None:
            self._bar.advance(self._task, n)

    def update(self, completed: float | None = None, *, total: float | None = None,
               description: str | None = None) -> None:
        """Set the units done (absolute), the total, or the description."""
        if self._bar is not None:
            self._bar.update(self._task, completed=completed, total=total, description=description)

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.stop()
