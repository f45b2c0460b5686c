"""The paper's constants, in one place (Yildirim, Saeed et al., CogSci 2019).

Every module that needs one of these imports it from here; none is written twice.
This module is on the ground floor of the project: it imports nothing of it.
"""
from __future__ import annotations

#: Edge of a 1-inch wooden cube [paper: "1-inch cubes"], metres: the block size d.
BLOCK_SIZE = 0.0254

#: The 24 trials in the paper's order (Figure 1): 12 easy/hard pairs.
PAIRS: tuple[int, ...] = tuple(range(1, 13))
LEVELS: tuple[str, ...] = ("E", "H")
TRIAL_IDS: tuple[str, ...] = tuple(f"{pair}{level}" for pair in PAIRS for level in LEVELS)

#: Random initial layouts of A per trial [paper: M = 30]; these are the `samples`
#: of every API and command line.
SAMPLES = 30
#: Noisy simulations per trial and sigma [paper: N = 100]; `n_sims` everywhere.
N_SIMS = 100
#: Simulated time of a noisy run [paper, footnote 1], s.
DURATION = 4.0
#: The sigma grid of the fit [paper: 0.05 d to 0.10 d in steps of 0.005 d].
SIGMA_GRID: tuple[float, ...] = tuple(round(0.05 + 0.005 * k, 3) for k in range(11))
#: The sigma the paper chose for all datasets ("sigma = 0.065").
PAPER_SIGMA = 0.065
#: A grid past the paper's (beyond the paper): 0.05 d to 0.30 d in steps
#: of 0.01 d, plus the paper's points, sorted. At the paper's grid most risks are 0;
#: the paper's risk contrasts appear past it (docs/results.md, "Pairs over sigma").
WIDE_SIGMA_GRID: tuple[float, ...] = tuple(sorted({round(0.05 + 0.01 * k, 3) for k in range(26)} | set(SIGMA_GRID)))
#: The named sigma grids (`--sigma-grid NAME`); "paper" is the default everywhere.
SIGMA_GRIDS: dict[str, tuple[float, ...]] = {"paper": SIGMA_GRID, "wide": WIDE_SIGMA_GRID}
#: Bootstrap resamples of participants [paper: 1000].
N_BOOT = 1000

#: Where B is built on the table (stimuli-spec.md; a reconstruction), x, y in m.
BUILD_SITE: tuple[float, float] = (0.35, 0.0)

#: Colours a block may have (stimuli-spec.md) and how every view draws them (r, g, b in 0..1).
COLOURS: tuple[str, ...] = ("natural", "green", "yellow", "blue", "red")
DISPLAY_RGB: dict[str, tuple[float, float, float]] = {
    "natural": (0.85, 0.70, 0.49),
    "green": (0.23, 0.61, 0.28),
    "yellow": (0.94, 0.81, 0.17),
    "blue": (0.21, 0.39, 0.79),
    "red": (0.80, 0.20, 0.20),
}


def display_hex(colour: str) -> str:
    """The display colour of a block colour as ``#rrggbb``."""
    r, g, b = DISPLAY_RGB[colour]
    return f"#{round(r * 255):02x}{round(g * 255):02x}{round(b * 255):02x}"


def canonical_trial_id(text: str) -> str:
    """A trial id in its one spelling: surrounding spaces dropped, letters upper-cased.

    Trial ids are case-insensitive everywhere (command lines, `stimuli.load_trial`,
    the human-data loader): ``" 7h"`` is ``"7H"``. Whether the id names a trial is
    the caller's check (e.g. ``canonical_trial_id(t) in TRIAL_IDS``).
    """
    return str(text).strip().upper()


#: The pairs whose easy and hard trials differ in risk by design (paper, Stimuli:
#: 4 staircase vs aligned tower, 5 bridge vs pyramid, 7 tower vs line, 8): the
#: paper's four risk contrasts, H riskier than E.
RISK_PAIRS: tuple[int, ...] = (4, 5, 7, 8)
