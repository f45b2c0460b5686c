"""Benchmark of reading and validating a large human-data CSV; writes the
"human data" section of docs/benchmarks.md (other sections are kept).

    python bench/human_data.py [--rows 2000000] [--out docs/benchmarks.md]

The file holds SIMULATED responses (dataset ``simulated-time``, standard normals),
only to time the validation: 24 trials per participant, rows/24 participants.
It times `load_human_data` (read + vectorised validation) and, on the same table,
the per-participant check it replaced (``set(group["trial"])`` built once per
trial and participant), which was the bulk of the old validation's time.

It also measures the memory of the largest file accepted by default
(analysis.data.MAX_PARTICIPANTS participants, padded with an extra column to
just under the byte limit): the peak resident memory of a fresh process that
loads it, then z-scores it and draws 1000 bootstrap resamples (the analysis'
largest arrays), against the same process importing only the libraries.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from common import machine, write_section  # noqa: E402
from analysis.data import TRIAL_IDS, load_human_data  # noqa: E402


def synthetic_csv(path: Path, rows: int, seed: int = 0) -> None:
    n = rows // len(TRIAL_IDS)
    rng = np.random.default_rng(seed)
    pd.DataFrame({
        "dataset": "simulated-time",
        "participant": np.repeat([f"p{k}" for k in range(n)], len(TRIAL_IDS)),
        "trial": np.tile(TRIAL_IDS, n),
        "response": rng.normal(size=n * len(TRIAL_IDS)).round(4),
    }).to_csv(path, index=False)


def old_missing_trials_check(table: pd.DataFrame) -> int:
    """The row-by-row check of missing trials: the reference the vectorised validation is timed against."""
    incomplete = 0
    for _, group in table.groupby(["dataset", "participant"], sort=False):
        incomplete += bool([t for t in TRIAL_IDS if t not in set(group["trial"])])
    return incomplete


_MEASURE = """
import sys
import numpy as np
from analysis.data import exclude_constant_participants, load_human_data, resample_trial_means, zscore_responses
step = sys.argv[2]
def hwm():  # peak resident memory of this process (kB); unlike ru_maxrss it starts anew at exec
    return int([l for l in open("/proc/self/status") if l.startswith("VmHWM:")][0].split()[1])
base = hwm()
if step != "imports":
    t = load_human_data(sys.argv[1], allow_simulated=True)
    if step == "analysis":
        kept, _ = exclude_constant_participants(t)
        resample_trial_means(zscore_responses(kept), 1000, np.random.default_rng(0))
print(base, hwm())
"""


def memory_section() -> str:
    """Peak RSS (MB) of loading (and analysing) the largest file accepted by default."""
    import os
    import subprocess

    from analysis.data import BYTES_PER_PARTICIPANT, MAX_PARTICIPANTS

    limit = MAX_PARTICIPANTS * BYTES_PER_PARTICIPANT
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "largest.csv"
        n = MAX_PARTICIPANTS
        df = pd.DataFrame({"dataset": "simulated-time", "participant": np.repeat([f"p{k}" for k in range(n)], 24),
                           "trial": np.tile(TRIAL_IDS, n), "response": np.random.default_rng(0).normal(size=24 * n).round(4)})
        plain = len(df.to_csv(index=False).encode())
        pad = max(0, (limit - plain) // len(df) - 2)
        df["note"] = "x" * pad
        df.to_csv(path, index=False)
        size = path.stat().st_size
        env = {**os.environ, "PYTHONPATH": str(ROOT)}
        peak = {}
        for step in ("imports", "load", "analysis"):
            out = subprocess.run([sys.executable, "-c", _MEASURE, str(path), step], env=env, capture_output=True,
                                 text=True, check=True).stdout.split()
            peak[step] = int(out[1]) / 1024  # kB
    return (f"\nMemory of the largest file accepted by default ({MAX_PARTICIPANTS:,} participants, "
            f"{size / 1e6:.1f} MB of the {limit / 1e6:.1f} MB limit; peak resident memory of a fresh process):\n\n"
            "| step | peak RSS, MB |\n|---|---|\n"
            f"| imports only | {peak['imports']:.0f} |\n"
            f"| + `load_human_data` | {peak['load']:.0f} |\n"
            f"| + z-scores and 1000 bootstrap resamples (blocks of 32 MB) | {peak['analysis']:.0f} |\n")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rows", type=int, default=2_000_000)
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "benchmarks.md")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "responses.csv"
        synthetic_csv(path, args.rows)
        t0 = time.process_time()
        table = load_human_data(path, allow_simulated=True, max_participants=args.rows // len(TRIAL_IDS) + 1)
        new = time.process_time() - t0
    t0 = time.process_time()
    assert old_missing_trials_check(table) == 0
    old = time.process_time() - t0
    text = (
        "## human data\n\n"
        f"`python bench/human_data.py --rows {args.rows}` on {machine()} (a loaded shared machine: "
        "CPU seconds, not wall time). A synthetic CSV of SIMULATED responses "
        f"({len(table):,} rows, {len(table) // len(TRIAL_IDS):,} participants x 24 trials):\n\n"
        "| step | CPU s |\n|---|---|\n"
        f"| `load_human_data` (read + vectorised validation, all rules) | {new:.1f} |\n"
        f"| the per-participant missing-trials loop it replaced (that rule alone) | {old:.1f} |\n"
    )
    text += memory_section()
    write_section(args.out, "human data", text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
