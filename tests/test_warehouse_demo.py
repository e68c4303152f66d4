"""``ials-zoo demo`` on the warehouse."""

import re

from ials_zoo.cli import main


def test_demo_prints_summary(capsys):
    assert main(["demo", "--steps", "20", "--seed", "1"]) == 0
    out = capsys.readouterr().out
    assert "warehouse_v0: 20 steps, seed 1, robot_20 random" in out
    collected = int(re.search(r"items collected \(all robots\)\s+(\d+)", out).group(1))
    assert collected > 0
    assert re.search(r"mean return, scripted\s+\d+\.\d+ \(n=35\)", out)
    assert "GS steps/s" in out


def test_demo_gif(tmp_path, capsys):
    path = tmp_path / "demo.gif"
    assert main(["demo", "--steps", "5", "--gif", str(path)]) == 0
    assert path.read_bytes()[:4] == b"GIF8"
    assert "6 frames" in capsys.readouterr().out


def test_demo_bad_steps(capsys):
    assert main(["demo", "--steps", "0"]) == 2
    assert "--steps" in capsys.readouterr().err
