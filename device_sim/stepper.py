"""The paper feed: the FPGA's cascaded-DDA "electronic cam" (seed 003), the L297 sequencer
(seed 000 3.4) and the trapezoid / Sigmoid S-curve profiles (seed 002).  docs/motion.md.

DDA (seed 003 1.3).  The DSP writes a segment CamMov(Dist, V0, V1, Acc), all in pulses:
V0, V1 in pulses/s, Acc in pulses/s^2.  The FPGA runs a state machine clocked at 50 MHz;
one DDA iteration takes DDA_STATES = 6 clocks (count/complete check, velocity accumulator,
position accumulator, bookkeeping), so the iteration rate is 8.333 MHz.  Two cascaded
23-bit accumulators:

    velocity: acc_v += Acc each iteration while V != V1; on overflow (>= 2^23) V += +-1
    position: acc_p += V  each iteration;   pul = acc_p bit 22;  overflow = end of a pulse

With an iteration rate of exactly 2^23 Hz the registers would be in true pulses/s and
pulses/s^2; at 50 MHz / 6 every time runs 2^23 / 8.333e6 = 1.00663 x long.  That is the
seed's "the clock cannot be set to the ideal value": CamMov(10, 50, 800, 40000) takes
21.289 ms in theory and 21.442 ms here, the seed's simulated figure to the microsecond.

pul is the position accumulator's MSB: it rises half way through a pulse period (the L297
steps on this rising edge of CLOCK) and falls on the overflow, which counts the pulse.  The
seed's MotionState[2] (V1 reached) sets while the 8th pulse is high; MotionState[0] (done)
on the 10th falling edge.  GetMotionSta: bit0 = segment done / idle, bit1 = the buffer
register is free (the DSP may write the next segment), bit2 = V1 reached.  A buffered
segment is taken over in the iteration the running one completes: no gap, the position
accumulator carries on, the velocity register loads the new V0.

Everything clock-level runs in one numba kernel (one loop pass per DDA iteration = 6
clocks); all times are exact multiples of the 20 ns clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from ..rip.compiled import kernel

DDA_CLOCK_HZ = 50_000_000
DDA_STATES = 6                       # clocks per DDA iteration
DDA_BITS = 23
IDEAL_ITERATION_HZ = 1 << DDA_BITS   # registers are pulses/s exactly at this rate

V_START_STEPS_S = 200                # start/stop speed (seed 002: a stepper starts below 250 Hz)

STATUS_DONE = 0x1
STATUS_READY = 0x2
STATUS_V1 = 0x4


@dataclass(frozen=True)
class CamMov:
    """One equal-acceleration segment, as the DSP writes it (seed 003 1.2)."""
    dist: int            # pulses
    v0: int              # pulses/s (register units)
    v1: int              # pulses/s
    acc: int             # pulses/s^2, absolute value

    def check(self, bits: int = DDA_BITS) -> None:
        if self.dist < 0 or self.v0 < 0 or self.v1 < 0 or self.acc < 0:
            raise ValueError(f"{self}: negative argument")
        half = 1 << (bits - 1)
        if self.v0 >= half or self.v1 >= half or self.acc >= (1 << bits):
            raise ValueError(f"{self}: register overflow ({bits}-bit accumulators)")
        if self.dist > 0 and max(self.v0, self.v1) == 0:
            raise ValueError(f"{self}: never moves")

    def theory_time(self) -> float:
        """Continuous-time duration (s) at the ideal iteration rate (seed 003: 21.289 ms)."""
        if self.dist == 0:
            return 0.0
        a, v0, v1, d = float(self.acc), float(self.v0), float(self.v1), float(self.dist)
        if a == 0 or v0 == v1:
            return d / v0
        d_ramp = abs(v1 * v1 - v0 * v0) / (2 * a)
        if d_ramp >= d:               # V1 is not reached within Dist
            s = 1.0 if v1 > v0 else -1.0
            vend = math.sqrt(max(v0 * v0 + s * 2 * a * d, 0.0))
            return abs(vend - v0) / a
        return abs(v1 - v0) / a + (d - d_ramp) / v1


# -- the DDA kernel ------------------------------------------------------------------------------
@kernel()
def _dda_kernel(dist, v0, v1, acc, bits, max_iter, rise, fall, v_rise, seg_of, seg_start,
                v1_it, done_it):
    """Iterate the cam module over the queued segments.  Iteration n (1-based) ends at clock
    n * DDA_STATES.  Returns (pulses, last iteration, stalled)."""
    full = 1 << bits
    half = 1 << (bits - 1)
    nseg = dist.shape[0]
    seg = 0
    # skip empty segments at the front
    while seg < nseg and dist[seg] == 0:
        seg_start[seg] = 0
        v1_it[seg] = 0
        done_it[seg] = 0
        seg += 1
    if seg == nseg:
        return 0, 0, False
    V = v0[seg]
    acc_v = 0
    acc_p = 0
    count = 0
    seg_start[seg] = 0
    if V == v1[seg]:
        v1_it[seg] = 0
    npulse = 0
    it = 0
    while it < max_iter:
        it += 1
        # velocity accumulator
        if V != v1[seg]:
            acc_v += acc[seg]
            if acc_v >= full:
                acc_v -= full
                if v1[seg] > V:
                    V += 1
                else:
                    V -= 1
                if V == v1[seg]:
                    v1_it[seg] = it
        # position accumulator: pul = MSB
        old = acc_p
        acc_p += V
        if old < half and acc_p >= half:
            rise[npulse] = it
            v_rise[npulse] = V
            seg_of[npulse] = seg
        if acc_p >= full:
            acc_p -= full
            fall[npulse] = it
            npulse += 1
            count += 1
            if acc_p >= half:              # V >= half is refused by CamMov.check
                rise[npulse] = it
                v_rise[npulse] = V
                seg_of[npulse] = seg
        # completion and the double buffer
        if count == dist[seg]:
            done_it[seg] = it
            seg += 1
            while seg < nseg and dist[seg] == 0:
                seg_start[seg] = it
                v1_it[seg] = it
                done_it[seg] = it
                seg += 1
            if seg == nseg:
                return npulse, it, False
            seg_start[seg] = it
            V = v0[seg]
            acc_v = 0
            count = 0
            if V == v1[seg]:
                v1_it[seg] = it
    return npulse, it, True


@dataclass
class CamRun:
    """Clock-level result of a queue of CamMov segments run back to back."""
    segments: list[CamMov]
    rise_clock: np.ndarray       # int64, pul rising edge of every pulse (the step)
    fall_clock: np.ndarray       # int64, falling edge (the pulse is counted)
    v_at_pulse: np.ndarray       # V register at each rising edge (pulses/s, register units)
    segment_of_pulse: np.ndarray
    start_clock: np.ndarray      # per segment: clock it was loaded
    v1_clock: np.ndarray         # per segment: clock V1 was reached (-1: never)
    done_clock: np.ndarray       # per segment: clock it completed (10th falling edge, ...)
    end_clock: int
    clock_hz: float = DDA_CLOCK_HZ
    states: int = DDA_STATES

    @property
    def clock_s(self) -> float:
        return 1.0 / self.clock_hz

    @property
    def iteration_hz(self) -> float:
        return self.clock_hz / self.states

    @property
    def time_scale(self) -> float:
        """Every duration runs this much longer than at the ideal 2^23 Hz iteration rate."""
        return IDEAL_ITERATION_HZ / self.iteration_hz

    @property
    def step_times(self) -> np.ndarray:
        return self.rise_clock * self.clock_s

    @property
    def duration(self) -> float:
        return self.end_clock * self.clock_s

    def status_at(self, clock: int) -> int:
        """GetMotionSta() read at a clock, with the DSP refilling the buffer register as soon
        as it frees (so bit1 shows free only once the last segment has been taken over)."""
        n = len(self.segments)
        # the segment running at `clock`: the last one loaded at or before it (one loaded in
        # the iteration another completes replaces it at once)
        cur = int(np.searchsorted(self.start_clock, clock, side="right")) - 1
        if cur < 0:
            return STATUS_DONE | STATUS_READY
        done = self.done_clock[cur] <= clock
        st = 0
        if done:
            st |= STATUS_DONE
        if cur == n - 1:
            st |= STATUS_READY
        if 0 <= self.v1_clock[cur] <= clock:
            st |= STATUS_V1
        return st

    def pulses_before(self, clock: int) -> tuple[int, int]:
        """(rising edges, falling edges) at or before a clock."""
        return (int(np.searchsorted(self.rise_clock, clock, side="right")),
                int(np.searchsorted(self.fall_clock, clock, side="right")))

    def speed_at_steps(self) -> np.ndarray:
        """Instantaneous step rate between consecutive steps (steps/s), len = steps - 1."""
        return 1.0 / np.diff(self.step_times)


def run_cam(segments: list[CamMov] | CamMov, clock_hz: float = DDA_CLOCK_HZ,
            states: int = DDA_STATES, bits: int = DDA_BITS,
            max_seconds: float = 600.0) -> CamRun:
    """Simulate the cam module cycle-exactly over segments queued through the double buffer."""
    if isinstance(segments, CamMov):
        segments = [segments]
    segments = list(segments)
    for s in segments:
        s.check(bits)
    n = sum(s.dist for s in segments)
    dist = np.array([s.dist for s in segments], dtype=np.int64)
    v0 = np.array([s.v0 for s in segments], dtype=np.int64)
    v1 = np.array([s.v1 for s in segments], dtype=np.int64)
    acc = np.array([s.acc for s in segments], dtype=np.int64)
    rise = np.zeros(n + 1, dtype=np.int64)
    fall = np.zeros(n + 1, dtype=np.int64)
    v_rise = np.zeros(n + 1, dtype=np.int64)
    seg_of = np.zeros(n + 1, dtype=np.int64)
    k = len(segments)
    seg_start = np.full(k, -1, dtype=np.int64)
    v1_it = np.full(k, -1, dtype=np.int64)
    done_it = np.full(k, -1, dtype=np.int64)
    max_iter = int(max_seconds * clock_hz / states)
    if k:
        npulse, last, stalled = _dda_kernel(dist, v0, v1, acc, bits, max_iter, rise, fall,
                                            v_rise, seg_of, seg_start, v1_it, done_it)
    else:
        npulse, last, stalled = 0, 0, False
    if stalled:
        raise RuntimeError("cam module never completed the queue (speed reached 0?)")
    to_clk = lambda a: np.where(a >= 0, a * states, -1)
    return CamRun(segments=segments, rise_clock=rise[:npulse] * states,
                  fall_clock=fall[:npulse] * states, v_at_pulse=v_rise[:npulse].copy(),
                  segment_of_pulse=seg_of[:npulse].copy(), start_clock=to_clk(seg_start),
                  v1_clock=to_clk(v1_it), done_clock=to_clk(done_it), end_clock=last * states,
                  clock_hz=clock_hz, states=states)


# -- L297 -------------------------------------------------------------------------------------
# Half-step master sequence (L297 data sheet): state -> A, B, C, D, INH1, INH2.  A/B drive
# bridge 1, C/D bridge 2; INHx (active low) switches a bridge off when its winding is
# unpowered.  State 1 is HOME (ABCD = 0101).
L297_TABLE = np.array([
    # A  B  C  D  INH1 INH2
    [0, 1, 0, 1, 1, 1],     # 1  HOME: both windings on
    [0, 0, 0, 1, 0, 1],     # 2
    [1, 0, 0, 1, 1, 1],     # 3
    [1, 0, 0, 0, 1, 0],     # 4
    [1, 0, 1, 0, 1, 1],     # 5
    [0, 0, 1, 0, 0, 1],     # 6
    [0, 1, 1, 0, 1, 1],     # 7
    [0, 1, 0, 0, 1, 0],     # 8
], dtype=np.uint8)
L297_SIGNALS = ("A", "B", "C", "D", "INH1", "INH2")


def l297_states(steps: int, cw: bool = True, half_step: bool = True, start_state: int = 1) -> np.ndarray:
    """The translator state (1..8) after each of `steps` CLOCK rising edges.  CW counts up,
    CCW down; full step (HALF/FULL low) moves two states per clock, so it stays on odd
    states (normal drive, two phases on) or even ones (wave drive) as the data sheet says."""
    if not 1 <= start_state <= 8:
        raise ValueError("L297 states are 1..8")
    inc = (1 if half_step else 2) * (1 if cw else -1)
    k = np.arange(1, steps + 1, dtype=np.int64)
    return ((start_state - 1 + inc * k) % 8 + 1).astype(np.int64)


def l297_outputs(states: np.ndarray) -> np.ndarray:
    """(n, 6) uint8: A, B, C, D, INH1, INH2 for translator states."""
    return L297_TABLE[np.asarray(states, dtype=np.int64) - 1]


# -- profiles ----------------------------------------------------------------------------------
def trapezoid_segments(steps: int, vmax: float, acc: float,
                       v_start: float = V_START_STEPS_S) -> list[CamMov]:
    """Accelerate / cruise / decelerate as three CamMov joined through the double buffer.
    Ramp distances are rounded up (seed 003: Dist slightly larger than the speed change
    needs); a move too short to reach vmax becomes a triangle at a lower integer peak."""
    steps = int(steps)
    vs = int(round(min(v_start, vmax)))
    a = int(round(acc))
    if steps <= 0:
        return []
    vp = int(math.floor(min(vmax, math.sqrt(vs * vs + a * steps))))

    def ramp(v):
        return int(math.ceil((v * v - vs * vs) / (2.0 * a))) if a > 0 else 0

    while vp > vs and 2 * ramp(vp) > steps:
        vp -= 1
    if vp <= vs or a == 0:
        return [CamMov(steps, vs, vs, 0)]
    d = ramp(vp)
    segs = [CamMov(d, vs, vp, a)]
    if steps - 2 * d > 0:
        segs.append(CamMov(steps - 2 * d, vp, vp, 0))
    segs.append(CamMov(d, vp, vs, a))
    return segs


SIGMOID_N = 6          # seed 002: the ramp lasts n = 6 periods ...
SIGMOID_K1 = 0.5       # ... cut into segments of k1 = 0.5 period (12 equal segments) ...
SIGMOID_K2 = 0.25      # ... and k2 = 0.25 period in the steep middle third: 16 segments


def sigmoid_breakpoints(n: int = SIGMOID_N, k1: float = SIGMOID_K1,
                        k2: float = SIGMOID_K2) -> tuple[np.ndarray, np.ndarray]:
    """The seed's non-uniform time discretisation of the Sigmoid ramp.

    Returns (u, g): breakpoints u in [0, 1] (fraction of the ramp time) and the normalised
    speed g(u) in [0, 1] there.  The ramp lasts n periods; the speed is the seed's
    v(t) = 1 / (1 + e^-(t - n)) with t in half-periods (t = 0 .. 2n, centre t = n = 6: the
    seed's formulas d(t) = ln(e^(t-6) + 1) etc.), rescaled to run exactly 0 -> 1.  Segments
    are k1 periods wide in the outer thirds and k2 in the middle third, where the speed
    changes fastest: with the seed's n = 6, k1 = 0.5, k2 = 0.25 that is 4 + 8 + 4 = 16
    segments instead of 12 equal ones."""
    third = n / 3.0
    pts = [np.arange(0.0, third, k1), np.arange(third, 2 * third, k2),
           np.arange(2 * third, n, k1), np.array([float(n)])]
    tau = np.concatenate(pts)                         # periods
    t = 2.0 * tau                                     # the seed's t, half-periods
    s = 1.0 / (1.0 + np.exp(-(t - n)))
    s0 = 1.0 / (1.0 + math.exp(n))
    s1 = 1.0 / (1.0 + math.exp(-n))
    return tau / n, (s - s0) / (s1 - s0)


def sigmoid_table(vmax: float, acc: float, v_start: float = V_START_STEPS_S,
                  steps: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(time s, speed steps/s) pairs of an acceleration ramp whose steepest segment has
    acceleration `acc` (the same limit a trapezoid uses); if `steps` is given the peak is
    lowered so that ramp up + ramp down fit in it."""
    u, g = sigmoid_breakpoints()
    sigma = float(np.max(np.diff(g) / np.diff(u)))     # steepest normalised slope (2.95)
    vs = min(v_start, vmax)
    vp = vmax
    if steps is not None:
        # 2 ramps of T (vs + vp)/2 with T = sigma (vp - vs)/a: sigma (vp^2 - vs^2)/a <= steps
        vp = min(vmax, math.sqrt(vs * vs + acc * steps / sigma))
    T = sigma * (vp - vs) / acc if vp > vs else 0.0
    return u * T, vs + (vp - vs) * g


def sigmoid_segments(steps: int, vmax: float, acc: float,
                     v_start: float = V_START_STEPS_S) -> tuple[list[CamMov], np.ndarray, np.ndarray]:
    """The S-curve as CamMov segments: each (time, speed) table interval is one constant-
    acceleration segment, so the FPGA interpolates the table linearly (continuous speed)
    instead of the seed-002 timer reload (a speed staircase).  Segment distances are the
    table's cumulative distance rounded to whole pulses; Acc is chosen so that V1 is reached
    within each segment's Dist.  Returns (segments, table time, table speed)."""
    steps = int(steps)
    if steps <= 0:
        return [], np.zeros(0), np.zeros(0)
    scale_v = scale_a = 1.0
    for _ in range(200):
        t, v = sigmoid_table(vmax * scale_v, acc * scale_a, v_start, steps)
        vi = np.round(v).astype(np.int64)
        d = np.concatenate(([0.0], np.cumsum(np.diff(t) * (v[1:] + v[:-1]) / 2)))
        bnd = np.round(d).astype(np.int64)
        up = []
        j0 = 0
        for j in range(1, len(t)):
            if bnd[j] == bnd[j0] and j < len(t) - 1:
                continue                    # under a pulse: merge with the next interval
            dist = int(bnd[j] - bnd[j0])
            va, vb = int(vi[j0]), int(vi[j])
            if dist <= 0:
                break
            a = int(math.ceil(abs(vb * vb - va * va) / (2.0 * dist))) if vb != va else 0
            up.append(CamMov(dist, va, vb, a))
            j0 = j
        ramp = sum(s.dist for s in up)
        worst = max((s.acc for s in up), default=0)
        if 2 * ramp > steps:
            scale_v *= 0.99                 # rounding pushed the ramps past the move
        elif worst > acc:
            scale_a *= 0.995 * acc / worst  # whole-pulse distances steepened a segment
        else:
            break
    if not up or up[-1].v1 <= up[0].v0:
        vs = int(round(min(v_start, vmax)))
        return [CamMov(steps, vs, vs, 0)], t, v
    vp = up[-1].v1
    down = [CamMov(s.dist, s.v1, s.v0, s.acc) for s in reversed(up)]
    mid = [CamMov(steps - 2 * ramp, vp, vp, 0)] if steps > 2 * ramp else []
    return up + mid + down, t, v


# -- the feed move ----------------------------------------------------------------------------
@dataclass
class FeedResult:
    steps: int                      # signed: > 0 forward (CW)
    profile: str
    step_times: np.ndarray          # s from the move's start, one per step (L297 CLOCK rise)
    duration: float                 # s until GetMotionSta reports the last segment done
    phases: np.ndarray              # (|steps|, 6) uint8 L297 outputs A,B,C,D,INH1,INH2 after each step
    states: np.ndarray              # translator state 1..8 after each step
    start_state: int
    end_state: int
    cw: bool
    half_step: bool
    segments: list[CamMov]
    cam: CamRun | None
    table_t: np.ndarray = field(default_factory=lambda: np.zeros(0))    # S-curve table
    table_v: np.ndarray = field(default_factory=lambda: np.zeros(0))

    @property
    def step_rate(self) -> np.ndarray:
        """Step rate between consecutive steps (steps/s)."""
        return 1.0 / np.diff(self.step_times) if self.step_times.size > 1 else np.zeros(0)

    @property
    def peak_rate(self) -> float:
        return float(self.step_rate.max()) if self.step_times.size > 1 else 0.0

    def segment_accelerations(self) -> np.ndarray:
        """Signed acceleration of each segment in the cam's real time (steps/s^2)."""
        if self.cam is None:
            return np.zeros(0)
        k = 1.0 / self.cam.time_scale ** 2
        out = []
        for s in self.segments:
            out.append(0.0 if s.v0 == s.v1 else math.copysign(s.acc * k, s.v1 - s.v0))
        return np.array(out)


def feed_move(steps: int, profile: str = "trapezoid", max_steps_s: float = 4000.0,
              accel_steps_s2: float = 40000.0, v_start_steps_s: float = V_START_STEPS_S,
              half_step: bool = True, start_state: int = 1,
              correct_clock: bool = True) -> FeedResult:
    """One paper feed: plan the profile, run it through the cam module, sequence the L297.
    steps > 0 feeds forward (CW), < 0 backward (CCW).  profile: "trapezoid" or "sigmoid".

    correct_clock: the DSP multiplies speeds by 1.00663 and accelerations by 1.00663^2
    before writing them (seed 003's suggested correction factor for the 50 MHz / 6 iteration
    clock), so the feed runs at the asked speeds; False writes them as they are."""
    steps = int(steps)
    n = abs(steps)
    cw = steps >= 0
    table_t = table_v = np.zeros(0)
    k = IDEAL_ITERATION_HZ / (DDA_CLOCK_HZ / DDA_STATES) if correct_clock else 1.0
    vmax, acc, vs = max_steps_s * k, accel_steps_s2 * k * k, v_start_steps_s * k
    if profile == "trapezoid":
        segs = trapezoid_segments(n, vmax, acc, vs)
    elif profile in ("sigmoid", "s-curve", "scurve"):
        segs, table_t, table_v = sigmoid_segments(n, vmax, acc, vs)
        table_t, table_v = table_t * k, table_v / k       # the table in real time and speed
        profile = "sigmoid"
    else:
        raise ValueError(f"unknown feed profile {profile!r} (trapezoid or sigmoid)")
    cam = run_cam(segs) if segs else None
    states = l297_states(n, cw=cw, half_step=half_step, start_state=start_state)
    return FeedResult(
        steps=steps, profile=profile,
        step_times=cam.step_times if cam is not None else np.zeros(0),
        duration=cam.duration if cam is not None else 0.0,
        phases=l297_outputs(states), states=states, start_state=start_state,
        end_state=int(states[-1]) if n else start_state, cw=cw, half_step=half_step,
        segments=segs, cam=cam, table_t=table_t, table_v=table_v)


def feed_move_from_profile(profile, steps: int, **kw) -> FeedResult:
    """feed_move with the profile's [feed] speed, acceleration and profile name."""
    f = profile.feed
    return feed_move(steps, kw.pop("profile", f.profile), f.max_steps_s, f.accel_steps_s2, **kw)
