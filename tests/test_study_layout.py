"""The study fits the participant's screen: a phone (390x844, and 360 px wide), laptops
(1280x720, 1366x768) and a desktop (1920x1080).

The suite's Difficulty Estimation and Time Estimation studies (`python -m
stimuli.experiment`, built once per suite run: conftest.suite_studies) are opened in headless Chromium (Debian's, via
playwright) from the local file with every network request refused. On each screen
size the test goes through the two anchors and the first trial and checks what docs/experiment.md promises:
nothing is wider than the window (no horizontal scroll); both pictures and the slider
lie inside it; Start is above Finish on a phone and beside it on a laptop; every part
of the trial, Next included, is visible without scrolling; the slider is answered by a
tap (touch screens) or by the arrow keys (laptops), which enables Next and removes
"Move the slider to answer.". Skipped, saying why, when the browser or playwright is
missing. LGP_SCREENSHOTS=DIR keeps a screenshot of each screen size: the docs'
study_trial_<W>x<H>.png are made so (the suite's studies have the study's own
picture size, 960x640).
"""
from __future__ import annotations

import pytest

from offline_browser import chromium, keep_screenshot, offline_page

pytestmark = pytest.mark.slow

#: (width, height, touch screen) of the screens checked.
SCREENS = ((390, 844, True), (360, 640, True), (1280, 720, False), (1366, 768, False), (1920, 1080, False))

_MEASURE = """() => {
  const box = s => { const r = document.querySelector(s).getBoundingClientRect();
                     return {left: r.left, right: r.right, top: r.top, bottom: r.bottom, width: r.width}; };
  return {scrollWidth: document.documentElement.scrollWidth, scrollHeight: document.documentElement.scrollHeight,
          start: box('.lgp-start'), finish: box('.lgp-finish'), slider: box('.jspsych-slider'),
          labels: box('.lgp-labels'), next: box('#jspsych-html-slider-response-next'), question: box('.lgp-question'),
          nextDisabled: document.querySelector('#jspsych-html-slider-response-next').disabled,
          message: document.getElementById('lgp-value').textContent,
          messageVisible: getComputedStyle(document.getElementById('lgp-value')).visibility === 'visible',
          value: document.querySelector('.jspsych-slider').valueAsNumber};
}"""


@pytest.fixture(scope="module")
def studies(suite_studies):
    """The Difficulty and Time Estimation studies with pictures of conftest.STUDY_SIZE
    (960x640, the study's own, or LGP_STUDY_LAYOUT_SIZE), built once per suite run (conftest.suite_studies)."""
    return suite_studies


@pytest.fixture(scope="module")
def browser():
    with chromium() as b:
        yield b


def _first_trial(browser, folder, width, height, touch, participant=0):
    page, errors, refused = offline_page(browser, viewport={"width": width, "height": height},
                                         has_touch=touch, is_mobile=touch)
    page.goto((folder / "index.html").resolve().as_uri() + f"?participant={participant}&simulated=1")
    page.click("#jspsych-instructions-next")
    page.click("#jspsych-instructions-next")
    page.wait_for_selector("#jspsych-html-slider-response-response")
    page.wait_for_function("Array.from(document.querySelectorAll('.lgp-pair img')).every(i => i.complete && i.naturalWidth > 0)")
    return page, errors, refused


def _inside(box, width):
    return box["left"] >= 0 and box["right"] <= width + 0.5


@pytest.mark.parametrize("width,height,touch", SCREENS, ids=[f"{w}x{h}" for w, h, _ in SCREENS])
def test_a_trial_fits_the_screen_and_its_slider_answers_a_tap_or_a_key(browser, studies, width, height, touch):
    """The two anchors and the first trial (participant 3: 5H, a tower beside a pyramid)."""
    page, errors, refused = _first_trial(browser, studies["difficulty"], width, height, touch, participant=3)
    for screen, tid in enumerate(("ANCHOR-EASY", "ANCHOR-HARD", "5H")):
        page.wait_for_function(f"document.querySelector('.lgp-pair').dataset.trial === '{tid}'")
        page.wait_for_function("Array.from(document.querySelectorAll('.lgp-pair img')).every(i => i.complete && i.naturalWidth > 0)")
        m = page.evaluate(_MEASURE)
        if tid == "5H":
            keep_screenshot(page, f"study_trial_{width}x{height}.png")
        assert m["scrollWidth"] <= width, f"{tid}: the page is {m['scrollWidth']} px wide in a {width} px window"
        for part in ("start", "finish", "slider", "labels", "next"):
            assert _inside(m[part], width), f"{tid}: {part} reaches outside the {width} px window: {m[part]}"
        if width < 700:  # a phone: Start above Finish, each nearly the window's width
            assert m["start"]["bottom"] <= m["finish"]["top"] and m["start"]["width"] >= min(0.8 * width, 300)
        else:  # a laptop or a desktop: side by side, each at least 30 % of the window's width
            assert m["start"]["right"] <= m["finish"]["left"] and abs(m["start"]["top"] - m["finish"]["top"]) < 1
            assert m["start"]["width"] >= 0.3 * width
        assert m["next"]["bottom"] <= height, f"{tid}: Next ends at {m['next']['bottom']:.0f} px, below the {height} px window"
        assert m["scrollHeight"] <= height
        assert m["nextDisabled"] and m["messageVisible"] and m["message"] == "Move the slider to answer."

        if touch:  # a tap on the slider's track answers (at the tapped place) and enables Next
            box = m["slider"]
            page.touchscreen.tap(box["left"] + 0.8 * box["width"], (box["top"] + box["bottom"]) / 2)
        else:  # keyboard: the slider takes the focus and an arrow key moves it by one step
            page.focus(".jspsych-slider")
            page.keyboard.press("ArrowRight")
        after = page.evaluate(_MEASURE)
        assert not after["nextDisabled"]
        assert not after["messageVisible"], "'Move the slider to answer.' is still shown after an answer"
        if touch:
            assert 70 <= after["value"] <= 90
        else:
            assert after["value"] == 51
        page.click("#jspsych-html-slider-response-next")
    assert errors == [] and refused == []
    page.context.close()


def test_the_time_slider_fits_a_phone_and_shows_the_estimate_once_moved(browser, studies):
    page, errors, refused = _first_trial(browser, studies["time"], 360, 640, True)
    m = page.evaluate(_MEASURE)
    assert m["scrollWidth"] <= 360 and _inside(m["labels"], 360) and _inside(m["slider"], 360)
    assert m["message"] == "Move the slider to your estimate."
    box = m["slider"]
    page.touchscreen.tap(box["left"] + box["width"] * 0.25, (box["top"] + box["bottom"]) / 2)
    after = page.evaluate(_MEASURE)
    assert not after["nextDisabled"] and after["messageVisible"]
    s = after["value"]
    assert after["message"] == (f"about {s // 60} min {s % 60} s" if s >= 60 else f"about {s} s")
    assert errors == [] and refused == []
    page.context.close()
