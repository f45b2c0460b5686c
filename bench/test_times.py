"""Where the test suite's time goes, in CPU seconds (they hold up on a shared machine).

    PYTHONPATH=.:bench python -m pytest -q -n 0 -p pytest_cpu --cpu-csv after.csv    # bench/pytest_cpu.py
    python bench/test_times.py after.csv                  # totals, per module, the slowest tests
    python bench/test_times.py before.csv after.csv       # the same, side by side
    python bench/test_times.py after.csv --over 0.4       # fast-subset tests over 0.4 CPU-s (candidates for slow)
    python bench/test_times.py after.csv --over 0.3 --write-slow    # ... added to tests/slow_cases.txt (conftest marks them)
    python bench/test_times.py --count                    # tests and asserts in tests/ (AST), for before/after notes
    python bench/test_times.py after.csv --write-file-seconds     # each file's wall seconds -> tests/file_seconds.csv

CPU = the test's own CPU seconds plus its children's (subprocesses, pool workers it
waited for). A test's wall time on idle cores is about its CPU time when it runs
on one core, less when its work uses both.
"""
from __future__ import annotations

import argparse
import ast
import csv
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def read(path: Path) -> dict[str, dict]:
    with open(path) as f:
        return {r["nodeid"]: {"wall": float(r["wall_s"]), "cpu": float(r["cpu_s"]) + float(r["child_cpu_s"]),
                              "slow": r["slow"] == "1"} for r in csv.DictReader(f)}


def totals(rows: dict[str, dict]) -> dict[str, float]:
    tests = {k: v for k, v in rows.items() if k != "<collection>"}
    coll = rows.get("<collection>", {"wall": 0.0, "cpu": 0.0})
    fast = [v for v in tests.values() if not v["slow"]]
    return {"tests": len(tests), "fast tests": len(fast), "collection cpu": coll["cpu"],
            "all cpu": sum(v["cpu"] for v in tests.values()), "fast cpu": sum(v["cpu"] for v in fast),
            "all wall": sum(v["wall"] for v in tests.values()), "fast wall": sum(v["wall"] for v in fast)}


def per_module(rows: dict[str, dict], fast_only: bool = False) -> dict[str, float]:
    out: dict[str, float] = defaultdict(float)
    for k, v in rows.items():
        if k != "<collection>" and not (fast_only and v["slow"]):
            out[k.split("::")[0]] += v["cpu"]
    return out


def count_asserts(folder: Path = ROOT / "tests") -> tuple[int, int, int]:
    """(test functions, test functions with an assert or pytest.raises/warns/approx check, assert statements)."""
    functions = checked = asserts = 0
    for path in sorted(folder.glob("test_*.py")):
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.name.startswith("test"):
                functions += 1
                n = sum(isinstance(x, ast.Assert) for x in ast.walk(node))
                raises = any(isinstance(x, ast.Attribute) and x.attr in ("raises", "warns", "fail") for x in ast.walk(node))
                calls_helper = any(isinstance(x, ast.Call) and isinstance(x.func, ast.Name)
                                   and x.func.id.startswith(("assert", "check")) for x in ast.walk(node))
                checked += bool(n or raises or calls_helper)
        asserts += sum(isinstance(x, ast.Assert) for x in ast.walk(tree))
    return functions, checked, asserts


SLOW_CASES = ROOT / "tests" / "slow_cases.txt"
FILE_SECONDS = ROOT / "tests" / "file_seconds.csv"


def write_file_seconds(rows: dict[str, dict], path: Path = FILE_SECONDS) -> None:
    """Each test file's wall seconds (the sum over its tests) to `path`, longest first:
    the order tests/conftest.py hands the files to the workers (longest_files_first)."""
    seconds: dict[str, float] = defaultdict(float)
    for nodeid, row in rows.items():
        if nodeid != "<collection>":
            seconds[nodeid.split("::")[0].split("/")[-1]] += row["wall"]
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["file", "seconds"])
        w.writerows((name, round(s, 1)) for name, s in sorted(seconds.items(), key=lambda kv: (-kv[1], kv[0])))


def write_slow(over: list, source: str, path: Path = SLOW_CASES) -> None:
    """Add the cases of `over` (node id, row) to `path`, one 'file.py::name[params]  # CPU s' line each."""
    lines = path.read_text().splitlines() if path.exists() else [
        "# Fast-subset cases measured over the fast subset's share of CPU seconds: tests/conftest.py marks",
        "# them slow (they run in the full suite). Written by bench/test_times.py --write-slow; edit freely.",
        "# file::case  # CPU s measured (its CSV)"]
    known = {line.split("#", 1)[0].strip() for line in lines}
    for nodeid, row in over:
        key = nodeid.split("/")[-1]
        if key not in known:
            lines.append(f"{key}  # {row['cpu']:.2f} CPU-s ({source})")
    path.write_text("\n".join(lines) + "\n")


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("csv", nargs="*", type=Path, help="one or two CSVs of bench/pytest_cpu.py (before, after)")
    p.add_argument("--top", type=int, default=30)
    p.add_argument("--over", type=float, help="list the fast-subset tests over this many CPU seconds")
    p.add_argument("--count", action="store_true", help="count test functions and asserts in tests/")
    p.add_argument("--write-slow", action="store_true",
                   help="add the fast-subset cases over --over CPU-s to tests/slow_cases.txt (entries there are kept)")
    p.add_argument("--write-file-seconds", action="store_true",
                   help="write each test file's wall seconds of the last CSV (a whole-suite run) to tests/file_seconds.csv")
    args = p.parse_args(argv)
    if args.count:
        f, c, a = count_asserts()
        print(f"tests/: {f} test functions, {c} with a check (assert, pytest.raises/warns, an assert_*/check_* helper), "
              f"{a} assert statements")
    runs = [read(path) for path in args.csv]
    if not runs:
        return 0
    names = [path.name for path in args.csv]
    t = [totals(r) for r in runs]
    print("totals".ljust(22) + "".join(n[:18].rjust(20) for n in names))
    for key in t[0]:
        print(key.ljust(22) + "".join(f"{x[key]:20.1f}" for x in t))
    mods = [per_module(r) for r in runs]
    print("\nper module (CPU s, all tests)".ljust(60) + "".join(n[:14].rjust(16) for n in names))
    for mod in sorted(set().union(*mods), key=lambda m: -mods[-1].get(m, 0.0))[: args.top]:
        print(mod.ljust(60) + "".join(f"{m.get(mod, 0.0):16.1f}" for m in mods))
    last = runs[-1]
    print(f"\nslowest tests of {names[-1]} (CPU s, wall s, slow?)")
    for k, v in sorted(((k, v) for k, v in last.items() if k != "<collection>"), key=lambda kv: -kv[1]["cpu"])[: args.top]:
        print(f"{v['cpu']:8.2f} {v['wall']:8.2f} {'slow' if v['slow'] else 'fast':5s} {k}")
    if args.over is not None:
        over = sorted(((k, v) for k, v in last.items() if k != "<collection>" and not v["slow"] and v["cpu"] > args.over),
                      key=lambda kv: -kv[1]["cpu"])
        print(f"\nfast-subset tests over {args.over} CPU s: {len(over)}, {sum(v['cpu'] for _, v in over):.1f} CPU s")
        for k, v in over:
            print(f"{v['cpu']:8.2f}  {k}")
        if args.write_slow:
            write_slow(over, args.csv[-1].name)
    if args.write_file_seconds:
        write_file_seconds(last)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
