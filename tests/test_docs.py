"""The documentation site builds from the repository with warnings as errors (a broken
reference or a docstring that does not parse fails it), and its environment pages are the env
classes' docstrings."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("sphinx")
pytest.importorskip("myst_parser")
pytest.importorskip("furo")

DOCS = Path(__file__).resolve().parent.parent / "docs"


def _build(source: Path, out: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", str(source),
                           str(out)], capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp("site")
    proc = _build(DOCS, out)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out


def test_the_site_builds_and_each_environment_page_is_its_docstring(site):
    from ials_zoo.sumo_net.env import SumoNetEnv
    from ials_zoo.traffic.env import TrafficGridEnv
    from ials_zoo.warehouse.env import WarehouseEnv

    for name, cls in (("warehouse_v0", WarehouseEnv), ("traffic_grid_v0", TrafficGridEnv),
                      ("sumo_net_v0", SumoNetEnv)):
        page = (site / "env" / f"{name}.html").read_text()
        first_line = cls.__doc__.strip().splitlines()[0].split("(")[0].strip()
        assert first_line in page and "Observation" in page, (name, first_line)
    for guide in ("first_hour", "leaderboard", "aips", "dials", "networks", "own_domain"):
        assert (site / "guide" / f"{guide}.html").is_file()
    index = (site / "index.html").read_text()
    assert "http://" not in index.split("<body")[0].replace("http://www.w3.org", "")  # no CDN in the head


def test_a_broken_reference_fails_the_build(tmp_path):
    """The same site with one link to a page that does not exist: the build fails, naming it."""
    copy = tmp_path / "docs"
    shutil.copytree(DOCS, copy, ignore=shutil.ignore_patterns("_build", "fidelity_diagnostics"))
    page = copy / "guide" / "first_hour.md"
    page.write_text(page.read_text() + "\nSee [the missing page](no_such_page.md).\n")
    proc = _build(copy, tmp_path / "out")
    assert proc.returncode != 0 and "no_such_page" in proc.stderr
