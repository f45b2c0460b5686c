"""analysis.power's inputs: the trials a SIMULATED study needs (`TrialTable`,
`trial_table`), the true worlds (`World`, `parse_world`; analysis.power's
docstring) and one study's simulated responses (`simulate_responses`)."""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np
import pandas as pd

from analysis.crossval import RiskGrid, grouping_label
from analysis.crossval.folds import structure_groups
from analysis.spec import FEATURES


class PowerInputError(ValueError):
    """Bad input to the power analysis: `flag` names the command-line flag it came from."""

    def __init__(self, flag: str, message: str):
        super().__init__(f"{flag}: {message}")
        self.flag = flag


@dataclass(frozen=True)
class TrialTable:
    """What a simulated study needs of its trials: ids, effort E (T,), risk over a
    sigma grid, the heuristic predictors {name: (T,)} and the structure groups of
    the held-out folds (crossval.structure_groups)."""

    trials: tuple[str, ...]
    effort: np.ndarray
    risk: RiskGrid
    features: Mapping[str, np.ndarray]
    groups: tuple[tuple[int, ...], ...] = field(default=())

    @property
    def grouping(self) -> str:
        return grouping_label(self.groups, self.trials)


#: Trials the comparison needs (a held-out fit of Eq. 1 keeps at least 4 training trials).
MIN_TRIALS = 5

def trial_table(effort, risk_table: pd.DataFrame, features: pd.DataFrame,
                trials: Sequence[str] | None = None, same: Sequence[Sequence[str]] = ()) -> TrialTable:
    """A TrialTable from tidy tables: `effort` (columns trial, effort; rows of a trial
    averaged) or a Series by trial; `risk_table` (trial, sigma, risk, optional
    n_sims); `features` (trial and FEATURES). `trials` defaults to the effort
    table's trials in order of appearance; `same` the sets of trials whose B is
    identical (analysis.heuristics.identical_targets), held out together. Raises PowerInputError naming the
    trial and table of a missing or non-finite value."""
    if isinstance(effort, pd.Series):
        e = effort.astype(float)
    else:
        e = effort.assign(trial=effort["trial"].astype(str)).groupby("trial", sort=False)["effort"].mean()
    trials = tuple(str(t) for t in (trials if trials is not None else e.index))
    if len(trials) < MIN_TRIALS:
        raise PowerInputError("--stimuli", f"{len(trials)} trials; the comparison needs at least {MIN_TRIALS}")
    missing = [t for t in trials if t not in e.index]
    if missing:
        raise PowerInputError("--stimuli", f"no effort for trial {missing[0]}")
    E = e.reindex(list(trials)).to_numpy(float)
    sig = np.unique(np.round(risk_table["sigma"].to_numpy(float), 9))
    rt = risk_table.assign(trial=risk_table["trial"].astype(str))
    risk = np.empty((len(sig), len(trials)))
    for k, s in enumerate(sig):
        rows = rt[np.isclose(rt["sigma"].astype(float), s, rtol=0, atol=1e-9)].groupby("trial")["risk"].mean()
        for i, t in enumerate(trials):
            if t not in rows.index:
                raise PowerInputError("--stimuli", f"no risk for trial {t} at sigma {s:g}")
            risk[k, i] = float(rows[t])
    f = features.set_index("trial") if "trial" in features.columns else features
    feats = {}
    for name in FEATURES:
        if name not in f.columns:
            raise PowerInputError("--stimuli", f"the features table lacks {name!r}")
        v = f[name].reindex(list(trials)).to_numpy(float)
        if not np.all(np.isfinite(v)):
            raise PowerInputError("--stimuli", f"heuristic {name!r} of trial {trials[int(np.argmin(np.isfinite(v)))]} "
                                  "is missing or not finite")
        feats[name] = v
    if not np.all(np.isfinite(E)) or not np.all(np.isfinite(risk)):
        raise PowerInputError("--stimuli", "effort or risk is not finite")
    grid = RiskGrid(np.asarray(sig, float), risk, None, "R")
    groups = tuple(structure_groups(trials, risk, same))
    return TrialTable(trials, E, grid, feats, groups)


# ----------------------------------------------------------------------------- worlds

WORLD_KINDS = ("effort-only", "full", "effort+height", "effort+stacked", "noise", "csv")


@dataclass(frozen=True)
class World:
    """One true model of the simulated participants (module docstring)."""

    kind: str
    b2b1: float | None = None
    sigma: float | None = None
    weight: float = 1.0
    means: tuple[tuple[str, float], ...] | None = None
    source: str = ""

    @property
    def label(self) -> str:
        if self.kind == "full":
            return f"full (b2/b1={self.b2b1:g}, sigma={self.sigma:g})"
        if self.kind in ("effort+height", "effort+stacked") and self.weight != 1.0:
            return f"{self.kind} (w={self.weight:g})"
        if self.kind == "csv":
            return f"csv:{self.source}"
        return self.kind

    def cost(self, table: TrialTable) -> np.ndarray:
        """The latent cost y (T,) of the trials of `table` in this world."""
        E = table.effort
        if self.kind == "effort-only":
            return E.copy()
        if self.kind == "noise":
            return np.zeros_like(E)
        if self.kind == "full":
            k = _sigma_index(table.risk.sigmas, self.sigma)
            R = table.risk.risk[k]
            return E * (1 - R) + self.b2b1 * E * R
        if self.kind in ("effort+height", "effort+stacked"):
            h = table.features[self.kind.split("+")[1]]
            return E / _sd(E) + self.weight * h / _sd(h)
        if self.kind == "csv":
            got = dict(self.means)
            unknown = [t for t in got if t not in table.trials]
            if unknown:
                raise PowerInputError("--world", f"csv:{self.source} names unknown trial {unknown[0]}")
            missing = [t for t in table.trials if t not in got]
            if missing:
                raise PowerInputError("--world", f"csv:{self.source} lacks trial {missing[0]}")
            return np.array([got[t] for t in table.trials], float)
        raise PowerInputError("--world", f"unknown world {self.kind!r}")


def _sd(x: np.ndarray) -> float:
    s = float(np.std(x))
    return s if s > 0 else 1.0


def _sigma_index(sigmas: np.ndarray, sigma: float) -> int:
    k = int(np.argmin(np.abs(sigmas - sigma)))
    if abs(sigmas[k] - sigma) > 1e-9:
        raise PowerInputError("--world", f"sigma {sigma:g} is not on the risk table's grid "
                              f"({sigmas.min():g}..{sigmas.max():g}, {len(sigmas)} values)")
    return k


def parse_world(text: str, table: TrialTable | None = None) -> World:
    """A World from its command-line text (module docstring). Raises PowerInputError
    naming --world for an unknown world, b2/b1 <= 0, a sigma off `table`'s grid, an
    unreadable CSV or one naming unknown trials."""
    text = str(text).strip()
    kind, _, rest = text.partition(":")
    kind = kind.strip().lower()
    if kind == "csv":
        path = Path(rest)
        try:
            df = pd.read_csv(path, dtype={"trial": str})
        except (OSError, ValueError, UnicodeDecodeError) as e:
            raise PowerInputError("--world", f"csv:{rest}: cannot read ({type(e).__name__})") from None
        col = "mean" if "mean" in df.columns else ("mean_z" if "mean_z" in df.columns else None)
        if "trial" not in df.columns or col is None:
            raise PowerInputError("--world", f"csv:{rest}: needs columns trial and mean")
        vals = pd.to_numeric(df[col], errors="coerce")
        if vals.isna().any() or not np.all(np.isfinite(vals)):
            raise PowerInputError("--world", f"csv:{rest}: mean of trial {df['trial'][vals.isna() | ~np.isfinite(vals)].iloc[0]} "
                                  "is not a finite number")
        if df["trial"].duplicated().any():
            raise PowerInputError("--world", f"csv:{rest}: trial {df['trial'][df['trial'].duplicated()].iloc[0]} repeated")
        world = World("csv", means=tuple(zip(df["trial"].astype(str).str.strip().str.upper(), vals.astype(float))),
                      source=path.name)
    else:
        if kind not in WORLD_KINDS:
            raise PowerInputError("--world", f"unknown world {text!r}; expected one of effort-only, "
                                  "full:b2b1=K,sigma=S, effort+height, effort+stacked, noise, csv:FILE")
        params = {}
        for item in filter(None, (s.strip() for s in rest.split(","))):
            key, eq, value = item.partition("=")
            try:
                params[key.strip().lower()] = float(value)
            except ValueError:
                raise PowerInputError("--world", f"{text!r}: {item!r} is not key=number") from None
            if not eq or not np.isfinite(params[key.strip().lower()]):
                raise PowerInputError("--world", f"{text!r}: {item!r} is not key=finite number")
        allowed = {"full": {"b2b1", "sigma"}, "effort+height": {"w"}, "effort+stacked": {"w"}}.get(kind, set())
        unknown = set(params) - allowed
        if unknown:
            raise PowerInputError("--world", f"{text!r}: unknown parameter {sorted(unknown)[0]!r}"
                                  + (f" (allowed: {', '.join(sorted(allowed))})" if allowed else " (takes none)"))
        if kind == "full":
            b = params.get("b2b1", 3.0)
            if b <= 0:
                raise PowerInputError("--world", f"{text!r}: b2/b1 must be > 0, got {b:g}")
            world = World("full", b2b1=b, sigma=params.get("sigma", 0.15))
        elif kind in ("effort+height", "effort+stacked"):
            world = World(kind, weight=params.get("w", 1.0))
        else:
            world = World(kind)
    if table is not None:
        if world.kind == "full":
            _sigma_index(table.risk.sigmas, world.sigma)
        if world.kind == "csv":
            world.cost(table)
    return world


def simulate_responses(y: np.ndarray, participants: int, noise_sd: float, rng: np.random.Generator,
                       scale_log_sd: float = 0.5, offset_sd: float = 10.0) -> np.ndarray:
    """(participants, T) z-scores of one SIMULATED study (analysis.recovery's draw:
    scales, offsets, noise, in that order)."""
    y = np.asarray(y, float)
    scale = np.exp(scale_log_sd * rng.standard_normal(participants))
    offset = offset_sd * rng.standard_normal(participants)
    noise = noise_sd * rng.standard_normal((participants, len(y)))
    responses = offset[:, None] + scale[:, None] * (y + noise)
    return (responses - responses.mean(axis=1, keepdims=True)) / responses.std(axis=1, keepdims=True)



def check_settings(participants, noise, studies, n_perm) -> None:
    if not (isinstance(participants, (int, np.integer)) and participants >= 2):
        raise PowerInputError("--participants", f"must be a whole number >= 2, got {participants!r}")
    if not (np.isfinite(noise) and noise > 0):
        raise PowerInputError("--noise", f"must be a finite number > 0, got {noise!r}")
    if not (isinstance(studies, (int, np.integer)) and studies >= 1):
        raise PowerInputError("--studies", f"must be a whole number >= 1, got {studies!r}")
    if not (isinstance(n_perm, (int, np.integer)) and n_perm >= 1):
        raise PowerInputError("--n-perm", f"must be a whole number >= 1, got {n_perm!r}")

