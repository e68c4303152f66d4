"""``ials-zoo demo``."""

import re

import pytest

from ials_zoo.cli import main


def test_demo_prints_summary(capsys):
    assert main(["demo", "--domain", "warehouse_v0", "--steps", "20", "--seed", "1"]) == 0
    out = capsys.readouterr().out
    assert "warehouse_v0: 20 steps, seed 1, robot_20 random" in out
    collected = int(re.search(r"items collected \(all robots\)\s+(\d+)", out).group(1))
    assert collected > 0
    assert re.search(r"mean return, scripted robots\s+\d+\.\d+ \(n=35\)", out)
    assert "GS steps/s" in out


@pytest.mark.parametrize("domain", ["warehouse_v0", "traffic_grid_v0"])
def test_demo_gif_has_a_caption_legend_and_real_frame_times(tmp_path, capsys, domain):
    from PIL import Image

    path = tmp_path / "demo.gif"
    assert main(["demo", "--domain", domain, "--steps", "5", "--gif", str(path)]) == 0
    assert path.read_bytes()[:4] == b"GIF8"
    assert "6 frames" in capsys.readouterr().out
    with Image.open(path) as gif:
        assert gif.n_frames == 6
        assert gif.info["duration"] >= 50  # milliseconds: not 0
        width, height = gif.size
    from ials_zoo.core.domains import get_domain

    env = get_domain(domain).parallel_env(render_mode="rgb_array", learners=[get_domain(domain).default_agents[0]])
    env.reset(seed=0)
    plain = env.render()
    env.close()
    assert height > plain.shape[0] + 20  # caption bar above and legend below the frame


def test_demo_runs_the_whole_episode_by_default(capsys):
    assert main(["demo", "--domain", "traffic_grid_v0"]) == 0
    assert "traffic_grid_v0: 300 steps" in capsys.readouterr().out


def test_demo_bad_steps(capsys):
    assert main(["demo", "--steps", "0"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("ials-zoo demo: --steps")
