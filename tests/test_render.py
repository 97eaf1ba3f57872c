"""Pictures: shot PNG, inning GIF, rgb_array (billiards.render); playing an inning and the command line (billiards.pictures)."""

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from billiards import pictures, render
from billiards.baselines import nearest_red_policy
from billiards.envs import Billiards4BallInningEnv
from billiards.physics import canonical_rack, simulate_shot

# the paper's opening rack, white shot straight along -x at red2 beside it: hits red2 first
ACTION = np.array([np.pi, 0.6, 0.0, 0.0])


def test_render_shot_png(tmp_path):
    path = tmp_path / "shot.png"
    result = render.render_shot(canonical_rack(), ACTION, path, title="test")
    ref = simulate_shot(canonical_rack(), ACTION)
    np.testing.assert_array_equal(result.positions, ref.positions)
    assert result.first_contact == 3
    image = np.asarray(Image.open(path).convert("RGB"))
    assert image.shape[0] > image.shape[1] > 200  # portrait table
    # the cloth, the white ball and a red are all in the picture
    colours = {tuple(int(v) for v in c) for c in image.reshape(-1, 3)[::7]}
    for hex_colour in (render.CLOTH, render.BALL_COLORS[2]):
        rgb = tuple(int(hex_colour[i:i + 2], 16) for i in (1, 3, 5))
        assert any(sum(abs(a - b) for a, b in zip(rgb, c)) < 30 for c in colours), hex_colour
    assert "first contact: red2" in render.outcome_text(result)


def test_table_rgb_array_and_gym_render():
    image = render.table_rgb_array(canonical_rack())
    assert image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3
    env = Billiards4BallInningEnv(render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == image.shape
    assert not np.array_equal(frame, image)  # a random rack, not the canonical one


@pytest.mark.slow
def test_play_and_render_inning_gif(tmp_path):
    shots = pictures.play_inning(nearest_red_policy(), seed=1, max_shots=2)
    assert len(shots) == 2
    pos0, act0 = shots[0]
    # the second shot starts where the first left the table
    np.testing.assert_array_equal(shots[1][0], simulate_shot(pos0, act0).positions)
    path = tmp_path / "inning.gif"
    n_frames = render.render_inning(shots, path, fps=8, speed=4.0, pause=0.25, dpi=30)
    gif = Image.open(path)
    assert gif.format == "GIF" and 2 < gif.n_frames <= n_frames


def test_command_line(tmp_path, capsys):
    out = tmp_path / "cli.png"
    pictures.main(["shot", "--out", str(out), "--seed", "0", "--policy", "nearest", "--dpi", "40"])
    assert out.stat().st_size > 1000
    assert str(out) in capsys.readouterr().out


def test_render_draws_a_trained_policys_shots_on_its_own_table(tmp_path, capsys, international_policy):
    from pathlib import Path

    from billiards.physics import PRESETS

    shipped = Path(__file__).resolve().parents[1] / "results" / "policies" / "base" / "seed0.pt"
    policy, constrain_aim, extra_features, made_on = pictures.load_player(str(shipped))
    assert constrain_aim and extra_features and made_on == PRESETS["korean_medium"]
    foreign = international_policy  # the same networks, saved as if trained on the international table
    assert pictures.load_player(str(foreign))[3] == PRESETS["international"]
    out = tmp_path / "policy.png"
    pictures.main(["shot", "--out", str(out), "--policy", str(foreign), "--seed", "2", "--dpi", "40"])
    assert out.is_file() and "first contact" in capsys.readouterr().out
    image = np.asarray(Image.open(out).convert("RGB"))
    # played on the international table: the cloth is 1.42 m wide at 3 inches per metre and 40 dpi
    # (the default table's would be 1.27 m)
    cloth = (np.abs(image.astype(int) - [0x1F, 0x6E, 0x43]).sum(-1) < 30)
    cols = np.flatnonzero(cloth.any(0))
    assert cols[-1] - cols[0] + 1 == pytest.approx(1.42 * 3.0 * 40, rel=0.03)
    with pytest.raises(SystemExit, match="not nearest, random, or an existing"):
        pictures.main(["shot", "--out", str(out), "--policy", "no/such/run"])


@pytest.mark.slow
def test_the_former_command_line_points_to_the_new_one():
    """``python -m billiards.render`` only draws now; it says where the command line went."""
    from conftest import app_here

    proc = app_here("billiards.render", "shot", "--out", "x.png", cwd=Path(__file__).resolve().parents[1])
    assert proc.returncode != 0 and "python -m billiards.pictures" in proc.stderr
