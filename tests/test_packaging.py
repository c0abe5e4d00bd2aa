"""What ``pyproject.toml`` declares against what is tested: ``.ci/lowest.txt`` pins each
dependency at the floor that ``pyproject.toml`` declares (``docs/install.md``'s lowest-versions
run)."""

from __future__ import annotations

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version

from conftest import ROOT

tomllib = pytest.importorskip("tomllib")  # Python 3.11+

#: Extras whose packages the lowest-versions run installs (the developer tools' floors are not
#: tested: ruff and mypy check the code, they do not run it).
TESTED_EXTRAS = ("test", "dask")


def declared() -> list[Requirement]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    texts = project["dependencies"] + [
        text for extra in TESTED_EXTRAS for text in project["optional-dependencies"][extra]
    ]
    return [Requirement(text) for text in texts]


def pins(text: str) -> dict[str, Version]:
    """The ``name==version`` lines of a constraints file."""
    pinned = {}
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            name, version = line.split("==")
            pinned[canonicalize_name(name)] = Version(version)
    return pinned


def floor(requirement: Requirement) -> Version:
    lows = [Version(s.version) for s in requirement.specifier if s.operator == ">="]
    assert len(lows) == 1, f"{requirement}: one '>=' floor expected"
    return lows[0]


def test_pins_parse_constraints_lines() -> None:
    text = "# a comment\nnumpy==1.24.0  # why\n\nDask==2024.1.0\n"
    assert pins(text) == {"numpy": Version("1.24.0"), "dask": Version("2024.1.0")}


def test_the_lowest_versions_pin_every_floor_pyproject_declares() -> None:
    pinned = pins((ROOT / ".ci" / "lowest.txt").read_text(encoding="utf-8"))
    for requirement in declared():
        name = canonicalize_name(requirement.name)
        assert name in pinned, f"{name} is not pinned in .ci/lowest.txt"
        # the floor itself, and a version the whole requirement admits (not an excluded one)
        assert pinned[name] == floor(requirement), f"{name}: {pinned[name]} vs {requirement}"
        assert requirement.specifier.contains(pinned[name]), f"{name}: {requirement}"
