"""Results cached by a hash of their inputs, checked on every read, written atomically.

A result is a pandas DataFrame stored under ``<root>/<kind>-<key>.csv``: one header
line ``# lgp.cache v1 rows=<n> sha256=<hex>`` (the row count and the SHA-256 of the
bytes that follow), then the CSV (``pd.read_csv(path, skiprows=1)`` reads it).

The key hashes everything the result depends on (the caller passes it to
`input_key`): the trial file's bytes, the parameters, the source of every project
module the computation imports (`modules_digest`, found by reading the imports, so
it cannot drift from the code), the data files it reads (`files_digest`), the
versions of the numerical libraries (`library_versions`) and, for risk, the physics
engine's settings.

A run killed half way leaves only whole files behind (each is written to a
temporary name, then renamed), so the next run resumes where it stopped. An entry
that is damaged anyway (truncated, emptied, garbled, lines lost, not UTF-8) fails
its checksum: it is reported in one line on stderr and recomputed, never used.
An entry whose checksum holds is still checked against its kind's schema
(`ENTRY_SCHEMAS`: columns, types, finite values in range, and the rows the
caller expects), so an entry re-signed with wrong contents (``effort: abc``,
``-1e308``) is recomputed too, whatever its checksum says.
`Cache.counts` says how many lookups were hits, misses and recomputed entries.
"""
from __future__ import annotations

import ast
import hashlib
import io
import json
import math
import platform
import re
import sys
from collections import Counter
from importlib import metadata
from pathlib import Path
from typing import Callable, Iterable

import pandas as pd

from lgp.app.files import write_bytes_atomic, write_csv_atomic  # noqa: F401  (the one atomic writer)

ROOT = Path(__file__).resolve().parents[2]  # lgp/app/cache.py -> the repository
#: The project's top-level packages: imports of anything else are libraries.
PACKAGES = ("lgp", "models", "stimuli", "analysis")
#: Libraries whose version can change a number the pipeline computes (the cache keys).
LIBRARIES = ("mujoco", "drake", "numpy", "scipy", "pandas")
#: Those and the libraries that only draw or read files: what a run's record names.
RECORDED_LIBRARIES = (*LIBRARIES, "matplotlib", "pyyaml")


# ----------------------------------------------------------------------------- what a result depends on


def library_versions(names: Iterable[str] = LIBRARIES) -> dict[str, str]:
    """Installed version of each library (and of Python); "not installed" if absent."""
    versions = {"python": platform.python_version()}
    for name in names:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


def module_path(module: str, root: Path = ROOT) -> Path | None:
    """Source file of project module `module` under `root`, None if there is none."""
    base = root.joinpath(*module.split("."))
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


def module_imports(module: str, root: Path = ROOT) -> list[tuple[str, bool]]:
    """Project modules that `module` imports, read from its source with `ast`, as
    (imported module, at_import_time) pairs: at_import_time is False for an import
    inside a function (it runs only when the function is called).

    ``import a.b`` and ``from a import b`` (b a submodule) import ``a.b``;
    ``from a.b import name`` imports ``a.b``. Relative imports are resolved.
    Parent packages that Python runs on the way (``a`` for ``a.b``) are not listed.
    """
    path = module_path(module, root)
    if path is None:
        raise ModuleNotFoundError(f"no project module {module!r} under {root}")
    source = path.read_bytes()
    memo = (module, path.name, hashlib.sha256(source).digest())  # same bytes, same statements
    if memo not in _STATEMENTS:
        _STATEMENTS[memo] = _import_statements(module, path, source)
    found: dict[str, bool] = {}

    def add(name: str, at_import_time: bool) -> None:
        if name.split(".")[0] in PACKAGES and module_path(name, root) is not None:
            found[name] = found.get(name, False) or at_import_time

    # Which names are modules is decided now, from the files as they are.
    for source_module, names, at_import_time in _STATEMENTS[memo]:
        if names is None:  # import a.b
            add(source_module, at_import_time)
            continue
        for name in names:
            sub = f"{source_module}.{name}"
            add(sub if name != "*" and module_path(sub, root) is not None else source_module, at_import_time)
    return sorted(found.items())


#: Parsed import statements by (module, file name, SHA-256 of the source): a run
#: asks for the same closures once per trial, and parsing every module each time
#: cost 0.17 s per trial. Only the parse is kept; the files are looked at anew.
_STATEMENTS: dict[tuple[str, str, bytes], list[tuple[str, tuple[str, ...] | None, bool]]] = {}


def _import_statements(module: str, path: Path, source: bytes) -> list[tuple[str, tuple[str, ...] | None, bool]]:
    """(module, imported names or None for ``import module``, at import time) of
    every import statement of the source, relative imports resolved."""
    tree = ast.parse(source, filename=str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out: list[tuple[str, tuple[str, ...] | None, bool]] = []

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.Import):
                out.extend((alias.name, None, not in_function) for alias in child.names)
            elif isinstance(child, ast.ImportFrom):
                if child.level:
                    base = package.split(".")
                    base = base[: len(base) - (child.level - 1)]
                    source_module = ".".join(base + ([child.module] if child.module else []))
                else:
                    source_module = child.module
                out.append((source_module, tuple(alias.name for alias in child.names), not in_function))
            visit(child, in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)))

    visit(tree, False)
    return out


def _parents(module: str) -> list[str]:
    parts = module.split(".")
    return [".".join(parts[:k]) for k in range(1, len(parts))]


def import_closure(*roots: str, root: Path = ROOT) -> list[str]:
    """Every project module that importing `roots` and calling their functions can run.

    A module imported by name contributes all its imports, those inside functions
    too (the computation may call them). A package run only because a submodule was
    imported (``lgp`` for ``lgp.scene``) contributes its import-time imports: its
    functions run only if some module imports the package by name.
    """
    mode: dict[str, str] = {}  # module -> "full" | "parent"
    todo: list[str] = []

    def reach(module: str, how: str) -> None:
        if mode.get(module) == "full" or mode.get(module) == how:
            return
        mode[module] = how
        todo.append(module)
        for parent in _parents(module):
            if parent not in mode:
                reach(parent, "parent")

    for name in roots:
        reach(name, "full")
    while todo:
        module = todo.pop()
        full = mode[module] == "full"
        for imported, at_import_time in module_imports(module, root):
            if full or at_import_time:
                reach(imported, "full")
    return sorted(mode)


def modules_digest(*roots: str, root: Path = ROOT) -> str:
    """Hash of the source of every module in `import_closure(*roots)`: editing any
    file the computation can run changes it; editing any other file does not."""
    h = hashlib.sha256()
    for module in import_closure(*roots, root=root):
        path = module_path(module, root)
        h.update(path.relative_to(root).as_posix().encode() + b"\0")
        h.update(hashlib.sha256(path.read_bytes()).digest())
    return h.hexdigest()[:16]


def files_digest(*patterns: str, root: Path = ROOT) -> str:
    """Hash of the data files matching `patterns` (globs relative to the repo root)."""
    h = hashlib.sha256()
    for pattern in patterns:
        for path in sorted(root.glob(pattern)):
            if path.is_file() and "__pycache__" not in path.parts:
                h.update(path.relative_to(root).as_posix().encode() + b"\0")
                h.update(hashlib.sha256(path.read_bytes()).digest())
    return h.hexdigest()[:16]


def input_key(**inputs) -> str:
    """Stable hash of JSON-serialisable inputs."""
    return hashlib.sha256(json.dumps(inputs, sort_keys=True, default=str).encode()).hexdigest()[:20]


# ----------------------------------------------------------------------------- entries

_HEADER = re.compile(rb"# lgp\.cache v2 kind=([A-Za-z0-9_.-]*) key=([A-Za-z0-9_.-]*) trial=(\S*) rows=(\d+) sha256=([0-9a-f]{64})")
_OLD_HEADER = re.compile(rb"# lgp\.cache v1 rows=(\d+) sha256=([0-9a-f]{64})")
#: Largest cache entry read (bytes); a risk entry of the full run is about 2 kB,
#: a build-risk stage table under 10 MB.
MAX_ENTRY_BYTES = 256 * 2**20


class DamagedEntry(ValueError):
    """A cache entry whose bytes are not what was written (the message says how)."""


def _trial_of(df: pd.DataFrame) -> str:
    """The one trial id of a table's ``trial`` column ("" when there is none or several)."""
    if "trial" not in df.columns or not len(df):
        return ""
    ids = pd.unique(df["trial"].astype(str))
    return str(ids[0]) if len(ids) == 1 and re.fullmatch(r"[A-Za-z0-9_-]+", str(ids[0])) else ""


def entry_bytes(df: pd.DataFrame, kind: str = "", key: str = "") -> bytes:
    """A cache entry: the header line (what it is: its kind, its key, its trial;
    and its row count and the SHA-256 of the CSV), then the CSV of `df`."""
    body = df.to_csv(index=False).encode()
    return (b"# lgp.cache v2 kind=%s key=%s trial=%s rows=%d sha256=%s\n"
            % (kind.encode(), key.encode(), _trial_of(df).encode(), len(df), hashlib.sha256(body).hexdigest().encode())
            + body)


def read_entry(path: Path, dtype=None, kind: str | None = None, key: str | None = None,
               within: Path | None = None) -> pd.DataFrame:
    """The DataFrame of a cache entry, or DamagedEntry if its checksum or row count
    fails, or if it is not the entry of `kind` and `key` (when given): an entry
    copied over another's has the right checksum but the wrong key. Read through
    the bounded reader (a regular file of at most MAX_ENTRY_BYTES, inside `within`)."""
    from lgp.inputs import read_bounded

    data = read_bounded(path, MAX_ENTRY_BYTES, "cache entry", within=within, limit_name="lgp.app.cache.MAX_ENTRY_BYTES")
    header, newline, body = data.partition(b"\n")
    match = _HEADER.fullmatch(header)
    if newline and _OLD_HEADER.fullmatch(header):
        raise DamagedEntry("written by an older version, without its key (lgp.cache v1)")
    if not newline or match is None:
        raise DamagedEntry(f"no checksum header ({len(data)} bytes)")
    if hashlib.sha256(body).hexdigest().encode() != match[5]:
        raise DamagedEntry(f"checksum mismatch ({len(body)} bytes of CSV)")
    if kind is not None and match[1].decode() != kind or key is not None and match[2].decode() != key:
        raise DamagedEntry(f"it holds the {match[1].decode()} entry {match[2].decode()}"
                           + (f" of trial {match[3].decode()}" if match[3] else "")
                           + f", not {kind} {key} (copied or renamed from another entry)")
    df = pd.read_csv(io.BytesIO(body), dtype=dtype)
    if len(df) != int(match[4]):  # only a hash collision gets here
        raise DamagedEntry(f"{len(df)} rows, header says {int(match[4])}")
    if _trial_of(df) != match[3].decode():
        raise DamagedEntry(f"its rows are of trial {_trial_of(df) or '(several)'}, its header says {match[3].decode() or '(none)'}")
    return df


#: What each kind of entry must hold, checked on every read after its checksum:
#: column -> "id" (a trial id), "bool" (True/False), or (kind, low, high): numbers
#: ("float" or "int"), finite, low <= value <= high (None: no bound). A column
#: named without "?" must be present; one with "?" is checked when present; others
#: are not looked at.
ENTRY_SCHEMAS: dict[str, dict[str, object]] = {
    # effort in J*s: the paper's trials need 0.1-10; 1e6 is far past any plan
    "effort": {"trial": "id", "effort": ("float", 0.0, 1e6), "sample?": ("int", 0, None),
               "n_actions?": ("int", 0, 10_000), "solve_time?": ("float", 0.0, None)},
    "riskruns": {"trial": "id", "sigma": ("float", 0.0, 1.0), "fell": "bool", "run?": ("int", 0, None),
                 "fall_threshold?": ("float", 0.0, None)},
    "sensitivity": {"trial": "id", "sigma?": ("float", 0.0, 1.0), "fell?": "bool"},
    "stable": {"trial": "id", "stable": "bool"},
}


def check_entry(kind: str, df: pd.DataFrame, rows: int | None = None) -> pd.DataFrame:
    """`df` with its numeric columns as numbers, if it obeys ENTRY_SCHEMAS[kind]
    (and has `rows` rows when given); else DamagedEntry naming the column, row
    and value. Kinds without a schema pass as they are."""
    if rows is not None and len(df) != rows:
        raise DamagedEntry(f"{len(df)} rows, this run expects {rows}")
    schema = ENTRY_SCHEMAS.get(kind)
    if not schema:
        return df
    missing = [c for c in schema if not c.endswith("?") and c not in df.columns]
    if missing:
        raise DamagedEntry(f"column(s) {', '.join(missing)} missing (a {kind} entry has "
                           f"{', '.join(c for c in schema if not c.endswith('?'))})")
    out = df.copy()
    for column, rule in schema.items():
        column = column.rstrip("?")
        if column not in df.columns:
            continue
        col = df[column]
        if rule == "id":
            bad = ~col.astype(str).str.fullmatch(r"[A-Za-z0-9_-]{1,64}")
        elif rule == "bool":
            values = col.map(lambda v: {"True": True, "False": False, True: True, False: False, 1: True, 0: False}.get(
                v if not isinstance(v, str) else v.strip(), None))
            bad = values.isna()
            if not bad.any():
                out[column] = values.astype(bool)
        else:
            number, low, high = rule
            values = pd.to_numeric(col, errors="coerce").astype(float)
            bad = ~values.map(math.isfinite)
            if low is not None:
                bad |= values < low
            if high is not None:
                bad |= values > high
            if number == "int":
                bad |= values.map(lambda v: math.isfinite(v) and v != int(v))
            if not bad.any():
                out[column] = values.astype(int) if number == "int" else values
        if bad.any():
            k = int(bad.to_numpy().nonzero()[0][0])
            what = {"id": "a trial id", "bool": "True or False"}.get(rule) if isinstance(rule, str) else (
                f"a finite {'whole number' if rule[0] == 'int' else 'number'}"
                + (f" in [{rule[1]:g}, {rule[2]:g}]" if rule[2] is not None else f" >= {rule[1]:g}"))
            raise DamagedEntry(f"row {k + 1}: {column} {str(col.iloc[k])!r} is not {what} ({int(bad.sum())} such row(s)); "
                               "its checksum holds, its contents do not")
    return out


class Cache:
    """Directory of cached DataFrames; ``enabled=False`` recomputes everything
    (and rewrites the entries).

    Every lookup is counted by kind and outcome in `counts`: ``"hit"`` (a sound
    entry, used), ``"miss"`` (no entry, or the cache disabled) or ``"recomputed"``
    (an entry failed its checksum, was reported on stderr, and is to be computed
    again); `damaged` lists the paths of those entries.
    """

    OUTCOMES = ("hit", "miss", "recomputed")

    def __init__(self, root: str | Path, enabled: bool = True, dtype=None):
        self.root = Path(root)
        self.enabled = enabled
        self.dtype = {"trial": str} if dtype is None else dtype
        self.counts: Counter = Counter()  # (kind, outcome) -> lookups
        #: (kind, "hit" | "miss") of files kept beside the tables (the page's pictures
        #: and replays), counted apart from `counts`, which are about computed results.
        self.files: Counter = Counter()
        self.damaged: list[Path] = []

    def count(self, outcome: str, kind: str | None = None) -> int:
        """Lookups with `outcome`, of entries of `kind` (all kinds if None)."""
        return sum(n for (k, o), n in self.counts.items() if o == outcome and kind in (None, k))

    @property
    def hits(self) -> int:
        return self.count("hit")

    @property
    def misses(self) -> int:
        return self.count("miss")

    @property
    def recomputed(self) -> int:
        return self.count("recomputed")

    def summary(self) -> str:
        """One line: hits, misses and recomputed entries per kind."""
        kinds = sorted({k for k, _ in self.counts})
        return "; ".join(f"{kind} " + ", ".join(f"{self.count(o, kind)} {o}" for o in self.OUTCOMES) for kind in kinds) or "no lookups"

    def path(self, kind: str, key: str) -> Path:
        return self.root / f"{kind}-{key}.csv"

    @property
    def computed(self) -> int:
        """Results computed by this run: misses and damaged entries recomputed."""
        return self.misses + self.recomputed

    def get(self, kind: str, key: str, rows: int | None = None) -> pd.DataFrame | None:
        """The cached table, or None when it must be computed (absent, disabled or
        damaged: a failed checksum, or contents that break ENTRY_SCHEMAS[kind], or
        not `rows` rows when given)."""
        path = self.path(kind, key)
        if not self.enabled or not (path.exists() or path.is_symlink()):
            self.counts[kind, "miss"] += 1
            return None
        try:
            df = check_entry(kind, read_entry(path, dtype=self.dtype, kind=kind, key=key, within=self.root), rows)
        except (DamagedEntry, OSError, ValueError, UnicodeDecodeError, pd.errors.ParserError) as e:
            print(f"lgp.cache: damaged entry {path}: {e}; recomputing it", file=sys.stderr, flush=True)
            self.counts[kind, "recomputed"] += 1
            self.damaged.append(path)
            return None
        self.counts[kind, "hit"] += 1
        return df

    def put(self, kind: str, key: str, df: pd.DataFrame) -> pd.DataFrame:
        """Write `df` as the entry (kind, key), atomically, with its checksum; return `df`."""
        write_bytes_atomic(entry_bytes(df, kind, key), self.path(kind, key))
        return df

    def get_or_compute(self, kind: str, key: str, compute: Callable[[], pd.DataFrame]) -> pd.DataFrame:
        df = self.get(kind, key)
        return df if df is not None else self.put(kind, key, compute())
