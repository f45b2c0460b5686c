"""No script from a trial file runs in a page: the replay's
caption puts the trial's description into a <script> as JSON, which must not let
``</script><script>alert(2)</script>`` close the element. Checked by reading the
HTML and by opening it in headless Chromium (no dialog may fire, and the
caption's own script must still run and show the text as text)."""
from __future__ import annotations

import json
import re
from types import SimpleNamespace

import numpy as np
import pytest

from lgp.app.view import caption_html, script_json
from offline_browser import chromium

EVIL = "</script><script>alert(2)</script><!-- & \u2028 \u2029 -->"


def _plan():
    """The least a caption reads of a plan: no actions, one block standing still."""
    t = np.linspace(0.0, 1.0, 21)
    return SimpleNamespace(t=t, tau=0.05, actions=[], p_WB={"b1": np.zeros((21, 3))},
                           initial=SimpleNamespace(blocks=[]))


def test_script_json_escapes_what_could_end_a_script_and_reads_back_the_same():
    text = script_json({"title": EVIL})
    assert not re.search(r"[<>&\u2028\u2029]", text)
    assert json.loads(text) == {"title": EVIL}


def test_the_replay_caption_holds_no_script_end_from_the_description():
    page = caption_html(_plan(), f"X1: {EVIL}")
    body = page[page.index("<script>") + len("<script>"): page.rindex("</script>")]
    assert "</script" not in body.lower() and "<script" not in body.lower() and "<!--" not in body


@pytest.mark.slow
def test_a_trial_description_with_a_script_runs_nothing_in_a_browser(tmp_path):
    path = tmp_path / "replay.html"
    path.write_text(f"<!DOCTYPE html><html><head><meta charset='utf-8'></head><body>"
                    f"{caption_html(_plan(), 'X1: ' + EVIL)}</body></html>")
    with chromium() as browser:
        page = browser.new_page()
        dialogs, errors = [], []
        page.on("dialog", lambda d: (dialogs.append(d.message), d.dismiss()))
        page.on("pageerror", lambda e: errors.append(str(e)))
        page.goto(path.resolve().as_uri())
        page.wait_for_timeout(400)  # the caption updates every 100 ms
        action = page.inner_text("#lgp-action")
        title = page.inner_text("#lgp-title")
    assert dialogs == [], f"a script from the description ran: alert({dialogs})"
    assert errors == []
    assert action == "nothing to move"  # the caption's own script ran
    assert "</script><script>alert(2)</script>" in title  # shown as text
