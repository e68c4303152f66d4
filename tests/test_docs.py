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
        assert first_line in page and "Observation" in page and "Version history" in page, (name, first_line)
    for guide in ("first_hour", "leaderboard", "aips", "dials", "networks", "own_domain"):
        assert (site / "guide" / f"{guide}.html").is_file()
    index = (site / "index.html").read_text()
    assert "http://" not in index.split("<body")[0].replace("http://www.w3.org", "")  # no CDN in the head


def test_a_broken_reference_fails_the_build(tmp_path):
    """The same site with one link to a page that does not exist: the build fails, naming it."""
    copy = tmp_path / "docs"
    shutil.copytree(DOCS, copy, ignore=shutil.ignore_patterns("_build"))
    # the pages the site includes from the board's folder, not its entries (no board page then)
    shutil.copytree(DOCS.parent / "leaderboard", tmp_path / "leaderboard",
                    ignore=shutil.ignore_patterns("results", "policies", "archive", "plots", "index.html"))
    page = copy / "guide" / "first_hour.md"
    assert _build(copy, tmp_path / "whole").returncode == 0  # the copy builds (no board beside it) ...
    page.write_text(page.read_text() + "\nSee [the missing page](no_such_page.md).\n")
    proc = _build(copy, tmp_path / "out")
    assert proc.returncode != 0 and "no_such_page" in proc.stderr  # ... until one link is broken


# -- the site in a browser -------------------------------------------------------------------

def _chromium() -> str | None:
    """A Chromium to drive: $IALS_ZOO_CHROMIUM, or one on the PATH (Debian's `chromium`)."""
    import os

    found = os.environ.get("IALS_ZOO_CHROMIUM")
    for name in ("chromium", "chromium-browser", "google-chrome"):
        found = found or shutil.which(name)
    return found


@pytest.fixture(scope="module")
def browser():
    playwright = pytest.importorskip("playwright.sync_api", reason="the dev extra installs playwright")
    executable = _chromium()
    if executable is None:
        pytest.skip("no Chromium on this machine (.ci/run installs Debian's `chromium`; or set IALS_ZOO_CHROMIUM)")
    with playwright.sync_playwright() as p:
        b = p.chromium.launch(executable_path=executable, args=["--no-sandbox"])
        yield b
        b.close()


def _open(browser, path: Path, width: int = 1300):
    page = browser.new_page(viewport={"width": width, "height": 900})
    errors: list[str] = []
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.on("requestfailed", lambda r: errors.append(f"failed: {r.url}"))
    page.goto(path.as_uri())
    page.wait_for_load_state("load")
    return page, errors


def test_every_page_loads_without_a_console_error_and_fetches_nothing_from_elsewhere(site, browser):
    requested: list[str] = []
    pages = sorted(site.rglob("*.html"))
    assert len(pages) > 15 and (site / "board.html") in pages
    for path in pages:
        page, errors = _open(browser, path)
        page.on("request", lambda r: requested.append(r.url))
        page.reload()
        assert not errors, (path.name, errors)
        page.close()
    assert all(u.startswith("file://") for u in requested), [u for u in requested if not u.startswith("file://")]


def _column(page, table, header: str) -> list[str]:
    index = table.eval_on_selector_all("thead th", f"hs => hs.findIndex(h => h.textContent.startsWith({header!r}))")
    assert index >= 0, header
    return table.eval_on_selector_all("tbody tr", f"rs => rs.map(r => r.cells[{index}].dataset.sort ?? '')")


def test_the_board_sorts_by_a_clicked_header_best_first(site, browser):
    """The GS score: highest first on the first click, lowest first on the second; RESCO's
    delay (lower is better): lowest first on the first click."""
    page, errors = _open(browser, site / "board.html")
    tables = page.query_selector_all("table.board")
    table = next(t for t in tables if len(t.query_selector_all("tbody tr")) >= 3)
    header = table.query_selector("thead th:has-text('GS score')")
    header.click()
    scores = [float(v) for v in _column(page, table, "GS score")]
    assert scores == sorted(scores, reverse=True) and scores[0] == max(scores)
    header.click()
    scores = [float(v) for v in _column(page, table, "GS score")]
    assert scores == sorted(scores)
    delay_table = next(t for t in tables if t.query_selector("thead th:has-text('delay (lower is better)')")
                       and len(t.query_selector_all("tbody tr")) >= 2)
    delay_table.query_selector("thead th:has-text('delay (lower is better)')").click()
    delays = [float(v) for v in _column(page, delay_table, "delay (lower") if v != ""]
    assert delays == sorted(delays)
    assert not errors


def test_a_curves_points_are_the_result_jsons_numbers(site, browser):
    """The circles of an entry's curve hold its learning curve's own steps and means, and a
    legend box hides them."""
    from ials_zoo import leaderboard as lb

    page, errors = _open(browser, site / "board.html")
    points = page.eval_on_selector_all("circle.point", "cs => cs.map(c => [c.dataset.entry, c.dataset.seed, "
                                       "c.dataset.x, c.dataset.mean, c.closest('svg').getAttribute('aria-label')])")
    entries = {p.name: d for p, d in lb.load_entries()[0]}
    checked = 0
    for name, d in entries.items():
        for curve in d["learning_curves"]:
            want = sorted((float(p["env_steps"]), float(p["mean"])) for p in curve["points"])
            got = sorted((float(x), float(m)) for e, s, x, m, label in points
                         if e == name and s == str(curve["seed"]) and "env steps" in label)
            assert got == want, (name, curve["seed"])
            checked += 1
    assert checked >= 10
    box = page.query_selector(".legend input")
    series = box.get_attribute("data-series")
    box.click()
    assert page.eval_on_selector_all(f'[data-series="{series}"]', "gs => gs.filter(g => g.tagName == 'g')"
                                     ".every(g => g.style.display == 'none')")
    assert not errors


LAPTOP = 1400  # px: the width the pages must fit, a laptop's browser window


def test_every_table_of_the_board_fits_a_laptops_width(site, browser):
    """No table of the board runs off the page (its last column, the files and checks, was off
    screen at 1,682 px)."""
    page, errors = _open(browser, site / "board.html", LAPTOP)
    assert page.evaluate("document.documentElement.scrollWidth") <= LAPTOP
    rights = page.eval_on_selector_all("table.board", "ts => ts.map(t => t.getBoundingClientRect().right)")
    assert rights and max(rights) <= LAPTOP, max(rights)
    assert not errors


def test_no_code_block_of_the_docs_hides_its_end(site, browser):
    """At a laptop's width no code block hides its end behind a scroll bar (the first hour's
    commands end with their durations)."""
    errors = []
    for path in sorted(site.rglob("*.html")):
        page, page_errors = _open(browser, path, LAPTOP)
        errors += page_errors
        cut = page.eval_on_selector_all("div.highlight pre", "ps => ps.filter(p => p.scrollWidth > p.clientWidth + 1)"
                                                               ".map(p => p.textContent.slice(0, 60))")
        assert not cut, (path.name, cut)
        page.close()
    assert not errors


def test_every_curve_label_lies_inside_its_panel(site, browser):
    page, errors = _open(browser, site / "board.html", LAPTOP)
    outside = page.evaluate("""() => { const out = [];
        for (const s of document.querySelectorAll('svg')) { const r = s.getBoundingClientRect();
          for (const t of s.querySelectorAll('text')) { const q = t.getBoundingClientRect();
            if (q.left < r.left - 0.5 || q.right > r.right + 0.5) out.push(t.textContent); } }
        return out; }""")
    assert page.eval_on_selector_all("svg text", "ts => ts.length") > 100
    assert not outside, outside
    assert not errors


def test_every_column_of_numbers_sorts_by_its_numbers(site, browser):
    """Every numeric column of every table (the 95% CI by its lower end, the IQM, the metrics)
    sorts by its values both ways, its empty cells ("-") last."""
    page, errors = _open(browser, site / "board.html", LAPTOP)
    checked, names = 0, set()
    for table in page.query_selector_all("table.board"):
        if len(table.query_selector_all("tbody tr")) < 2:
            continue
        headers = table.query_selector_all("thead th")
        for i, header in enumerate(headers):
            numeric = table.eval_on_selector_all("tbody tr", f"rs => rs.every(r => r.cells[{i}].classList.contains('num'))")
            if not numeric:
                continue
            names.add(header.text_content())
            for _ in range(2):
                header.click()
                values = table.eval_on_selector_all("tbody tr", f"rs => rs.map(r => r.cells[{i}].dataset.sort ?? null)")
                assert None not in values, header.text_content()  # every number cell says how it sorts
                filled = [float(v) for v in values if v != ""]
                ascending = "sorted-asc" in (header.get_attribute("class") or "")
                assert filled == sorted(filled, reverse=not ascending), (header.text_content(), values)
                assert values[len(filled):] == [""] * (len(values) - len(filled)), (header.text_content(), values)
                checked += 1
    assert checked >= 40
    assert {"GS score", "95% CI", "IQM [95% CI]", "seeds", "env steps"} <= names, names
    assert not errors


def test_hovering_a_point_reaches_the_point(site, browser):
    """The bands of the other series do not take the pointer: at every visible point's centre
    the element under the pointer is a point (the one drawn last there)."""
    page, errors = _open(browser, site / "board.html", LAPTOP)
    missed = page.evaluate("""() => { let missed = [], seen = 0;
        for (const c of document.querySelectorAll('circle.point')) {
          let r = c.getBoundingClientRect(); if (!r.width) continue; seen++;
          window.scrollTo(0, window.scrollY + r.top - 300); r = c.getBoundingClientRect();
          const e = document.elementFromPoint(r.left + r.width / 2, r.top + r.height / 2);
          if (!e || !e.classList.contains('point')) missed.push(c.dataset.entry); }
        return [seen, missed]; }""")
    seen, missed = missed
    assert seen > 100 and not missed, (seen, len(missed))
    assert not errors


def test_the_boards_contents_lead_with_the_networks(site, browser):
    """The table of contents opens with the tables of the real maps (a track per network), and
    every entry of it leads to its table."""
    page, errors = _open(browser, site / "board.html", LAPTOP)
    first = page.eval_on_selector_all("nav.toc ul:first-of-type a", "as => as.map(a => [a.textContent, a.hash])")
    assert first and all("net=" in text for text, _ in first), first
    for text, hash_ in page.eval_on_selector_all("nav.toc a", "as => as.map(a => [a.textContent, a.hash])"):
        assert page.eval_on_selector(hash_, "h => h.textContent") == text
    assert not errors


def test_every_internal_link_of_the_site_resolves(site):
    """LinkChecker over the built site (external links not followed); a copy with one broken
    link fails it. (LinkChecker drops root's privileges, so the site is checked from a folder
    anyone can read.)"""
    import os
    import tempfile

    linkchecker = shutil.which("linkchecker")
    if linkchecker is None:
        pytest.skip("LinkChecker is not installed (the dev extra installs it)")

    def check(root: Path) -> subprocess.CompletedProcess:
        return subprocess.run([linkchecker, "--no-status", "--no-warnings", str(root / "index.html")],
                              capture_output=True, text=True, timeout=300)

    readable = Path(tempfile.mkdtemp(prefix="ials-zoo-site-"))
    try:
        os.chmod(readable, 0o755)
        for name in ("site", "broken"):
            shutil.copytree(site, readable / name)
        for folder, dirs, files in os.walk(readable):
            for d in dirs:
                os.chmod(Path(folder) / d, 0o755)
            for f in files:
                os.chmod(Path(folder) / f, 0o644)
        proc = check(readable / "site")
        assert proc.returncode == 0, proc.stdout[-3000:]
        index = readable / "broken" / "index.html"
        index.write_text(index.read_text().replace('href="board.html"', 'href="no_such_board.html"'))
        assert check(readable / "broken").returncode != 0
    finally:
        shutil.rmtree(readable, ignore_errors=True)


def test_the_fast_api_example_of_the_guide_runs():
    """The guide's examples, as written (a 2x2 floor and a three-light city keep them quick)."""
    import re

    text = (DOCS / "guide" / "fast_api.md").read_text()
    code, city = re.findall(r"```python\n(.*?)```", text, re.S)
    namespace: dict = {}
    exec(compile(code, "fast_api.md", "exec"), namespace)
    assert namespace["done"] is True and namespace["rewards"].shape == (4, namespace["copies"])
    assert namespace["gs_obs"].shape[:2] == (4, 2) and namespace["gs_rewards"].shape == (4, 2)
    exec(compile(city, "fast_api.md", "exec"), namespace)
    assert namespace["city_obs"].shape[:2] == (3, 2) and namespace["city_rewards"].shape == (3, 2)
    assert namespace["city_done"] is False


def test_the_readme_example_runs():
    """The landing page's ten lines, as written."""
    import re

    code = re.findall(r"```python\n(.*?)```", (DOCS.parent / "README.md").read_text(), re.S)[0]
    namespace: dict = {}
    exec(compile(code, "README.md", "exec"), namespace)
    try:
        assert set(namespace["rewards"]) == {"robot_20"} and namespace["every"].possible_agents[0] == "tls_0"
    finally:
        for name in ("env", "ials", "every", "city"):
            namespace[name].close()
