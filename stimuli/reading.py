"""Reading a trial file: its bytes through the one bounded reader, and YAML without
anchors, aliases or duplicate keys, with errors in one line that keeps the position."""
from __future__ import annotations

import re
from pathlib import Path

import yaml

from lgp.scene import StimulusError

#: Largest trial file read (bytes): a 10,000-block trial is about 0.6 MB.
MAX_TRIAL_BYTES = 2_000_000
#: Most characters of a number in a trial file: coordinates in metres need a few
#: dozen; a 5000-digit integer would fail inside Python's int conversion.
MAX_NUMBER_CHARS = 40
_LONG_NUMBER = re.compile(r"[-+]?[0-9][0-9_]*(\.[0-9_]*)?([eE][-+]?[0-9]+)?|[-+]?\.[0-9_]+([eE][-+]?[0-9]+)?|0[xXoObB][0-9a-fA-F_]+")


class _TrialLoader(yaml.SafeLoader):
    """YAML's safe loader without anchors and aliases: a trial file never needs
    them, and aliases let a few lines expand into gigabytes ("billion laughs")."""

    def compose_node(self, parent, index):
        _refuse_anchors(self.name, self.peek_event())
        return super().compose_node(parent, index)


def _refuse_anchors(where: str, event) -> None:
    if isinstance(event, yaml.AliasEvent) or getattr(event, "anchor", None) is not None:
        raise StimulusError(f"{where}: line {event.start_mark.line + 1}: YAML anchors and aliases (&name, *name) "
                            "are not allowed in trial files")


def _check_events(where: str, events) -> None:
    """One pass over the parse events, before anything is built: no anchors or
    aliases, and no key given twice in one mapping (YAML would keep the last value
    silently; a trial file that says ``count`` twice is a mistake)."""
    stack: list[list] = []  # per open collection: [keys seen (None for a sequence), next node is a key]
    for event in events:
        _refuse_anchors(where, event)
        if (isinstance(event, yaml.ScalarEvent) and not event.style and len(event.value) > MAX_NUMBER_CHARS
                and _LONG_NUMBER.fullmatch(event.value)):
            raise StimulusError(f"{where}: line {event.start_mark.line + 1}: a number of {len(event.value)} characters "
                                f"({event.value[:20]}...), more than the {MAX_NUMBER_CHARS} a trial file's number may have "
                                "(stimuli.reading.MAX_NUMBER_CHARS)")
        if isinstance(event, (yaml.ScalarEvent, yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            top = stack[-1] if stack else None
            if top is not None and top[0] is not None:
                if top[1] and isinstance(event, yaml.ScalarEvent):
                    if event.value in top[0]:
                        raise StimulusError(f"{where}: line {event.start_mark.line + 1}: key {event.value!r} given twice "
                                            f"in one mapping (first on line {top[0][event.value]}); each field once")
                    top[0][event.value] = event.start_mark.line + 1
                top[1] = not top[1]
            if isinstance(event, yaml.MappingStartEvent):
                stack.append([{}, True])
            elif isinstance(event, yaml.SequenceStartEvent):
                stack.append([None, False])
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            stack.pop()


def _at(mark) -> str:
    return f"line {mark.line + 1}, column {mark.column + 1}"


def yaml_error_line(e: yaml.YAMLError) -> str:
    """A YAML error as one line that keeps its position ("not valid YAML at line 8,
    column 11: mapping values are not allowed here"); PyYAML's own text spreads the
    position over further lines, which a one-line CLI error would cut off."""
    problem = getattr(e, "problem", None)
    mark = getattr(e, "problem_mark", None)
    if not problem or mark is None:
        return "not valid YAML: " + " ".join(str(e).split())
    text = f"not valid YAML at {_at(mark)}: {problem}"
    context, context_mark = getattr(e, "context", None), getattr(e, "context_mark", None)
    if context:
        text += f" ({context}" + (f" at {_at(context_mark)}" if context_mark is not None else "") + ")"
    return text


def safe_load_yaml(text: str, where: str):
    """yaml.safe_load without anchors, aliases or duplicate keys; libyaml's C parser
    when present (a first pass over the parse events refuses them before anything
    is built)."""
    if getattr(yaml, "__with_libyaml__", False):
        _check_events(where, yaml.parse(text, Loader=yaml.CSafeLoader))
        return yaml.load(text, Loader=yaml.CSafeLoader)
    _check_events(where, yaml.parse(text, Loader=yaml.SafeLoader))
    loader = _TrialLoader(text)
    loader.name = where
    try:
        return loader.get_single_data()
    finally:
        loader.dispose()


def read_trial_bytes(path: str | Path) -> bytes:
    """The bytes of a trial file: a regular file of at most MAX_TRIAL_BYTES, read
    through the one bounded reader (lgp.inputs: no FIFO, device or endless file)."""
    from lgp.inputs import InputFileError, read_bounded

    try:
        return read_bounded(path, MAX_TRIAL_BYTES, "trial file", limit_name="stimuli.reading.MAX_TRIAL_BYTES")
    except InputFileError as e:
        raise StimulusError(str(e)) from None
