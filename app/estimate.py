"""Estimates shown before printing (docs/gui.md, "Estimates"): time, area, ink, strokes.

Time, per stroke (every number from the printer profile):

    L      = image width + head spread + 2 ramps                       (mm)
             head spread = max(x_counts) - min(x_counts); ramp = v²/2a + 2 columns
    t_line = L / v + v / a           the carriage's trapezoidal move over L at the dpi
                                     mode's speed v and acceleration a (L/v is the
                                     brief's "(width + spread + two ramps) / speed";
                                     v/a is what accelerating and braking add)
    t_ret  = L / v_max + v_max / a   unidirectional only: the carriage returns to the
                                     start of the next line at the rail's top speed
    t_feed = n / f + f / α  (n ≥ f²/α)  or  2 √(n / α)   the paper advance of A rows
             n = A * row / step (feed steps), f = max steps/s, α = steps/s²

    time = copies * strokes * (t_line + t_ret + t_feed)

strokes = RipJob(...).planner().total_strokes (blank strokes, which the driver skips,
are counted: the estimate is an upper bound for images with empty bands).

Ink per colour (ml) = drops * profile.drop_volume_pl * 1e-9, with the drops counted in
the preview's halftone (the RIP's real separation and dither at preview size) and
scaled by (job dots / preview dots) and by the dpi mode's [color] drop_budget (the
preview is made without it: docs/color.md "Linearisation").  Area (m²) = width * length of the image.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..rip.profile import Profile


@dataclass
class Estimate:
    width_dots: int = 0
    height_rows: int = 0
    width_mm: float = 0.0
    height_mm: float = 0.0
    strokes: int = 0                         # carriage strokes of one copy
    copies: int = 1
    time_s: float = 0.0                      # all copies
    stroke_s: float = 0.0                    # one stroke
    area_m2: float = 0.0                     # one copy
    drops: list = field(default_factory=lambda: [0, 0, 0, 0])   # one copy
    ink_ml: list = field(default_factory=lambda: [0.0] * 4)     # all copies

    @property
    def total_ink_ml(self) -> float:
        return float(sum(self.ink_ml))


def _trapezoid_s(distance: float, v: float, a: float) -> float:
    if distance <= 0:
        return 0.0
    if distance * a >= v * v:
        return distance / v + v / a
    return 2.0 * math.sqrt(distance / a)


def stroke_time_s(profile: Profile, width_dots: int, dpi: int, passes: int, bidir: bool) -> dict:
    """The parts of one stroke's time (seconds) and the lengths they come from (mm); `passes`
    is the weave's (it sets the paper advance between strokes)."""
    cpi = profile.counts_per_inch
    k = profile.k(dpi)
    v = profile.speed_counts_s(dpi) / cpi * 25.4                     # mm/s
    a = profile.accel_counts_s2() / cpi * 25.4                       # mm/s²
    vmax = profile.carriage.max_speed_mm_s
    ramp = v * v / (2 * a) + 2 * k / cpi * 25.4
    xs = [h.x_counts for h in profile.heads]
    spread = (max(xs) - min(xs)) / cpi * 25.4
    width = width_dots * k / cpi * 25.4
    length = width + spread + 2 * ramp
    t_line = _trapezoid_s(length, v, a)
    t_ret = 0.0 if bidir else _trapezoid_s(length, vmax, a)
    s0, s1 = profile.usable_slots()
    advance = (s1 - s0) // passes
    f = profile.feed
    steps = advance * profile.row_um / profile.feed_um_per_step
    t_feed = _trapezoid_s(steps, f.max_steps_s, f.accel_steps_s2)
    return dict(line_mm=length, width_mm=width, spread_mm=spread, ramp_mm=ramp, speed_mm_s=v,
                t_line=t_line, t_return=t_ret, t_feed=t_feed, advance_rows=advance,
                total=t_line + t_ret + t_feed)


def estimate(profile: Profile, width_dots: int, height_rows: int, dpi: int, passes_n: int,
             bidir: bool, total_strokes: int, copies: int = 1,
             preview_drops=None, preview_dots: int = 0) -> Estimate:
    """An Estimate from the job's size in device dots, the weave's pass count (passes_n) and
    the planner's stroke count.
    preview_drops: drops per colour counted in a halftone of preview_dots dots."""
    cpi = profile.counts_per_inch
    k = profile.k(dpi)
    e = Estimate(width_dots=int(width_dots), height_rows=int(height_rows), strokes=int(total_strokes),
                 copies=int(copies))
    e.width_mm = width_dots * k / cpi * 25.4
    e.height_mm = height_rows * profile.row_um / 1000.0
    e.area_m2 = e.width_mm * e.height_mm * 1e-6
    parts = stroke_time_s(profile, width_dots, dpi, passes_n, bidir)
    e.stroke_s = parts["total"]
    e.time_s = copies * total_strokes * e.stroke_s
    if preview_drops is not None and preview_dots > 0:
        ratio = (width_dots * height_rows) / preview_dots * profile.color.drop_budget.get(dpi, 1.0)
        e.drops = [int(round(float(d) * ratio)) for d in preview_drops]
        e.ink_ml = [d * profile.drop_volume_pl * 1e-9 * copies for d in e.drops]
    return e


def fmt_duration(s: float) -> str:
    s = int(round(s))
    h, rem = divmod(s, 3600)
    m, sec = divmod(rem, 60)
    return f"{h}:{m:02d}:{sec:02d}" if h else f"{m}:{sec:02d}"


def fmt_ml(ml: float) -> str:
    return f"{ml:.3f}" if ml < 10 else f"{ml:.1f}"
