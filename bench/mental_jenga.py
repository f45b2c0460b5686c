"""Mental Jenga facts the docs quote (docs/mental-jenga.md), measured on Experiment 2:

1. does the scaling change verdicts? deterministic counterfactual (black brick
   removed, no noise) per red brick at SCALE 0.1 against 0.2 (and with the authors'
   linear damping off);
2. how often do those verdicts agree with the authors' Box2D run (exp2_info `fall`)?
3. the "above" set the noise moves against the authors' feature `above` (+1: theirs
   counts the black brick);
4. cost per run (CPU and wall, with the load), and the projection to the issue's
   speed target (42 scenes x 31 sigmas x 100 runs on 2 cores).

    python bench/mental_jenga.py --repo /work/shared/mental-jenga/repo-exp2 [--write]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench.common import machine, write_section  # noqa: E402
from models.counterfactual import FallSettings, JengaWorld, Perturbation, counterfactual_runs, deterministic_falls  # noqa: E402
from stimuli.mental_jenga import read_info, read_scenes  # noqa: E402


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repo", default="/work/shared/mental-jenga/repo-exp2")
    ap.add_argument("--write", action="store_true", help="write the section of docs/benchmarks.md")
    args = ap.parse_args()
    repo = Path(args.repo)
    load0 = machine()
    info = read_info(repo, 2)
    scenes = read_scenes(repo, 2)
    big = {s.trial: s for s in read_scenes(repo, 2, scale=0.2)}
    feats = json.loads((repo / "code/R/data/features/black_exp2.json").read_text())
    n_red = agree_scale = agree_ref = agree_nodamp = agree_above = 0
    counts_ref, counts_mine = [], []
    for s in scenes:
        f = deterministic_falls(s)
        f2 = deterministic_falls(big[s.trial])
        f0 = deterministic_falls(s, FallSettings(damping=False))
        ref = info[info.trial == s.trial].set_index("index")["fall"]
        red = [k for k, b in enumerate(s.bricks) if not b.black]
        n_red += len(red)
        agree_scale += int(sum(f[k] == f2[k] for k in red))
        agree_ref += int(sum(int(f[k]) == ref.get(s.bricks[k].index, 0) for k in red))
        agree_nodamp += int(sum(int(f0[k]) == ref.get(s.bricks[k].index, 0) for k in red))
        counts_ref.append(int(sum(ref.get(s.bricks[k].index, 0) for k in red)))
        counts_mine.append(int(f.sum()))
        agree_above += int(Perturbation(JengaWorld(s)).above.sum() + 1 == feats[f"trial_{s.trial}"]["above"])
    same_count = int(sum(a == b for a, b in zip(counts_ref, counts_mine)))
    r_counts = float(np.corrcoef(counts_ref, counts_mine)[0, 1])
    # cost: 3 scenes x 2 sigmas x 5 runs, authors-x
    t0, c0 = time.time(), time.process_time()
    n_runs = 0
    for s in (scenes[0], scenes[20], scenes[35]):
        n_runs += len(counterfactual_runs(s, "authors-x", [0.12, 0.24], 5))
    wall, cpu = (time.time() - t0) / n_runs, (time.process_time() - c0) / n_runs
    target = 42 * 31 * 100
    text = f"""## Mental Jenga (bench/mental_jenga.py)

Machine at start: {load0}; at end: {machine()}.

| measure (experiment 2, 42 scenes, {n_red} red bricks) | value |
|---|---|
| deterministic verdicts per red brick, SCALE 0.1 vs 0.2 | {agree_scale}/{n_red} the same |
| deterministic verdicts vs the authors' Box2D run (exp2_info `fall`), damping on | {agree_ref}/{n_red} agree |
| the same, the authors' linear damping off | {agree_nodamp}/{n_red} agree |
| fallen count per scene equal to the authors' | {same_count}/42 scenes (r = {r_counts:.2f}) |
| bricks the noise moves ("above" set) = the authors' `above` feature - 1 | {agree_above}/42 scenes |
| cost of one run (authors-x, sigma 0.12/0.24, {n_runs} runs) | {cpu:.3f} s CPU, {wall:.3f} s wall |
| projected: 42 x 31 x 100 = {target:,} runs on 2 cores | {target * cpu / 2 / 60:.0f} min of CPU per core (target: 3 min) |
"""
    print(text)
    if args.write:
        write_section(Path(__file__).resolve().parents[1] / "docs" / "benchmarks.md", "Mental Jenga (bench/mental_jenga.py)", text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
