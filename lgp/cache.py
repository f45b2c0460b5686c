"""Results cached by a hash of their inputs, written atomically.

A result is a pandas DataFrame stored as CSV under ``<root>/<kind>-<key>.csv``.
The key hashes everything the result depends on: the trial file's bytes, the
parameters, and the source code that computes it. A run killed half way leaves
only whole files behind (each is written to a temporary name, then renamed), so
the next run resumes where it stopped and computes nothing twice.
"""
from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Callable

import pandas as pd

ROOT = Path(__file__).resolve().parent.parent


def code_version(*patterns: str) -> str:
    """Hash of the source files matching `patterns` (globs relative to the repo root)."""
    h = hashlib.sha256()
    for pattern in patterns:
        for path in sorted(ROOT.glob(pattern)):
            if path.is_file() and "__pycache__" not in path.parts:
                h.update(path.relative_to(ROOT).as_posix().encode())
                h.update(path.read_bytes())
    return h.hexdigest()[:16]


def input_key(**inputs) -> str:
    """Stable hash of JSON-serialisable inputs."""
    return hashlib.sha256(json.dumps(inputs, sort_keys=True, default=str).encode()).hexdigest()[:20]


def write_csv_atomic(df: pd.DataFrame, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(fd, "w") as f:
            df.to_csv(f, index=False)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


class Cache:
    """Directory of cached DataFrames; ``enabled=False`` recomputes everything."""

    def __init__(self, root: str | Path, enabled: bool = True):
        self.root = Path(root)
        self.enabled = enabled
        self.hits = 0
        self.misses = 0

    def path(self, kind: str, key: str) -> Path:
        return self.root / f"{kind}-{key}.csv"

    def get(self, kind: str, key: str) -> pd.DataFrame | None:
        """The cached entry, or None when there is none (or the cache is off)."""
        path = self.path(kind, key)
        if self.enabled and path.exists():
            self.hits += 1
            return pd.read_csv(path, dtype={"trial": str})
        return None

    def put(self, kind: str, key: str, df: pd.DataFrame) -> pd.DataFrame:
        """Store a freshly computed entry (counted as a miss) and return it."""
        self.misses += 1
        write_csv_atomic(df, self.path(kind, key))
        return df

    def get_or_compute(self, kind: str, key: str, compute: Callable[[], pd.DataFrame]) -> pd.DataFrame:
        path = self.path(kind, key)
        if self.enabled and path.exists():
            self.hits += 1
            return pd.read_csv(path, dtype={"trial": str})
        self.misses += 1
        df = compute()
        write_csv_atomic(df, path)
        return df
