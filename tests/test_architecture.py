"""The package's shape: pipeline layers, imports only downward, no cycles, small modules
and functions, no private names across modules, a public API at the root.

Read from the source with :mod:`ast` (function-level imports count), so a violation is
caught wherever it hides.
"""
from __future__ import annotations

import ast
import importlib
import pathlib
import re

import pytest

PACKAGE = pathlib.Path(__file__).resolve().parents[1] / "povlens"

# The pipeline, lowest first.  A module may import its own layer and the ones below.
# ``data`` holds the bundled lenses, templates and scenes (no code).
# The package root (its public API, ``povlens/__init__.py``) sits just below ``cli``: the
# command line is a thin layer over it.
LAYERS = ["data", "errors", "util", "lens", "pupil", "thinlens", "pov", "plan", "rendering",
          "cluster", "report", "bench", "api", "cli"]
MAX_MODULE_LINES = 700
MAX_FUNCTION_LINES = 80
#: Where a longer function may stay: the benchmarks' drivers (a run's steps in order)
#: and the tracers' kernels (one pass over the surfaces, kept whole for speed and for
#: being read against pbrt's).
LONG_FUNCTIONS_ALLOWED = ("povlens.bench.", "povlens.lens.tracer", "povlens.lens.reference_tracer")


def _modules() -> dict[str, pathlib.Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _layer(module: str) -> int:
    parts = module.split(".")
    if len(parts) < 2:
        return LAYERS.index("api")
    name = parts[1]
    if name == "__main__":
        return LAYERS.index("cli")
    return LAYERS.index(name)


def _resolve(module: str, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    is_pkg = MODULES[module].name == "__init__.py"
    base = module.split(".")
    base = base if is_pkg else base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _imports(module: str) -> list[tuple[str, str | None, int]]:
    """(imported module, imported name or None, line) for every import in ``module``."""
    tree = ast.parse(MODULES[module].read_text())
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("povlens"):
                    found.append((alias.name, None, node.lineno))
        elif isinstance(node, ast.ImportFrom):
            target = _resolve(module, node)
            if not target.startswith("povlens"):
                continue
            for alias in node.names:
                sub = f"{target}.{alias.name}"
                if sub in MODULES:
                    found.append((sub, None, node.lineno))
                else:
                    found.append((target, alias.name, node.lineno))
    return found


def test_every_module_belongs_to_a_layer():
    for module in MODULES:
        parts = module.split(".")
        if len(parts) > 1:
            assert parts[1] in LAYERS + ["__main__"], f"{module} is in no pipeline layer"


def test_imports_only_go_downward():
    bad = []
    for module in MODULES:
        own = _layer(module)
        for target, _, line in _imports(module):
            other = _layer(target)
            if other is not None and other > own:
                bad.append(f"{module}:{line} imports {target} (layer {LAYERS[other]} "
                           f"above {LAYERS[own]})")
    assert not bad, "\n".join(bad)


def test_no_import_cycles():
    graph = {m: {t for t, _, _ in _imports(m) if t in MODULES and t != m} for m in MODULES}
    # a package's __init__ is imported with its modules; only edges between modules count
    graph = {m: {t for t in ts if MODULES[t].name != "__init__.py"} for m, ts in graph.items()}
    state: dict[str, int] = {}
    cycles = []

    def visit(node, stack):
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycles.append(" -> ".join(stack[stack.index(nxt):] + [nxt]))
            elif nxt not in state:
                visit(nxt, stack)
        stack.pop()
        state[node] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [])
    assert not cycles, "\n".join(cycles)


def test_no_private_name_is_imported_from_another_module():
    bad = [f"{m}:{line} imports {name} from {target}"
           for m in MODULES for target, name, line in _imports(m)
           if name is not None and name.startswith("_") and not name.startswith("__")]
    assert not bad, "\n".join(bad)


def test_modules_and_functions_are_small():
    bad = []
    for module, path in MODULES.items():
        text = path.read_text()
        n = len(text.splitlines())
        if n > MAX_MODULE_LINES:
            bad.append(f"{module}: {n} lines (> {MAX_MODULE_LINES})")
        if module.startswith(LONG_FUNCTIONS_ALLOWED):
            continue
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - node.lineno + 1
                if length > MAX_FUNCTION_LINES:
                    bad.append(f"{module}.{node.name}: {length} lines (> {MAX_FUNCTION_LINES})")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("name", ["read_lens", "focus", "build_pupil_table", "convert",
                                  "render", "composite", "compare"])
def test_public_api_at_the_package_root(name):
    import povlens
    assert name in povlens.__all__
    assert callable(getattr(povlens, name))
    assert getattr(povlens, name).__doc__, f"povlens.{name} has no docstring"


def test_tests_use_public_names():
    bad = []
    for path in PACKAGE.parent.joinpath("tests").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("povlens"):
                bad += [f"{path.name}:{node.lineno} imports {a.name} from {node.module}"
                        for a in node.names
                        if a.name.startswith("_") and not a.name.startswith("__")]
    assert not bad, "\n".join(bad)


SDL = "povlens.pov.sdl"


def _benchmark_imports() -> list[tuple[str, str, int]]:
    """(file name, imported module, line) for every absolute import in ``benchmarks/``;
    ``from a import b`` counts as importing ``a.b`` when that is a module of the package."""
    found = []
    for path in PACKAGE.parent.joinpath("benchmarks").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                found += [(path.name, a.name, node.lineno) for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                found.append((path.name, node.module, node.lineno))
                found += [(path.name, f"{node.module}.{a.name}", node.lineno)
                          for a in node.names if f"{node.module}.{a.name}" in MODULES]
    return found


def test_sdl_reader_is_used_through_its_front():
    """Modules outside ``povlens.pov.sdl`` (the package's and the benchmarks') import the
    SDL subpackage's front, ``povlens.pov.sdl``, never one of its inner modules."""
    inner = SDL + "."
    bad = [f"{m}:{line} imports {target}"
           for m in MODULES if m != SDL and not m.startswith(inner)
           for target, _, line in _imports(m) if target.startswith(inner)]
    bad += [f"benchmarks/{name}:{line} imports {target}"
            for name, target, line in _benchmark_imports() if target.startswith(inner)]
    assert not bad, "\n".join(bad)


#: The module that formats every file name of a render folder (and a focus pull's folder).
FOLDER_LAYOUT = "povlens.plan.render_folder"
#: What a render folder's file names look like, formatted or as globs.
FOLDER_NAMES = re.compile(
    r"sample_\d|sample_\{|batch_\{|\.weight\.exr|\.mask\.npy|\.transmission\.npy|\.blocked"
    r"|\.done\b|view-|group_\{|group_\(|exposure\.txt|pupil\.npz|plan\.json|illumination\.json"
    r"|image\.exr|image\.png|image\.\{|frame-\{|frame-\d|frames\.json|\.timing\.json"
    r"|pinhole\.pov|focal_blur\.pov|\.speculative-")


def _strings(tree: ast.AST) -> list[tuple[int, str]]:
    """(line, text) of the string literals and f-strings of a module (a formatted value
    as ``{expression}``), docstrings left out."""
    docs, parts = set(), set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
                docs.add(id(body[0].value))
        if isinstance(node, ast.JoinedStr):
            parts.update(id(v) for v in node.values)
    found = []
    for node in ast.walk(tree):
        if id(node) in docs or id(node) in parts:
            continue
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            found.append((node.lineno, node.value))
        elif isinstance(node, ast.JoinedStr):
            found.append((node.lineno, "".join(
                v.value if isinstance(v, ast.Constant) else "{" + ast.unparse(v.value) + "}"
                for v in node.values)))
    return found


def _folder_file_names(text: str) -> list[str]:
    """The words of ``text`` that spell a render folder's file: the whole string when it
    is one word (a name, a path, a glob), else a word that formats a value into a name
    or joins one to a path (``{...}``) or globs (``*``).  Prose that mentions a file (a
    help text's "kept in plan.json") is not a name being made."""
    words = text.split()
    return [w for w in words if FOLDER_NAMES.search(w)
            and (len(words) == 1 or "{" in w or "*" in w)]


def test_render_folder_names_in_one_module():
    """Every file and marker name of a render folder (samples, weights, masks, groups,
    batches, views, caches, images, a focus pull's frames) is formatted in
    :mod:`povlens.plan.render_folder`; everything else asks its ``RenderFolder``."""
    bad = []
    for module, path in MODULES.items():
        if module == FOLDER_LAYOUT:
            continue
        for line, text in _strings(ast.parse(path.read_text())):
            bad += [f"{module}:{line}: {name!r}" for name in _folder_file_names(text)]
    assert not bad, "\n".join(bad)


# A ``povlens.<module>[.<name>]`` in a docstring (not part of a path or a longer name), and
# a ``povlens/...py`` path.
DOTTED_NAME = re.compile(r"(?<![\w./-])povlens(?:\.\w+)+")
SOURCE_PATH = re.compile(r"(?<![\w./-])povlens/[\w/]+\.py\b")


def _docstrings(path: pathlib.Path):
    """(line, docstring) of the module, classes and functions of the file ``path``."""
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            doc = ast.get_docstring(node, clean=False)
            if doc:
                yield getattr(node, "lineno", 1), doc


def _names_something(name: str) -> bool:
    """Whether ``name`` is a module of the package or an attribute of one (a dataclass
    field without a default counts: it is declared, if not a class attribute)."""
    parts = name.split(".")
    for i in range(len(parts), 0, -1):
        module = ".".join(parts[:i])
        if module in MODULES:
            break
    else:
        return False
    obj = importlib.import_module(module)
    for part in parts[i:]:
        if hasattr(obj, part):
            obj = getattr(obj, part)
        else:
            return part in getattr(obj, "__annotations__", {})
    return True


def test_docstrings_name_existing_modules():
    """Every ``povlens.<module>[.<name>]`` a docstring (module, class, function) of
    ``povlens/`` or ``tests/`` names is a module or a module's attribute, and every
    ``povlens/...py`` path it names exists: a module that moved leaves no stale name
    behind.  A name followed by ``*`` or ``.*`` (a family of modules) is not checked."""
    root = PACKAGE.parent
    bad = []
    for path in sorted([*PACKAGE.rglob("*.py"), *root.joinpath("tests").rglob("*.py")]):
        where = path.relative_to(root)
        for line, doc in _docstrings(path):
            for m in DOTTED_NAME.finditer(doc):
                if doc[m.end():m.end() + 2].startswith(("*", ".*")):
                    continue
                if not _names_something(m.group(0)):
                    bad.append(f"{where}:{line} names {m.group(0)}")
            bad += [f"{where}:{line} names {m.group(0)}" for m in SOURCE_PATH.finditer(doc)
                    if not root.joinpath(m.group(0)).exists()]
    assert not bad, "\n".join(bad)


# --- options, the command line over the API, the README's layout table -------------

#: What the command line may import: the API, its own modules, the option declarations,
#: errors, and the lens, pupil, report, bench and util layers of the lens commands
#: (``inspect``, ``pupil``, ``compare``, ``bench``...).  Not the render internals.
RENDER_INTERNALS = ("povlens.pov", "povlens.plan", "povlens.rendering", "povlens.cluster")
CLI_MAY_IMPORT = ("povlens.plan.options",)


def test_command_modules_use_the_api_not_the_render_internals():
    bad = [f"{m}:{line} imports {target}"
           for m in MODULES if m.startswith("povlens.cli")
           for target, _, line in _imports(m)
           if target.startswith(RENDER_INTERNALS) and target not in CLI_MAY_IMPORT]
    assert not bad, "\n".join(bad)


def _literal(node) -> bool:
    """A number or text written out (not a name, not None/True/False, not empty)."""
    if isinstance(node, ast.Constant):
        return node.value is not None and not isinstance(node.value, bool) and node.value != ""
    if isinstance(node, (ast.BinOp, ast.UnaryOp)):
        return all(_literal(n) for n in ast.walk(node) if isinstance(n, ast.Constant))
    return False


def test_no_literal_defaults_on_the_command_line():
    """A default is declared once, where the value is used (an option's declaration,
    the core's named constant, the API's keyword); the command line refers to it."""
    bad = []
    for m, path in MODULES.items():
        if not m.startswith("povlens.cli"):
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "attr", "") in (
                    "add_argument", "set_defaults"):
                bad += [f"{m}:{node.lineno}: {k.arg}={ast.unparse(k.value)}"
                        for k in node.keywords
                        if k.arg == "default" and _literal(k.value)]
    assert not bad, "\n".join(bad)


#: The modules that take a conversion's options from the user (the lens commands
#: ``focus``, ``pupil``, ``check``... have their own, different ``--focus``, ``--units``).
CONVERSION_MODULES = ("povlens.cli.render_cmd", "povlens.cli.plan_cmd",
                      "povlens.cli.convert_args", "povlens.cli.focus_pull_run", "povlens.api",
                      *(m for m in MODULES if m.startswith("povlens.plan.")
                        and m != "povlens.plan.options"))


def test_each_option_is_declared_once():
    """The options of a conversion (and of a render's Dask cluster) are declared in
    :mod:`povlens.plan.options` only: no other module spells their flags, and the
    command line's convert/render/plan have exactly the declared ones, with the
    declared defaults, plus their few own arguments."""
    from povlens.cli import build_parser
    from povlens.plan.options import dask_options, options
    declared = {spec.flag: f for _, f, spec in options() if spec.flag}
    dask = {spec.flag: f for f, spec in dask_options()}
    own = {"--lens", "--outdir", "--json", "--frames", "--jobs", "--quiet", "--help"}
    flags = set(declared) | set(dask)
    bad = []
    for m in CONVERSION_MODULES:
        for node in ast.walk(ast.parse(MODULES[m].read_text())):
            if isinstance(node, ast.Constant) and node.value in flags:
                bad.append(f"{m}:{node.lineno} spells {node.value}")
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(getattr(a, "choices", None), dict))
    for command in ("convert", "render", "plan"):
        for action in sub.choices[command]._actions:
            long = [o for o in action.option_strings if o.startswith("--")]
            if not long:
                continue
            flag = long[0]
            field = declared.get(flag) or (dask.get(flag) if command == "render" else None)
            if field is None:
                if flag not in own:
                    bad.append(f"{command} {flag}: declared by hand, not in plan.options")
            elif action.dest != field.name or (action.default != field.default and not (
                    isinstance(field.default, tuple) and list(field.default) == action.default)):
                bad.append(f"{command} {flag}: dest {action.dest!r} default {action.default!r}"
                           f" differ from the declaration ({field.name!r}, {field.default!r})")
    assert not bad, "\n".join(bad)


README = PACKAGE.parent / "README.md"


def _layout_table() -> dict[str, set[str]]:
    """The README's layout table: folder (``util/``, or a top module ``errors.py``)
    -> the module names it lists (``sdl/`` (``lexer``, ...) as ``sdl.lexer``)."""
    text = README.read_text()
    start = text.index("| folder | stage | modules |")
    rows = {}
    for line in text[start:].splitlines()[2:]:
        if not line.startswith("|"):
            break
        folder, _, modules = (c.strip() for c in line.strip("|").split("|"))
        names = set()
        for sub, inner, name in re.findall(r"`(\w+)/` \(([^)]*)\)|`(\w+)`", modules):
            if sub:
                names |= {f"{sub}.{n}" for n in re.findall(r"`(\w+)`", inner)}
            else:
                names.add(name)
        for key in re.findall(r"`([\w.]+/?)`", folder):
            rows[key] = names
    return rows


def test_readme_layout_table_lists_every_module():
    rows = _layout_table()
    bad = []
    for module in MODULES:
        parts = module.split(".")[1:]
        if not parts or parts == ["__main__"] or parts[0] == "data":
            continue
        if len(parts) == 1 and MODULES[module].name != "__init__.py":
            if f"{parts[0]}.py" not in rows:
                bad.append(f"{module}: no row for {parts[0]}.py")
            continue
        folder, rest = parts[0] + "/", ".".join(parts[1:])
        if not rest:
            continue                           # a package's __init__
        if folder not in rows:
            bad.append(f"{module}: no row for {folder}")
        elif rest not in rows[folder] and not any(n.startswith(rest + ".")
                                                  for n in rows[folder]):
            bad.append(f"{module}: not listed in the {folder} row")
    for folder, names in rows.items():
        for name in names:
            if f"povlens.{folder.rstrip('/')}.{name}" not in MODULES:
                bad.append(f"README lists {folder}{name}, which does not exist")
    assert not bad, "\n".join(bad)
