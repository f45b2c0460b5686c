"""Time the study's pieces: rendering the 48 pictures, building a study folder
(cold: its 52 pictures rendered; warm: from the render cache), and how soon the
built study shows its first screen and first trial in headless Chromium from a
local file. Writes the '## Study: pictures and study folders' section of
docs/benchmarks.md (--out to write elsewhere).

    python bench/study.py [--out docs/benchmarks.md] [--repeats 3]
"""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
from bench.common import machine, write_section  # noqa: E402

ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync"]


def cpu_model() -> str:
    for line in Path("/proc/cpuinfo").read_text().splitlines():
        if line.startswith("model name"):
            return line.split(":", 1)[1].strip()
    return "unknown CPU"


def timed(cmd, env) -> tuple[float, float]:
    """(wall seconds, CPU seconds user + sys of the command and every process it waited for)."""
    import resource

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    run = subprocess.run(cmd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if run.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{run.stderr[-2000:]}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def first_screens(index: Path, repeats: int) -> list[tuple[float, float]]:
    from playwright.sync_api import sync_playwright

    out = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=shutil.which("chromium") or "/usr/bin/chromium", args=ARGS)
        for k in range(repeats):
            page = browser.new_page(viewport={"width": 1280, "height": 800})
            t0 = time.perf_counter()
            page.goto(index.resolve().as_uri() + f"?participant={k}&simulated=1")
            page.wait_for_selector("#jspsych-instructions-next")
            screen = time.perf_counter() - t0
            page.click("#jspsych-instructions-next")
            page.click("#jspsych-instructions-next")
            page.wait_for_selector("#jspsych-html-slider-response-response")
            page.wait_for_function("Array.from(document.querySelectorAll('.lgp-pair img')).every(i => i.complete && i.naturalWidth > 0)")
            out.append((screen, time.perf_counter() - t0))
            page.close()
        browser.close()
    return out


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--out", default=str(ROOT / "docs" / "benchmarks.md"))
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    load_before = machine()
    with tempfile.TemporaryDirectory(prefix="bench-study-") as tmp:
        tmp = Path(tmp)
        env = {**os.environ, "PYTHONPATH": str(ROOT), "LGP_RENDER_CACHE": str(tmp / "cache")}
        py = sys.executable
        render = timed([py, "-m", "stimuli.render", "--out", str(tmp / "renders"), "--jobs", "2"], env)
        cold = timed([py, "-m", "stimuli.experiment", "--task", "difficulty", "--out", str(tmp / "difficulty")], env)
        warm = timed([py, "-m", "stimuli.experiment", "--task", "time", "--out", str(tmp / "time")], env)
        one = timed([py, "-m", "stimuli.render", "--out", str(tmp / "one"), "--trials", "7H", "--jobs", "1"], env)
        screens = first_screens(tmp / "difficulty" / "index.html", args.repeats)
        size_mb = sum(f.stat().st_size for f in (tmp / "difficulty").rglob("*") if f.is_file()) / 1e6
    load_after = machine()
    rows = "\n".join(f"| {k + 1} | {a:.2f} | {b:.2f} |" for k, (a, b) in enumerate(screens))
    text = f"""## Study: pictures and study folders

`python bench/study.py` on {cpu_model()}; before: {load_before}; after: {load_after}
(the machine is shared with other sessions: the load is theirs and ours).

| step | wall time (s) | CPU time (s, user + sys, all processes) |
|---|---|---|
| `python -m stimuli.render --out DIR` (48 pictures, 960x640, 2 processes) | {render[0]:.1f} | {render[1]:.1f} |
| `python -m stimuli.render --trials 7H --jobs 1` (2 pictures, 1 process: start-up and shader compilation included) | {one[0]:.1f} | {one[1]:.1f} |
| `python -m stimuli.experiment --task difficulty` with an empty render cache (52 pictures rendered, folder written) | {cold[0]:.1f} | {cold[1]:.1f} |
| `python -m stimuli.experiment --task time` with the pictures cached | {warm[0]:.1f} | {warm[1]:.1f} |

Rendering the 48 pictures and building a study folder (the cold build renders its
52 pictures itself): {cold[0]:.1f} s of wall time, {cold[1]:.1f} s of CPU time on the 2 cores; the
cold build against the render alone: ratio {cold[0] / render[0]:.2f} (wall). Under the
load above, wall time is mostly waiting for a core: the CPU time is what the work
costs. A study folder holds {size_mb:.1f} MB (pictures, jsPsych, page).

Seconds from `page.goto` of the local `index.html` (headless Chromium, 1280x800) to
the first screen (the instructions, all 52 pictures preloaded) and to the first trial
on screen with both pictures loaded (two instruction clicks included):

| run | first screen | first trial |
|---|---|---|
{rows}
"""
    write_section(Path(args.out), "Study: pictures and study folders", text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
