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


def test_every_shipped_yaml_file_reads_the_same_in_a_yaml_1_1_tool():
    """Found by an integrator: the shipped mapping's field ``on`` is ``True`` to PyYAML (YAML
    1.1), and the mapping edited with it (loaded and dumped back) was refused by ``lunaris
    check``. Every shipped data file quotes the words such a tool reads otherwise; a file
    edited so is refused with the fix in words."""
    import yaml

    from common.datafile import load_yaml
    from services.bridge.mapping import parse_mapping
    def booleans(a, b, where: str) -> list[str]:  # where PyYAML's a has a boolean and ours not
        if isinstance(a, dict) and isinstance(b, dict):
            out = [f"{where}.{ka}" for ka, kb in zip(a, b, strict=False) if isinstance(ka, bool)
                   and not isinstance(kb, bool)]
            return out + [x for (ka, va), vb in zip(a.items(), b.values(), strict=False)
                          for x in booleans(va, vb, f"{where}.{ka}")]
        if isinstance(a, list) and isinstance(b, list):
            return [x for i, (va, vb) in enumerate(zip(a, b, strict=False))
                    for x in booleans(va, vb, f"{where}[{i}]")]
        return [where] if isinstance(a, bool) and not isinstance(b, bool) else []

    for path in sorted((ROOT / "config").rglob("*.yaml")):
        text = path.read_text()
        assert booleans(yaml.safe_load(text), load_yaml(text, str(path)), path.name) == [], \
            f"{path}: quote on/off/yes/no"
    parse_mapping(yaml.safe_dump(yaml.safe_load(SHIPPED.read_text())), "edited.yaml")  # still valid
    edited = SHIPPED.read_text().replace('field: "on"', "field: on").replace('{"on": data}', "{on: data}")
    try:
        parse_mapping(yaml.safe_dump(yaml.safe_load(edited)), "edited.yaml")
    except Exception as exc:  # ConfigError, naming each place
        said = str(exc)
    else:
        raise AssertionError("a mapping with booleans for names was taken")
    assert "mappings[19].field: a boolean where a name was expected: quote it" in said, said
    assert "request.True: a boolean where a name was expected" in said, said
