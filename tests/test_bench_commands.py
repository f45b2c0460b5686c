"""bench/commands.py keeps what it measured before: a command that fails (or a run
that is stopped) leaves that command's earlier rows of lgp/command_times.csv in place,
and only a command with a new row loses its old ones."""
import csv
import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _commands_module(monkeypatch):
    monkeypatch.syspath_prepend(str(ROOT / "bench"))  # its `from common import ...`
    spec = importlib.util.spec_from_file_location("bench_commands", ROOT / "bench" / "commands.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_failing_command_keeps_its_earlier_rows_and_a_measured_one_replaces_them(tmp_path, monkeypatch):
    bench = _commands_module(monkeypatch)
    quick, tests = bench.COMMANDS["quick"][0], bench.COMMANDS["tests"][0]
    row = dict(jobs=2, cache="cold", cores=2, cpu_model="earlier CPU", load_before="1 1 1", load_after="1 1 1",
               date="2026-01-01")
    earlier = [dict(row, command=quick, wall_s=99.0, cpu_s=99.0), dict(row, command=tests, wall_s=23.5, cpu_s=42.7)]
    times = tmp_path / "times.csv"
    with times.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=bench.FIELDS)
        w.writeheader()
        w.writerows(earlier)

    def fake_run(command, jobs, folder):
        if command == tests:
            raise SystemExit(f"{command} failed")
        return dict(row, command=command, jobs=jobs, wall_s=1.0, cpu_s=2.0, cpu_model="this CPU")

    monkeypatch.setattr(bench, "run", fake_run)
    with pytest.raises(SystemExit, match="failed"):
        bench.main(["--only", "quick", "tests", "--csv", str(times), "--out", str(tmp_path / "b.md")])
    with times.open() as f:
        kept = list(csv.DictReader(f))
    # kept as it was (rows from before the speed probe read back with its columns empty)
    assert [r for r in kept if r["command"] == tests] == [{"probe_before_s": "", "probe_after_s": "",
                                                          **{k: str(v) for k, v in earlier[1].items()}}]
    new_quick = [r for r in kept if r["command"] == quick]
    assert len(new_quick) == len(bench.COMMANDS["quick"][1])
    assert {r["cpu_model"] for r in new_quick} == {"this CPU"}


def test_a_table_outside_the_repository_is_written_and_named_as_given(tmp_path, monkeypatch):
    """--csv and --out in a scratch folder (a trial run of the bench): the rows and the
    section are written there, the section naming the CSV by its path; rows measured
    with the speed probe show it, earlier ones say it was not measured."""
    bench = _commands_module(monkeypatch)
    quick, sheet = bench.COMMANDS["quick"][0], bench.COMMANDS["sheet"][0]
    earlier = dict(command=quick, jobs=2, cache="cold", wall_s=9.0, cpu_s=9.0, cores=2, cpu_model="CPU",
                   load_before="1 1 1", load_after="1 1 1", date="2026-01-01")
    times = tmp_path / "times.csv"
    with times.open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=[k for k in bench.FIELDS if not k.startswith("probe")])
        w.writeheader()
        w.writerow(earlier)
    monkeypatch.setattr(bench, "run", lambda command, jobs, folder: dict(
        earlier, command=command, jobs=jobs, wall_s=1.5, cpu_s=1.6, probe_before_s=0.3, probe_after_s=0.31))
    out = tmp_path / "b.md"
    assert bench.main(["--only", "sheet", "--csv", str(times), "--out", str(out)]) == 0
    text = out.read_text()
    assert f"rows: `{times.resolve()}`" in text
    assert f"| `{sheet}` | 1 | cold | 1.5 | 1.6 | 1 1 1 -> 1 1 1 | 0.3 -> 0.31 |" in text
    assert f"| `{quick}` | 2 | cold | 9.0 | 9.0 | 1 1 1 -> 1 1 1 | not measured |" in text
