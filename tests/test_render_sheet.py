"""The rendered contact sheet (stimuli.render.contact_sheet, the picture stimuli.design
writes of its set): every trial's A and B side by side with white between them, and
no two pictures touch. Flat-coloured stand-in pictures (one colour each) make each
picture's extent on the sheet readable pixel by pixel."""
from __future__ import annotations

import json

import numpy as np
from PIL import Image

from stimuli import render
from stimuli.render import run


def _renders(folder, trials, size=(96, 64)):
    """A renders.json and flat pictures as render_trials writes them; {file: colour}."""
    colours, pictures = {}, []
    for k, tid in enumerate(trials):
        for j, state in enumerate(("A", "B")):
            colour = (40 + 9 * k, 90 + 60 * j, 200 - 7 * k)
            name = f"{tid}-{state}.png"
            Image.new("RGB", size, colour).save(folder / name)
            colours[name] = colour
            pictures.append({"trial": tid, "state": state, "file": name})
    (folder / "renders.json").write_text(json.dumps({"camera": {"width": size[0], "height": size[1]}, "pictures": pictures}))
    return colours


def _runs(line: np.ndarray) -> list[tuple[tuple, int, int]]:
    """(colour, first pixel, length) of each run of one colour along a row or column of pixels."""
    out, start = [], 0
    for x in range(1, len(line) + 1):
        if x == len(line) or tuple(line[x]) != tuple(line[start]):
            out.append((tuple(int(v) for v in line[start]), start, x - start))
            start = x
    return out


def test_a_and_b_of_each_trial_and_neighbouring_trials_are_separated_by_white(tmp_path):
    trials = [f"D{k:02d}" for k in range(1, 7)]  # 6 trials on 4 columns: two rows, the second half full
    colours = _renders(tmp_path, trials)
    thumb = 80
    sheet = np.asarray(Image.open(render.contact_sheet(tmp_path, tmp_path / "sheet.png", columns=4, thumb=thumb)))
    h = round(thumb * 64 / 96)
    white = (255, 255, 255)
    for r, row_trials in enumerate((trials[:4], trials[4:])):
        y = r * (h + run.SHEET_LABEL + run.SHEET_AB_GAP) + run.SHEET_LABEL + h // 2  # through the middle of the pictures
        runs = _runs(sheet[y])
        shown = [(c, x, n) for c, x, n in runs if c in colours.values()]
        expected = [colours[f"{t}-{s}.png"] for t in row_trials for s in "AB"]
        assert [c for c, _, _ in shown] == expected  # each picture once, in order A, B, A, B ...
        assert all(n == thumb for _, _, n in shown)  # whole, not overdrawn by a neighbour
        for (c0, x0, n0), (c1, x1, _) in zip(shown, shown[1:]):
            between = [c for c, x, n in runs if x0 + n0 <= x < x1]
            gap = x1 - (x0 + n0)
            assert between and between[0] == white and between[-1] == white, (c0, c1, between)  # never touching
            same_trial = expected.index(c1) % 2 == 1
            assert gap == (run.SHEET_AB_GAP if same_trial else run.SHEET_TRIAL_GAP), (c0, c1, gap)
    # and rows do not touch either: white between the bottom of row 1's pictures and row 2's labels
    x = thumb // 2
    column = [(c, y, n) for c, y, n in _runs(sheet[:, x]) if c in colours.values()]
    assert len(column) == 2 and column[1][1] - (column[0][1] + column[0][2]) == run.SHEET_AB_GAP + run.SHEET_LABEL
