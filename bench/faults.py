"""The bad-input probe of docs/faults.md: every bad trial file, human-data file,
study download, command line, API argument, cache entry and output folder tried,
and what the project does with it (the cases: bench/faults_files.py,
bench/faults_calls.py, bench/faults_disk.py).

    python bench/faults.py [--out docs/faults.md]

Each case runs in this process under a 20 s deadline (SIGALRM) and is judged:

- ``refused``: an error of the project's own (what a command line prints as one
  line ``prog: error: ...``, lgp.cli.is_known_error), naming the rule, in time;
- ``recomputed``: a cache entry reported as damaged and computed again;
- ``accepted (by design)``: input the format allows (a lower-case trial id, a
  UTF-16 file with its byte-order mark, ...), said so in the table;
- anything else (a traceback, a hang, bad input accepted) is a ``FAILURE``.

It writes the "## Bad inputs tried" section of docs/faults.md (the rest is kept)
and prints the figures. The faults of a running pipeline (killed workers,
concurrent runs, a full disk, ...) are the tests listed in docs/faults.md.
"""
from __future__ import annotations

import argparse
import contextlib
import itertools
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from common import Deadline, deadline, machine, write_section  # noqa: E402

from faults_calls import api_cases, command_cases  # noqa: E402
from faults_disk import cache_cases, output_cases, resigned_cases, table  # noqa: E402
from faults_files import crowded, human_cases, import_cases, trial_cases  # noqa: E402
from lgp.cli import is_known_error, one_line  # noqa: E402


def judge(run, accept=False) -> tuple[str, str]:
    """(verdict, what happened) of one case."""
    t0 = time.monotonic()
    try:
        with deadline(20):
            result = run()
    except Deadline as e:
        return "FAILURE", f"hung: {e}"
    except MemoryError:
        return "FAILURE", "MemoryError"
    except Exception as e:  # noqa: BLE001 - judged here
        took = time.monotonic() - t0
        if accept:
            return "FAILURE", f"refused good input: {one_line(e)}"
        if is_known_error(e):
            return "refused", f"{type(e).__name__}: {one_line(e)} ({took:.1f} s)"
        return "FAILURE", f"traceback: {type(e).__name__}: {e}"
    if isinstance(result, str) and result.startswith("recomputed"):
        return "recomputed", result
    if accept:
        return "accepted (by design)", result if isinstance(result, str) else "accepted"
    return "FAILURE", f"accepted: {result!r}"[:200]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--out", type=Path, default=ROOT / "docs" / "faults.md")
    args = p.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        groups = [("trial file", trial_cases(tmp)), ("human data", human_cases(tmp)),
                  ("study import", import_cases(tmp)), ("output folder", output_cases(tmp)), ("command line", command_cases(tmp)), ("API", api_cases()),
                  ("cache entry", itertools.chain(((n, _cache_run(d, tmp)) for n, d in cache_cases(tmp)),
                                                  resigned_cases(tmp)))]
        for group, cases in groups:
            for name, run in cases:
                accept = False
                if isinstance(run, tuple):
                    accept, run = True, run[1]
                if run == "crowded":
                    run = lambda: crowded(tmp)  # noqa: E731
                verdict, what = judge(run, accept)
                rows.append((group, name, verdict, what.replace("|", "\\|").replace(str(tmp), "TMP").replace(str(ROOT), "<repo>")))
                print(f"{verdict:>22}  {group}: {name}: {what[:150]}", flush=True)
    bad = [r for r in rows if not r[2].startswith("accepted")]
    refused = [r for r in bad if r[2] in ("refused", "recomputed")]
    accepted = [r for r in rows if r[2].startswith("accepted")]
    lines = ["## Bad inputs tried", "",
             f"`python bench/faults.py` on {machine()}: **{len(refused)} of {len(bad)} bad inputs refused** in one "
             "named line (or, for a cache entry, reported and recomputed), none after a hang or a traceback; "
             f"{len(accepted)} inputs the formats allow were accepted as designed. "
             f"By kind: " + ", ".join(f"{g} {sum(1 for r in refused if r[0] == g)}/{sum(1 for r in bad if r[0] == g)}"
                                      for g in ("trial file", "human data", "study import", "output folder", "command line", "API",
                                                "cache entry")) + ".", "",
             "| kind | input | verdict | what the project does |", "|---|---|---|---|"]
    bar = "\\|"
    lines += [f"| {g} | {n.replace('|', bar)} | {v} | {w[:220]} |" for g, n, v, w in rows]
    write_section(args.out, "Bad inputs tried", "\n".join(lines) + "\n")
    print(f"{len(refused)}/{len(bad)} bad inputs refused; {len(accepted)} accepted by design")
    return 0 if len(refused) == len(bad) else 1


def _cache_run(damage, tmp):
    """A case: two sound entries, `damage` done to the first, then a fresh Cache reads it."""
    from lgp.app.cache import Cache

    def run():
        root = Path(tempfile.mkdtemp(dir=tmp)) / "cache"
        cache = Cache(root)
        cache.put("risk", "aaaa", table("1E", 0.2))
        cache.put("risk", "bbbb", table("7H", 0.9))
        damage(cache.path("risk", "aaaa"), cache)
        fresh = Cache(root)
        with open(os.devnull, "w") as null, contextlib.redirect_stderr(null):
            got = fresh.get("risk", "aaaa")
        if got is None and fresh.count("recomputed") == 1:
            return "recomputed (reported in one line on stderr, never used)"
        return f"used: {got['trial'].tolist() if got is not None else None}"
    return run


if __name__ == "__main__":
    raise SystemExit(main())
