"""The structure of the package: imports flow one way and the two operator kinds share one
interface (docs/method.md, "Layout").

The import graph is read from the source with :mod:`ast`, counting imports inside functions too:
a cycle hidden in a function is still a cycle for whoever reads or moves the code."""
import ast
import io
import pathlib
import re
import textwrap
import tokenize

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PACKAGES = {"layersim": ROOT / "layersim", "layersim.kernels": ROOT / "kernels",
            "layersim.montecarlo": ROOT / "montecarlo"}
#: Modules that define the operator kinds and may tell them apart.
OPERATOR_MODULES = ("layersim.operators.operator", "layersim.aniso.operator")


def _modules() -> dict:
    out = {}
    for package, folder in PACKAGES.items():
        for path in folder.rglob("*.py"):
            parts = list(path.relative_to(folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join([package] + parts)] = path
    return out


MODULES = _modules()


def _target(module: str, path: pathlib.Path, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    base = module.split(".")
    if path.name != "__init__.py":
        base = base[:-1]
    base = base[:len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _imports():
    """``{module: set of imported modules}`` and the list of private names imported."""
    graph, private = {}, []
    for module, path in MODULES.items():
        deps = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                target = _target(module, path, node)
                for alias in node.names:
                    if f"{target}.{alias.name}" in MODULES:
                        deps.add(f"{target}.{alias.name}")
                    elif target in MODULES:
                        deps.add(target)
                        if (alias.name.startswith("_") and not alias.name.startswith("__")
                                and target != module):
                            private.append(f"{module} imports {target}.{alias.name}")
            elif isinstance(node, ast.Import):
                deps.update(a.name for a in node.names if a.name in MODULES)
        deps.discard(module)
        # a package's face importing its own modules is not a dependency of theirs on it
        graph[module] = deps
    return graph, private


def _cycles(graph: dict) -> list:
    """Strongly connected components with more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
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
            if len(component) > 1:
                found.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def _without_faces(graph: dict) -> dict:
    """The graph less the edges into package faces (``__init__``) from their own modules: a
    module that imports ``from . import x`` goes through its package's face, which is the usual
    Python layout and not a dependency on the face's other names."""
    faces = {m for m, p in MODULES.items() if p.name == "__init__.py"}
    return {m: {d for d in deps if not (d in faces and m.startswith(d + "."))}
            for m, deps in graph.items()}


def test_no_import_cycles():
    graph, _ = _imports()
    assert _cycles(_without_faces(graph)) == []


def test_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_module_imports_private_names_of_another():
    _, private = _imports()
    assert private == []


def test_no_branching_on_operator_kind_outside_the_operator_modules():
    pattern = re.compile(r"isinstance\([^)]*\b(IsoOperator|AnisoOperator)\b"
                         r"|hasattr\([^)]*[\"']albedo_slots[\"']")
    found = [f"{m}:{i}: {line.strip()}"
             for m, path in MODULES.items() if m not in OPERATOR_MODULES
             for i, line in enumerate(path.read_text().splitlines(), 1)
             if pattern.search(line)]
    assert found == []


def _function(module: str, name: str) -> ast.FunctionDef:
    tree = ast.parse(MODULES[module].read_text())
    return next(n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == name)


@pytest.mark.parametrize("module", ["layersim.stacking.adding", "layersim.aniso.adding"])
def test_the_adding_equations_fit_on_one_screen(module):
    fn = _function(module, "add")
    assert fn.end_lineno - fn.lineno + 1 <= 60


def test_settings_are_read_from_the_environment_in_one_place():
    """Only :mod:`layersim.config` reads ``LAYERSIM_*`` variables (other packages' own
    variables, such as pyopencl's ``PYOPENCL_CTX``, are theirs to read)."""
    pattern = re.compile(r"(environ\.get\(|environ\[|getenv\()\s*[\"']LAYERSIM_")
    readers = [m for m, path in MODULES.items()
               if m != "layersim.config" and pattern.search(path.read_text())]
    assert readers == []


def test_importing_layersim_changes_nothing_in_the_process():
    """The package's face only imports and names things: no call (an allocator setting, a
    thread pool, a kernel build) runs at ``import layersim``."""
    tree = ast.parse(MODULES["layersim"].read_text())
    calls = [ast.unparse(n) for n in tree.body
             if isinstance(n, ast.Expr) and isinstance(n.value, ast.Call)]
    assert calls == []


def test_no_private_api_of_other_packages():
    """Only public modules and names of numpy, scipy, Warp and the rest are used: a private
    one can change or vanish in any release."""
    found = []
    for module, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                if node.module == "__future__" or node.module.split(".")[0] == "layersim":
                    continue
                names = node.module.split(".") + [a.name for a in node.names]
            elif isinstance(node, ast.Import):
                names = [part for a in node.names for part in a.name.split(".")]
            else:
                continue
            if any(n.startswith("_") and not n.startswith("__") for n in names):
                found.append(f"{module}:{node.lineno}: {ast.unparse(node)}")
    assert found == []


def test_only_the_layer_kinds_branch_on_the_kind():
    """What a layer kind is lives in its module of :mod:`layersim.layers`; every other module asks
    the registry (``kind_of(layer)``) or a record's properties (``opaque``, ``is_interface``)
    instead of testing which kind a layer is."""
    records = {"Dielectric", "Conductor", "Medium", "Diffuse", "Measured", "Interface", "Layer"}
    kind_names = {"dielectric", "conductor", "medium", "diffuse", "measured"}
    found = []
    for module, path in MODULES.items():
        if module.startswith("layersim.layers"):
            continue
        tree = ast.parse(path.read_text())
        imported = {a.asname or a.name for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)
                    and n.module and n.module.split(".")[-1] in ("scene", "layers")
                    for a in n.names} & records
        for node in ast.walk(tree):
            if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                    and node.func.id == "isinstance" and len(node.args) == 2):
                names = {n.id for n in ast.walk(node.args[1]) if isinstance(n, ast.Name)}
                if names & imported:
                    found.append(f"{module}:{node.lineno}: {ast.unparse(node)}")
            if isinstance(node, ast.Compare) and any(
                    isinstance(c, ast.Constant) and c.value in kind_names
                    for c in [node.left, *node.comparators]) and "kind" in ast.unparse(node):
                found.append(f"{module}:{node.lineno}: {ast.unparse(node)}")
    assert found == []


#: Longest function allowed, in lines of code: lines with code on them, not counting blank
#: lines, comment lines and docstrings (a nested function counts within its parent too).
MAX_FUNCTION_LINES = 80

#: Functions allowed to be longer, ``"path: qualified name"`` (or a whole module's path), with
#: what makes them long.
LONG_FUNCTIONS = {
    "layersim/cli.py: build_parser": "the argument parser",
    "kernels/opencl_codegen.py": "the translator's dispatch",
}

_NOT_CODE = {tokenize.COMMENT, tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT,
             tokenize.ENCODING, tokenize.ENDMARKER}


def _code_lines(text: str, tree: ast.Module) -> set:
    """Numbers of the lines of ``text`` that hold code: a token other than a comment, outside
    docstrings (of the module, classes and functions)."""
    lines = set()
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type not in _NOT_CODE:
            lines.update(range(tok.start[0], tok.end[0] + 1))
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            first = node.body[0] if node.body else None
            if (isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant)
                    and isinstance(first.value.value, str)):
                lines.difference_update(range(first.lineno, first.end_lineno + 1))
    return lines


def function_lengths(text: str) -> dict:
    """``{qualified name: lines of code}`` of every function and method in the source
    ``text`` (nested ones as ``outer.inner``)."""
    tree = ast.parse(text)
    code = _code_lines(text, tree)
    out = {}

    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                name = prefix + child.name
                if not isinstance(child, ast.ClassDef):
                    out[name] = sum(1 for n in code if child.lineno <= n <= child.end_lineno)
                visit(child, name + ".")
            else:
                visit(child, prefix)

    visit(tree, "")
    return out


def _long_functions() -> dict:
    """``{"path: name": lines of code}`` of the functions of all packages over
    :data:`MAX_FUNCTION_LINES`."""
    found = {}
    for path in MODULES.values():
        rel = path.relative_to(ROOT).as_posix()
        for name, n in function_lengths(path.read_text()).items():
            if n > MAX_FUNCTION_LINES:
                found[f"{rel}: {name}"] = n
    return found


def test_functions_fit_on_a_screen():
    """A function over :data:`MAX_FUNCTION_LINES` lines of code mixes concerns; split it by
    concept. Each function named in :data:`LONG_FUNCTIONS` is still over the limit: an entry
    that no longer allows anything would let the function grow back unnoticed."""
    found = _long_functions()
    allowed = lambda name: name in LONG_FUNCTIONS or name.split(":")[0] in LONG_FUNCTIONS
    assert {name: n for name, n in found.items() if not allowed(name)} == {}
    for key in LONG_FUNCTIONS:
        assert (ROOT / key.split(":")[0]).is_file(), key
        assert ": " not in key or key in found, f"{key} is within the limit: drop its entry"


def test_function_lengths_count_code_only():
    """Blank lines, comments and docstrings do not count; lines of a multi-line string do (a
    ``#`` in it is no comment); a nested function counts within its parent."""
    text = textwrap.dedent('''\
        def f(x):
            """Doc

            more doc."""
            # a comment

            y = (x +
                 1)
            s = """a
        # not a comment
        """

            def g():
                return y
            return g, s


        class A:
            def m(self):
                """Doc."""
                pass
        ''')
    assert function_lengths(text) == {"f": 9, "f.g": 2, "A.m": 2}


# ---- physics written once (docs/method.md, "Physics, written once") -------------------------

#: Names of functions that compute a physics term: Fresnel and Schlick, the NDFs and their
#: peak factors, Smith's masking and shadowing, Henyey-Greenstein, refraction, Airy's
#: thin-film reflectance, Lambert. Outside the kernels a function so named may only delegate
#: (no arithmetic of its own), unless listed in :data:`PHYSICS_EXCEPTIONS`.
PHYSICS_NAME = re.compile(r"^_*(fresnel|schlick|beckmann|ggx|smith|masking|shadowing|hg_|henyey|"
                          r"refract|snell|airy|lambert|ndf$|ndf_(peak|eval|value))",
                          re.IGNORECASE)

#: Functions named like physics that do arithmetic outside the kernels, and why that is not a
#: second copy of a formula of ``kernels/physics.py``.
PHYSICS_EXCEPTIONS = {
    "layersim.compensation.tables:fresnel_average":
        "Gauss-Legendre average of physics.fresnel_conductor, whose values a kernel computes",
    "layersim.ingredients.medium:hg_scaling":
        "delta-M scaling of HG's Legendre moments g^k (Wiscombe 1977): a series representation "
        "for the discrete ordinates, tested against physics.hg_eval (tests/test_physics.py)",
    "layersim.ingredients.medium:hg_orders":
        "length of HG's Legendre series (the number of Fourier orders it needs)",
    "layersim.ingredients.medium:hg_components":
        "Fourier components of HG's Legendre series by the addition theorem, tested against "
        "physics.hg_eval (tests/test_physics.py)",
    "layersim.ndf.microfacet:shadowing_table":
        "Wang et al. 2008 eq. (5) as a quadrature over a table of D (no pointwise formula); "
        "the check of shadowing_rings",
    "layersim.ndf.microfacet:shadowing_rings":
        "the same quadrature on rings of directions by FFT along phi",
    "layersim.ndf.table:NDFTable.shadowing":
        "bilinear lookup of the tabulated S(k) that kernels/tabulated.py reads too",
    "layersim.operators.quadrature:snell_split":
        "how many ordinates of a Snell-matched grid lie in the escape cone (grid geometry)",
    "layersim.operators.quadrature:snell_matched":
        "nodes and weights of the Snell-matched grid: Snell's cosine map of quadrature nodes, "
        "computed once per grid",
}


def _functions(tree: ast.AST, prefix: str = ""):
    """``(qualified name, node)`` of every function and method in ``tree``, nested ones too."""
    for node in ast.iter_child_nodes(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            yield prefix + node.name, node
            yield from _functions(node, prefix + node.name + ".")
        elif isinstance(node, ast.ClassDef):
            yield from _functions(node, prefix + node.name + ".")
        else:
            yield from _functions(node, prefix)


def _computes(fn: ast.AST) -> bool:
    """Whether a function does arithmetic of its own (a delegate that only calls, converts
    and returns does none)."""
    return any(isinstance(n, ast.BinOp) or (isinstance(n, ast.UnaryOp)
                                            and not isinstance(n.op, ast.Not))
               for n in ast.walk(fn))


#: Names the package gives a roughness (``self.au`` counts as ``au``).
ROUGHNESS = {"alpha", "alpha_u", "alpha_v", "au", "av", "a_u", "a_v"}


def _roughness(node: ast.AST) -> str | None:
    if isinstance(node, ast.Name) and node.id in ROUGHNESS:
        return node.id
    if isinstance(node, ast.Attribute) and node.attr in ROUGHNESS:
        return node.attr
    return None


def _squared_roughness(node: ast.AST) -> bool:
    """``alpha ** 2`` or ``alpha * alpha`` (a product of squared roughnesses counts too)."""
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Pow):
        return (_roughness(node.left) is not None and isinstance(node.right, ast.Constant)
                and node.right.value == 2)
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Mult):
        name = _roughness(node.left)
        if name is not None and name == _roughness(node.right):
            return True
        return _squared_roughness(node.left) or _squared_roughness(node.right)
    return False


def _physics_outside_kernels(sources: dict) -> list:
    """Offences against "physics once" in ``{module: source}`` (modules outside the kernels):
    physics-named functions that compute, a Warp function or kernel defined there, the error
    function (it enters the package only through Beckmann's Smith Lambda) and a division by a
    squared roughness (the slope-space form of an NDF, ``tan^2 / alpha^2``)."""
    found = []
    for module, text in sources.items():
        tree = ast.parse(text)
        for name, fn in _functions(tree):
            if (PHYSICS_NAME.match(name.split(".")[-1]) and _computes(fn)
                    and f"{module}:{name}" not in PHYSICS_EXCEPTIONS):
                found.append(f"{module}:{name} computes a physics term")
            for dec in getattr(fn, "decorator_list", []):
                target = dec.func if isinstance(dec, ast.Call) else dec
                if ast.unparse(target) in ("wp.func", "wp.kernel", "warp.func", "warp.kernel"):
                    found.append(f"{module}:{name} is a Warp {ast.unparse(target)[3:]}")
        for node in ast.walk(tree):
            if ((isinstance(node, ast.Name) and node.id == "erf")
                    or (isinstance(node, ast.Attribute) and node.attr == "erf")
                    or (isinstance(node, ast.alias) and node.name.split(".")[-1] == "erf")):
                found.append(f"{module}:{getattr(node, 'lineno', '?')} uses erf")
            if (isinstance(node, ast.BinOp) and isinstance(node.op, ast.Div)
                    and _squared_roughness(node.right)):
                found.append(f"{module}:{node.lineno} divides by a squared roughness")
    return sorted(set(found))


def test_physics_is_written_once_in_the_kernels():
    """No module outside ``kernels/`` re-implements a physics term of ``kernels/physics.py``:
    the host gets values from the Warp functions (``kernels/pointwise.py`` and the other host
    wrappers), so the solver, the fit and the walk cannot disagree on a formula."""
    sources = {m: p.read_text() for m, p in MODULES.items()
               if not m.startswith("layersim.kernels")}
    assert _physics_outside_kernels(sources) == []
    listed = {key.split(":")[0] for key in PHYSICS_EXCEPTIONS}
    assert listed <= set(sources), "an exception names a module that does not exist"
    defined = {f"{m}:{name}" for m in listed for name, _ in _functions(ast.parse(sources[m]))}
    assert set(PHYSICS_EXCEPTIONS) <= defined, "an exception names a function that is gone"


def test_physics_check_finds_a_formula_and_lets_a_delegate_pass():
    snippet = ("import numpy as np\nfrom scipy.special import erf\n"
               "def beckmann_d(t2, a):\n    return np.exp(-t2 / (a * a)) / (np.pi * a * a)\n"
               "def fresnel(c, eta):\n    return kernel_fresnel(c, eta)\n"
               "class Lobe:\n    def _smith_g1(self, w):\n        return 1.0 / (1.0 + w)\n"
               "import warp as wp\n@wp.func\ndef helper(x: float):\n    return x\n"
               "def weight(h, alpha_u, alpha_v):\n"
               "    return np.exp(-h[0] ** 2 / alpha_u ** 2 - h[1] ** 2 / (alpha_v * alpha_v))\n")
    assert _physics_outside_kernels({"m": snippet}) == [
        "m:15 divides by a squared roughness", "m:2 uses erf",
        "m:Lobe._smith_g1 computes a physics term", "m:beckmann_d computes a physics term",
        "m:helper is a Warp func"]
