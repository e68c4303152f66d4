"""Trust, round four: wall-clocks a reader can compare, every cost bounded, pages and files that
show what they hold, processes that leave quietly, and tests for what let bugs live."""

from __future__ import annotations

import json

import pytest
from test_trust3 import _board, trained  # noqa: F401  (trained: a module fixture, two tiny IPPO runs)

from ials_zoo.errors import BadInput

# -- 4. pages and files that show what they hold ---------------------------------------------


def test_a_result_file_name_outside_the_boards_alphabet_is_skipped_by_name(tmp_path, trained):  # noqa: F811
    """A name holding markup would go raw into README.md's ``[json](...)`` link: the board names
    its files itself, so any other name is a problem named in the lists, never linked."""
    from ials_zoo import leaderboard as lb
    from ials_zoo.leaderboard.site import render_site

    board = _board(tmp_path)
    entry = (trained / "s0" / "result.json").read_text()
    (board / "results" / 'x"><img src=x onerror=alert(1)>.json').write_text(entry)
    (board / "results" / "fine_name-0.json").write_text(entry)
    entries, problems = lb.load_entries(board)
    assert [p.name for p, _ in entries] == ["fine_name-0.json"]
    assert len(problems) == 1 and "[A-Za-z0-9._-]" in problems[0][1]
    readme = lb.render(board).read_text()
    page = render_site(board).read_text()
    for text in (readme, page):
        assert "<img" not in text and "onerror=alert(1)>" not in text
    assert "fine_name-0.json" in readme


def test_control_and_direction_characters_are_escaped_on_the_page_and_in_the_readme(tmp_path, trained):  # noqa: F811
    """U+202E shows a name reversed, NUL/ESC/BEL/U+2028 break lines or terminals: the page and
    README write them as escapes, as ``show`` does."""
    from ials_zoo import leaderboard as lb
    from ials_zoo.leaderboard.site import render_site

    board = _board(tmp_path)
    entry = json.loads((trained / "s0" / "result.json").read_text())
    entry["algorithm"] = "ippo\u202eevil\x00\x1b[2K\u2028\x07"
    (board / "results" / "e.json").write_text(json.dumps(entry))
    lb.load_result(board / "results" / "e.json")  # a valid entry
    page = render_site(board).read_text()
    readme = lb.render(board).read_text()
    for text in (page, readme):
        assert not any(c in text for c in "\u202e\x00\x1b\u2028\x07"), repr(text[:200])
        assert "ippo\\u202eevil\\x00\\x1b" in text


def test_the_board_page_escapes_an_off_board_policy_path_and_an_algorithm_label(tmp_path, trained):  # noqa: F811
    from ials_zoo.leaderboard.site import render_site

    board = _board(tmp_path)
    entry = json.loads((trained / "s0" / "result.json").read_text())
    entry["scores"][0]["policy_file"] = '"><script>alert(1)</script>'
    entry["algorithm"] = "<img src=x onerror=alert(1)>"
    (board / "results" / "e.json").write_text(json.dumps(entry))
    page = render_site(board).read_text()
    assert "<script>alert" not in page and "<img src=x" not in page
    assert "&lt;img src=x onerror=alert(1)&gt;" in page and "&lt;script&gt;alert(1)&lt;/script&gt;" in page
