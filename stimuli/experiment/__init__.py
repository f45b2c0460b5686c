"""The paper's experiments as a static browser study (jsPsych), and the lab's build console.

    python -m stimuli.experiment --task difficulty --out study-difficulty   # Difficulty Estimation
    python -m stimuli.experiment --task time --out study-time               # Time Estimation
    python -m stimuli.experiment --task build --out build-console           # the Build Task, in the lab

Each writes a self-contained folder: open its ``index.html`` in a browser (no
server, no network), or upload the folder to a static host or an experiment server
(JATOS, Pavlovia). How to run a study, what each file holds and how the order is
counterbalanced: docs/experiment.md.

The pictures are renderings of the trial files (`stimuli.render`), not the paper's
photographs. jsPsych comes from the npm registry at the version pinned in
``stimuli/experiment/package.json`` / ``package-lock.json`` (``npm ci``); nothing
of it is kept in the repository.
"""
from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

HERE = Path(__file__).resolve().parent
WEB = HERE / "web"
ANCHOR_DIR = HERE / "anchors"
#: Default anchors: "one particularly easy and one particularly hard structure" shown first.
DEFAULT_ANCHORS = (ANCHOR_DIR / "ANCHOR-EASY.yaml", ANCHOR_DIR / "ANCHOR-HARD.yaml")
TASKS = ("difficulty", "time", "build")
#: The paper's questions (Procedure), one per estimation task.
QUESTIONS = {"difficulty": "How difficult would it be to do this?",
             "time": "How long would it take to make this?"}
#: The dataset name of each task in the human-data format (docs/human-data.md).
DATASET = {"difficulty": "difficulty", "time": "time", "build": "build"}
#: Columns of every response row a study writes, in this order (docs/experiment.md).
COLUMNS = ("study", "task", "participant", "participant_source", "simulated", "condition", "phase", "position",
           "trial", "pair", "level", "first_in_pair", "response", "unit", "rt_ms", "slider_start", "collapses",
           "discarded_ms", "n_trials", "time_elapsed_ms", "build", "jspsych")
#: jsPsych's files copied from node_modules into a study folder (lib/).
JSPSYCH_FILES = {
    "jspsych/dist/index.browser.min.js": "jspsych.js",
    "jspsych/css/jspsych.css": "jspsych.css",
    "@jspsych/plugin-html-slider-response/dist/index.browser.min.js": "plugin-html-slider-response.js",
    "@jspsych/plugin-html-keyboard-response/dist/index.browser.min.js": "plugin-html-keyboard-response.js",
    "@jspsych/plugin-html-button-response/dist/index.browser.min.js": "plugin-html-button-response.js",
    "@jspsych/plugin-instructions/dist/index.browser.min.js": "plugin-instructions.js",
    "@jspsych/plugin-preload/dist/index.browser.min.js": "plugin-preload.js",
}
#: Slider of the Time Estimation task: 0 to this many seconds (the paper does not say).
TIME_MAX_S = 180


#: How this package names itself on the terminal.
PROG = "python -m stimuli.experiment"


class StudyError(ValueError):
    """A study cannot be built from these inputs (anchors, stimuli, output folder)."""


# ----------------------------------------------------------------------------- order and counterbalancing


_M = 0xFFFFFFFF


def mulberry32(seed: int):
    """The 32-bit generator study.js uses (mulberry32), bit for bit: a function
    returning floats in [0, 1)."""
    state = seed & _M

    def draw() -> float:
        nonlocal state
        state = (state + 0x6D2B79F5) & _M
        t = state
        t = ((t ^ (t >> 15)) * (t | 1)) & _M
        t ^= (t + (((t ^ (t >> 7)) * (t | 61)) & _M)) & _M
        return ((t ^ (t >> 14)) & _M) / 4294967296

    return draw


def block_seed(order_seed: int, block: int) -> int:
    """Seed of one block of participants: (order_seed * 0x9E3779B1 + block) mod 2^32."""
    return (order_seed * 0x9E3779B1 + block) & _M


def units_of(trials: list[dict]) -> tuple[list[list[dict]], bool]:
    """Units whose order is randomised: each easy/hard pair with both trials present
    (easy first), then every other trial alone; and whether any pair exists."""
    by_pair: dict[int, dict[str, dict]] = {}
    for t in trials:
        if t.get("pair") is not None:
            by_pair.setdefault(t["pair"], {})[t["level"]] = t
    pairs = [[p["E"], p["H"]] for _, p in sorted(by_pair.items()) if set(p) == {"E", "H"}]
    paired = {t["id"] for u in pairs for t in u}
    singles = [[t] for t in trials if t["id"] not in paired]
    return pairs + singles, bool(pairs)


def trial_order(trials: list[dict], participant: int, order_seed: int = 0) -> list[dict]:
    """The trials participant number `participant` sees, in order, as study.js draws them.

    With pairs: participants 2k and 2k + 1 form block k. The block's generator
    mulberry32(block_seed(order_seed, k)) shuffles the units (pairs and lone trials)
    by Fisher-Yates, then draws, pair by pair in pair-number order, whether E comes
    first (draw < 0.5). Participant 2k follows those draws (condition 0); 2k + 1
    the opposite within every pair (condition 1). So each pair's order is
    counterbalanced exactly within every block, and the order of the pairs differs
    between blocks. Without pairs: every participant is their own block (the
    generator of block n shuffles the trials) and condition is 0.
    Returns dicts with the trial's fields plus position (1-based), condition and
    first_in_pair (E, H or empty for a lone trial).
    """
    units, has_pairs = units_of(trials)
    block, condition = (participant // 2, participant % 2) if has_pairs else (participant, 0)
    draw = mulberry32(block_seed(order_seed, block))
    units = list(units)
    for i in range(len(units) - 1, 0, -1):
        j = int(draw() * (i + 1))
        units[i], units[j] = units[j], units[i]
    easy_first = {}
    for u in sorted((u for u in units if len(u) == 2), key=lambda u: u[0]["pair"]):
        easy_first[u[0]["pair"]] = (draw() < 0.5) != bool(condition)
    out = []
    for u in units:
        if len(u) == 2:
            first = "E" if easy_first[u[0]["pair"]] else "H"
            seq = u if first == "E" else u[::-1]
        else:
            first, seq = "", u
        for t in seq:
            out.append({**t, "position": len(out) + 1, "condition": condition, "first_in_pair": first})
    return out


# ----------------------------------------------------------------------------- jsPsych from npm


def jspsych_version() -> str:
    """The jsPsych version pinned in package.json."""
    return json.loads((HERE / "package.json").read_text())["dependencies"]["jspsych"]


def node_modules() -> Path:
    """Where `npm ci` puts the study's packages: stimuli/experiment/node_modules, or
    $LGP_NPM_PREFIX/node_modules when that is set (a copy outside the source tree)."""
    prefix = os.environ.get("LGP_NPM_PREFIX")
    return (Path(prefix) if prefix else HERE) / "node_modules"


def _installed(nm: Path) -> bool:
    try:
        have = json.loads((nm / "jspsych" / "package.json").read_text())["version"]
    except (OSError, ValueError, KeyError):
        return False
    return have == jspsych_version() and all((nm / src).exists() for src in JSPSYCH_FILES)


def ensure_jspsych(log=None) -> Path:
    """node_modules holding the pinned jsPsych; runs ``npm ci`` (from package-lock.json)
    the first time. Raises StudyError in one line when npm is missing or fails."""
    log = log or (lambda m: print(m, file=sys.stderr, flush=True))
    nm = node_modules()
    if _installed(nm):
        return nm
    npm = shutil.which("npm")
    if npm is None:
        raise StudyError(f"jsPsych {jspsych_version()} is not installed in {nm} and npm is not on PATH: install Node.js "
                         f"(apt-get install nodejs npm), then run: npm ci --prefix {HERE}")
    prefix = nm.parent
    if prefix != HERE:
        prefix.mkdir(parents=True, exist_ok=True)
        for name in ("package.json", "package-lock.json"):
            shutil.copyfile(HERE / name, prefix / name)
    log(f"{PROG}: installing jsPsych {jspsych_version()} from the npm registry (npm ci --prefix {prefix})")
    run = subprocess.run([npm, "ci", "--prefix", str(prefix), "--no-audit", "--no-fund"], capture_output=True, text=True)
    if run.returncode != 0 or not _installed(nm):
        last = (run.stderr or run.stdout).strip().splitlines()[-1:] or ["no output"]
        raise StudyError(f"npm ci --prefix {prefix} failed (exit {run.returncode}): {last[0]}")
    return nm


# ----------------------------------------------------------------------------- building a study folder


@dataclass
class StudyPlan:
    """What a study folder is built from (validated before anything is written)."""

    task: str
    trials: list  # stimuli.Trial
    anchors: list  # stimuli.Trial (rendered for every task, shown in the estimation tasks)
    seed: int
    order_seed: int
    has_pairs: bool


def load_anchor(path: str | Path, role: str, trial_ids: set[str]):
    """An anchor trial file, validated like every trial file (StudyError naming the file)."""
    import stimuli

    from lgp.cli import path_kind

    p = Path(path)
    kind = path_kind(p) or ("a directory" if p.is_dir() else None)
    if kind is not None:  # a FIFO, a device, a loop of links: say what it is, never open it
        raise StudyError(f"--anchor-{role} {path}: {kind}, not a trial file (a regular file; the default anchors "
                         f"are in {ANCHOR_DIR})")
    if not p.is_file():
        raise StudyError(f"--anchor-{role} {path}: no such file (the default anchors are in {ANCHOR_DIR})")
    try:
        trial = stimuli.load_file(p)
    except stimuli.StimulusError as e:
        raise StudyError(f"--anchor-{role} {path}: not a valid trial file: {e}") from None
    if trial.id in trial_ids:
        raise StudyError(f"--anchor-{role} {path}: its id {trial.id} is one of the study's trials; an anchor is shown first and not analysed, give it another id")
    return trial


def study_id(trials, anchors, seed: int, order_seed: int) -> str:
    """Identity of a study: the trial files, the anchors, the layout seed and the order
    seed. The three tasks built from the same inputs share it (their data import
    together); data of another stimulus set or seed do not."""
    h = hashlib.sha256()
    for t in [*trials, *anchors]:
        h.update(f"{t.id}:{t.digest}\n".encode())
    h.update(f"seed={seed};order_seed={order_seed}".encode())
    return h.hexdigest()[:12]


def plan_study(task: str, stimuli_dir=None, anchor_files=DEFAULT_ANCHORS, seed: int = 0, order_seed: int = 0) -> StudyPlan:
    import stimuli

    if task not in TASKS:
        raise StudyError(f"unknown task {task!r}; expected one of {', '.join(TASKS)}")
    if stimuli_dir is not None and not stimuli.trial_ids(stimuli_dir):
        raise StudyError(f"--stimuli {stimuli_dir}: no trial files (*.yaml) there")
    trials = stimuli.load_all(stimuli_dir)
    ids = {t.id for t in trials}
    # The build console shows no anchors, but its pictures are rendered with them, so
    # that every task of a study shares one render folder.
    anchors = [load_anchor(f, role, ids) for f, role in zip(anchor_files, ("easy", "hard"))]
    if anchors[0].id == anchors[1].id:
        raise StudyError(f"--anchor-easy and --anchor-hard have the same id {anchors[0].id}")
    _, has_pairs = units_of([_trial_entry(t) for t in trials])
    return StudyPlan(task, trials, anchors, seed, order_seed, has_pairs)


def _trial_entry(t) -> dict:
    return {"id": t.id, "pair": t.pair, "level": t.level, "start": f"img/{t.id}-A.png", "finish": f"img/{t.id}-B.png",
            "description": t.description}


def _render(plan: StudyPlan, size, jobs: int, log) -> tuple[Path, dict]:
    from stimuli.render import cache_folder, picture_store, render_trials

    every = [*plan.trials, *plan.anchors]
    # A of a trial of pair p is sample p - 1 of the seed: a pair's two trials share
    # their Start, no two pairs do (docs/experiment.md, section 8).
    where = cache_folder(every, plan.seed, size, "pair")
    return where, render_trials(every, where, plan.seed, size, jobs, log=lambda m: log(f"{PROG}: pictures: {m}"), layout="pair",
                                store=picture_store())


#: What every build writes at the top of a study folder (besides study.json, lib/ and img/).
BUILT = ("index.html", "config.js", "study.js", "style.css")
MANIFEST = "study.json"


def is_study_manifest(data: dict) -> bool:
    """A study.json written by this builder: the study, its build and its files with their sha256."""
    return isinstance(data.get("files"), dict) and isinstance(data.get("study"), str) and "build" in data


def check_output_dir(out: Path, into_existing: bool = False) -> dict[str, set[str]]:
    """Refuse a folder this build may not write into; return the earlier build's
    listed files (lgp.owned.manifest_entries, {} for none). A rebuild deletes only
    the earlier build's own files (listed in its study.json, same sha256): the
    study's collected data (data/*.csv, anything it did not build) stay. A folder
    with other files and no study.json is refused unless `into_existing`; a
    study.json of something else is never replaced; a file the build writes that is
    there and not the earlier build's (an index.html edited by hand) refuses it."""
    from lgp import owned

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise StudyError(f"--out {out}: exists and is not a folder")
    if not out.exists():
        return {}
    status, data = owned.read_manifest(out / MANIFEST, is_study_manifest)
    if status == "foreign":
        raise StudyError(f"--out {out}: its {MANIFEST} was not written by python -m stimuli.experiment (or is damaged): "
                         "refusing to replace it; give another --out")
    entries = owned.manifest_entries(data) if data else {}
    if status == "absent":
        foreign = owned.foreign_entries(out, skip={".lgp-run.lock"})
        if foreign and not into_existing:
            raise StudyError(f"--out {out}: the folder is not empty and holds no study ({MANIFEST}): refusing to write "
                             f"into it ({owned.describe(foreign)}); give an empty or new folder, or --into-existing to "
                             "add the study beside those files (nothing there is deleted or overwritten)")
    bad = owned.collisions(out, list(BUILT), set(owned.own_files(out, entries)))
    if bad:
        raise StudyError(f"--out {out}: {owned.describe(bad)} there {'is' if len(bad) == 1 else 'are'} not the earlier "
                         f"build's (not listed in its {MANIFEST} with these contents); a rebuild would overwrite "
                         f"{'it' if len(bad) == 1 else 'them'}: move {'it' if len(bad) == 1 else 'them'} away or give "
                         "another --out")
    return entries


def build_study(plan: StudyPlan, out: str | Path, size=None, jobs: int = 2, jatos: bool = False,
                time_max: int = TIME_MAX_S, log=None, into_existing: bool = False) -> dict:
    """Write the study folder `out` (see docs/experiment.md); returns study.json's content.

    The build writes into a staging folder inside `out` and swaps it in at the end
    (lgp/owned.py): a rebuild replaces only the earlier build's own files, and a
    failed build leaves the earlier one byte-identical."""
    from lgp import owned
    from lgp.app.manifest import OutputLock, checked_before_the_lock
    from stimuli.render import DEFAULT_SIZE

    log = log or (lambda m: print(m, file=sys.stderr, flush=True))
    out = Path(out)
    checked_before_the_lock(check_output_dir, out, into_existing)
    nm = ensure_jspsych(log)
    renders, record = _render(plan, size or DEFAULT_SIZE, jobs, log)
    created = []
    folder = out
    while not folder.exists() and not folder.is_symlink() and folder != folder.parent:
        created.append(folder)
        folder = folder.parent
    out.mkdir(parents=True, exist_ok=True)
    done = False
    try:
        with OutputLock(out, f"python -m stimuli.experiment --task {plan.task} --out {out}"):
            earlier = check_output_dir(out, into_existing)  # again, under the lock
            owned.remove_stale_staging(out)
            tmp = owned.new_staging(out)
            try:
                manifest = _write_study(plan, tmp, nm, renders, record, jatos, time_max)
                try:
                    owned.swap_in(out, tmp, earlier, MANIFEST)
                except owned.ForeignFiles as e:  # a file appeared where the build writes: one line, exit 2
                    raise StudyError(str(e)) from None
            finally:
                owned.remove_staging(tmp)
        done = True
    finally:
        if not done:
            for folder in created:
                try:
                    folder.rmdir()
                except OSError:
                    break
    return manifest


def _write_study(plan: StudyPlan, tmp: Path, nm: Path, renders: Path, record: dict, jatos: bool, time_max: int) -> dict:
    """The study's files in the (staging) folder `tmp`, study.json last; its content."""
    from lgp import owned

    (tmp / "lib").mkdir(parents=True)
    (tmp / "img").mkdir()
    for src, dst in JSPSYCH_FILES.items():
        shutil.copyfile(nm / src, tmp / "lib" / dst)
    (tmp / "lib" / "README.txt").write_text(
        f"jsPsych {jspsych_version()} and its plugins (MIT license, https://www.jspsych.org), copied by\n"
        "python -m stimuli.experiment from the npm packages pinned in stimuli/experiment/package-lock.json.\n")
    shown = {t.id for t in plan.trials} | ({t.id for t in plan.anchors} if plan.task != "build" else set())
    for p in record["pictures"]:
        if p["trial"] in shown:
            shutil.copyfile(renders / p["file"], tmp / "img" / p["file"])
    sid = study_id(plan.trials, plan.anchors, plan.seed, plan.order_seed)
    config = {
        "study": sid,
        "task": plan.task,
        "dataset": DATASET[plan.task],
        "question": QUESTIONS.get(plan.task, ""),
        "slider": ({"min": 0, "max": 100, "start": 50, "step": 1, "labels": ["Very easy", "Very difficult"], "unit": "scale 0-100"}
                   if plan.task == "difficulty" else
                   {"min": 0, "max": time_max, "start": time_max // 2, "step": 1,
                    "labels": ["0 s"] + [f"{m} min" for m in range(1, time_max // 60 + 1)], "unit": "s"}
                   if plan.task == "time" else None),
        "order_seed": plan.order_seed,
        "layout_seed": plan.seed,
        "pair_counterbalancing": plan.has_pairs,
        "trials": [_trial_entry(t) for t in plan.trials],
        "anchors": [] if plan.task == "build" else [{**_trial_entry(t), "role": role} for t, role in zip(plan.anchors, ("easy", "hard"))],
        "columns": list(COLUMNS),
        "jspsych": jspsych_version(),
        "jatos": jatos,
        "renderer": record["renderer"],
        "camera": record["camera"],
        "cameras": record["cameras"],
        "picture_size": [record["camera"]["width"], record["camera"]["height"]],
    }
    build = hashlib.sha256(json.dumps(config, sort_keys=True).encode()).hexdigest()[:12]
    config["build"] = build
    (tmp / "config.js").write_text("// Written by python -m stimuli.experiment: this study's settings (docs/experiment.md).\n"
                                   f"window.LGP_STUDY = {json.dumps(config, indent=1)};\n")
    for name in ("study.js", "style.css"):
        shutil.copyfile(WEB / name, tmp / name)
    scripts = "".join(f'  <script src="lib/{dst}"></script>\n' for dst in JSPSYCH_FILES.values() if dst.endswith(".js"))
    if jatos:
        scripts = '  <script src="jatos.js"></script>\n' + scripts
    title = {"difficulty": "Block structures: how difficult?", "time": "Block structures: how long?",
             "build": "Build task console"}[plan.task]
    html = (WEB / "index.html").read_text().replace("{{TITLE}}", title).replace("{{SCRIPTS}}\n", scripts)
    (tmp / "index.html").write_text(html)
    files = owned.staged_files(tmp)
    manifest = {**{k: v for k, v in config.items() if k not in ("trials", "anchors")},
                "trials": config["trials"], "anchors": config["anchors"],
                "files": {f: hashlib.sha256((tmp / f).read_bytes()).hexdigest() for f in files}}
    (tmp / MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n")
    return manifest
