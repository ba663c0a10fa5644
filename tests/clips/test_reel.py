"""Reels: three moments of one search's summary (a HIGHLIGHTS-style summary: windows of the leader alone, and a
disagreement) rendered by the crowd domain's renderer and joined into one playable clip with cards between them."""

from __future__ import annotations

import json
import re
import subprocess

import imageio_ffmpeg
import numpy as np
import pytest
from PIL import Image

from search.cli import main
from search.clips.reel import CARD_SECONDS, render_reel
from search.clips.render import INK, RenderOptions
from search.core.domain import domain_for
from tests.clips.test_render import colour_mask, probe, top_level_boxes

FAST = RenderOptions(speed=4.0, hold_start=0.25, hold_end=0.25, event_hold=0.25)


@pytest.fixture(scope="module")
def summary(tmp_path_factory) -> dict:
    """`foil search`'s best summary of lo and hi on paper-code (100 steps)."""
    out = tmp_path_factory.mktemp("search")
    args = ["search", "--agents", "lo,hi", "--scenario", "paper-code", "--solver", "nfirst", "--budget", "300"]
    assert main([*args, "--top-k", "1", "--seed", "0", "--out", str(out)]) == 0
    return json.loads((out / "summary-001.json").read_text())


def segments(folder, summary: dict, variants: list[dict]) -> list:
    paths = []
    for n, keys in enumerate(variants):
        path = folder / f"moment-{n}.json"
        path.write_text(json.dumps(summary | keys))
        paths.append(path)
    return paths


def crowd(numbers=(1, 2)):
    domain = domain_for(["lo", "hi"], "paper-code")
    return lambda summary, out: domain.render(summary, out, list(numbers), FAST)


def decoded(path) -> list[np.ndarray]:
    frames = imageio_ffmpeg.read_frames(str(path))
    meta = next(frames)
    width, height = meta["size"]
    return [np.frombuffer(frame, np.uint8).reshape(height, width, 3) for frame in frames]


def test_a_reel_of_three_segments_is_one_playable_clip_of_their_length_plus_the_cards(tmp_path, summary):
    steps = len(summary["steps"])
    moments = segments(
        tmp_path,
        summary,
        [
            {"window": [0, 16], "follow": {"leader": 1, "steps": steps}},
            {"window": [40, 56], "follow": {"leader": 1, "steps": steps}},
            {"window": [84, 100], "follow": {"leader": 1, "steps": steps}},
        ],
    )
    singles = [crowd()(path, tmp_path / f"single-{n}.mp4") for n, path in enumerate(moments)]
    result = render_reel(moments, tmp_path / "reel" / "reel.mp4", crowd(), FAST)

    cards = 3 * round(CARD_SECONDS * 24)  # "Moment 1 of 3" before the first too
    assert result.frames == sum(s.frames for s in singles) + cards
    assert result.seconds == pytest.approx(sum(s.seconds for s in singles) + 3 * CARD_SECONDS)
    frames, seconds = imageio_ffmpeg.count_frames_and_secs(str(result.clip))
    assert frames == result.frames and seconds == pytest.approx(result.seconds, abs=0.05)
    info = probe(result.clip)
    video = re.search(r"Video: (\w+).*?, (\w+)(?:\(.*?\))?, (\d+)x(\d+)", info)
    assert video and (video.group(1), video.group(2)) == ("h264", "yuv420p") and "24 fps" in info, info
    assert (
        (int(video.group(3)), int(video.group(4)))
        == (result.width, result.height)
        == (singles[0].width, singles[0].height)
    )
    boxes = top_level_boxes(result.clip)
    assert boxes.index("moov") < boxes.index("mdat")
    errors = subprocess.run(
        [imageio_ffmpeg.get_ffmpeg_exe(), "-v", "error", "-i", str(result.clip), "-f", "null", "-"],
        capture_output=True,
        text=True,
    ).stderr
    assert errors == ""  # decodes cleanly from end to end

    pictures = decoded(result.clip)
    first_card = round(CARD_SECONDS * 24) + singles[0].frames + round(CARD_SECONDS * 24) // 2
    card, moment = pictures[first_card], pictures[first_card + round(CARD_SECONDS * 24)]
    assert colour_mask(card, INK, tolerance=40).sum() > 500  # "Moment 2 of 3", large
    assert colour_mask(card, (255, 255, 255), tolerance=3).mean() > 0.9  # and nothing else
    assert colour_mask(moment, (255, 255, 255), tolerance=3).mean() < 0.5  # the second segment's arena
    with Image.open(result.poster) as poster, Image.open(singles[0].poster) as first:
        assert np.array_equal(np.asarray(poster), np.asarray(first))
    with Image.open(result.sheet) as sheet, Image.open(singles[0].sheet) as one:
        assert sheet.width == one.width and sheet.height == 3 * one.height
    assert sorted(p.name for p in result.clip.parent.iterdir()) == ["reel.mp4", "reel.poster.png", "reel.sheet.png"]


def test_segments_of_different_sizes_are_padded_and_re_encoded(tmp_path, summary):
    """The leader alone (one legend line) beside a disagreement (two): the reel takes the larger size."""
    moments = segments(
        tmp_path,
        summary,
        [{"window": [0, 12], "follow": {"leader": 1, "steps": len(summary["steps"])}}, {"window": [0, 12]}],
    )
    singles = [crowd()(path, tmp_path / f"single-{n}.mp4") for n, path in enumerate(moments)]
    assert singles[0].height < singles[1].height
    result = render_reel(moments, tmp_path / "reel.mp4", crowd(), FAST)
    assert (result.width, result.height) == (singles[1].width, singles[1].height)
    assert result.frames == sum(s.frames for s in singles) + 2 * round(CARD_SECONDS * 24)
    assert imageio_ffmpeg.count_frames_and_secs(str(result.clip))[0] == result.frames
    assert "24 fps" in probe(result.clip)


def test_a_failed_segment_leaves_no_reel(tmp_path, summary):
    moments = segments(tmp_path, summary, [{"window": [0, 12]}, {"window": [12, 6]}])
    with pytest.raises(ValueError, match="window must be"):
        render_reel(moments, tmp_path / "reel.mp4", crowd(), FAST)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["moment-0.json", "moment-1.json"]
