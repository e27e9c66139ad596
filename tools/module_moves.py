"""Rewrite imports and path mentions of layersim's modules moved into pipeline folders.

The modules that sat flat in ``layersim/`` now live in folders named for the stages of a solve
(:data:`MOVES`). A file written against the old names -- one added on another branch, or a moved
module that another branch edited -- is brought to the new names by::

    python tools/module_moves.py FILE...          # rewrite in place
    python tools/module_moves.py --check FILE...  # list the files that would change; exit 1 if any

Forms rewritten: ``from layersim.X import a``, ``from layersim import X``, ``import layersim.X``,
dotted mentions ``layersim.X.name`` (code, strings, documentation), relative imports inside the
package (``from .X import a``, ``from . import X``, ``from ..X import a``, where ``kernels/`` and
``montecarlo/`` install as ``layersim.kernels`` and ``layersim.montecarlo``), and paths
``layersim/X.py``. The rewrite is idempotent: no new folder takes the name of an old module, so a
new name never matches an old one.

A relative import in a moved module can be read against the module's old package or its new one;
the reading whose target exists in the tree wins, and a statement that both readings resolve to
different existing names is left as it is and reported on stderr.
"""
from __future__ import annotations

import argparse
import ast
import pathlib
import re
import sys

#: Old module -> new module.
MOVES = {
    "layersim.accuracy": "layersim.plan.accuracy",
    "layersim.operator": "layersim.operators.operator",
    "layersim.quadrature": "layersim.operators.quadrature",
    "layersim.fourier": "layersim.operators.fourier",
    "layersim.energy": "layersim.operators.energy",
    "layersim.interpolation": "layersim.operators.interpolation",
    "layersim.adding": "layersim.stacking.adding",
    "layersim.deltas": "layersim.operators.deltas",
    "layersim.subtract": "layersim.stacking.subtract",
    "layersim.determined": "layersim.stacking.determined",
    "layersim.bsdf": "layersim.solved.bsdf",
    "layersim.isobsdf": "layersim.solved.isobsdf",
    "layersim.evaluator": "layersim.solved.evaluator",
    "layersim.sampling": "layersim.solved.sampling",
    "layersim.boundary": "layersim.solved.boundary",
    "layersim.lobe": "layersim.solved.lobe",
    "layersim.channels": "layersim.solved.channels",
    "layersim.directions": "layersim.solved.directions",
    "layersim.plot": "layersim.solved.plot",
    "layersim.merl": "layersim.layers.merl",
}
#: Old module names that ``layersim/__init__.py`` rebinds to a public function of the same name:
#: ``layersim.subtract(...)`` and ``from layersim import subtract`` mean the function, and only
#: an attribute (``layersim.subtract.x``), an import or a ``:mod:`` role means the module.
SHADOWED = {"layersim.subtract"}
#: Installed package -> its folder in the repository.
FOLDERS = {"layersim.kernels": "kernels", "layersim.montecarlo": "montecarlo", "layersim": "layersim"}

_OLD = "|".join(sorted((m.split(".", 1)[1] for m in MOVES), key=len, reverse=True))
_FROM = re.compile(r"^(?P<indent>[ \t]*(?:>>> |\.\.\. )?)from[ \t]+(?P<module>\.+[\w.]*|layersim(?:\.[\w.]+)?)"
                   r"[ \t]+import[ \t]+(?P<names>\([^)]*\)|[^\n#]*[^\s#])", re.M)
_DOTTED = re.compile(rf"(?<![\w.])layersim\.(?P<name>{_OLD})\b(?P<after>\.\w)?")
_PATH = re.compile(rf"(?<![\w.])layersim/(?P<name>{_OLD})\.py\b")
#: What before a shadowed name makes it the module: an import keyword or a ``:mod:`` role.
_MODULE_BEFORE = re.compile(r"(\b(import|from)[ \t]+|:mod:`~?)$")


def module_of(path: pathlib.Path, root: pathlib.Path):
    """The module a source file installs as, or ``None`` outside the packages.

    Parameters
    ----------
    path, root : pathlib.Path
        The file, and the repository root holding ``layersim/``, ``kernels/``, ``montecarlo/``.

    Returns
    -------
    tuple (str, bool) or None
        The dotted module name, and whether the file is a package's ``__init__.py``.
    """
    try:
        parts = list(path.resolve().relative_to(root.resolve()).with_suffix("").parts)
    except ValueError:
        return None
    for package, folder in FOLDERS.items():
        if parts and parts[0] == folder:
            is_init = parts[-1] == "__init__"
            names = package.split(".") + parts[1:len(parts) - is_init]
            return ".".join(names), is_init
    return None


def existing_modules(root: pathlib.Path) -> dict:
    """``{module: source path}`` of every module and package in the tree under ``root``."""
    out = {}
    for package, folder in FOLDERS.items():
        for path in (root / folder).rglob("*.py"):
            name, _ = module_of(path, root)
            out[name] = path
    return out


def _defined_names(path: pathlib.Path) -> set:
    """Names bound at the top level of a module (imports, definitions, assignments)."""
    try:
        tree = ast.parse(path.read_text())
    except (SyntaxError, UnicodeDecodeError, OSError):
        return set()
    names = set()
    for node in tree.body:
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            names.update((a.asname or a.name).split(".")[0] for a in node.names)
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names.update(n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name))
    return names


def moved(module: str) -> str:
    """The new name of a module (itself when it did not move)."""
    return MOVES.get(module, module)


def resolve(package: str, dots: int, rest: str):
    """The absolute module of a relative import ``from <dots><rest> import``, or ``None`` when
    the dots climb above ``layersim``."""
    base = package.split(".")
    if dots - 1 >= len(base):
        return None
    base = base[:len(base) - (dots - 1)]
    return ".".join(base + ([rest] if rest else []))


def relative(target: str, package: str) -> str:
    """``target`` written relative to ``package`` (both inside ``layersim``): ``..x.y``."""
    t, p = target.split("."), package.split(".")
    common = 0
    while common < min(len(t), len(p)) and t[common] == p[common]:
        common += 1
    return "." * (len(p) - common + 1) + ".".join(t[common:])


def _aliases(names: str) -> list:
    """``[(name, asname or None)]`` of an import's name list (parentheses and comments allowed)."""
    body = re.sub(r"#[^\n]*", "", names).strip().strip("()")
    out = []
    for item in (i.strip() for i in body.split(",")):
        if item:
            name, _, asname = (p.strip() for p in item.partition(" as "))
            out.append((name, asname or None))
    return out


def _groups(target: str, aliases: list) -> dict:
    """The new ``{module: [imported name text]}`` of ``from target import aliases``: a name that
    is itself a moved module is imported from its new package, every other name from the
    (possibly moved) target."""
    groups = {}
    for name, asname in aliases:
        full = f"{target}.{name}"
        if full in MOVES and full not in SHADOWED:
            parent, leaf = MOVES[full].rsplit(".", 1)
            bound = asname or (name if leaf != name else None)
            groups.setdefault(parent, []).append(leaf + (f" as {bound}" if bound else ""))
        else:
            groups.setdefault(moved(target), []).append(name + (f" as {asname}" if asname else ""))
    return groups


def _valid(target: str, aliases: list, modules: dict) -> bool:
    """Whether every name of ``from target import aliases`` exists in the new tree."""
    source = modules.get(moved(target))
    if source is None:
        return False
    defined = _defined_names(source)
    return all(moved(f"{target}.{n}") in modules or n == "*" or n in defined for n, _ in aliases)


def _render(match: re.Match, groups: dict, package) -> str:
    """The statement text for ``groups``; the original text with only its module replaced where
    the names stay as they were (keeping parentheses and comments)."""
    written = {m: (relative(m, package) if match["module"].startswith(".") else m) for m in groups}
    original = [n + (f" as {a}" if a else "") for n, a in _aliases(match["names"])]
    if len(groups) == 1 and next(iter(groups.values())) == original:
        start, end = match.span("module")
        text = match.group(0)
        offset = match.start(0)
        return text[:start - offset] + written[next(iter(groups))] + text[end - offset:]
    lines = [f"from {written[m]} import {', '.join(names)}" for m, names in groups.items()]
    return match["indent"] + ("\n" + match["indent"]).join(lines)


def _readings(match: re.Match, packages: tuple) -> list:
    """``[(target, aliases)]``: the absolute target of the statement under each package it may be
    read against (one for absolute imports)."""
    module, aliases = match["module"], _aliases(match["names"])
    if not module.startswith("."):
        return [(module, aliases)]
    dots = len(module) - len(module.lstrip("."))
    targets = {resolve(p, dots, module[dots:]) for p in packages if p is not None}
    return [(t, aliases) for t in sorted(t for t in targets if t is not None)]


def _rewrite_from(match: re.Match, packages: tuple, modules: dict, where: str, warnings: list):
    """The rewritten text of one ``from ... import ...`` statement."""
    readings = _readings(match, packages)
    if len(readings) > 1:
        readings = [r for r in readings if _valid(*r, modules)] or readings
    texts = {_render(match, _groups(*r), packages[-1]) for r in readings}
    if len(texts) != 1:
        warnings.append(f"{where}: ambiguous, left as it is: {match.group(0).strip()}")
        return match.group(0)
    return texts.pop()


def _rewrite_dotted(match: re.Match) -> str:
    """The new name of one dotted mention ``layersim.X``; a shadowed name (:data:`SHADOWED`) only
    where it means the module."""
    old = f"layersim.{match['name']}"
    before = match.string[max(0, match.start() - 12):match.start()]
    if old in SHADOWED and not match["after"] and not _MODULE_BEFORE.search(before):
        return match.group(0)
    return MOVES[old] + (match["after"] or "")


def rewrite_text(text: str, packages: tuple = (None,), modules: dict | None = None,
                 where: str = "<text>", warnings: list | None = None) -> str:
    """Rewrite the old module names of one file's text.

    Parameters
    ----------
    text : str
        The file's contents.
    packages : tuple of str or None
        The packages a relative import of the file may be read against: ``(old, new)`` for a
        moved module, ``(package,)`` otherwise; ``(None,)`` for files outside the packages, whose
        relative imports are not the package's.
    modules : dict, optional
        :func:`existing_modules` of the tree, used to choose between two readings.
    where : str
        The file's name in warnings.
    warnings : list, optional
        Receives one line per statement left as it is.

    Returns
    -------
    str
        The rewritten text.
    """
    modules = modules or {}
    warnings = [] if warnings is None else warnings

    def from_statement(match):
        if match["module"].startswith(".") and packages[-1] is None:
            return match.group(0)
        return _rewrite_from(match, packages, modules, where, warnings)

    text = _FROM.sub(from_statement, text)
    text = _DOTTED.sub(_rewrite_dotted, text)
    return _PATH.sub(lambda m: MOVES[f"layersim.{m['name']}"].replace(".", "/") + ".py", text)


def packages_of(path: pathlib.Path, root: pathlib.Path) -> tuple:
    """The packages a relative import in ``path`` may be read against: the module's package
    before the moves (when the file is a moved module) and after them."""
    found = module_of(path, root)
    if found is None:
        return (None,)
    module, is_init = found
    new_package = module if is_init else module.rsplit(".", 1)[0]
    old = {v: k for k, v in MOVES.items()}.get(module)
    if old is None:
        return (new_package,)
    return (old.rsplit(".", 1)[0], new_package)


def main(argv=None) -> int:
    """Rewrite (or with ``--check`` list) the given files; exit 1 when ``--check`` finds any."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("files", nargs="+", type=pathlib.Path)
    parser.add_argument("--check", action="store_true", help="list files that would change")
    parser.add_argument("--root", type=pathlib.Path,
                        default=pathlib.Path(__file__).resolve().parents[1],
                        help="repository root (default: this file's checkout)")
    args = parser.parse_args(argv)
    modules, warnings, changed = existing_modules(args.root), [], []
    for path in args.files:
        text = path.read_text()
        new = rewrite_text(text, packages_of(path, args.root), modules, str(path), warnings)
        if new != text:
            changed.append(str(path))
            if not args.check:
                path.write_text(new)
    for line in warnings:
        print(line, file=sys.stderr)
    print("\n".join(changed) if changed else "no changes")
    return 1 if (args.check and changed) else 0


if __name__ == "__main__":
    sys.exit(main())
