"""The trial pictures (results page cards, stimuli/sheet.py): A and B of a trial on
one world frame with the table and the build site, so a tower that is moved (10E:
10 cm, 10H: 40 cm) is seen to move; B shows every block of the finished table,
also the ones A leaves where they were (pair 12's bucket keeps 15 of its 20)."""
import io

import numpy as np
import pytest

import stimuli
from models.effort import sample_rng
from stimuli.sheet import draw_trial, finished_scene, world_limits


def _halves(trial_id: str) -> tuple[np.ndarray, np.ndarray]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    trial = stimuli.load_trial(trial_id)
    fig = plt.figure(figsize=(4.4, 2.2))
    draw_trial(fig, trial, trial.sample_initial(sample_rng(0, 0)), ("", ""))
    fig.subplots_adjust(left=0, right=1, bottom=0, top=1, wspace=0)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=60)
    plt.close(fig)
    img = plt.imread(io.BytesIO(buf.getvalue()))[..., :3]
    w = img.shape[1] // 2
    return img[:, :w], img[:, w:2 * w]


def test_b_of_a_bucket_trial_keeps_the_blocks_the_tower_does_not_use():
    for tid in ("12E", "12H"):
        trial = stimuli.load_trial(tid)
        A = trial.sample_initial(sample_rng(0, 0))
        B = finished_scene(A, trial.target)
        assert len(A) == 20 and len(trial.target) == 5 and len(B) == 20
        left = B.positions[len(trial.target):]
        # the 15 left behind are where A had them: in the bucket (x = 0.5 m, inside its walls)
        assert np.all(np.abs(left[:, 0] - 0.5) < 0.03) and np.all(np.abs(left[:, 1]) < 0.13)
        # and the tower's colour is taken from the bucket: no block of that colour stays there
        colour = trial.target.blocks[0].colour
        assert not any(b.colour == colour for b in B.blocks[len(trial.target):])


def test_a_and_b_share_one_world_frame_holding_both_and_the_build_site():
    trial = stimuli.load_trial("10H")
    A = trial.sample_initial(sample_rng(0, 0))
    (x0, x1), (y0, y1), _ = world_limits(A, trial.target, build_site=trial.initial.build_site)
    for p in np.vstack([A.positions, trial.target.positions]):
        assert x0 < p[0] < x1 and y0 < p[1] < y1
    # the tower moves 40 cm: a frame around one of them alone would be a few cm wide
    assert max(x1 - x0, y1 - y0) > 0.40


@pytest.mark.parametrize("trial_id", ["10E", "10H"])
def test_a_moved_tower_is_drawn_in_another_place(trial_id):
    """The same 4-block tower in A and B: zoomed to each, the two halves were the same
    picture; on one world frame they differ (the tower is elsewhere on the table)."""
    a, b = _halves(trial_id)
    differ = np.abs(a - b).max(axis=-1) > 0.1
    assert differ.mean() > 0.01, f"{trial_id}: A and B pictures differ in {differ.mean():.2%} of the pixels"
