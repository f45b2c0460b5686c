"""Designing stimuli that can decide the question (issue 34): a grammar of tasks
(`grammar`), the checks every candidate passes or is discarded by (`checks`), a
cheap screen (`screen`: static centre-of-mass Monte Carlo risk, distance-based
effort), the design objective (`objective`), the run (`run`) and its outputs
(`outputs`). Command line: ``python -m stimuli.design --out DIR --trials 24 --seed S``.
docs/design.md.

This package sits above the stimuli loader: it imports the models (effort, risk)
and the application's cached stages, so ``stimuli`` itself never imports it.
"""
