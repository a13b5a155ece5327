"""The progress bar of long runs (report/progress.py): shown only when enabled and after its delay, transient."""
from __future__ import annotations

from mechsys.report.progress import ProgressBar


def test_bar_appears_after_the_delay_and_goes_away(capsys):
    bar = ProgressBar(10.0, delay=0.0, enabled=True)
    for t in (1.0, 5.0, 10.0, 12.0):  # past the end is clamped
        bar(t)
    assert bar._progress is not None
    assert bar._progress.tasks[0].completed == 10.0
    bar.close()
    assert bar._progress is None
    bar.close()  # closing twice is harmless
    assert bar.updates == 4


def test_bar_stays_hidden_when_disabled_or_before_the_delay(capsys):
    off = ProgressBar(10.0, delay=0.0, enabled=False)
    off(3.0)
    late = ProgressBar(10.0, delay=3600.0, enabled=True)
    late(3.0)
    assert off._progress is None and late._progress is None
    assert off.updates == late.updates == 1
    off.close()
    late.close()
    assert capsys.readouterr().err == ""
