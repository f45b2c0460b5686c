"""`lgp.reproduce --sigma-from FILE`: a noise sigma measured on another lab's data
(the summary.json of `python -m analysis.mental_jenga`, docs/mental-jenga.md), put
beside the run's own sigma: the risk is simulated at it too and the report gets a
section with the pair table at that sigma."""
from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

from lgp.errors import InputError

#: The summary's noise rule whose sigma is in the paper's unit (a fraction of the
#: block's edge along each perturbed axis).
PAPER_RULE = "paper-3d"


@dataclass(frozen=True)
class SigmaFrom:
    """The sigma (paper's unit, x d) another lab's data imply, its 95% interval and where it came from."""

    sigma: float
    interval: tuple[float, float]
    held_out_r: float
    experiment: int
    source: str


def read_sigma_from(path: str | Path) -> SigmaFrom:
    """The paper-unit sigma of a summary.json; InputError naming the file and the problem."""
    from lgp.inputs import InputFileError, read_bounded

    try:
        data = json.loads(read_bounded(path, 2_000_000, "summary file").decode("utf-8"))
        rule = data["rules"][PAPER_RULE]
        sigma = float(rule["best_sigma"])
        lo, hi = (float(v) for v in rule["best_sigma_interval_95"])
        r = float(rule.get("held_out_r", float("nan")))
        experiment = int(data.get("experiment", 0))
    except InputFileError as e:
        raise InputError(f"--sigma-from {path}: {e}") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(f"--sigma-from {path}: not valid JSON ({e})") from None
    except (KeyError, TypeError, ValueError) as e:
        raise InputError(f"--sigma-from {path}: not a summary.json of analysis.mental_jenga with a {PAPER_RULE!r} "
                         f"sigma ({type(e).__name__}: {e})") from None
    if not (math.isfinite(sigma) and 0 <= sigma <= 1):
        raise InputError(f"--sigma-from {path}: sigma {sigma} is not in [0, 1] (units of d)")
    return SigmaFrom(sigma, (lo, hi), r, experiment, str(path))


def grid_with(sigmas: tuple[float, ...], link: SigmaFrom) -> tuple[float, ...]:
    """The run's sigma grid with the linked sigma added (a zero sigma adds nothing: no noise, no risk grid point)."""
    if link.sigma <= 0 or any(math.isclose(s, link.sigma) for s in sigmas):
        return tuple(sigmas)
    return tuple(sorted((*sigmas, link.sigma)))


def report_lines(link: SigmaFrom, run_sigma: float, fitted: float | None, pairs_text: str | None) -> list[str]:
    """The report's section: the linked sigma beside the run's (and the fitted one, with human data)."""
    lo, hi = link.interval
    lines = ["## Sigma from another lab's data (--sigma-from)", "",
             f"Mental Jenga experiment {link.experiment} (Zhou, Smith, Tenenbaum & Gerstenberg 2023), the paper's noise rule: "
             f"best sigma {link.sigma:g} d, 95% interval over participants [{lo:g}, {hi:g}] d, held-out r {link.held_out_r:.2f} "
             f"({link.source}). This run's pair table uses sigma {run_sigma:g} d"
             + (f"; the sigma fitted to the difficulty ratings is {fitted:g} d" if fitted is not None else "")
             + f". The paper's grid is 0.05-0.10 d (0.065 d {'inside' if lo <= 0.065 <= hi else 'outside'} the interval).", ""]
    if pairs_text is None:
        lines += ["No pair table at this sigma: " + ("it is zero (no noise, so no risk)." if link.sigma <= 0
                                                     else "the run lacks the paper's 24 trials."), ""]
    else:
        lines += [f"Pairs at sigma = {link.sigma:g} d:", "", pairs_text, ""]
    return lines


@dataclass(frozen=True)
class SigmaBeside:
    """The linked sigma beside the run's: the pair table's sigma, the sigma fitted to
    the human data (None without them) and the pair table at the linked sigma (None
    when it is zero)."""

    link: SigmaFrom
    run_sigma: float
    fitted: float | None
    pairs: object | None
    #: the dataset whose sigma `fitted` is (the first row of the analysis's sigma_choice)
    fitted_to: str = ""


class _Stage:
    name, phase = "sigma_from", "analysis"

    def enabled(self, config) -> bool:
        return bool(config.sigma_from)

    def run(self, ctx):
        from analysis.pairs import pair_orderings
        core = ctx.core
        if not core["paper"]:
            return None
        link = read_sigma_from(ctx.config.sigma_from)
        at = pair_orderings(core["paper_effort"], core["paper_risk"], link.sigma, core["pair_names"]) if link.sigma > 0 else None
        choice = core["analysis"].get("sigma_choice")
        fitted = float(choice["sigma"].iloc[0]) if hasattr(choice, "columns") and len(choice) and "sigma" in choice else None
        return SigmaBeside(link, core["sigma"], fitted, at, str(choice["dataset"].iloc[0]) if fitted is not None else "")


STAGE = _Stage()
