"""Tests of the renderer: frames are real pictures drawn by highway-env, react to the state, and show works headless."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import time

import numpy as np
import pytest

from timegap_env.envs import rendering
from timegap_env.envs.rendering import (
    ALARM_COLOR,
    COLLIDED_COLOR,
    FOLLOWER_COLOR,
    LEADER_COLOR,
    LIMIT_COLOR,
    PlatoonRenderer,
    RenderFrame,
)

N_FOLLOWERS = 5
WIDTH, HEIGHT = 800, 520  # [px]
HW_GREY = (100, 100, 100)  # highway-env's road colour (WorldSurface.GREY)
HW_WHITE = (255, 255, 255)  # highway-env's lane markings
HW_OUTLINE = (60, 60, 60)  # highway-env's vehicle outline (VehicleGraphics.BLACK)


def make_frame(**overrides: object) -> RenderFrame:
    """5 followers 40 m apart at 25 m/s, 30 s of estimates around 1.6 s; follower 2 drifts above the UCL."""
    t = 30.0  # [s]
    history_t = np.arange(0.0, t + 1e-9, 0.1)
    estimate = 1.6 + 0.05 * np.sin(history_t[:, None] / 4.0 + np.arange(N_FOLLOWERS))
    estimate[:, 1] += 0.4 * (history_t > 25.0)
    setting = np.full(N_FOLLOWERS, 1.6)
    lcl, ucl = setting - 0.25, setting + 0.25
    fields = dict(
        t=t,
        x=500.0 - 45.0 * np.arange(N_FOLLOWERS + 1),
        v=np.full(N_FOLLOWERS + 1, 25.0),
        vehicle_length=5.0,
        history_t=history_t,
        estimate_history=estimate,
        lcl=lcl,
        ucl=ucl,
        center=setting,
        alarm=(estimate[-1] < lcl) | (estimate[-1] > ucl),
        v2v=np.array([True, True, False, True, True]),
        collided=np.zeros(N_FOLLOWERS, dtype=bool),
    )
    fields.update(overrides)
    return RenderFrame(**fields)


@pytest.fixture(scope="module")
def renderer() -> PlatoonRenderer:
    renderer = PlatoonRenderer(N_FOLLOWERS, WIDTH, HEIGHT)
    yield renderer
    renderer.close()


def count(image: np.ndarray, color: tuple[int, int, int]) -> int:
    """Number of pixels of exactly this colour."""
    return int(np.all(image == np.array(color, dtype=np.uint8), axis=-1).sum())


def road_band(renderer: PlatoonRenderer, image: np.ndarray) -> np.ndarray:
    """The road panel of a frame."""
    return image[renderer._road_rect.top : renderer._road_rect.bottom]


def chart_band(renderer: PlatoonRenderer, image: np.ndarray) -> np.ndarray:
    """The control chart panel of a frame."""
    return image[renderer._chart_rect.top : renderer._chart_rect.bottom]


# ---- the module is cheap to import ---------------------------------------------------------------


def test_import_does_not_load_pygame_or_highway_env():
    """The module alone (without the package's __init__, which loads highway-env for the human leader)."""
    code = (
        "import importlib.util, sys\n"
        f"spec = importlib.util.spec_from_file_location('rendering', {rendering.__file__!r})\n"
        "module = sys.modules['rendering'] = importlib.util.module_from_spec(spec)\n"
        "spec.loader.exec_module(module)\n"
        "print('pygame' in sys.modules, 'highway_env' in sys.modules)"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert result.stdout.split() == ["False", "False"]


# ---- the picture -------------------------------------------------------------------------------------


def test_frame_shape_and_dtype(renderer):
    image = renderer.render(make_frame())
    assert image.shape == (HEIGHT, WIDTH, 3)
    assert image.dtype == np.uint8
    assert image.flags.c_contiguous


def test_frame_is_not_blank(renderer):
    image = renderer.render(make_frame())
    assert image.max() > 0 and image.mean() > 50  # not the black frame of a disabled EnvViewer
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 50


def test_road_is_highway_env_drawing(renderer):
    road = road_band(renderer, renderer.render(make_frame()))
    assert count(road, HW_GREY) > 0.5 * road.shape[0] * road.shape[1]  # RoadGraphics fills the ground
    assert count(road, HW_WHITE) > 200  # lane markings (and our white labels)
    assert count(road, HW_OUTLINE) > 20  # VehicleGraphics outlines every car
    for color in (LEADER_COLOR, FOLLOWER_COLOR, ALARM_COLOR):
        assert count(road, color) > 10, color


def test_leader_is_drawn_ahead_of_the_followers(renderer):
    road = road_band(renderer, renderer.render(make_frame()))
    leader_columns = np.nonzero(np.all(road == LEADER_COLOR, axis=-1))[1]
    follower_columns = np.nonzero(np.all(road == FOLLOWER_COLOR, axis=-1))[1]
    assert leader_columns.min() > follower_columns.max()  # the road runs left to right


def test_whole_platoon_fits_and_is_centred(renderer):
    road = road_band(renderer, renderer.render(make_frame()))
    vehicle_columns = np.nonzero(np.all(road == LEADER_COLOR, axis=-1) | np.all(road == FOLLOWER_COLOR, axis=-1))[1]
    middle = 0.5 * (vehicle_columns.min() + vehicle_columns.max())
    assert abs(middle - WIDTH / 2) < 0.05 * WIDTH


def test_chart_shows_limits_and_alarm(renderer):
    chart = chart_band(renderer, renderer.render(make_frame()))
    assert count(chart, LIMIT_COLOR) > 2 * N_FOLLOWERS * 0.5 * WIDTH  # LCL and UCL across every row
    assert count(chart, ALARM_COLOR) > 50  # follower 2's line above its UCL and its state box


def test_past_estimates_are_judged_against_the_limits_of_their_time(renderer):
    """Follower 4 was switched from 1.6 s to 1.0 s at t = 15 s and stayed inside its limits throughout."""
    frame = make_frame(alarm=np.zeros(N_FOLLOWERS, dtype=bool))
    setting = np.full(frame.estimate_history.shape, 1.6)
    setting[frame.history_t >= 15.0, 3] = 1.0
    estimate = np.minimum(frame.estimate_history, 1.7)  # everybody inside 1.35 .. 1.85 ...
    estimate[frame.history_t >= 15.0, 3] = 1.0  # ... and follower 4 inside 0.75 .. 1.25 after its switch
    current = dict(estimate_history=estimate, lcl=setting[-1] - 0.25, ucl=setting[-1] + 0.25, center=setting[-1])
    without = chart_band(renderer, renderer.render(dataclasses.replace(frame, **current)))
    assert count(without, ALARM_COLOR) > 100  # its first 15 s look out of control against today's limits
    recorded = dict(lcl_history=setting - 0.25, ucl_history=setting + 0.25, center_history=setting)
    with_history = chart_band(renderer, renderer.render(dataclasses.replace(frame, **current, **recorded)))
    assert count(with_history, ALARM_COLOR) == 0


def test_rendering_is_deterministic(renderer):
    np.testing.assert_array_equal(renderer.render(make_frame()), renderer.render(make_frame()))


def test_positions_change_the_road(renderer):
    frame = make_frame()
    before = renderer.render(frame)
    after = renderer.render(dataclasses.replace(frame, x=frame.x + np.array([3.0, 0.0, 0.0, 0.0, 0.0, -8.0])))
    assert np.any(road_band(renderer, before) != road_band(renderer, after))


def test_estimates_change_the_chart_only(renderer):
    frame = make_frame()
    before = renderer.render(frame)
    after = renderer.render(dataclasses.replace(frame, estimate_history=frame.estimate_history - 0.1))
    assert np.any(chart_band(renderer, before) != chart_band(renderer, after))
    np.testing.assert_array_equal(road_band(renderer, before), road_band(renderer, after))


def test_alarm_colours_the_follower(renderer):
    frame = make_frame()
    alarm = renderer.render(dataclasses.replace(frame, alarm=np.array([False, True, False, False, False])))
    calm = renderer.render(dataclasses.replace(frame, alarm=np.zeros(N_FOLLOWERS, dtype=bool)))
    assert count(road_band(renderer, alarm), ALARM_COLOR) > count(road_band(renderer, calm), ALARM_COLOR) == 0
    assert count(chart_band(renderer, alarm), ALARM_COLOR) > count(chart_band(renderer, calm), ALARM_COLOR)


def test_collision_colours_the_follower(renderer):
    collided = np.array([False, False, True, False, False])
    road = road_band(renderer, renderer.render(make_frame(collided=collided)))
    assert count(road, COLLIDED_COLOR) > 10
    assert count(road_band(renderer, renderer.render(make_frame())), COLLIDED_COLOR) == 0


def test_v2v_status_changes_the_picture(renderer):
    frame = make_frame()
    all_off = renderer.render(dataclasses.replace(frame, v2v=np.zeros(N_FOLLOWERS, dtype=bool)))
    assert np.any(road_band(renderer, renderer.render(frame)) != road_band(renderer, all_off))


# ---- awkward frames ----------------------------------------------------------------------------------


def test_start_of_episode_without_history(renderer):
    frame = make_frame(
        t=0.0,
        x=-45.0 * np.arange(N_FOLLOWERS + 1),  # the leader at 0, the followers behind it
        history_t=np.empty(0),
        estimate_history=np.empty((0, N_FOLLOWERS)),
        alarm=np.zeros(N_FOLLOWERS, dtype=bool),
    )
    road = road_band(renderer, renderer.render(frame))
    assert count(road, HW_WHITE) > 200  # lane markings behind x = 0 too
    assert count(road, FOLLOWER_COLOR) > 10


def test_nan_estimates_and_far_outliers(renderer):
    frame = make_frame()
    estimate = frame.estimate_history.copy()
    estimate[100:120] = np.nan
    estimate[-5:, 0] = 50.0  # far above the chart's range: clipped to the row
    image = renderer.render(dataclasses.replace(frame, estimate_history=estimate))
    assert image.shape == (HEIGHT, WIDTH, 3)


def test_very_long_platoon(renderer):
    image = renderer.render(make_frame(x=-1000.0 * np.arange(N_FOLLOWERS + 1)))  # too long to fit
    assert count(road_band(renderer, image), LEADER_COLOR) == 0  # both ends leave the view
    assert count(road_band(renderer, image), HW_WHITE) > 100


def test_wrong_shapes_are_rejected(renderer):
    with pytest.raises(ValueError, match="lcl"):
        renderer.render(make_frame(lcl=np.full(N_FOLLOWERS + 1, 1.35)))
    with pytest.raises(ValueError, match="estimate_history"):
        renderer.render(make_frame(estimate_history=np.zeros((3, N_FOLLOWERS))))
    with pytest.raises(ValueError, match="finite"):
        renderer.render(make_frame(x=np.full(N_FOLLOWERS + 1, np.nan)))
    with pytest.raises(ValueError, match="ucl_history"):
        renderer.render(make_frame(ucl_history=np.full((2, N_FOLLOWERS), 1.85)))


def test_bad_constructor_arguments():
    with pytest.raises(ValueError):
        PlatoonRenderer(0)
    with pytest.raises(ValueError):
        PlatoonRenderer(5, width=100, height=100)


def test_other_sizes_and_platoon_lengths():
    renderer = PlatoonRenderer(10, width=640, height=400, time_window=20.0)
    frame = make_frame()
    history = np.repeat(frame.estimate_history, 2, axis=1)
    image = renderer.render(
        RenderFrame(
            t=frame.t, x=-12.0 * np.arange(11), v=np.full(11, 3.0), vehicle_length=4.5,
            history_t=frame.history_t, estimate_history=history,
            lcl=np.full(10, 1.35), ucl=np.full(10, 1.85), center=np.full(10, 1.6),
            alarm=np.zeros(10, dtype=bool), v2v=np.ones(10, dtype=bool), collided=np.zeros(10, dtype=bool),
        )
    )
    assert image.shape == (400, 640, 3)
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 50


def test_rendering_is_fast(renderer):
    frame = make_frame()
    renderer.render(frame)
    start = time.perf_counter()
    for k in range(10):
        renderer.render(dataclasses.replace(frame, x=frame.x + k))
    assert (time.perf_counter() - start) / 10 < 0.25  # [s]; about 10 ms on a laptop


# ---- window ---------------------------------------------------------------------------------------------


def test_close_without_show_and_twice(renderer):
    renderer.close()
    renderer.close()
    assert renderer.render(make_frame()).shape == (HEIGHT, WIDTH, 3)  # render needs no window


@pytest.mark.parametrize("driver", ["dummy", "offscreen"])
def test_show_headless(monkeypatch, driver):
    """Human mode with a headless SDL video driver: the window holds the same picture as render()."""
    import pygame

    pygame.display.quit()  # the driver is chosen when the display initialises
    monkeypatch.setenv("SDL_VIDEODRIVER", driver)
    renderer = PlatoonRenderer(N_FOLLOWERS, WIDTH, HEIGHT)
    frame = make_frame()
    renderer.show(frame)
    window = pygame.display.get_surface()
    assert window.get_size() == (WIDTH, HEIGHT)
    shown = np.transpose(pygame.surfarray.array3d(window), (1, 0, 2))
    np.testing.assert_array_equal(shown, renderer.render(frame))
    renderer.show(dataclasses.replace(frame, t=31.0))  # the second call reuses the window
    assert pygame.display.get_surface() is window
    renderer.close()
    assert not pygame.display.get_init()
    renderer.close()


# ---- the state box says what is going on (issue 22, item 14) -------------------------------------


def state_boxes(renderer: PlatoonRenderer, image: np.ndarray) -> np.ndarray:
    """The column of state boxes left of the chart rows (nothing else is drawn there)."""
    return chart_band(renderer, image)[:, : rendering.STATE_BOX_WIDTH]


def labels(frame: RenderFrame) -> list[str]:
    """Each follower's state label for a frame, judged as the renderer judges it (the whole history visible)."""
    limits = np.stack([rendering._limit_history(frame, name) for name in rendering._LIMIT_HISTORIES], axis=-1)
    return [rendering.state_label(frame, i, frame.estimate_history[:, i], limits[:, i]) for i in range(N_FOLLOWERS)]


def test_the_state_box_names_every_state():
    quiet = np.zeros(N_FOLLOWERS, dtype=bool)
    frame = make_frame(alarm=quiet)  # follower 2's estimate is above its UCL, without an alarm (yet)
    assert labels(frame) == ["in control", "out of limits", "in control", "in control", "in control"]
    settling = np.array([False, True, True, False, False])
    assert labels(dataclasses.replace(frame, settling=settling))[:3] == ["in control", "settling", "settling"]
    assert labels(make_frame())[1] == "ALARM"
    assert labels(make_frame(collided=~quiet))[1] == "COLLIDED"
    start = make_frame(t=0.0, history_t=np.empty(0), estimate_history=np.empty((0, N_FOLLOWERS)), alarm=quiet)
    assert labels(start) == ["in control"] * N_FOLLOWERS  # nothing estimated yet
    estimate = frame.estimate_history.copy()
    estimate[-3:, 1] = np.nan  # the latest finite estimate, the one the row marks and prints, is what counts
    assert labels(dataclasses.replace(frame, estimate_history=estimate))[1] == "out of limits"


def test_an_estimate_outside_its_limits_is_not_drawn_as_in_control(renderer):
    """Only follower 2's history differs, and only inside the plot; its state box must differ too (it read "in
    control" either way)."""
    quiet = np.zeros(N_FOLLOWERS, dtype=bool)
    outside = make_frame(alarm=quiet)
    inside = dataclasses.replace(outside, estimate_history=np.minimum(outside.estimate_history, 1.8))
    boxes_outside, boxes_inside = (state_boxes(renderer, renderer.render(frame)) for frame in (outside, inside))
    differ = np.flatnonzero(np.any(boxes_outside != boxes_inside, axis=(1, 2)))
    assert differ.size > 0
    row = renderer._chart_rect.height // N_FOLLOWERS  # the changed pixels lie in follower 2's row
    assert differ.min() >= rendering.CHART_SUBTITLE_HEIGHT + row // 2 and differ.max() < 2 * row + row // 2
    assert labels(inside) == ["in control"] * N_FOLLOWERS
    settling = renderer.render(dataclasses.replace(inside, settling=np.array([False, True, False, False, False])))
    assert np.any(state_boxes(renderer, settling) != boxes_inside)


def test_a_settling_vector_of_the_wrong_shape_is_rejected(renderer):
    with pytest.raises(ValueError, match="settling"):
        renderer.render(make_frame(settling=np.zeros(N_FOLLOWERS + 1, dtype=bool)))


def test_the_env_frame_says_settling_while_the_chart_holds_its_alarms_off():
    """After 1.6 s -> 1.0 s the estimate lags above the new UCL while the chart holds its alarms off: the box said
    "in control"; it says "settling" until the hold ends, then "in control" again."""
    import gymnasium as gym

    import timegap_env

    levels = list(timegap_env.EnvConfig().setting_levels)
    env = gym.make(timegap_env.ENV_ID, render_mode="rgb_array", config={"degradation": {"kind_weights": {"none": 1.0}}})
    env.reset(seed=0, options={"scenario": "aggressive_cycles"})
    seen = []
    for step in range(30):
        env.step(levels.index(1.6) if step < 10 else levels.index(1.0))
        frame = env.unwrapped.task.render_frame(rendering.DEFAULT_TIME_WINDOW)
        estimate, ucl = frame.estimate_history[-1], frame.ucl
        seen.append((bool(np.any(estimate > ucl)), set(labels(frame)), bool(frame.settling.all())))
    assert seen[9] == (False, {"in control"}, False)
    assert seen[13] == (True, {"settling"}, True)  # 4 s after the change: the estimates are above 1.25 s
    assert seen[29] == (False, {"in control"}, False)
    image = env.render()
    assert image.shape == (rendering.DEFAULT_HEIGHT, rendering.DEFAULT_WIDTH, 3)
    env.close()

