"""Progress of long runs: one live line on a terminal, a short line every few percent in a log.

tqdm redraws its bar with carriage returns, which is right on a terminal and floods a log
file (a run under ``nohup`` or in CI writes thousands of partial lines). :func:`progress_bar`
gives tqdm on a terminal and, when the stream is not one, a :class:`LineProgress` with the same
``update`` / ``set_postfix`` / ``close`` calls that prints one line as it starts, then one
each time another ``every`` percent is done (and at the end)::

    evaluate: 0% (0/200 missions, 0 s)
    evaluate: 25% (50/200 missions, 12 s)

How a long command ends early is here too: :func:`report_interrupt` (Ctrl-C, or SIGTERM
turned into :class:`Terminated` by :func:`sigterm_as_interrupt`) and :func:`run_reporting`, the
error and interrupt handling every trainer's ``main`` shares.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any

from tqdm import tqdm

__all__ = ["LineProgress", "Terminated", "continue_hint", "progress_bar", "report_interrupt",
           "run_reporting", "sigterm_as_interrupt"]


class LineProgress:
    """A tqdm stand-in for streams that are not terminals.

    Args:
        total: the count that is 100 %.
        desc: the name printed first.
        unit: what is counted (plural as printed).
        initial: already done (a resumed run).
        every: print a line each time this many more percent are done.
        file: the stream (default stderr).
    """

    def __init__(self, total: int, desc: str, unit: str, initial: int = 0, every: float = 5.0,
                 file: IO[str] | None = None) -> None:
        self.total = max(int(total), 0)
        self.n = int(initial)
        self.desc, self.unit, self.every = desc, unit, float(every)
        self.file = file if file is not None else sys.stderr
        self.start = time.monotonic()
        self.postfix = ""
        self._printed_percent = self._percent()
        self._closed = False
        if self.n < self.total:
            # A line at once, where it starts: the first ``every`` percent can take minutes
            # (a first run compiles, a slow planner's missions), and a log stays empty.
            self._print()

    def _percent(self) -> float:
        return 100.0 * self.n / self.total if self.total else 100.0

    def _print(self) -> None:
        elapsed = time.monotonic() - self.start
        extra = f", {self.postfix}" if self.postfix else ""
        print(f"{self.desc}: {self._percent():.0f}% ({self.n}/{self.total} {self.unit}, "
              f"{elapsed:.0f} s{extra})", file=self.file, flush=True)
        self._printed_percent = self._percent()

    def update(self, n: int = 1) -> None:
        self.n += int(n)
        if self._percent() - self._printed_percent >= self.every or (
                self.n >= self.total and self._printed_percent < 100.0):
            self._print()

    def set_postfix(self, **values: Any) -> None:
        self.postfix = " ".join(f"{k}={v}" for k, v in values.items())

    def close(self) -> None:
        self._closed = True

    def __enter__(self) -> LineProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def progress_bar(total: int, desc: str, unit: str, initial: int = 0, disable: bool = False,
                 file: IO[str] | None = None) -> tqdm | LineProgress:
    """tqdm on a terminal, :class:`LineProgress` otherwise; ``disable`` shows nothing."""
    stream = file if file is not None else sys.stderr
    if disable or stream.isatty():
        return tqdm(total=total, initial=initial, desc=desc, unit=unit, disable=disable,
                    dynamic_ncols=True, file=stream)
    return LineProgress(total, desc, unit, initial=initial, file=stream)


class Terminated(KeyboardInterrupt):
    """SIGTERM during a command's work (``kill PID``, a scheduler ending a job), raised where
    Ctrl-C raises KeyboardInterrupt, so the run stops the same orderly way: worker processes
    stopped, what is stored kept, one line saying how to continue."""


@contextlib.contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM raises :class:`Terminated` in the main thread instead of
    ending the process at once; the previous handler is restored after it. Elsewhere than in
    the main thread (where Python runs signal handlers) it changes nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def terminate(signum: int, frame: Any) -> None:
        raise Terminated()

    previous = signal.signal(signal.SIGTERM, terminate)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def report_interrupt(tool: str, how_to_continue: str,
                     interrupt: BaseException | None = None) -> int:
    """Ctrl-C in a long run: one line on stderr saying how to continue; returns 130 (SIGINT),
    or for a :class:`Terminated` ``interrupt`` says "terminated" and returns 143 (SIGTERM), as
    a shell reports the two signals.

    Args:
        tool: the command, e.g. ``ipp-compare``.
        how_to_continue: the rest of the sentence, e.g. ``continue with --resume --out RUN``.
        interrupt: the KeyboardInterrupt caught, if any.
    """
    terminated = isinstance(interrupt, Terminated)
    print(f"\n{tool}: {'terminated' if terminated else 'interrupted'}; {how_to_continue}",
          file=sys.stderr)
    return 143 if terminated else 130


def continue_hint(folder: str | os.PathLike[str], checkpoint: str, resume: str
                  ) -> Callable[[], str]:
    """How an interrupted training run goes on, for :func:`run_reporting`: ``resume`` (e.g.
    ``continue with --resume --out RUN``) where a ``checkpoint`` file (e.g. ``last.pt``) lies in
    ``folder`` or in a folder inside it (a recipe's stages); else that none was written yet,
    so the same command starts the run again (a rerun into such a folder starts afresh)."""

    def hint() -> str:
        root = Path(folder)
        if (root / checkpoint).is_file() or next(root.glob(f"*/{checkpoint}"), None):
            return resume
        return (f"no checkpoint was written yet in {os.fspath(folder)!r}: run the same command "
                "again (without --resume) to start afresh")

    return hint


def run_reporting(tool: str, work: Callable[[], int], how_to_continue: str | Callable[[], str],
                  errors: tuple[type[BaseException], ...] = ()) -> int:
    """Run a command's ``work`` and return its exit code, reporting how it ends early alike in
    every command: bad input as one line ``TOOL: error: MESSAGE`` and exit code 2, never a
    traceback; Ctrl-C as :func:`report_interrupt` (130), and SIGTERM likewise (143).

    Bad input is any ValueError: the limits' ``LimitError`` and a damaged checkpoint's
    ``CheckpointError`` are ValueErrors, so a limit refused anywhere in the work is reported as
    a bad flag is.

    Args:
        tool: the command, e.g. ``ipp-train ppo``.
        work: the command's work once its flags are parsed; returns its exit code.
        how_to_continue: the rest of the interrupt's sentence, or a function giving it (called
            only on an interrupt, so it may name what the work found out, e.g. its folder).
        errors: more exception types reported as bad input (``ConnectionError``: no Ray at
            ``--address``; ``FileExistsError``: a folder that holds a run).
    """
    try:
        with sigterm_as_interrupt():
            return work()
    except (ValueError, *errors) as error:
        print(f"{tool}: error: {error}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as interrupt:
        return report_interrupt(tool, how_to_continue if isinstance(how_to_continue, str)
                                else how_to_continue(), interrupt)
