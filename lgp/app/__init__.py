"""The application wing of lgp: what runs the paper's pipeline and shows its results.

The planning library (the rest of lgp/: scene, logic, KOMO, planner) imports
nothing from here; this wing is the only part of lgp/ that imports models/,
analysis/ and stimuli/ (tests/test_layers.py). Its commands are
``python -m lgp.reproduce`` (lgp/reproduce.py) and ``python -m lgp.show``
(lgp/show.py).

- cache: results cached by a hash of their inputs, checked on read, written atomically
- manifest: what a run wrote (manifest.json) and the compute time of its results
- progress: progress lines of long stages
- build_risk: the --build-risk stage (risk through the build) and its outputs
- sensitivity: the --sensitivity sections (risk by engine and fall rule, effort by motion design)
- page: the results page index.html; replays: its 3-D replays; view: replay and figure of one plan
"""
