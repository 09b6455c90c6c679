"""The bridge's mapping format is public (``services.bridge``) and the shipped mapping is
package data: one file, ``config/bridge/default.yaml``, found by an installed Lunaris run
anywhere, not only from the repository."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

from tests.harness import ROOT

SHIPPED = ROOT / "config" / "bridge" / "default.yaml"


def test_the_shipped_mapping_is_package_data_and_one_file():
    package_data = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    assert package_data["services.bridge"] == ["default.yaml"]
    data = ROOT / "services" / "bridge" / "default.yaml"
    assert data.is_symlink() and data.resolve() == SHIPPED.resolve(), \
        "services/bridge/default.yaml is a link to config/bridge/default.yaml: one copy"
    from services.bridge import DEFAULT_MAPPING, resolve_mapping
    assert DEFAULT_MAPPING == SHIPPED.resolve()
    assert resolve_mapping(None) == SHIPPED.resolve()  # from the repository, as before


def test_every_mapping_file_of_the_repository_is_valid():
    from services.bridge import load_mapping
    files = sorted((ROOT / "config" / "bridge").glob("*.yaml"))
    assert SHIPPED in files
    for path in files:
        assert load_mapping(path).mappings, path


def test_an_installed_lunaris_finds_the_shipped_mapping_away_from_the_repository(tmp_path):
    """The packages as a wheel holds them (links followed, so the mapping's text is inside),
    imported from a folder that is not the repository, run from one with no config/."""
    site = tmp_path / "site-packages"
    for package in ("common", "services", "lunaris"):
        shutil.copytree(ROOT / package, site / package, symlinks=False,
                        ignore=shutil.ignore_patterns("__pycache__", "static"))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    code = ("import json; from services.bridge import DEFAULT_MAPPING, load_mapping, resolve_mapping; "
            "path = resolve_mapping(None); "
            "print(json.dumps([str(DEFAULT_MAPPING), str(path), len(load_mapping(path).mappings)]))")
    env = {**os.environ, "PYTHONPATH": str(site), "PYTHONSAFEPATH": "1"}
    out = subprocess.run([sys.executable, "-c", code], cwd=elsewhere, env=env, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    default, found, mappings = json.loads(out.stdout)
    assert default == found == str(site / "services" / "bridge" / "default.yaml")
    assert not Path(found).is_symlink()
    from services.bridge import load_mapping
    assert mappings == len(load_mapping(SHIPPED).mappings)
