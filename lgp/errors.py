"""The project's error for bad input that has no more specific class.

A check at a boundary (a count, a sigma, a profile name, a results folder) raises
`InputError` naming the value and the rule broken. Like every exception class of
the project (StimulusError, HumanDataError, PlanningError, ...), a command line
prints it in one line (lgp.cli.run_cli); a plain ValueError, wherever raised, is
a bug and keeps its traceback. InputError is a ValueError, so callers that catch
ValueError keep working. Ground floor: it imports nothing.
"""
from __future__ import annotations


class InputError(ValueError):
    """A value the caller gave breaks a rule (the message names both)."""
