"""Packaging: every Python package in the source tree is installed by a regular (non-editable) install.

An editable install finds sub-packages on disk whether or not ``pyproject.toml`` lists them, so a
missing entry only shows up on a fresh ``pip install .`` (as it did for ``layersim.aniso`` on the
GPU machine). This test compares the list with the folders.
"""
import pathlib
import tomllib

ROOT = pathlib.Path(__file__).resolve().parents[1]


def _declared():
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    return set(cfg["packages"]), cfg["package-dir"]


def test_every_source_package_is_declared():
    packages, package_dir = _declared()
    on_disk = set()
    for top, folder in package_dir.items():
        base = ROOT / folder
        for init in base.rglob("__init__.py"):
            rel = init.parent.relative_to(base)
            name = ".".join((top, *rel.parts)) if rel.parts else top
            on_disk.add(name)
    missing = on_disk - packages
    assert not missing, f"add {sorted(missing)} to [tool.setuptools] packages in pyproject.toml"
    assert packages <= on_disk, f"declared but absent: {sorted(packages - on_disk)}"
