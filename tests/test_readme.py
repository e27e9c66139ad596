"""The README is a product document: its Python examples run as written, it stays short, it
links only to files that exist and it carries no development history (commit hashes)."""

import pathlib
import re

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
MAX_LINES = 335


def _python_blocks(text):
    """The bodies of the README's ```python fenced blocks, in order."""
    return re.findall(r"^```python\n(.*?)^```\s*$", text, flags=re.S | re.M)


BLOCKS = _python_blocks(README.read_text())


def test_readme_has_python_examples():
    assert len(BLOCKS) >= 1, "README.md has no ```python block to run"


@pytest.mark.parametrize("index", range(len(BLOCKS)))
def test_readme_python_block_runs_as_written(index, tmp_path, monkeypatch):
    """Each block runs in a fresh namespace inside an empty temporary directory (files it writes
    land there), where ``examples/`` is the repository's folder of example scenes."""
    (tmp_path / "examples").symlink_to(ROOT / "examples", target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    code = compile(BLOCKS[index], f"README.md python block {index + 1}", "exec")
    exec(code, {"__name__": "__readme__"})


def test_readme_length_is_capped():
    n = len(README.read_text().splitlines())
    assert n <= MAX_LINES, f"README.md has {n} lines; move detail to docs/ (limit {MAX_LINES})"


def test_readme_has_no_commit_hashes_or_session_talk():
    text = README.read_text()
    # 7-40 hex digits with at least one letter and one digit, as a word: an abbreviated hash.
    hashes = [m for m in re.findall(r"\b[0-9a-f]{7,40}\b", text)
              if re.search(r"[a-f]", m) and re.search(r"[0-9]", m)]
    assert not hashes, f"README.md cites commit hashes: {hashes}"
    assert "this session" not in text.lower()


def test_readme_links_point_to_existing_files():
    text = README.read_text()
    targets = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text)
    local = [t for t in targets if "://" not in t]
    assert local, "README.md links to none of docs/"
    missing = [t for t in local if not (ROOT / t).exists()]
    assert not missing, f"README.md links to missing files: {missing}"
