"""The renderer: geometry, names, events, timeline and the encoded file, checked on real frames and real ffmpeg."""

from __future__ import annotations

import dataclasses
import json
import re
import subprocess
from pathlib import Path

import imageio_ffmpeg
import numpy as np
import pytest
from PIL import Image

from search.clips.render import (
    AGENT_COLOURS,
    AGENT_SHAPES,
    AGENT_STYLES,
    BACKGROUND,
    CRASH,
    INK,
    SUCCESS,
    AgentSprites,
    Frame,
    RenderOptions,
    agent_style,
    number_ink,
)
from search.clips.windows import SummaryError
from search.crowd.render import HUMAN_FILL, CrowdClipRenderer, render, render_file
from search.crowd.scene import load_scene, scene_from_summary
from search.crowd.sim.scenarios import load_scenario
from tests.support.live_server import REPO
from tests.support.summaries import summary_from_simulation, visible

FAST = RenderOptions(speed=4.0, hold_start=0.25, hold_end=0.25, event_hold=0.25)


def colour_mask(image, colour, tolerance=6) -> np.ndarray:
    pixels = np.asarray(image, dtype=np.int16)
    return np.all(np.abs(pixels - np.array(colour)) <= tolerance, axis=-1)


def blob_centre(mask: np.ndarray, around, radius: float):
    """Centroid (column, row) of the masked pixels within ``radius`` of ``around``, or None."""
    rows, cols = np.nonzero(mask)
    near = np.hypot(cols - around[0], rows - around[1]) <= radius
    if not near.any():
        return None
    return np.array([cols[near].mean(), rows[near].mean()])


def test_layout_maps_the_arena_with_y_up_and_sizes_in_multiples_of_16(shared_summary):
    renderer = CrowdClipRenderer(scene_from_summary(shared_summary))
    lay = renderer.layout
    assert lay.width % 16 == 0 and lay.height % 16 == 0
    bottom_left = lay.to_pixel(0, lay.origin)
    top_right = lay.to_pixel(0, (lay.origin[0] + lay.span, lay.origin[1] + lay.span))
    np.testing.assert_allclose(bottom_left, [0, lay.header + lay.panel])
    np.testing.assert_allclose(top_right, [lay.panel, lay.header])


@pytest.mark.parametrize("width", [None, 640, 1280])
def test_legend_text_stays_readable_on_a_360_px_phone(shared_summary, width):
    lay = CrowdClipRenderer(scene_from_summary(shared_summary), options=RenderOptions(width=width)).layout
    assert lay.text * 360 / lay.width >= 13
    assert lay.header + lay.panel + lay.legend == lay.height  # the legend lies below the arena, not on it


def test_every_human_is_drawn_where_the_summary_puts_it(shared_summary):
    scene = scene_from_summary(shared_summary)
    renderer = CrowdClipRenderer(scene)
    r_px = scene.human_radius * renderer.layout.scale
    for step in (0, 10, 30):
        t = shared_summary["steps"][step]["t"]
        image = renderer.draw(Frame(t))
        mask = colour_mask(image, HUMAN_FILL)
        humans = np.array(shared_summary["steps"][step]["other_positions"])
        robots = np.array(shared_summary["steps"][step]["agent_positions"])
        for h, xy in enumerate(humans):
            others = np.concatenate([np.delete(humans, h, axis=0), robots])
            if np.min(np.hypot(*(others - xy).T)) < 3 * scene.human_radius:
                continue  # a neighbour or a robot would overlap the search window
            expected = renderer.layout.to_pixel(0, xy)
            found = blob_centre(mask, expected, 1.2 * r_px)
            assert found is not None, f"human {h} not drawn at step {step}"
            found += 0.5  # pixel (c, r) covers [c, c + 1) x [r, r + 1): its centre is at c + 0.5
            assert np.hypot(*(found - expected)) < 1.5, f"human {h} drawn at {found}, expected {expected}"


def test_positions_between_steps_are_interpolated(shared_summary):
    scene = scene_from_summary(shared_summary)
    renderer = CrowdClipRenderer(scene)
    t0, t1 = scene.times[5], scene.times[6]
    _, robots, humans = renderer._state((t0 + t1) / 2)
    lay = renderer.layout
    np.testing.assert_allclose(humans[0], lay.to_pixel(0, (scene.humans[5, 0] + scene.humans[6, 0]) / 2))
    np.testing.assert_allclose(robots, lay.to_pixel(0, (scene.robots[5] + scene.robots[6]) / 2))


def test_timeline_is_smooth_holds_both_ends_and_pauses_on_events(shared_summary):
    options = RenderOptions(fps=24, speed=1.0, hold_start=1.0, hold_end=1.5, event_hold=0.5)
    scene = scene_from_summary(shared_summary)
    frames = CrowdClipRenderer(scene, options=options).frames
    times = np.array([f.time for f in frames])
    assert np.all(times[:24] == 0) and times[24] == 0
    assert np.all(times[-36:] == scene.end_time)
    assert np.all(np.diff(times) >= 0)
    assert np.max(np.diff(times)) <= options.speed / options.fps + 1e-9
    for event_time in scene.event_times():
        assert np.sum(np.isclose(times, event_time)) >= 12
    faster = CrowdClipRenderer(scene, options=RenderOptions(speed=2.0, hold_start=0, hold_end=0, event_hold=0))
    assert len(faster.frames) < len(frames) / 2


def test_labels_never_reveal_agent_names(tmp_path, shared_summary):
    summary = broken(shared_summary, lambda s: s["agents"][0].update(source="checkpoints/SECRET-SOURCE.pt"))
    secrets = [a["name"] for a in summary["agents"]] + ["SECRET-SOURCE"]
    scene = scene_from_summary(summary)
    renderer = CrowdClipRenderer(scene, numbers=[2, 1], options=FAST)
    for frame in renderer.frames:
        renderer.draw(frame)
    drawn = " ".join(sorted(renderer.texts))
    assert "Robot 1" in drawn and "Robot 2" in drawn
    for secret in secrets:
        assert secret.lower() not in drawn.lower()
    result = render(scene, tmp_path / "clip.mp4", numbers=[2, 1], options=FAST)
    for path in (result.clip, result.poster, result.sheet):
        data = path.read_bytes().lower()
        for secret in secrets:
            assert secret.lower().encode() not in data, f"{secret} in {path.name}"


def test_robot_numbers_pick_colour_and_order(shared_summary):
    scene = scene_from_summary(shared_summary)
    swapped = CrowdClipRenderer(scene, numbers=[2, 1])
    assert swapped.order == [1, 0]  # legend and panels list Robot 1 first: the summary's second agent
    image = swapped.draw(Frame(5.0))
    blue = colour_mask(image, AGENT_STYLES[0][0], tolerance=3)
    _, robots, _ = swapped._state(5.0)
    found = blob_centre(blue, robots[1], 0.3 * swapped.layout.scale)
    assert found is not None  # Robot 1's colour is drawn at the summary's second robot
    with pytest.raises(ValueError, match="one agent number"):
        CrowdClipRenderer(scene, numbers=[1, 1])
    with pytest.raises(ValueError, match="its own colour and shape"):
        CrowdClipRenderer(scene, numbers=[3, 3 + len(AGENT_STYLES)])  # another name, but the same look
    high = CrowdClipRenderer(scene, numbers=[40, 41])  # any number is drawn, in its own colour and shape
    image = high.draw(Frame(0.0))
    assert {"Robot 40", "Robot 41"} <= high.texts
    assert colour_mask(image, agent_style(41)[0], tolerance=3).sum() > 50


def linear(colour) -> np.ndarray:
    c = np.asarray(colour) / 255
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def contrast(a, b) -> float:
    """WCAG contrast ratio."""
    high, low = sorted((linear(a) @ [0.2126, 0.7152, 0.0722], linear(b) @ [0.2126, 0.7152, 0.0722]), reverse=True)
    return (high + 0.05) / (low + 0.05)


def lab(colour) -> np.ndarray:
    """CIE L*a*b* (D65) of an sRGB colour."""
    xyz = np.array([[0.4124, 0.3576, 0.1805], [0.2126, 0.7152, 0.0722], [0.0193, 0.1192, 0.9505]]) @ linear(colour)
    f = np.cbrt(xyz / [0.9505, 1.0, 1.089])
    f = np.where(xyz / [0.9505, 1.0, 1.089] > 0.008856, f, 7.787 * xyz / [0.9505, 1.0, 1.089] + 16 / 116)
    return np.array([116 * f[1] - 16, 500 * (f[0] - f[1]), 200 * (f[1] - f[2])])


def test_every_robot_style_is_distinct():
    """A robot's look (colour and shape) is its own: every style differs from every other, any round's robots
    (consecutive numbers) differ in colour and in shape, and each number is legible on its colour."""
    assert len(set(AGENT_STYLES)) == len(AGENT_STYLES) == len(AGENT_COLOURS) * len(AGENT_SHAPES)
    for first in range(1, len(AGENT_STYLES) + 1):
        block = [agent_style(n) for n in range(first, first + len(AGENT_SHAPES))]
        assert len({colour for colour, _ in block}) == len({shape for _, shape in block}) == len(block)
    for i, a in enumerate(AGENT_COLOURS):
        assert contrast(number_ink(a), a) >= 4.0
        assert np.linalg.norm(lab(a) - lab(CRASH)) > 20  # never the collision's yellow
        for b in AGENT_COLOURS[i + 1 :]:
            assert np.linalg.norm(lab(a) - lab(b)) > 20, (a, b)  # CIE76 distance: clearly different colours
    # silhouettes: each shape's marker (with its white rim) overlaps any other by at most 5/6 of their union
    numbers = list(range(1, len(AGENT_SHAPES) + 1))
    sprites = AgentSprites(numbers, 30.0, 13)
    masks = {n: np.asarray(sprites.markers[n][0])[..., 3] > 128 for n in numbers}
    for a in numbers:
        for b in numbers[a:]:
            overlap = (masks[a] & masks[b]).sum() / (masks[a] | masks[b]).sum()
            assert overlap < 0.85, (agent_style(a)[1], agent_style(b)[1], overlap)


def test_the_robots_of_a_clip_and_of_a_ranking_round_have_clearly_different_colours():
    """Not two blues (Robot 13 sky blue beside Robot 15 blue): `foil bundle` numbers a round's robots, and a clip's
    pair, in a block of consecutive numbers, and any three consecutive numbers are far apart in colour."""
    from search.bundle.searches import plan_clips
    from search.bundle.spec import load_build

    for name in ("demo", "paper"):
        spec, _ = load_build(REPO / "studies" / f"{name}.toml")
        jobs = plan_clips(spec)
        rounds = {}
        for job in (job for job in jobs if "ranking" in job.parts):
            rounds.setdefault((job.scheme.name, job.scenario), set()).update(job.numbers)
        for numbers in [set(job.numbers) for job in jobs] + list(rounds.values()):
            assert max(numbers) - min(numbers) < 3, numbers  # a block of at most three consecutive numbers
    for first in range(1, len(AGENT_STYLES) + 1):
        colours = [agent_style(n)[0] for n in range(first, first + 3)]
        for i, a in enumerate(colours):
            for b in colours[i + 1 :]:
                assert np.linalg.norm(lab(a) - lab(b)) > 50, (first, a, b)


def number_height(sprite, ink, within: float) -> int:
    """Rows spanned by the number's pixels (ink colour, within ``within`` half sizes of the centre)."""
    image, half = sprite
    pixels = np.asarray(image, dtype=np.int16)
    rows, cols = np.mgrid[: pixels.shape[0], : pixels.shape[1]]
    mask = (
        (np.hypot(cols - half, rows - half) <= within * half)
        & (pixels[..., 3] > 200)
        & (np.abs(pixels[..., :3] - np.array(ink)).max(axis=-1) < 60)
    )
    found = np.nonzero(mask.any(axis=1))[0]
    return found.max() - found.min() + 1


@pytest.mark.parametrize("robot_visible", [False, True])
@pytest.mark.parametrize("width", [None, 640, 1280])
def test_people_and_robots_stay_readable_on_a_360_px_phone(robot_visible, width):
    """Shown 360 px wide, a person's number is at least 10 px tall and a robot's one-digit number 9 px, also when
    the view is wide or split in two arenas (markers are then drawn larger than to scale)."""
    scenario = load_scenario("paper-bl-tr")
    scene = scene_from_summary(
        summary_from_simulation(["goal", "orca"], visible(scenario) if robot_visible else scenario)
    )
    renderer = CrowdClipRenderer(scene, numbers=[7, 12], options=RenderOptions(width=width))
    phone = 360 / renderer.layout.width
    assert renderer.layout.marker(scene.human_radius) >= scene.human_radius * renderer.layout.scale
    for sprite in renderer.sprites.humans:
        assert number_height(sprite, INK, 0.7) * phone >= 10
    assert number_height(renderer.sprites.markers[7], number_ink(agent_style(7)[0]), 0.4) * phone >= 9
    assert number_height(renderer.sprites.markers[12], number_ink(agent_style(12)[0]), 0.4) * phone >= 8


def test_collision_is_marked_where_and_when_it_happens(shared_summary):
    scene = scene_from_summary(shared_summary)
    crashed = [k for k, (event, _) in enumerate(scene.outcomes) if event == "collision"]
    assert crashed, "the fixture's scripted robot is expected to collide"
    k = crashed[0]
    when = scene.outcomes[k][1]
    renderer = CrowdClipRenderer(scene)
    start = renderer.event_starts[when]
    before = colour_mask(renderer.draw(Frame(when - 0.5)), CRASH)
    after = colour_mask(renderer.draw(Frame(when, start)), CRASH)
    later = colour_mask(renderer.draw(Frame(scene.end_time, start + 10.0)), CRASH)
    _, robots, _ = renderer._state(when)
    near = 4 * renderer.layout.scale
    assert blob_centre(before, robots[k], near) is None
    assert blob_centre(after, robots[k], near) is not None
    assert blob_centre(later, robots[k], near) is not None  # the burst stays where it happened
    window = (
        slice(max(0, int(robots[k][1] - near)), int(robots[k][1] + near)),
        slice(max(0, int(robots[k][0] - near)), int(robots[k][0] + near)),
    )
    assert after[window].sum() > later[window].sum()  # the CRASH tag goes after a while, not to hide people
    assert f"CRASHED · {when:.1f} s" in renderer.texts and "CRASH" in renderer.texts


def test_the_crash_tag_moves_off_a_goal_and_off_the_other_robot(shared_summary):
    """A goal just above a crash: the CRASH tag, drawn above a crash where there is room, goes to another side,
    so the goal's target stays whole."""
    scene = scene_from_summary(shared_summary)
    k = [k for k, (event, _) in enumerate(scene.outcomes) if event == "collision"][0]
    when = scene.outcomes[k][1]
    plain = CrowdClipRenderer(scene)
    i = int(np.searchsorted(scene.times, when, side="right") - 1)
    goals = scene.goals.copy()
    goals[1 - k] = scene.robots[i, k] + [0.0, 3.0 * plain.robot_px / plain.layout.scale]  # where the tag stood
    renderer = CrowdClipRenderer(dataclasses.replace(scene, goals=goals))
    frame = renderer.draw(Frame(when, renderer.event_starts[when] + renderer.options.event_hold + 0.5))
    goal = renderer.layout.to_pixel(0, goals[1 - k])
    assert "CRASH" in renderer.texts
    assert blob_centre(colour_mask(frame, CRASH), goal, 1.4 * renderer.robot_px) is None


def test_marks_near_the_arenas_edge_stay_off_the_header_and_the_legend(shared_summary):
    """A goal far off widens the view until its target, kept at a readable size, is larger than the border around
    it: it is cut at the arena's edge, and the header holds the clock and the scale bar alone."""
    scene = scene_from_summary(shared_summary)
    goals = scene.goals.copy()
    goals[0] += [0.0, 30.0]
    renderer = CrowdClipRenderer(dataclasses.replace(scene, goals=goals))
    top = renderer.layout.to_pixel(0, goals[0])[1] - 1.4 * renderer.robot_px
    assert top < renderer.layout.header  # drawn whole, the target would reach into the header
    clean = Image.new("RGB", (renderer.layout.width, renderer.layout.height), BACKGROUND)
    renderer._draw_scale_bar(clean)
    renderer.draw_header(clean, 0.0)
    header = (0, 0, renderer.layout.width, renderer.layout.header)
    assert np.array_equal(np.asarray(renderer.draw(Frame(0.0)).crop(header)), np.asarray(clean.crop(header)))


def test_arrival_and_timeout_are_marked(shared_summary):
    scene = scene_from_summary(shared_summary)
    k = [k for k, (event, _) in enumerate(scene.outcomes) if event == "success"][0]
    when = scene.outcomes[k][1]
    renderer = CrowdClipRenderer(scene)
    _, robots, _ = renderer._state(when)
    near = 1.5 * renderer.layout.scale
    assert blob_centre(colour_mask(renderer.draw(Frame(when - 0.25)), SUCCESS), robots[k], near) is None
    assert blob_centre(colour_mask(renderer.draw(Frame(when)), SUCCESS), robots[k], near) is not None
    assert f"reached goal · {when:.1f} s" in renderer.texts

    short = dataclasses.replace(load_scenario("paper-bl-tr"), world={"time_limit": 5.0})
    timed_out = CrowdClipRenderer(scene_from_summary(summary_from_simulation(["orca", "social_force"], short)))
    assert {event for event, _ in timed_out.scene.outcomes} == {"timeout"}
    for frame in timed_out.frames:
        timed_out.draw(frame)
    assert "out of time · 5.0 s" in timed_out.texts


def test_each_robot_has_its_own_panel_when_robots_are_visible():
    summary = summary_from_simulation(["goal", "orca"], visible(load_scenario("paper-bl-tr")))
    scene = scene_from_summary(summary)
    assert scene.n_panels == 2
    renderer = CrowdClipRenderer(scene, numbers=[2, 1])
    assert renderer.layout.width % 16 == 0 and renderer.layout.height % 16 == 0
    image = renderer.draw(Frame(scene.end_time))
    mask = colour_mask(image, HUMAN_FILL)
    step = summary["steps"][-1]
    crowds = np.array(step["other_positions"])
    assert not np.allclose(crowds[0], crowds[1])  # each robot pushed its own crowd differently
    for agent in range(2):
        panel = renderer.panel_of[agent]
        assert panel == 1 - agent  # Robot 1 (the second agent) on the left
        others = np.concatenate([crowds[agent], np.array(step["agent_positions"])[agent][None]])
        gaps = [np.sort(np.hypot(*(others - xy).T))[1] for xy in crowds[agent]]
        loneliest = crowds[agent][int(np.argmax(gaps))]  # a human nothing else overlaps
        expected = renderer.layout.to_pixel(panel, loneliest)
        assert blob_centre(mask, expected, 0.5 * scene.human_radius * renderer.layout.scale) is not None


def probe(path) -> str:
    run = subprocess.run(
        [imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-i", str(path)], capture_output=True, text=True
    )
    return run.stderr


def top_level_boxes(path) -> list[str]:
    data = path.read_bytes()
    boxes, offset = [], 0
    while offset + 8 <= len(data):
        size = int.from_bytes(data[offset : offset + 4], "big")
        boxes.append(data[offset + 4 : offset + 8].decode("latin-1"))
        if size == 1:
            size = int.from_bytes(data[offset + 8 : offset + 16], "big")
        if size < 8:
            break
        offset += size
    return boxes


def test_clip_is_browser_safe_h264_with_poster_and_contact_sheet(tmp_path, summary_file):
    result = render_file(summary_file, tmp_path / "out" / "clip.mp4", options=FAST)
    info = probe(result.clip)
    video = re.search(r"Video: (\w+).*?, (\w+)(?:\(.*?\))?, (\d+)x(\d+)", info)
    assert video, info
    codec, pix_fmt, width, height = video.group(1), video.group(2), int(video.group(3)), int(video.group(4))
    assert (codec, pix_fmt) == ("h264", "yuv420p")
    assert (width, height) == (result.width, result.height) and width % 16 == 0 and height % 16 == 0
    assert "24 fps" in info
    boxes = top_level_boxes(result.clip)
    assert "moov" in boxes and "mdat" in boxes and boxes.index("moov") < boxes.index("mdat"), boxes
    frames, _ = imageio_ffmpeg.count_frames_and_secs(str(result.clip))
    assert frames == result.frames
    assert result.poster.name == "clip.poster.png" and result.sheet.name == "clip.sheet.png"
    with Image.open(result.poster) as poster:
        assert poster.size == (width, height)
    with Image.open(result.sheet) as sheet:
        assert sheet.width > width  # several thumbnails side by side
    assert not list(result.clip.parent.glob(".*partial*"))


def test_rendering_refuses_a_non_mp4_target(tmp_path, summary_file):
    with pytest.raises(ValueError, match=".mp4"):
        render_file(summary_file, tmp_path / "clip.webm", options=FAST)


def broken(summary: dict, change) -> dict:
    copy = json.loads(json.dumps(summary))
    change(copy)
    return copy


BAD = [
    (lambda s: s.update(format="foil.summary/0"), "format is 'foil.summary/0'"),
    (lambda s: s.pop("steps"), r"missing key\(s\) \['steps'\]"),
    (lambda s: s.update(steps=[]), "steps must be a non-empty list"),
    (
        lambda s: s["steps"][3].update(agent_positions=[[0, 0]]),
        r"steps\[3\].agent_positions has 1 positions, expected one per agent",
    ),
    (lambda s: s["steps"][2]["other_positions"].pop(), r"steps\[2\].other_positions has shape"),
    (
        lambda s: s["steps"][1]["other_positions"][0].__setitem__(0, float("nan")),
        r"steps\[1\].other_positions contains NaN",
    ),
    (lambda s: s["steps"][4].update(t=0.5), r"steps\[4\].t = 0.5 does not come after"),
    (lambda s: s["outcomes"][1].update(event="exploded"), r"outcomes\[1\].event must be one of"),
    (lambda s: s["outcomes"].pop(), "one entry per agent"),
    (lambda s: s["scenario"].pop("robot"), "scenario is not a valid initial state"),
    (lambda s: s.update(agents=[{"name": "only"}]), "at least two"),
    (lambda s: s.update(window=[5, 3]), r"window must be \[first, last\] with 0 <= first < last <= 67"),
    (lambda s: s.update(window=[0, 68]), r"window must be .* got \[0, 68\]"),
    (
        lambda s: s.update(follow={"leader": 2, "steps": 3}),
        r"follow must be \{leader, steps\} with a leader from 0 to 1",
    ),
    (lambda s: s.update(follow={"leader": 0}), "follow must be"),
    (
        lambda s: s["scenario"]["world"].update(robot_visible=True),
        r"steps\[0\].other_positions holds one crowd, but the robots "
        "are visible",
    ),
]


@pytest.mark.parametrize(("change", "message"), BAD)
def test_bad_summaries_give_clear_errors(shared_summary, change, message):
    with pytest.raises(SummaryError, match=message):
        scene_from_summary(broken(shared_summary, change), source="bad.json")


def test_unreadable_summary_files_give_clear_errors(tmp_path, shared_summary):
    truncated = tmp_path / "cut.json"
    truncated.write_text(json.dumps(shared_summary)[:500])
    with pytest.raises(ValueError, match="not valid JSON"):
        load_scene(truncated)
    with pytest.raises(FileNotFoundError, match="no summary file"):
        load_scene(tmp_path / "missing.json")


def test_render_options_are_checked():
    with pytest.raises(ValueError, match="fps must be at least 20"):
        RenderOptions(fps=10)
    with pytest.raises(ValueError, match="speed"):
        RenderOptions(speed=0)


def test_the_pages_robot_key_shows_each_robots_colour_and_shape():
    """The survey pages' key beside a clip (templates/_macros.html, static/survey.css) draws Robot N in the
    colour and shape the clip gives it."""
    from jinja2 import Environment, FileSystemLoader

    root = Path(__file__).resolve().parents[2]
    css = (root / "static" / "survey.css").read_text()
    colours = {
        int(k): tuple(map(int, rgb.split(",")))
        for k, rgb in re.findall(r"\.robot-colour-(\d+) \{ background: rgb\(([\d, ]+)\); \}", css)
    }
    shapes = set(re.findall(r"\.robot-([a-z-]+) \{", css)) - {"x", "key"}
    macros = (
        Environment(loader=FileSystemLoader(root / "templates"), autoescape=True).get_template("_macros.html").module
    )
    for number in range(1, 2 * len(AGENT_STYLES) + 1):
        marker = str(macros.agent_marker(f"Robot {number}"))
        colour, shape = re.fullmatch(
            r'<span class="marker robot-colour-(\d+) robot-([a-z-]+)" aria-hidden="true">'
            r"</span>",
            marker.strip(),
        ).groups()
        assert (colours[int(colour)], shape) == agent_style(number)
        assert shape in shapes
    assert "robot-x" in str(macros.agent_marker("Robot A"))
