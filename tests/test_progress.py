"""The progress line: counts, rate and ETA on a terminal; one line per stage otherwise."""
import io

from lgp.app.progress import Progress


def test_not_a_terminal_prints_one_line_when_the_stage_ends():
    out = io.StringIO()
    with Progress("effort", 10, "plans", stream=out) as bar:
        for _ in range(10):
            bar.advance()
        assert out.getvalue() == ""  # nothing while it runs
    lines = out.getvalue().splitlines()
    assert len(lines) == 1 and lines[0].startswith("[effort] 10/10 plans in ")


def test_a_terminal_sees_a_bar_with_count_rate_and_eta_in_words(monkeypatch):
    monkeypatch.setenv("COLUMNS", "120")  # a wide terminal: the whole line fits (pytest-xdist workers see 80)
    monkeypatch.setenv("LINES", "24")
    out = io.StringIO()
    bar = Progress("risk", 100, "runs", stream=out, tty=True, interval=0.0, what="noisy runs of B")
    bar.advance(25)
    now = bar._bar._time()
    bar._bar._time = lambda: now  # the bar's clock stopped: no rate noise from a loaded machine
    bar._bar.start_t = now - 10.0  # started 10 s ago: 2.5 runs/s, so the 75 left take 30 s
    bar._bar.refresh()
    last = out.getvalue().split("\r")[-1]
    assert last.startswith("risk: noisy runs of B:  25%|") and "25/100 runs" in last, last
    assert "2.5 runs/s" in last and "ETA 30 s" in last, last
    bar.advance(75)
    bar.close()
    assert out.getvalue().endswith("\n") and "100/100 runs" in out.getvalue().split("\r")[-1]


def test_an_empty_stage_says_nothing():
    out = io.StringIO()
    Progress("effort", 0, "plans", stream=out).close()
    assert out.getvalue() == ""


def test_log_lines_go_above_the_bar_on_a_terminal(monkeypatch):
    import sys

    from lgp.app.progress import log

    out = io.StringIO()
    monkeypatch.setattr(sys, "stderr", out)
    bar = Progress("effort", 4, "plans", stream=out, tty=True, interval=0.0)
    bar.advance()
    log("[effort  1/2] 1E: done")
    text = out.getvalue()
    # the message on its own line, then the bar drawn again below it
    assert "[effort  1/2] 1E: done\n" in text
    assert text.rindex("effort:") > text.index("1E: done")
    bar.close()
    assert Progress.active is None
