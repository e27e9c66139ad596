"""The ``benchmarks/`` paths that the documents and sources cite exist, and the index of
``benchmarks/`` (its README) names every script and committed output.

Cited paths are read from README.md, docs/*.md, the package's sources (``layersim/``,
``kernels/``, ``montecarlo/``), the tests, the examples and the benchmark scripts themselves
(their docstrings and usage lines). Committed outputs are records of runs and keep the command
as it was run, so they are not read. A path component in capitals (``SCENE.npz``, ``OUTDIR``)
is a placeholder and matches any name."""
import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[1]
BENCH = ROOT / "benchmarks"
#: Files whose text may cite benchmark paths.
SOURCES = sorted(
    [ROOT / "README.md", BENCH / "README.md", *(ROOT / "docs").glob("*.md"),
     *(p for d in ("layersim", "kernels", "montecarlo", "tests") for p in (ROOT / d).rglob("*.py")),
     *(ROOT / "examples").glob("*.toml"),
     *BENCH.rglob("*.py"), *BENCH.rglob("*.sh")])
PATH = re.compile(r"(?<![\w/.-])benchmarks/[\w./*-]*")
#: What a benchmark folder holds besides scripts and their outputs: scene files, solver
#: ladders (binary data of benchmarks/accuracy/convergence_tables.py) and the plots and tables
#: of ``layersim bench`` reports.
NOT_INDEXED = ("scenes/", "accuracy/convergence/", "reports/cpu/", "reports/gpu/report/")


def cited_paths(text: str) -> list:
    """``benchmarks/...`` paths in ``text``, trailing punctuation removed."""
    return [m.rstrip(".,:;") for m in PATH.findall(text)]


def exists(path: str) -> bool:
    pattern = "/".join(re.sub(r"\b[A-Z][A-Z_]+\b", "*", part) for part in path.split("/"))
    if "*" not in pattern:
        return (ROOT / pattern).exists()
    return any(ROOT.glob(pattern.rstrip("/")))


def test_the_path_finder_reads_docstrings_and_commands():
    text = "(``benchmarks/speed/table2.py``), `python benchmarks/features/ndf_fit.py 91 180`."
    assert cited_paths(text) == ["benchmarks/speed/table2.py", "benchmarks/features/ndf_fit.py"]
    assert exists("benchmarks/accuracy/convergence/SCENE.npz")
    assert not exists("benchmarks" + "/table2.py")        # split: this file is read as a source


def test_cited_benchmark_paths_exist():
    assert len(SOURCES) > 100          # the globs found the package, tests and scripts
    missing = {}
    for source in SOURCES:
        gone = sorted({p for p in cited_paths(source.read_text()) if not exists(p)})
        if gone:
            missing[source.relative_to(ROOT).as_posix()] = gone
    assert not missing, f"cited benchmark paths that do not exist: {missing}"


def test_the_benchmarks_index_names_every_script_and_output():
    index = set(cited_paths((BENCH / "README.md").read_text()))
    index |= {p.rstrip("/") for p in index}
    files = [p.relative_to(ROOT).as_posix() for p in BENCH.rglob("*")
             if p.is_file() and p.name != "README.md" and "__pycache__" not in p.parts
             and not p.relative_to(BENCH).as_posix().startswith(NOT_INDEXED)]
    files += [f"benchmarks/{folder}".rstrip("/") for folder in NOT_INDEXED]
    unnamed = sorted(f for f in files if f not in index)
    assert not unnamed, f"benchmarks/README.md does not name: {unnamed}"
