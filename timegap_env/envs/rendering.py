"""Draw the environment: the platoon on a highway-env road above a live Shewhart control chart.

A frame (``PlatoonRenderer.render`` -> (height, width, 3) uint8 RGB) has three bands, top to bottom:

- **title bar**: time, leader speed, the applied settings tau* (the centre lines), alarm and collision counts;
- **road**: highway-env's own graphics (``WorldSurface``, ``RoadGraphics``, ``VehicleGraphics``) of a
  straight three-lane road, the platoon in the middle lane. The view is centred on the platoon's
  middle and zoomed so that the whole platoon fits (never closer than ``MAX_SCALE`` px/m, and never
  farther than ``MIN_SCALE`` px/m: a platoon longer than that loses both ends). Colours: leader
  green, follower blue, follower in alarm orange, collided follower red. Above each car its name
  (``F1`` = first follower), below it its mode: ``V2V`` (CACC) in cyan or ``ACC`` in grey;
- **control chart**: one row per follower sharing the time axis (the last ``time_window`` seconds):
  the posterior mean of its time gap (blue; orange where it lay outside the limits of its time),
  its LCL and UCL (red) and CL = tau* (dashed dark red) as step lines, the current value on the
  right, and on the left a box coloured like the car and labelled with the follower's state
  (:func:`state_label`: ``COLLIDED``, ``ALARM``, ``settling`` while the chart holds its alarms off
  after a setting change, ``out of limits`` when the latest estimate lies outside its limits
  without an alarm, else ``in control``). The limits of the past come from the frame's
  optional ``lcl_history`` / ``ucl_history`` / ``center_history``; without them the current
  limits are drawn over the whole history, and after a setting change the older part of the line
  then shows as outside the (new) limits.

``render`` draws on plain pygame Surfaces and never opens a display, so it works headless without
any ``SDL_VIDEODRIVER``. ``show`` (the "human" render mode) opens a window on its first call.
pygame and highway-env are imported inside the class, so importing this module is cheap.
"""

from __future__ import annotations

import dataclasses
import os
from typing import TYPE_CHECKING

import numpy as np

from timegap_env._extras import require

if TYPE_CHECKING:
    import pygame

__all__ = ["RenderFrame", "PlatoonRenderer", "state_label"]

# ---- colours (RGB) -------------------------------------------------------------------------------
LEADER_COLOR = (50, 200, 0)  # highway-env's ego green: the human-driven leader
FOLLOWER_COLOR = (100, 200, 255)  # highway-env's blue: follower, estimate inside the limits
ALARM_COLOR = (255, 140, 0)  # follower whose estimate is outside the limits now
COLLIDED_COLOR = (220, 0, 0)  # follower that collided
V2V_COLOR = (0, 230, 255)  # "V2V" label: CACC on
ACC_COLOR = (190, 190, 190)  # "ACC" label: CACC off
ROAD_TEXT_COLOR = (255, 255, 255)
TITLE_BACKGROUND = (30, 30, 30)
TITLE_TEXT_COLOR = (255, 255, 255)
CHART_BACKGROUND = (255, 255, 255)
CHART_TEXT_COLOR = (20, 20, 20)
PLOT_BORDER_COLOR = (170, 170, 170)
GRID_COLOR = (225, 225, 225)
LIMIT_COLOR = (210, 0, 0)  # LCL and UCL
CENTER_LINE_COLOR = (150, 0, 0)  # CL = tau*
ESTIMATE_COLOR = (30, 100, 220)  # estimate inside the limits (a darker blue than the cars: white background)
LABEL_TEXT_ON_STATE = (0, 0, 0)  # text in the state-coloured box of a chart row

# ---- sizes ---------------------------------------------------------------------------------------
DEFAULT_WIDTH = 1000  # [px]
DEFAULT_HEIGHT = 640  # [px]
MIN_WIDTH, MIN_HEIGHT = 480, 320  # [px]
DEFAULT_TIME_WINDOW = 60.0  # time span of the chart [s]
TITLE_HEIGHT = 30  # [px]
ROAD_FRACTION = 0.22  # share of the height below the title bar given to the road
TITLE_FONT_SIZE = 22
LABEL_FONT_SIZE = 16
TICK_FONT_SIZE = 14

# road
ROAD_LANES = 3
PLATOON_LANE = 1  # lanes are numbered from the top of the picture
ROAD_START = -1.0e5  # [m]: the followers start behind x = 0, and highway-env clips lane markings to the lane
ROAD_LENGTH = 1.0e7  # [m]
VIEW_MARGIN = 60  # free space left and right of the platoon [px]
MAX_SCALE = 8.0  # closest zoom [px/m]
MIN_SCALE = 0.5  # farthest zoom [px/m]
LABEL_GAP = 2  # between a car and its labels [px]
SCALE_BAR_TARGET = 100  # approximate length of the scale bar [px]
SCALE_BAR_LENGTHS = (5, 10, 20, 50, 100, 200, 500, 1000, 2000)  # candidates [m]

# chart
CHART_SUBTITLE_HEIGHT = 24  # [px]
CHART_AXIS_HEIGHT = 34  # time tick labels and axis title under the last row [px]
STATE_BOX_WIDTH = 72  # coloured box with the follower's name and mode [px]
Y_TICK_WIDTH = 42  # LCL / CL / UCL values [px]
VALUE_WIDTH = 58  # current estimate right of the plot [px]
CHART_PADDING = 8  # [px]
ROW_GAP = 6  # [px]
LIMIT_LINE_WIDTH = 2  # [px]
ESTIMATE_LINE_WIDTH = 2  # [px]
MARKER_RADIUS = 4  # current estimate [px]
DASH_LENGTH = 6  # CL dashes [px]
MIN_LIMIT_BAND = 0.05  # UCL - LCL used for scaling when the limits (almost) coincide [s]
Y_PADDING = 0.3  # space above UCL and below LCL, in units of UCL - LCL
Y_MAX_EXCURSION = 2.0  # the y range extends at most this many (UCL - LCL) beyond the limits
TIME_TICK_STEPS = (1, 2, 5, 10, 15, 20, 30, 60, 120, 300, 600)  # candidates [s]
TIME_TICK_TARGET = 8  # approximate number of time ticks


@dataclasses.dataclass(frozen=True)
class RenderFrame:
    """Everything one picture shows; vehicle arrays are leader first, follower arrays follower 1 first.

    The three ``*_history`` arrays are optional: give them so that the chart draws the limits each
    past estimate was judged against (they change when a time gap setting changes). ``settling`` is
    optional too: give it so that the state box says when a follower's alarms are held off.
    """

    t: float  # simulation time [s]
    x: np.ndarray  # (n_vehicles,) front-bumper positions, leader first [m]
    v: np.ndarray  # (n_vehicles,) speeds [m/s]
    vehicle_length: float  # [m]
    history_t: np.ndarray  # (n_history,) times of the chart history [s] (may be empty at t = 0)
    estimate_history: np.ndarray  # (n_history, n_followers) posterior mean of each follower's time gap [s]
    lcl: np.ndarray  # (n_followers,) current lower control limit [s]
    ucl: np.ndarray  # (n_followers,) current upper control limit [s]
    center: np.ndarray  # (n_followers,) current centre line, the applied setting tau* [s]
    alarm: np.ndarray  # (n_followers,) bool, the chart's alarm now: its statistic outside the limits, not settling
    v2v: np.ndarray  # (n_followers,) bool, CACC (V2V) on
    collided: np.ndarray  # (n_followers,) bool
    lcl_history: np.ndarray | None = None  # (n_history, n_followers) LCL at history_t [s]; None: lcl throughout
    ucl_history: np.ndarray | None = None  # (n_history, n_followers) UCL at history_t [s]; None: ucl throughout
    center_history: np.ndarray | None = None  # (n_history, n_followers) centre line at history_t [s]; None: center
    settling: np.ndarray | None = None  # (n_followers,) bool, the chart holds alarms off (settling); None: nowhere


_LIMIT_HISTORIES = ("lcl_history", "center_history", "ucl_history")  # optional RenderFrame fields: LCL, CL, UCL


class PlatoonRenderer:
    """Draws ``RenderFrame``s of a platoon of one leader and ``n_followers`` followers.

    ``render(frame)`` returns the picture as a (height, width, 3) uint8 RGB array; ``show(frame)``
    draws it in a pygame window; ``close()`` closes that window. ``time_window`` is the time span
    of the control chart [s].
    """

    def __init__(
        self,
        n_followers: int,
        width: int = DEFAULT_WIDTH,
        height: int = DEFAULT_HEIGHT,
        time_window: float = DEFAULT_TIME_WINDOW,
    ) -> None:
        if n_followers < 1:
            raise ValueError(f"n_followers must be >= 1, got {n_followers}")
        if width < MIN_WIDTH or height < MIN_HEIGHT:
            raise ValueError(f"the picture must be at least {MIN_WIDTH} x {MIN_HEIGHT} px, got {width} x {height}")
        if not time_window > 0:
            raise ValueError(f"time_window must be > 0 s, got {time_window}")
        require("render", "pygame", "highway_env", needed_for="Rendering (render_mode='rgb_array' or 'human')")
        os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
        import pygame
        from highway_env.road.graphics import WorldSurface
        from highway_env.road.road import Road, RoadNetwork
        from highway_env.vehicle.kinematics import Vehicle

        self.n_followers = n_followers
        self.width = width
        self.height = height
        self.time_window = float(time_window)

        pygame.font.init()
        self._title_font = pygame.font.Font(None, TITLE_FONT_SIZE)
        self._label_font = pygame.font.Font(None, LABEL_FONT_SIZE)
        self._tick_font = pygame.font.Font(None, TICK_FONT_SIZE)

        road_height = round(ROAD_FRACTION * (height - TITLE_HEIGHT))
        self._canvas = pygame.Surface((width, height))
        self._title_rect = pygame.Rect(0, 0, width, TITLE_HEIGHT)
        self._road_rect = pygame.Rect(0, TITLE_HEIGHT, width, road_height)
        self._chart_rect = pygame.Rect(0, TITLE_HEIGHT + road_height, width, height - TITLE_HEIGHT - road_height)

        size = self._road_rect.size
        self._world = WorldSurface(size, 0, pygame.Surface(size))
        network = RoadNetwork.straight_road_network(lanes=ROAD_LANES, start=ROAD_START, length=ROAD_LENGTH)
        self._road = Road(network=network)
        self._lane_y = PLATOON_LANE * network.get_lane(("0", "1", PLATOON_LANE)).width_at(0)  # [m]
        self._vehicles = [Vehicle(self._road, [0.0, self._lane_y]) for _ in range(n_followers + 1)]
        self._road.vehicles = list(self._vehicles)

        self._window: pygame.Surface | None = None

    # ---- public API ------------------------------------------------------------------------------

    def render(self, frame: RenderFrame) -> np.ndarray:
        """The frame as a (height, width, 3) uint8 RGB array."""
        import pygame

        self._draw(frame)
        pixels = pygame.surfarray.pixels3d(self._canvas)  # (width, height, 3), a view that locks the surface
        image = np.ascontiguousarray(pixels.transpose(1, 0, 2))
        del pixels
        return image

    def show(self, frame: RenderFrame) -> None:
        """Draw the frame in a pygame window, opened on the first call ("human" render mode)."""
        import pygame

        if self._window is None:
            try:
                pygame.display.init()
                self._window = pygame.display.set_mode((self.width, self.height))
            except pygame.error as error:
                raise RuntimeError(
                    f"human rendering needs a display ({error}); use render_mode='rgb_array' when headless"
                ) from error
            pygame.display.set_caption("TimeGapMonitor")
        self._draw(frame)
        self._window.blit(self._canvas, (0, 0))
        pygame.event.pump()
        pygame.display.flip()

    def close(self) -> None:
        """Close the window if ``show`` opened one; ``render`` keeps working."""
        import pygame

        if self._window is not None:
            pygame.display.quit()
            self._window = None

    # ---- the three bands -------------------------------------------------------------------------

    def _draw(self, frame: RenderFrame) -> None:
        """Draw the whole frame on the canvas."""
        self._check(frame)
        self._draw_title(frame)
        self._draw_road(frame)
        self._canvas.blit(self._world, self._road_rect.topleft)
        self._draw_chart(frame)

    def _check(self, frame: RenderFrame) -> None:
        """Raise ValueError if the frame's arrays do not fit ``n_followers``."""
        n = self.n_followers
        n_history = np.shape(frame.history_t)[0] if np.ndim(frame.history_t) == 1 else -1
        expected = {
            "x": (n + 1,), "v": (n + 1,), "history_t": (n_history,), "estimate_history": (n_history, n),
            "lcl": (n,), "ucl": (n,), "center": (n,), "alarm": (n,), "v2v": (n,), "collided": (n,),
        }
        limit_histories = [name for name in _LIMIT_HISTORIES if getattr(frame, name) is not None]
        expected.update({name: (n_history, n) for name in limit_histories})
        if frame.settling is not None:
            expected["settling"] = (n,)
        for name, shape in expected.items():
            if np.shape(getattr(frame, name)) != shape:
                raise ValueError(f"RenderFrame.{name} has shape {np.shape(getattr(frame, name))}, expected {shape}")
        for name in ("x", "v", "lcl", "ucl", "center", *limit_histories):
            if not np.all(np.isfinite(getattr(frame, name))):
                raise ValueError(f"RenderFrame.{name} must be finite")

    def _draw_title(self, frame: RenderFrame) -> None:
        """Title bar: t, leader speed, applied settings, alarm and collision counts."""
        import pygame

        settings = np.asarray(frame.center, dtype=float)
        shown = settings[:1] if np.all(settings == settings[0]) else settings
        setting_text = " / ".join(_seconds(s) for s in shown) + " s"
        text = (
            f"t = {frame.t:6.1f} s     leader {float(frame.v[0]):5.1f} m/s     τ* = {setting_text}     "
            f"alarms {int(np.sum(frame.alarm))}/{self.n_followers}     collisions {int(np.sum(frame.collided))}"
        )
        pygame.draw.rect(self._canvas, TITLE_BACKGROUND, self._title_rect)
        image = self._title_font.render(text, True, TITLE_TEXT_COLOR)
        self._canvas.blit(image, image.get_rect(midleft=(CHART_PADDING, self._title_rect.centery)))

    def _draw_road(self, frame: RenderFrame) -> None:
        """Road band: highway-env's road and vehicles on the world surface, then names, modes, scale bar."""
        from highway_env.road.graphics import RoadGraphics

        length = float(frame.vehicle_length)
        x = np.asarray(frame.x, dtype=float)
        front, rear = float(np.max(x)), float(np.min(x)) - length
        world = self._world
        world.scaling = float(np.clip((world.get_width() - 2 * VIEW_MARGIN) / max(front - rear, 1.0),
                                      MIN_SCALE, MAX_SCALE))
        world.move_display_window_to(np.array([0.5 * (front + rear), self._lane_y]))

        for i, vehicle in enumerate(self._vehicles):
            vehicle.LENGTH = length  # a class attribute in highway-env (5 m); positions are centres
            vehicle.position = np.array([x[i] - 0.5 * length, self._lane_y])
            vehicle.speed = float(frame.v[i])
            vehicle.color = self._vehicle_color(frame, i)
        RoadGraphics.display(self._road, world)
        RoadGraphics.display_traffic(self._road, world, offscreen=True)  # offscreen: no convert_alpha, no display
        self._draw_vehicle_labels(frame)
        self._draw_scale_bar()

    def _draw_chart(self, frame: RenderFrame) -> None:
        """Chart band: subtitle, one row per follower, time axis."""
        import pygame

        rect = self._chart_rect
        pygame.draw.rect(self._canvas, CHART_BACKGROUND, rect)
        subtitle = self._label_font.render(
            "Time gap estimate [s], orange outside LCL / UCL (red); CL = τ* dashed",
            True, CHART_TEXT_COLOR,
        )
        self._canvas.blit(subtitle, (CHART_PADDING, rect.top + (CHART_SUBTITLE_HEIGHT - subtitle.get_height()) // 2))

        t_right = max(float(frame.t), self.time_window)
        t_left = t_right - self.time_window
        history_t = np.asarray(frame.history_t, dtype=float)
        visible = (history_t >= t_left) & (history_t <= t_right)
        times = history_t[visible]
        estimates = np.asarray(frame.estimate_history, dtype=float)[visible]
        limits = np.stack([_limit_history(frame, name)[visible] for name in _LIMIT_HISTORIES], axis=-1)

        plot_left = CHART_PADDING + STATE_BOX_WIDTH + Y_TICK_WIDTH
        plot_width = rect.width - plot_left - VALUE_WIDTH - CHART_PADDING
        rows_top = rect.top + CHART_SUBTITLE_HEIGHT
        rows_height = rect.bottom - CHART_AXIS_HEIGHT - rows_top
        row_height = (rows_height - (self.n_followers - 1) * ROW_GAP) // self.n_followers
        plots = [
            pygame.Rect(plot_left, rows_top + i * (row_height + ROW_GAP), plot_width, row_height)
            for i in range(self.n_followers)
        ]
        self._draw_time_axis(plots, t_left)  # first: its grid lines go under the data
        for i, plot in enumerate(plots):
            self._draw_row(frame, i, plot, times, estimates[:, i], limits[:, i], t_left)

    # ---- road details ----------------------------------------------------------------------------

    @staticmethod
    def _vehicle_color(frame: RenderFrame, i: int) -> tuple[int, int, int]:
        """Colour of vehicle ``i`` (0 = leader) by its state."""
        if i == 0:
            return LEADER_COLOR
        if frame.collided[i - 1]:
            return COLLIDED_COLOR
        if frame.alarm[i - 1]:
            return ALARM_COLOR
        return FOLLOWER_COLOR

    def _draw_vehicle_labels(self, frame: RenderFrame) -> None:
        """Name above each car, mode (V2V / ACC) below the followers."""
        world = self._world
        half_width = 0.5 * self._vehicles[0].WIDTH  # [m]
        _, top = world.pos2pix(0.0, self._lane_y - half_width)  # pixel rows of the cars' sides
        _, bottom = world.pos2pix(0.0, self._lane_y + half_width)
        for i, vehicle in enumerate(self._vehicles):
            centre_x, _ = world.vec2pix(vehicle.position)
            name = self._label_font.render("leader" if i == 0 else f"F{i}", True, ROAD_TEXT_COLOR)
            world.blit(name, name.get_rect(midbottom=(centre_x, top - LABEL_GAP)))
            if i > 0:
                v2v = bool(frame.v2v[i - 1])
                mode = self._label_font.render("V2V" if v2v else "ACC", True, V2V_COLOR if v2v else ACC_COLOR)
                world.blit(mode, mode.get_rect(midtop=(centre_x, bottom + LABEL_GAP)))

    def _draw_scale_bar(self) -> None:
        """A horizontal bar of a round length [m] in the lower left corner of the road band."""
        import pygame

        world = self._world
        metres = min(SCALE_BAR_LENGTHS, key=lambda m: abs(m * world.scaling - SCALE_BAR_TARGET))
        pixels = world.pix(metres)
        y = world.get_height() - 10
        x0 = CHART_PADDING
        pygame.draw.line(world, ROAD_TEXT_COLOR, (x0, y), (x0 + pixels, y), 2)
        for x in (x0, x0 + pixels):
            pygame.draw.line(world, ROAD_TEXT_COLOR, (x, y - 4), (x, y + 4), 2)
        label = self._tick_font.render(f"{metres} m", True, ROAD_TEXT_COLOR)
        world.blit(label, label.get_rect(midleft=(x0 + pixels + 6, y)))

    # ---- chart details ---------------------------------------------------------------------------

    def _draw_row(
        self,
        frame: RenderFrame,
        i: int,
        plot: pygame.Rect,
        times: np.ndarray,
        estimate: np.ndarray,
        limits: np.ndarray,
        t_left: float,
    ) -> None:
        """Follower ``i``'s row: state box, limits, estimate line (orange outside its limits), current value.

        ``times`` (n,) [s] and ``estimate`` (n,) [s] are the visible history, ``limits`` (n, 3) its
        LCL, CL, UCL [s].
        """
        import pygame

        canvas = self._canvas
        now = np.array([frame.lcl[i], frame.center[i], frame.ucl[i]], dtype=float)  # LCL, CL, UCL [s]
        starts = np.r_[times, frame.t]  # each level holds from its time to the next; the current one to the end
        starts[0] = t_left
        levels = np.vstack([limits, now])
        low, high = self._y_range(levels, estimate)

        def to_x(t: np.ndarray) -> np.ndarray:
            """Time [s] -> pixel column."""
            return plot.left + (t - t_left) / self.time_window * (plot.width - 1)

        def to_y(value: np.ndarray) -> np.ndarray:
            """Time gap [s] -> pixel row."""
            return plot.bottom - (value - low) / (high - low) * plot.height

        self._draw_state_box(frame, i, plot, estimate, limits)
        pygame.draw.rect(canvas, PLOT_BORDER_COLOR, plot, 1)
        canvas.set_clip(plot)
        x_starts = to_x(starts)
        self._draw_steps(x_starts, plot.right - 1, to_y(levels[:, 0]), LIMIT_COLOR, dashed=False)
        self._draw_steps(x_starts, plot.right - 1, to_y(levels[:, 2]), LIMIT_COLOR, dashed=False)
        self._draw_steps(x_starts, plot.right - 1, to_y(levels[:, 1]), CENTER_LINE_COLOR, dashed=True)
        xs, ys = to_x(times), to_y(estimate)
        outside = (estimate < limits[:, 0]) | (estimate > limits[:, 2])
        self._draw_polyline(xs, ys, ESTIMATE_COLOR)
        self._draw_polyline(xs, np.where(outside, ys, np.nan), ALARM_COLOR)
        canvas.set_clip(None)
        y_lcl, y_cl, y_ucl = (int(round(y)) for y in to_y(now))
        self._draw_y_ticks(plot, [(now[2], y_ucl), (now[1], y_cl), (now[0], y_lcl)])

        finite = np.flatnonzero(np.isfinite(estimate))
        if finite.size:
            last = finite[-1]
            marker_color = ALARM_COLOR if frame.alarm[i] else ESTIMATE_COLOR
            marker = (int(round(xs[last])), int(np.clip(round(ys[last]), plot.top, plot.bottom - 1)))
            pygame.draw.circle(canvas, marker_color, marker, MARKER_RADIUS)
            value = self._label_font.render(f"{estimate[last]:.2f} s", True, marker_color)
            canvas.blit(value, value.get_rect(midleft=(plot.right + 6, plot.centery)))

    @staticmethod
    def _y_range(levels: np.ndarray, estimate: np.ndarray) -> tuple[float, float]:
        """Values [s] at the bottom and top of a row: all limits with some room, widened for the estimate.

        ``levels`` (n, 3) are LCL, CL, UCL [s]; ``estimate`` (n,) [s].
        """
        lcl, ucl = float(levels[:, 0].min()), float(levels[:, 2].max())
        band = max(float(np.max(levels[:, 2] - levels[:, 0])), MIN_LIMIT_BAND)
        low, high = lcl - Y_PADDING * band, ucl + Y_PADDING * band
        finite = estimate[np.isfinite(estimate)]
        if finite.size:
            low = max(min(low, float(finite.min())), lcl - Y_MAX_EXCURSION * band)
            high = min(max(high, float(finite.max())), ucl + Y_MAX_EXCURSION * band)
        return low, high

    def _draw_steps(
        self, starts: np.ndarray, end: float, levels: np.ndarray, color: tuple[int, int, int], dashed: bool
    ) -> None:
        """A step line: ``levels[k]`` [px] from ``starts[k]`` to ``starts[k + 1]`` (the last one to ``end``) [px]."""
        import pygame

        rows = np.round(levels).astype(int)
        keep = np.r_[True, rows[1:] != rows[:-1]]  # one piece per level, however many samples it spans
        starts, rows = np.round(starts[keep]).astype(int), rows[keep]
        ends = np.r_[starts[1:], int(round(end))]
        if dashed:
            for x0, x1, y in zip(starts, ends, rows, strict=True):
                for x in range(x0, x1, 2 * DASH_LENGTH):
                    pygame.draw.line(self._canvas, color, (x, y), (min(x + DASH_LENGTH, x1), y))
        else:
            points = np.column_stack([np.column_stack([starts, ends]).ravel(), np.repeat(rows, 2)])
            pygame.draw.lines(self._canvas, color, False, points.tolist(), LIMIT_LINE_WIDTH)

    def _draw_state_box(
        self, frame: RenderFrame, i: int, plot: pygame.Rect, estimate: np.ndarray, limits: np.ndarray
    ) -> None:
        """Box left of the row, coloured like the car: name, mode and state (:func:`state_label` of the row's visible
        history, ``estimate`` (n,) [s] and ``limits`` (n, 3) [s]), as many lines as fit."""
        import pygame

        box = pygame.Rect(CHART_PADDING, plot.top, STATE_BOX_WIDTH - CHART_PADDING, plot.height)
        pygame.draw.rect(self._canvas, self._vehicle_color(frame, i + 1), box, border_radius=4)
        lines = [f"F{i + 1}", "V2V" if frame.v2v[i] else "ACC", state_label(frame, i, estimate, limits)]
        line_height = self._label_font.get_linesize()
        lines = lines[: max(1, box.height // line_height)]
        top = box.centery - len(lines) * line_height // 2
        for k, text in enumerate(lines):
            font = self._label_font if k < 2 else self._tick_font
            image = font.render(text, True, LABEL_TEXT_ON_STATE)
            self._canvas.blit(image, image.get_rect(midtop=(box.centerx, top + k * line_height)))

    def _draw_y_ticks(self, plot: pygame.Rect, ticks: list[tuple[float, int]]) -> None:
        """Values of UCL, CL, LCL left of the plot, skipping any that would overlap the previous one."""
        last_bottom = -1
        for value, y in ticks:  # top to bottom
            image = self._tick_font.render(f"{value:.2f}", True, CHART_TEXT_COLOR)
            rect = image.get_rect(midright=(plot.left - 4, y))
            if rect.top > last_bottom:
                self._canvas.blit(image, rect)
                last_bottom = rect.bottom

    def _draw_polyline(self, xs: np.ndarray, ys: np.ndarray, color: tuple[int, int, int]) -> None:
        """Lines through the points, broken where the value is not finite."""
        import pygame

        finite = np.flatnonzero(np.isfinite(ys))
        for run in np.split(finite, np.flatnonzero(np.diff(finite) != 1) + 1):  # runs of consecutive indices
            if run.size == 0:
                continue
            points = np.column_stack([xs[run], ys[run]]).round().astype(int).tolist()
            if len(points) == 1:
                pygame.draw.circle(self._canvas, color, points[0], ESTIMATE_LINE_WIDTH)
            else:
                pygame.draw.lines(self._canvas, color, False, points, ESTIMATE_LINE_WIDTH)

    def _draw_time_axis(self, plots: list[pygame.Rect], t_left: float) -> None:
        """Vertical grid lines at round times in every row, their labels and the axis title under the last."""
        import pygame

        step = min(TIME_TICK_STEPS, key=lambda s: abs(self.time_window / s - TIME_TICK_TARGET))
        last = plots[-1]
        for tick in np.arange(np.ceil(t_left / step) * step, t_left + self.time_window + 1e-9, step):
            x = int(round(last.left + (tick - t_left) / self.time_window * (last.width - 1)))
            for plot in plots:
                pygame.draw.line(self._canvas, GRID_COLOR, (x, plot.top + 1), (x, plot.bottom - 2))
            label = self._tick_font.render(f"{tick:g}", True, CHART_TEXT_COLOR)
            self._canvas.blit(label, label.get_rect(midtop=(x, last.bottom + 3)))
        title = self._tick_font.render("time [s]", True, CHART_TEXT_COLOR)
        self._canvas.blit(title, title.get_rect(bottomright=(last.right, self._chart_rect.bottom - 2)))


def state_label(frame: RenderFrame, i: int, estimate: np.ndarray, limits: np.ndarray) -> str:
    """Follower ``i``'s state as its chart row's box names it: ``COLLIDED``, ``ALARM``, ``settling`` (alarms held
    off after a setting change), ``out of limits`` (the latest estimate outside its limits, no alarm yet), else
    ``in control``.

    ``estimate`` (n,) [s] and ``limits`` (n, 3: LCL, CL, UCL) [s] are the row's visible history; the latest finite
    estimate is the one the row marks and prints (none at the start of an episode: ``in control``).
    """
    if frame.collided[i]:
        return "COLLIDED"
    if frame.alarm[i]:
        return "ALARM"
    if frame.settling is not None and frame.settling[i]:
        return "settling"
    finite = np.flatnonzero(np.isfinite(estimate))
    if finite.size and not limits[finite[-1], 0] <= estimate[finite[-1]] <= limits[finite[-1], 2]:
        return "out of limits"
    return "in control"


def _limit_history(frame: RenderFrame, name: str) -> np.ndarray:
    """(n_history, n_followers) values of one limit history [s]: the recorded ones, else the current ones."""
    recorded = getattr(frame, name)
    if recorded is not None:
        return np.asarray(recorded, dtype=float)
    current = np.asarray(getattr(frame, name.removesuffix("_history")), dtype=float)
    return np.broadcast_to(current, (len(frame.history_t), current.size))


def _seconds(value: float) -> str:
    """A time gap [s] with two decimals, or one when the second is 0: 1.6, 1.0, 1.35."""
    text = f"{value:.2f}"
    return text[:-1] if text.endswith("0") else text
