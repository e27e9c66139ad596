"""``tools/module_moves.py``: old module names rewritten to the pipeline folders, in every form a
file may cite them, idempotently; and the tree itself cites no old name."""
import importlib.util
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
_spec = importlib.util.spec_from_file_location("module_moves", ROOT / "tools" / "module_moves.py")
mm = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(mm)
MODULES = mm.existing_modules(ROOT)

# a module at the top of the package, written against the old names
TOP_OLD = '''\
from layersim.adding import add
from layersim import accuracy, bsdffile, plot as pl
from layersim import subtract
import layersim.fourier
x = layersim.fourier.taper_factors(3)
y = layersim.subtract(stack, known)
patch("layersim.interpolation.spline_weights")
see `layersim/adding.py`, :mod:`layersim.subtract` and :func:`layersim.subtract`
from .operator import Grid
from . import accuracy, adding
def f():
    from . import plot   # matplotlib is slow to import
    from .operator import (BLOCKS,  # the four blocks
                           Grid)
>>> from layersim.bsdf import BSDF
'''
TOP_NEW = '''\
from layersim.stacking.adding import add
from layersim.plan import accuracy
from layersim import bsdffile
from layersim.solved import plot as pl
from layersim import subtract
import layersim.operators.fourier
x = layersim.operators.fourier.taper_factors(3)
y = layersim.subtract(stack, known)
patch("layersim.operators.interpolation.spline_weights")
see `layersim/stacking/adding.py`, :mod:`layersim.stacking.subtract` and :func:`layersim.subtract`
from .operators.operator import Grid
from .plan import accuracy
from .stacking import adding
def f():
    from .solved import plot   # matplotlib is slow to import
    from .operators.operator import (BLOCKS,  # the four blocks
                           Grid)
>>> from layersim.solved.bsdf import BSDF
'''
# kernels/ installs as layersim.kernels: `..X` reaches layersim.X
KERNEL_OLD = "from ..operator import Grid\nfrom ..scene import Scene\nfrom .. import merl\n" \
             "from .physics import fresnel\n"
KERNEL_NEW = "from ..operators.operator import Grid\nfrom ..scene import Scene\n" \
             "from ..layers import merl\nfrom .physics import fresnel\n"
# a moved module (layersim/evaluator.py -> layersim/solved/evaluator.py) that another branch
# edited: old-form lines beside lines already rewritten
MOVED_OLD = "from .deltas import add_deltas\nfrom ..operators.operator import BLOCKS\n" \
            "from .isobsdf import IsoEvaluator\nfrom . import interpolation\n" \
            "from .errors import SceneError\n"
MOVED_NEW = "from ..operators.deltas import add_deltas\n" \
            "from ..operators.operator import BLOCKS\nfrom .isobsdf import IsoEvaluator\n" \
            "from ..operators import interpolation\nfrom ..errors import SceneError\n"
CASES = [(TOP_OLD, ("layersim",), TOP_NEW), (KERNEL_OLD, ("layersim.kernels",), KERNEL_NEW),
         (MOVED_OLD, ("layersim", "layersim.solved"), MOVED_NEW)]


@pytest.mark.parametrize("old, packages, new", CASES, ids=["top", "kernels", "moved"])
def test_every_form_is_rewritten(old, packages, new):
    warnings = []
    assert mm.rewrite_text(old, packages, MODULES, "sample", warnings) == new
    assert warnings == []


@pytest.mark.parametrize("old, packages, new", CASES, ids=["top", "kernels", "moved"])
def test_rewriting_twice_changes_nothing(old, packages, new):
    assert mm.rewrite_text(new, packages, MODULES) == new


def test_relative_imports_outside_the_package_are_left():
    text = "from .operator import Grid\nfrom layersim.operator import Grid\n"
    assert mm.rewrite_text(text, (None,)) == \
        "from .operator import Grid\nfrom layersim.operators.operator import Grid\n"


def test_a_statement_both_readings_resolve_is_left_and_reported():
    """In plan/accuracy.py (moved from the top), ``.layers`` may be layersim.layers (old) or
    layersim.plan.layers (new): both exist."""
    warnings = []
    text = "from .layers import kind_of\n"
    assert mm.rewrite_text(text, ("layersim", "layersim.plan"), MODULES, "a.py", warnings) == text
    assert warnings == ["a.py: ambiguous, left as it is: from .layers import kind_of"]


def test_packages_of_a_file():
    assert mm.packages_of(ROOT / "layersim/solved/evaluator.py", ROOT) == ("layersim",
                                                                           "layersim.solved")
    assert mm.packages_of(ROOT / "layersim/solved/__init__.py", ROOT) == ("layersim.solved",)
    assert mm.packages_of(ROOT / "kernels/sparse.py", ROOT) == ("layersim.kernels",)
    assert mm.packages_of(ROOT / "montecarlo/stack.py", ROOT) == ("layersim.montecarlo",)
    assert mm.packages_of(ROOT / "tests/test_scene.py", ROOT) == (None,)


def test_the_moves_match_the_tree():
    """Every new module exists, no old one remains, and no module or package of the tree takes an
    old name (which keeps the rewrite idempotent)."""
    assert all(new in MODULES for new in mm.MOVES.values())
    assert not any(old in MODULES for old in mm.MOVES)


def test_the_command_rewrites_in_place_and_checks(tmp_path, capsys):
    path = tmp_path / "study.py"
    path.write_text("from layersim.operator import Grid\n")
    assert mm.main(["--check", str(path)]) == 1
    assert path.read_text() == "from layersim.operator import Grid\n"
    assert mm.main([str(path)]) == 0
    assert path.read_text() == "from layersim.operators.operator import Grid\n"
    assert mm.main(["--check", str(path)]) == 0
    assert capsys.readouterr().out.splitlines()[-1] == "no changes"


def _cited_files():
    skip = {ROOT / "tools" / "module_moves.py", pathlib.Path(__file__).resolve()}
    folders = ("layersim", "kernels", "montecarlo", "tests", "benchmarks", "docs", "examples",
               "tools")
    files = [p for d in folders for ext in ("*.py", "*.md", "*.toml") for p in (ROOT / d).rglob(ext)]
    return [p for p in files + [ROOT / "README.md", ROOT / "pyproject.toml"] if p not in skip]


def test_the_tree_cites_no_old_module():
    stale = [str(p.relative_to(ROOT)) for p in _cited_files()
             if mm.rewrite_text(p.read_text(), mm.packages_of(p, ROOT), MODULES) != p.read_text()]
    assert stale == []
