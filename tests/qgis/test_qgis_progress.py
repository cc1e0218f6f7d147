"""Progress moves through every stage (registration included) and each step is logged once, in
the plugin's words (no command-line flags, no RANSAC planes when the surface correction runs)."""

from __future__ import annotations

import pytest

from .recording import RecordingFeedback


@pytest.fixture(scope="module")
def recorded(run_alg_session, scene_dir, tmp_path_factory) -> RecordingFeedback:
    out = tmp_path_factory.mktemp("progress")
    feedback = RecordingFeedback()
    run_alg_session(
        "estimatevolumechange",
        {
            "BEFORE": str(scene_dir / "before.las"),
            "AFTER": str(scene_dir / "after.las"),
            "CELL": 1.0,
            "DIFFERENCE": str(out / "d.tif"),
        },
        feedback=feedback,
    )
    return feedback


def test_progress_moves_through_registration(recorded):
    steps = recorded.progress
    assert steps == sorted(steps) and steps[-1] == pytest.approx(100)
    registration = {round(p, 1) for p in steps if 15 < p < 55}
    assert len(registration) >= 3, steps  # ICP levels move the bar
    assert len({round(p) for p in steps}) >= 10


def test_each_step_logged_once_in_plain_words(recorded):
    engine_lines = [line for line in recorded.infos if not line.startswith(("Before point cloud", "Volumes"))]
    steps = [line for line in engine_lines if line.startswith(("Reading", "Registering", "Gridding"))]
    assert len(steps) == len(set(steps)) == 3, steps
    assert not any("--" in line for line in recorded.infos)
    assert not any("RANSAC" in line for line in recorded.infos)
    assert all(line[:1].isupper() for line in engine_lines if line[:1].isalpha())
