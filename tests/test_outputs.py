"""An output folder describes one run, and the report says true things: the tie rule,
the engine with its settings, and both times (the results' compute time and this run's)."""
import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from analysis import TIE_REL, pair_order, pair_table
from lgp import reproduce
from conftest import QUICK_RUN, copy_of_run
from lgp.paper import TRIAL_IDS

#: The session's --quick run's effort and risk (conftest.QUICK_RUN; a copy of its cache,
#: `copy_of_run`, holds them), without --quick's analysis settings: one job, 10 bootstrap
#: resamples, no replays.
TINY = [*(a for a in QUICK_RUN if a != "--quick"), "--jobs", "1", "--n-boot", "10", "--no-replays"]


def _listed(out: Path) -> set[str]:
    return {f["path"] for f in json.loads((out / "manifest.json").read_text())["files"]}


def _on_disk(out: Path) -> set[str]:
    return {p.relative_to(out).as_posix() for p in out.rglob("*")
            if p.is_file() and p.relative_to(out).parts[0] != "cache" and p.name != "manifest.json"}


def _printed(stdout: str, out: Path) -> set[str]:
    """The files `--verbose` prints at the end (indented lines), relative to `out`."""
    return {Path(line.strip()).resolve().relative_to(out.resolve()).as_posix() for line in stdout.splitlines()
            if line.startswith("  ")}


def _participants(path: Path) -> str:
    """A response file in the human-data format, drawn at random: it only has to be
    valid (no claim is tested on it; these are not human data)."""
    rng = np.random.default_rng(0)
    rows = [("difficulty", f"p{k}", t, float(rng.normal())) for k in range(6) for t in TRIAL_IDS]
    pd.DataFrame(rows, columns=["dataset", "participant", "trial", "response"]).to_csv(path, index=False)
    return str(path)


@pytest.mark.slow
def test_each_run_lists_and_leaves_only_its_own_outputs_and_reports_true_times(tmp_path, capsys, quick_run):
    out = copy_of_run(quick_run, tmp_path / "r")  # a first run whose results were computed by the session's run
    assert reproduce.main([*TINY, "--out", str(out), "--verbose"]) == 0
    full = capsys.readouterr()
    assert _listed(out) == _on_disk(out)
    assert {"pairs.csv", "figures/orderings.csv", "figures/effort_risk_pairs.png", "report.md"} <= _listed(out)
    assert not (out / "figures" / "pairs.csv").exists()  # one name per table
    assert _printed(full.out, out) == _listed(out) | {"manifest.json"}
    first = json.loads((out / "manifest.json").read_text())
    assert first["compute_time_s"] > 0 and first["compute_time_unknown_results"] == 0
    assert first["parameters"]["trials"] == list(TRIAL_IDS) and len(first["input_hash"]) == 64

    # The report: engine with settings, the one tie rule, the counts it gives.
    report = (out / "report.md").read_text()
    assert re.search(r"Risk engine: mujoco \S+ \(timestep ", report)
    assert f"|H - E| <= {TIE_REL:g} x max(E, H)" in report
    pairs = pd.read_csv(out / "pairs.csv")
    orders = [pair_order(e, h) for e, h in zip(pairs["effort_E"], pairs["effort_H"])]
    assert pairs["effort_order"].tolist() == orders
    assert f"Effort: E < H in {orders.count('E<H')} of 12 pairs" in report
    # 6E and 6H carry the same 5 blocks, one way and back: tied by the rule
    assert pairs.set_index("pair").loc[6, "effort_order"] == "tie"
    assert "Without human data there are no fitted betas" in report

    # A subset run into the same folder: only its files are there and listed.
    assert reproduce.main([*TINY, "--trials", "1e", "--out", str(out), "--verbose"]) == 0
    subset = capsys.readouterr()
    assert "removed the outputs of an earlier run" in subset.err
    assert _listed(out) == _on_disk(out) == {"effort_samples.csv", "effort.csv", "risk.csv", "risk_precision.csv", "report.md", "index.html", "page/1E.png", "page/risk.html"}
    assert _printed(subset.out, out) == _listed(out) | {"manifest.json"}

    # The full run again, from the cache: compute time is the first run's, this run's time its own.
    assert reproduce.main([*TINY, "--out", str(out)]) == 0
    capsys.readouterr()
    again = json.loads((out / "manifest.json").read_text())
    assert again["compute_time_s"] == pytest.approx(first["compute_time_s"], abs=0.2)
    report = (out / "report.md").read_text()
    # rounded to whole seconds in the report: 3.49 and 3.51 s may print as 3 and 4
    reported = re.search(r"Compute time of these results (\d+) s", report)
    assert reported and abs(int(reported.group(1)) - again["compute_time_s"]) <= 1
    assert re.search(r"this run took \d+ s", report)
    assert again["input_hash"] == first["input_hash"]

    # With human data: analysis/ replaces figures/ (which keeps only the run's risk-over-sigma
    # figure, issue 22), and the report no longer says there are no betas.
    assert reproduce.main([*TINY, "--out", str(out), "--human-data", _participants(tmp_path / "h.csv")]) == 0
    capsys.readouterr()
    assert {p.name for p in (out / "figures").iterdir()} == {"risk_over_sigma.png"}
    assert (out / "analysis" / "orderings.csv").exists()
    assert _listed(out) == _on_disk(out)
    report = (out / "report.md").read_text()
    assert "no fitted betas" not in report and "## fits" in report
    assert json.loads((out / "manifest.json").read_text())["input_hash"] != first["input_hash"]


def test_the_tie_rule_is_relative_and_symmetric():
    assert pair_order(1.0, 1.0 + 0.5 * TIE_REL) == "tie" == pair_order(1.0 + 0.5 * TIE_REL, 1.0)
    assert pair_order(1.0, 1.0 + 2 * TIE_REL) == "E<H"
    assert pair_order(1.0 + 2 * TIE_REL, 1.0) == "H<E"
    assert pair_order(0.0, 0.0) == "tie" and pair_order(0.0, 0.01) == "E<H"  # risks: equal only
    cost = pd.Series({t: float(k) for k, t in enumerate(TRIAL_IDS)})
    cost["6H"] = cost["6E"] * (1 + 1e-5)
    table = pair_table(cost).set_index("pair")
    assert table.loc[6, "order"] == "tie" and not table.loc[6, "E_lt_H"]
    assert int(table["E_lt_H"].sum()) == 11


@pytest.mark.slow
def test_the_tie_threshold_is_above_the_plan_to_plan_noise_and_pair_6_is_within_it():
    """Re-planning one layout from other planner seeds moves its effort by less than
    TIE_REL; 6E and 6H (fixed layouts) differ by less than TIE_REL as well."""
    import stimuli
    from lgp import plan
    from models.effort import kinetic_energy, physical_effort

    trial = stimuli.load_trial("6H")
    layout = trial.sample_initial(np.random.default_rng([0, 0]))
    efforts = [kinetic_energy(plan(layout, trial.target, seed)) for seed in (0, 1, 2)]
    assert (max(efforts) - min(efforts)) / max(efforts) < TIE_REL
    e6, h6 = physical_effort("6E", samples=1).mean, physical_effort("6H", samples=1).mean
    assert pair_order(e6, h6) == "tie"
    assert abs(h6 - e6) > 0  # a tie by the rule, not equal numbers


def test_a_folder_written_before_manifests_existed_is_refused_not_cleared(tmp_path):
    """Issue 30: outputs were once removed by name (effort.csv, figures/, analysis/, ...)
    whoever wrote them; a folder without a manifest is now refused, every file kept."""
    from lgp import owned
    from lgp.app.manifest import check_output_folder

    for name in ["effort_sensitivity.csv", "participant_sigma.csv", "effort.csv"]:
        (tmp_path / name).write_text("x\n")
    (tmp_path / "recovery").mkdir()
    (tmp_path / "recovery" / "simulated_recovery_summary.csv").write_text("x\n")
    (tmp_path / "cache").mkdir()
    (tmp_path / "cache" / "effort-k.csv").write_text("kept\n")
    before = sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*"))
    with pytest.raises(owned.ForeignFiles, match="no manifest.json"):
        check_output_folder(tmp_path)
    assert sorted(p.relative_to(tmp_path).as_posix() for p in tmp_path.rglob("*")) == before
