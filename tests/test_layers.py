"""The project is a layered house: every module imports only from its own layer or
below, and no project modules import each other in a cycle. Imports are read from
the source with `ast` (lgp.app.cache.module_imports), those inside functions too.

lgp/ holds two wings: the planning library (scene, logic, KOMO, planner) and the
application wing (lgp/app/ with the commands lgp.reproduce and lgp.show). No module
of the library imports the wing, and only the wing imports models/, analysis/ or
stimuli/ (`wing_imports`).

The rule is written once, here, as an ordered list of layers (lowest first) of
module-name patterns. A module may import modules of lower layers freely and of
its own layer as long as no cycle results; a layer with a `may_import` list may
import only those layers (and its own). Patterns of the application layer win over
the others (``models.risk.__main__`` is a CLI, not a model), and an exact name wins
over a wildcard.
"""
from __future__ import annotations

from fnmatch import fnmatchcase
from pathlib import Path

from lgp.app.cache import PACKAGES, ROOT, module_imports

#: lgp's application wing: the folder lgp/app/ and the two commands beside it.
APP_WING = ["lgp.app", "lgp.app.*", "lgp.reproduce", "lgp.show"]

#: (layer, module-name patterns, layers it may import besides its own; None = all lower)
LAYERS = [
    # lgp.cli (argument checks, one-line errors) is used by CLIs on every floor, so it sits here
    ("ground", ["lgp.paper", "lgp.scene", "lgp.scene.*", "lgp.geometry", "lgp.executor", "lgp.executor.*", "lgp.cli", "lgp.command_times", "lgp.inputs", "lgp.atomic", "lgp.errors", "lgp.owned"], None),
    ("stimuli and logic", ["stimuli", "stimuli.start", "stimuli.reading", "stimuli.trial", "stimuli.mental_jenga", "lgp.assignment", "lgp.symbolic"], None),
    ("arm", ["lgp.arm"], None),
    ("KOMO", ["lgp.komo", "lgp.komo.*"], None),
    ("planner", ["lgp.planner", "lgp.planner.*"], None),
    # the logic layer that searches: skeletons over the planner's KOMO;
    # the package lgp re-exports lgp.plan (lazily: planner="paper" or "search"), so it sits here
    ("search", ["lgp.search", "lgp.search.*", "lgp"], None),
    ("models", ["models", "models.*"], None),
    # analysis imports nothing of the physics: no stimuli, scene, planner or models
    ("analysis", ["analysis", "analysis.*"], ["ground"]),
    # the application: lgp's application wing (lgp/app/ and its two commands), CLIs,
    # caches, report and page writers
    # stimuli.render is a package (camera, engine, run, __main__): the renderer and its cached run;
    # stimuli.design searches for stimuli through the pipeline's stages and caches (lgp.app)
    ("application", [*APP_WING, "stimuli.sheet", "stimuli.generate", "stimuli.render", "stimuli.render.*",
                     "stimuli.experiment", "stimuli.experiment.*", "stimuli.design", "stimuli.design.*", "analysis.import_study", "analysis.mental_jenga",
                     # they read trial files, plans and lgp.reproduce's caches
                     "analysis.heuristics", "analysis.power", "analysis.demo", "*.__main__"], None),
]
APPLICATION = LAYERS[-1][0]
RANK = {name: k for k, (name, _, _) in enumerate(LAYERS)}


def project_modules(root: Path = ROOT) -> list[str]:
    modules = []
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            if "__pycache__" in path.parts:
                continue
            parts = list(path.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            modules.append(".".join(parts))
    return modules


def layer_of(module: str) -> str | None:
    """The layer whose pattern matches `module` best (application first, then exact names)."""
    best, best_score = None, None
    for name, patterns, _ in LAYERS:
        for pattern in patterns:
            if fnmatchcase(module, pattern):
                score = (name == APPLICATION, "*" not in pattern, len(pattern))
                if best_score is None or score > best_score:
                    best, best_score = name, score
    return best


def import_graph(root: Path = ROOT) -> dict[str, list[str]]:
    return {m: [imported for imported, _ in module_imports(m, root)] for m in project_modules(root)}


def upward_imports(graph: dict[str, list[str]]) -> list[str]:
    """One line per import that breaks the layer rule."""
    allowed_only = {name: may for name, _, may in LAYERS}
    broken = []
    for module, imports in sorted(graph.items()):
        here = layer_of(module)
        for imported in imports:
            there = layer_of(imported)
            if here is None or there is None or there == here:
                continue
            may = allowed_only[here]
            ok = there in may if may is not None else RANK[there] < RANK[here]
            if not ok:
                broken.append(f"{module} ({here}) imports {imported} ({there})")
    return broken


def in_app_wing(module: str) -> bool:
    return any(fnmatchcase(module, pattern) for pattern in APP_WING)


def wing_imports(graph: dict[str, list[str]]) -> list[str]:
    """One line per import inside lgp/ that crosses the wings the wrong way: a
    module of the planning library importing the application wing, or importing
    models/, analysis/ or stimuli/ (only the application wing may)."""
    broken = []
    for module, imports in sorted(graph.items()):
        if module.split(".")[0] != "lgp" or in_app_wing(module):
            continue
        for imported in imports:
            if in_app_wing(imported):
                broken.append(f"{module} (planning library) imports {imported} (application wing)")
            elif imported.split(".")[0] in ("models", "analysis", "stimuli"):
                broken.append(f"{module} (planning library) imports {imported} (only the application wing may)")
    return broken


def cycles(graph: dict[str, list[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), and self-imports."""
    index, low, on_stack, stack, found = {}, {}, set(), [], []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, []):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1 or v in graph.get(v, []):
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_every_project_module_has_a_layer():
    missing = [m for m in project_modules() if layer_of(m) is None]
    assert not missing, f"add these modules to LAYERS in tests/test_layers.py: {missing}"


def test_no_module_imports_from_a_higher_layer():
    broken = upward_imports(import_graph())
    assert not broken, "upward imports:\n" + "\n".join(broken)


def test_the_planning_library_does_not_import_the_application_wing_or_the_models():
    broken = wing_imports(import_graph())
    assert not broken, "imports across lgp's two wings:\n" + "\n".join(broken)


def test_no_import_cycle_between_project_modules():
    found = cycles(import_graph())
    assert not found, "import cycles: " + "; ".join(" <-> ".join(c) for c in found)


def test_the_checks_catch_an_upward_import_a_cycle_and_an_unplaced_module(tmp_path):
    """The checker on a small made-up tree: a scene that plans (in a function), a
    cycle within a layer, analysis that reads stimuli, a module with no layer, and
    planning-library modules that import the application wing or stimuli."""
    files = {
        "lgp/__init__.py": "",
        "lgp/scene.py": "def f():\n    from lgp.planner import plan\n",
        "lgp/planner.py": "",
        "lgp/assignment.py": "import lgp.symbolic\n",
        "lgp/symbolic.py": "def f():\n    from lgp import assignment\n",
        "lgp/mystery.py": "",
        "lgp/executor.py": "def f():\n    from lgp.app import cache\n",
        "lgp/arm.py": "import stimuli\n",
        "lgp/app/__init__.py": "",
        "lgp/app/cache.py": "",
        "lgp/app/page.py": "import stimuli\nfrom models import risk\n",
        "lgp/reproduce.py": "from lgp.app import page\nimport analysis\n",
        "models/__init__.py": "",
        "models/risk.py": "",
        "analysis/__init__.py": "",
        "analysis/data.py": "from lgp.scene import X\nimport stimuli\n",
        "stimuli/__init__.py": "from lgp import scene\n",
    }
    for name, text in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    graph = import_graph(tmp_path)
    assert upward_imports(graph) == ["analysis.data (analysis) imports stimuli (stimuli and logic)",
                                     "lgp.executor (ground) imports lgp.app.cache (application)",
                                     "lgp.scene (ground) imports lgp.planner (planner)"]
    assert cycles(graph) == [["lgp.assignment", "lgp.symbolic"]]  # one layer, but a cycle
    assert [m for m in project_modules(tmp_path) if layer_of(m) is None] == ["lgp.mystery"]
    assert layer_of("models.risk.__main__") == APPLICATION and layer_of("models.risk.core") == "models"
    assert layer_of("lgp.app.page") == APPLICATION and layer_of("lgp.reproduce") == APPLICATION
    assert layer_of("lgp.planner.design") == "planner" and layer_of("lgp.komo.solve") == "KOMO"
    # inside lgp/: the planning library imports neither the application wing (a function
    # of lgp.executor) nor stimuli (lgp.arm: a lower layer, so only the wing rule sees it);
    # the wing imports what it likes
    assert wing_imports(graph) == ["lgp.arm (planning library) imports stimuli (only the application wing may)",
                                   "lgp.executor (planning library) imports lgp.app.cache (application wing)"]
