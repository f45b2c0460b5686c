"""The results page and a 3-D replay, opened in a real browser.

A small `python -m lgp.reproduce --quick` run writes results/index.html and the
replays; headless Chromium (Debian's `chromium`, driven by `playwright` with
`executable_path`) opens them with every network request refused, as on a laptop
offline. Skipped, saying why, only when the browser or playwright is missing
(.ci/run installs both). Set LGP_SCREENSHOTS=DIR to keep the screenshots.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

from lgp.paper import TRIAL_IDS
from offline_browser import chromium, keep_screenshot, offline_page

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def browser():
    with chromium() as b:
        yield b


@pytest.fixture(scope="module")
def results(browser, quick_run) -> Path:
    """The session's small --quick run (conftest.QUICK_RUN: 24 trials, 4 sigmas up to 0.2)."""
    return quick_run


def _open(browser, path: Path):
    """A page at 1280x800 that records console errors and refuses every non-file request, at `path`, loaded."""
    page, errors, refused = offline_page(browser)
    page.goto(path.resolve().as_uri())
    page.wait_for_load_state("load")
    return page, errors, refused


def test_results_page_opens_offline_with_every_picture_pair_and_trial(browser, results):
    page, errors, refused = _open(browser, results / "index.html")
    images = page.evaluate("Array.from(document.images).map(i => [i.getAttribute('src'), i.complete ? i.naturalWidth : 0])")
    assert len(images) >= 24 + 1  # a picture per trial and at least one figure
    assert [src for src, width in images if width <= 0] == []
    assert page.locator("#pairs tr.pair-row").count() == 12
    cards = page.locator("article.card")
    assert cards.count() == 24
    assert page.evaluate("Array.from(document.querySelectorAll('article.card')).map(c => c.id)") == [f"trial-{t}" for t in TRIAL_IDS]
    # Every card links its replay, and every replay exists beside the page.
    links = page.evaluate("Array.from(document.querySelectorAll('a.replay')).map(a => a.getAttribute('href'))")
    assert links == [f"replays/{t}.html" for t in TRIAL_IDS]
    assert all((results / link).exists() for link in links)
    keep_screenshot(page, "results_page.png")
    # A link to a trial lands on its card.
    page.goto((results / "index.html").resolve().as_uri() + "#trial-7H")
    assert page.evaluate("document.querySelector(':target').id") == "trial-7H"
    keep_screenshot(page, "results_page_trial.png")
    assert errors == [] and refused == []
    page.close()


def test_pair_table_sorts_by_the_clicked_column(browser, results):
    page, errors, _ = _open(browser, results / "index.html")
    table = page.locator("#pairs table")
    col = page.evaluate("Array.from(document.querySelectorAll('#pairs th')).map(th => th.textContent).indexOf('effort_H')")
    assert col >= 0

    def column():
        return [float(v) for v in table.locator(f"tbody tr td:nth-child({col + 1})").evaluate_all("tds => tds.map(td => td.dataset.v)")]

    before = column()
    table.locator("th").nth(col).click()
    assert column() == sorted(before)
    table.locator("th").nth(col).click()
    assert column() == sorted(before, reverse=True)
    assert errors == []
    page.close()


def test_pairs_over_sigma_section_shows_every_pair_at_every_sigma_with_its_figure(browser, results):
    page, errors, refused = _open(browser, results / "index.html")
    section = page.locator("#over-sigma")
    assert section.count() == 1 and "Pairs over sigma" in section.locator("h2").inner_text()
    rows = section.locator("table.oversigma tbody tr")
    assert rows.count() == 4  # one per sigma of the run
    assert [rows.nth(k).get_attribute("class") for k in range(4)] == ["paper", "paper", "paper", ""]  # 0.2 d is past the grid
    assert section.locator("table.oversigma thead th").count() == 1 + 12 + 2
    assert section.locator("thead th.riskpair").evaluate_all("ths => ths.map(t => t.textContent)") == ["4", "5", "7", "8"]
    # every cell carries both intervals and the Eq. 1 range, and a starred cell is one whose intervals separate
    import pandas as pd

    over = pd.read_csv(results / "pairs_over_sigma.csv")
    cells = section.locator("tbody td[title]")
    assert cells.count() == 4 * 12
    first = cells.nth(0).get_attribute("title")
    assert "1E" in first and "1H" in first and "[" in first and "b2/b1" in first
    starred = section.locator("tbody td.holds").count()
    assert starred == int(over["holds"].sum())
    assert (over["holds"] == (over["risk_H_low"] > over["risk_E_high"])).all()
    width = section.locator("img").evaluate("i => i.complete ? i.naturalWidth : 0")
    assert width > 800
    # the trial cards say how careful one must be: sigma* at both levels
    card = page.locator("#trial-4H .precision").inner_text()
    assert "risk 0.5" in card and "risk 0.1" in card and "sigma*" in card
    keep_screenshot(page, "results_page_over_sigma.png", full_page=False)
    assert errors == [] and refused == []
    page.close()


def _hue_pixels(rgb: np.ndarray, colour, tol_deg: float = 8.0) -> int:
    """Pixels of `rgb` (h, w, 3 in 0..1) whose hue is within tol of `colour`'s, saturated and not dark.

    Lighting changes a face's brightness and whitens it a little; its hue stays.
    """
    from matplotlib.colors import rgb_to_hsv

    hsv = rgb_to_hsv(rgb.reshape(-1, 3))
    h0 = rgb_to_hsv(np.asarray(colour, float))[0]
    dh = np.abs(hsv[:, 0] - h0)
    dh = np.minimum(dh, 1 - dh)
    return int(((dh < tol_deg / 360) & (hsv[:, 1] > 0.3) & (hsv[:, 2] > 0.1)).sum())


def test_replay_renders_the_blocks_in_their_placement_colours(browser, results):
    from PIL import Image

    import stimuli
    from lgp.app.view import order_colours, placement_order
    from models.effort import plan_of_sample

    page, errors, refused = _open(browser, results / "replays" / "7H.html")
    page.wait_for_function("typeof viewer !== 'undefined' && viewer.animator.duration > 0", timeout=20000)
    page.wait_for_timeout(1500)
    caption = page.locator("#lgp-caption").inner_text()
    assert "7H" in caption and "action" in caption and "effort so far" in caption
    keep_screenshot(page, "replay_7H.png")
    # The end of the recording: the tower is built at the site; caption hidden, canvas only.
    page.evaluate("viewer.animator.pause(); viewer.animator.seek(viewer.animator.duration); viewer.render()")
    page.evaluate("document.getElementById('lgp-caption').style.display = 'none'")
    page.wait_for_timeout(500)
    shot = np.asarray(Image.open(io.BytesIO(page.locator("canvas").first.screenshot())).convert("RGB")) / 255.0
    assert errors == [] and refused == []
    page.close()

    h, w, _ = shot.shape
    assert shot.std() > 0.05, "the canvas is blank"
    centre = shot[h // 4: 3 * h // 4, w // 4: 3 * w // 4]
    plan = plan_of_sample(stimuli.load_trial("7H"), 0, 0)
    colours = order_colours(plan)
    order = placement_order(plan)
    found = [name for name in order if _hue_pixels(centre, colours[name]) >= 10]
    assert len(found) >= 0.7 * len(order), f"block colours seen in the centre: {found} of {order}"
    assert _hue_pixels(centre, (0.9, 0.1, 0.9)) < 10  # magenta is in no block: the check can fail


#: A number as a reader sees it on the page: not part of a word, a version or a date
#: (3.11.7, 2026-12-01 and trial ids like 10E are not numbers here).
_NUMBER = r"(?<![\w.\-/:])[-+]?(?:\d+\.\d+|\d+|\.\d+)(?:e[-+]?\d+)?(?![\w.\-/:]|\.\d)"


def significant_digits(text: str) -> int:
    """Significant digits of a number as written: 0.1159 -> 4, 2124 -> 4, 20000 -> 1, 4.2e-17 -> 2."""
    mantissa = text.lower().lstrip("+-").split("e")[0]
    if "." in mantissa:
        return len(mantissa.replace(".", "").lstrip("0")) or 1
    return len(mantissa.lstrip("0").rstrip("0")) or 1


def test_significant_digits_counts_as_a_reader_would():
    import re

    assert [significant_digits(t) for t in ("0.1159", "2124", "20000", "4.2e-17", "0.116", "0", "12.50")] == [4, 4, 1, 2, 3, 1, 4]
    found = re.findall(_NUMBER, "10E: 0.1159 J s, python 3.11.7, 2026-12-01 20:23 UTC, +126 %, 1.1e-16, sigma 0.065 d")
    assert found == ["0.1159", "+126", "1.1e-16", "0.065"]


def test_no_number_on_the_page_prints_more_than_four_significant_digits(browser, results):
    import re

    page, errors, _ = _open(browser, results / "index.html")
    # what a reader sees: the visible text, less the command line and file paths (code)
    text = page.evaluate("""(() => { const b = document.body.cloneNode(true);
        b.querySelectorAll('code, script, style, details:not([open]) > :not(summary)').forEach(e => e.remove());
        return b.innerText; })()""")
    long = sorted({n for n in re.findall(_NUMBER, text) if significant_digits(n) > 4})
    assert long == [], f"numbers with more than 4 significant digits: {long[:20]}"
    assert not re.search(r"\bnan\b", text, flags=re.I), "a raw nan on the page"
    assert "e-1" not in text, "round-off such as 4.2e-17 printed"
    assert errors == []
    page.close()


def test_every_navigation_link_resolves(browser, results):
    page, errors, _ = _open(browser, results / "index.html")
    hrefs = page.evaluate("Array.from(document.querySelectorAll('nav a, .trialnav a, .card h3 a')).map(a => a.getAttribute('href'))")
    assert len(hrefs) >= 24 + 5
    ids = set(page.evaluate("Array.from(document.querySelectorAll('[id]')).map(e => e.id)"))
    dead = [h for h in hrefs if (h[1:] not in ids if h.startswith("#") else not (results / h.split("#")[0]).exists())]
    assert dead == [], f"links that lead nowhere: {dead}"
    assert errors == []
    page.close()


def test_a_and_b_of_a_moved_tower_differ_on_the_page(browser, results):
    """10E moves a 4-block tower 10 cm: on one world frame its A and B pictures differ."""
    from PIL import Image

    page, errors, _ = _open(browser, results / "index.html")
    img = page.locator("#trial-10E img")
    assert img.evaluate("i => i.complete && i.naturalWidth") > 0
    shot = np.asarray(Image.open(io.BytesIO(img.screenshot())).convert("RGB"), dtype=float) / 255.0
    w = shot.shape[1] // 2
    differ = np.abs(shot[:, :w] - shot[:, w:2 * w]).max(axis=-1) > 0.1
    assert differ.mean() > 0.01, f"A and B of 10E look the same ({differ.mean():.2%} of pixels differ)"
    assert errors == []
    page.close()


def test_a_replay_links_back_to_its_card_and_has_a_visible_play_pause(browser, results):
    page, errors, refused = _open(browser, results / "replays" / "7H.html")
    page.wait_for_function("typeof viewer !== 'undefined' && viewer.animator.duration > 0", timeout=20000)
    back = page.locator("#lgp-back")
    assert back.is_visible() and back.get_attribute("href") == "../index.html#trial-7H"
    button = page.locator("#lgp-play")
    assert button.is_visible()
    playing = page.evaluate("viewer.animator.playing")
    button.click()
    assert page.evaluate("viewer.animator.playing") == (not playing)
    assert ("play" in button.inner_text()) == playing  # the label says what a click does next
    back.click()
    page.wait_for_load_state("load")
    assert page.url.endswith("index.html#trial-7H")
    assert page.evaluate("document.querySelector(':target').id") == "trial-7H"
    assert errors == [] and refused == []
    page.close()


@pytest.mark.parametrize("width, name", [(1280, "results_page.png"), (390, "results_page_phone.png")])
def test_the_page_fits_a_laptop_and_a_phone(browser, results, width, name):
    page = browser.new_page(viewport={"width": width, "height": 800 if width > 600 else 844})
    page.goto((results / "index.html").resolve().as_uri())
    page.wait_for_load_state("load")
    # nothing but wide tables (which scroll in their own box) pushes the page sideways
    overflow = page.evaluate("document.documentElement.scrollWidth - document.documentElement.clientWidth")
    assert overflow <= 2, f"the page is {overflow} px wider than a {width} px screen"
    assert page.locator("#quick").is_visible()  # a --quick page says it is a preview
    keep_screenshot(page, name)
    page.close()


def _wood_lean(shot: np.ndarray) -> float:
    """Sideways lean of the wooden tower in a picture (pixels): the mean column of its
    top block's rows minus that of its bottom block's rows (4 blocks)."""
    wood = (shot[:, :, 0] - shot[:, :, 2] > 25 / 255) & (shot[:, :, 0] > 60 / 255)
    vs, us = np.nonzero(wood)
    assert len(us) > 100, "no tower found in the picture"
    block = (vs.max() - vs.min()) / 4
    return float(us[vs < vs.min() + 0.6 * block].mean() - us[vs > vs.max() - 0.6 * block].mean())


def test_the_cards_of_4E_and_4H_show_a_column_and_a_staircase_large_enough_to_tell_apart(browser, results):
    """The Finish picture on each card is at least 250 px wide at 1280x800, and 4H's
    staircase (each block d/5 further in x) leans sideways where 4E's column does not,
    by more than 4 screen pixels."""
    from PIL import Image

    page, errors, _ = _open(browser, results / "index.html")
    lean, widths = {}, {}
    for tid in ("4E", "4H"):
        img = page.locator(f"#trial-{tid} img")
        img.scroll_into_view_if_needed()
        assert img.evaluate("i => i.complete && i.naturalWidth") > 0
        shot = np.asarray(Image.open(io.BytesIO(img.screenshot())).convert("RGB"), dtype=float) / 255.0
        half = shot.shape[1] // 2
        widths[tid] = half
        lean[tid] = _wood_lean(shot[int(0.1 * shot.shape[0]):, half:])  # B, below the label
    assert min(widths.values()) >= 250, widths
    assert lean["4H"] - lean["4E"] > 4, lean
    assert errors == []
    page.close()


def test_every_risk_mini_plot_spans_0_to_1_and_its_labels_are_readable(browser, results):
    page, errors, _ = _open(browser, results / "index.html")
    plots = page.evaluate("""Array.from(document.querySelectorAll('article.card svg.risk')).map(s =>
        [s.dataset.ymin, s.dataset.ymax, Array.from(s.querySelectorAll('text')).map(t => t.textContent)])""")
    assert len(plots) == 24
    assert all(lo == "0" and hi == "1" and "0" in texts and "1" in texts for lo, hi, texts in plots)
    sizes = page.evaluate("Array.from(document.querySelectorAll('article.card svg text')).map(t => parseFloat(getComputedStyle(t).fontSize))")
    assert min(sizes) >= 11
    text = page.locator("#trial-7H").inner_text()
    assert "riskruns" not in page.content()
    if "required precision" in text:
        assert "sigma*: the least noise" in text
    assert errors == []
    page.close()


def test_the_folder_works_when_copied_elsewhere(browser, results, tmp_path):
    """Every link of the page stays inside the output folder: a copy opens with every
    picture and the risk explanation it links (docs/risk.md carried as page/risk.html)."""
    import shutil

    copy = tmp_path / "elsewhere" / "results-copy"
    shutil.copytree(results, copy, ignore=shutil.ignore_patterns("cache"))
    page, errors, refused = _open(browser, copy / "index.html")
    hrefs = page.evaluate("Array.from(document.querySelectorAll('a[href], img[src]')).map(a => a.getAttribute('href') || a.getAttribute('src'))")
    local = [h.split("#")[0] for h in hrefs if not h.startswith("#") and h.split("#")[0]]
    assert [h for h in local if h.startswith("..") or h.startswith("/")] == []
    assert [h for h in local if not (copy / h).exists()] == []
    doc = page.evaluate("document.querySelector('.explain a').getAttribute('href')")
    assert doc == "page/risk.html"
    page.goto((copy / doc).resolve().as_uri())
    assert "common random numbers" in page.content().lower()
    assert errors == [] and refused == []
    page.close()


def test_a_replay_fits_a_phone(browser, results):
    page = browser.new_page(viewport={"width": 390, "height": 844}, is_mobile=True, has_touch=True)
    page.goto((results / "replays" / "7H.html").resolve().as_uri())
    assert page.evaluate("document.querySelector('meta[name=viewport]').content") == "width=device-width, initial-scale=1"
    assert page.evaluate("window.innerWidth") == 390  # the layout width is the screen's, not a 980 px desktop
    page.close()
