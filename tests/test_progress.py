"""Progress output: one live bar on a terminal, a short line every few percent in a log."""

from __future__ import annotations

import io

from ipp_toolkit.runs.progress import LineProgress, progress_bar


def test_a_log_gets_one_short_line_every_five_percent():
    stream = io.StringIO()
    bar = progress_bar(200, "evaluate", "missions", file=stream)
    assert isinstance(bar, LineProgress)
    with bar:
        for _ in range(200):
            bar.update(1)
    lines = stream.getvalue().splitlines()
    assert "\r" not in stream.getvalue()
    assert len(lines) == 21  # where it starts, then 5 %, 10 %, ..., 100 %
    # A line at once: the first 5 % can take minutes, and the log would stay empty.
    assert lines[0].startswith("evaluate: 0% (0/200 missions, ")
    assert lines[1].startswith("evaluate: 5% (10/200 missions, ")
    assert lines[-1].startswith("evaluate: 100% (200/200 missions, ")


def test_a_resumed_run_counts_from_where_it_stopped_and_shows_its_postfix():
    stream = io.StringIO()
    bar = LineProgress(10, "COMA", "updates", initial=8, every=5.0, file=stream)
    bar.set_postfix(val_H="0.300")
    bar.update(1)
    bar.update(1)
    lines = stream.getvalue().splitlines()
    assert lines[0].startswith("COMA: 80% (8/10 updates, ")  # where the resumed run starts
    assert lines[1].startswith("COMA: 90% (9/10 updates") and lines[1].endswith("val_H=0.300)")
    assert lines[-1].startswith("COMA: 100% (10/10 updates")


def test_disabled_progress_prints_nothing():
    stream = io.StringIO()
    with progress_bar(5, "x", "missions", disable=True, file=stream) as bar:
        bar.update(5)
    assert stream.getvalue() == ""


def test_a_finished_count_prints_no_start_line():
    stream = io.StringIO()
    LineProgress(4, "evaluate", "missions", initial=4, file=stream).close()
    assert stream.getvalue() == ""  # nothing left to do (a rerun that reuses every mission)
