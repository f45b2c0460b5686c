"""The application wing of lgp: what runs the paper's pipeline and shows its results.

The planning library (the rest of lgp/: scene, logic, KOMO, planner) imports
nothing from here; this wing is the only part of lgp/ that imports models/,
analysis/ and stimuli/ (tests/test_layers.py). Its commands are
``python -m lgp.reproduce`` (lgp/reproduce.py: the command line and `run`) and
``python -m lgp.show`` (lgp/show.py).

- config: RunConfig, the run's settings built once from the command line
- run: `run(config) -> RunResult`, the pipeline computed (the core stages, then
  every feature Stage of `run.stages()` with its renderer); result: RunResult,
  RunRecord, Stage, Section, Rendered
- write: `write_all(result, out)`, the writers (tables, analysis, sections,
  report, page), which read only the RunResult
- stages: the computing stages (target check, effort, risk) and their cache keys
- cache: results cached by a hash of their inputs, checked on read
- files: the one atomic writer of every output and cache entry
- manifest: what a run wrote (manifest.json, its parameters from RunConfig) and the compute time of its results
- progress: progress lines of long stages, wall time per stage
- build_risk: the --build-risk stage (risk through the build), its renderer build_risk_view
- sigma_from: the --sigma-from stage, its renderer sigma_from_view (report and page)
- participant_sigma: --per-participant-sigma's stage and renderer
- recovery: --recovery's SIMULATED studies, stage and renderer
- sensitivity: the --sensitivity sections (sensitivity.risk: by engine and fall rule;
  sensitivity.effort: by motion design), one stage
- report: report.md, and the pair tables in words
- page: the results page index.html (page.css, page.js; page_parts, page_cards,
  page_human: its pieces); charts: its inline SVG; pictures: its trial pictures;
  replays: its 3-D replays; view: replay and figure of one plan
"""
