"""The carriage servo: DSP position loop + L298/LM393 power stage + PITTMAN DC motor + belt.

Seed 000 ch. 3; docs/motion.md explains every number.  The DSP plans a trapezoidal position
reference in encoder counts (accelerate, cruise, decelerate), samples the QEP counter every
`period_s` and runs the incremental (velocity-form) controller of seed eq. 3-10 on the
position error e = reference - count (counts -> volts):

    du[k] = kp (e[k] - e[k-1]) + ki e[k] + (kv / W) ((e[k] - e[k-m]) - (e[k-1] - e[k-1-m]))
    u[k]  = u[k-1] + du[k]          (clamped so that the bridge voltage stays within supply)
    V[k]  = u[k] + kff_v v_ref + kff_a a_ref

i.e. u = kp e + ki sum(e) + kv (speed error measured over the window W = m T): the thesis'
PI speed regulator (Kp on the speed error, Kp/Ti on its integral, the position error) plus
an integral of the position error, plus velocity and acceleration feed-forward from the
reference's mean over the coming period.  The PWM is modelled as its average voltage (seed
eq. 3-6/3-7: the L298 is a pure gain), saturating at +-supply.  The LM393 cuts the bridge
when the sense current reaches 2 A: modelled as an ideal current clamp, and the cut is
reported (`Trajectory.tripped`).

The plant (seed eq. 3-1/3-2) is integrated with a fixed step of at most `max_dt_s` (20 us;
the electrical time constant L/R is 0.83 ms): per step the armature current is advanced
exactly (exponential) at the step's back-EMF, clamped, then the mechanics take the step's
mean torque (semi-implicit), with optional Coulomb friction.  All of it runs in one numba
kernel: a 5.6 s production line costs about 10 ms.

Units: position in encoder counts (1/600 inch of belt), speed counts/s, current A, voltage
V, time s.  `counts_per_rad` = pulley radius / count pitch = 118.1 counts per motor radian.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np
from ..rip.compiled import kernel

from .motion import Trapezoid

MM_PER_INCH = 25.4

# seed 000 3.3.2.4: speed-feedback scale K_g (V per rad/s), PWM amplifier gain K_w (V/V), and
# the thesis' PI (Ziegler-Nichols) with its 50 ms sampling.  Used to express the seed's gains
# in our units (docs/motion.md, "Gains") and to reproduce the thesis test.
SEED_KG_V_PER_RAD_S = 0.25
SEED_KW = 2.4
SEED_KP = 32.0
SEED_TI_S = 1.32
SEED_PERIOD_S = 0.05

# Recommended production sampling period (docs/motion.md): a 1 kHz loop with the speed error
# measured over 4 ms.  Faster sampling buys nothing with a 600 counts/inch strip.
PRODUCTION_PERIOD_S = 0.001


def seed_gains(kp_seed: float = SEED_KP, ti_seed: float = SEED_TI_S,
               counts_per_rad: float = 5.0 / (MM_PER_INCH / 600)) -> tuple[float, float]:
    """The thesis' PI in our units: (kp V/count, kv V per count/s).

    Its regulator acts on the speed error through K_g and drives the bridge through K_w:
    V = K_w Kp (K_g e_w + (K_g / Ti) integral(e_w)), e_w in rad/s.  The integral of the speed
    error is the position error, so  kv = K_w K_g Kp / counts_per_rad  (0.163 V per count/s)
    and kp = kv / Ti  (0.123 V per count)."""
    kv = SEED_KW * SEED_KG_V_PER_RAD_S * kp_seed / counts_per_rad
    return kv / ti_seed, kv


@dataclass
class ServoParams:
    """Plant, power stage and DSP controller of the carriage axis."""
    # plant (seed 000 table 3-3; profile [carriage])
    ke: float = 0.0287                  # back-EMF constant, V s/rad
    kt: float = 0.0287                  # torque constant, N m/A
    r_ohm: float = 1.89
    l_h: float = 0.00156
    j_kg_m2: float = 1e-4               # at the motor shaft, carriage included
    friction_nm: float = 0.0            # Coulomb friction at the shaft (profile: optional)
    supply_v: float = 19.1              # L298 bridge: the average voltage saturates here
    current_limit_a: float = 2.0        # LM393 cut
    pulley_diameter_mm: float = 10.0
    counts_per_inch: int = 600          # 150 lpi x4
    # DSP
    period_s: float = PRODUCTION_PERIOD_S   # servo sampling period T
    kp: float = 0.0                     # V per count of position error
    ti_s: float = SEED_TI_S             # integral time of the position error (ki = kp T / Ti)
    kv: float = 0.0                     # V per count/s of speed error
    speed_window: int = 1               # m: the speed error is measured over m periods
    kff_v: float = 0.0                  # V per count/s of reference speed
    kff_a: float = 0.0                  # V per count/s^2 of reference acceleration
    max_dt_s: float = 20e-6             # plant integration step (upper bound)

    # -- derived -------------------------------------------------------------------------
    @property
    def counts_per_rad(self) -> float:
        return (self.pulley_diameter_mm / 2) / (MM_PER_INCH / self.counts_per_inch)

    @property
    def counts_per_mm(self) -> float:
        return self.counts_per_inch / MM_PER_INCH

    @property
    def tau_mech_s(self) -> float:
        """Electromechanical time constant T_m = J R / (Ke Kt) (0.23 s)."""
        return self.j_kg_m2 * self.r_ohm / (self.ke * self.kt)

    @property
    def tau_elec_s(self) -> float:
        """Armature time constant T_a = L / R (0.83 ms)."""
        return self.l_h / self.r_ohm

    @property
    def ki(self) -> float:
        """Integral gain per sample, V per count: kp T / Ti (seed 3-9)."""
        return self.kp * self.period_s / self.ti_s if self.ti_s > 0 else 0.0

    @property
    def max_accel_counts_s2(self) -> float:
        """Acceleration the current cut allows (no friction): Kt I_lim / J at the pulley."""
        return (self.kt * self.current_limit_a - self.friction_nm) / self.j_kg_m2 * self.counts_per_rad

    def model_ff(self) -> tuple[float, float]:
        """Feed-forward gains from the nominal model: V = Ke w + R J alpha / Kt (per count)."""
        c = self.counts_per_rad
        return self.ke / c, self.r_ohm * self.j_kg_m2 / (self.kt * c)

    def with_period(self, period_s: float) -> "ServoParams":
        """The same axis with the DSP loop tuned for a sampling period (tuned_gains)."""
        kp, kv, m = tuned_gains(self, period_s)
        fv, fa = self.model_ff()
        return replace(self, period_s=float(period_s), kp=kp, kv=kv, speed_window=m,
                       kff_v=fv, kff_a=fa)

    def with_seed_gains(self, period_s: float = SEED_PERIOD_S) -> "ServoParams":
        """The thesis' Kp = 32, Ti = 1.32 mapped literally (seed_gains), no position integral:
        unstable at 50 ms on the real motor (docs/motion.md).  For comparison only."""
        kp, kv = seed_gains(counts_per_rad=self.counts_per_rad)
        fv, fa = self.model_ff()
        return replace(self, period_s=float(period_s), kp=kp, kv=kv, speed_window=1,
                       ti_s=0.0, kff_v=fv, kff_a=fa)

    @classmethod
    def from_profile(cls, profile, period_s: float | None = None) -> "ServoParams":
        """Plant from the profile's [carriage], counts/inch from the profile, the loop tuned for
        period_s (default: the profile's servo_period_s)."""
        c = profile.carriage
        base = cls(
            ke=c.motor_ke, kt=c.torque_constant, r_ohm=c.motor_r_ohm, l_h=c.motor_l_h,
            j_kg_m2=c.inertia_kg_m2, friction_nm=c.friction_nm, supply_v=c.supply_v,
            current_limit_a=c.current_limit_a, pulley_diameter_mm=c.pulley_diameter_mm,
            counts_per_inch=int(profile.counts_per_inch), ti_s=c.ti_s,
        )
        T = float(period_s if period_s is not None else c.servo_period_s)
        return base.with_period(T)

    @classmethod
    def thesis(cls, profile=None) -> "ServoParams":
        """The thesis set-up: 50 ms sampling (seed 000 3.3.1), gains tuned for it."""
        if profile is not None:
            return cls.from_profile(profile, period_s=SEED_PERIOD_S)
        return cls().with_period(SEED_PERIOD_S)


# -- tuning ------------------------------------------------------------------------------------
SPEED_WINDOW_S = 0.004        # speed error measured over >= 4 ms of encoder counts
SPEED_NOISE_V = 0.6           # volts the speed term may jump when one count enters the window
DAMPING = 0.55                # target damping ratio of the position loop
FAST_PERIOD_S = 0.004         # at or below: continuous design; above: discrete (ZOH) design


def tuned_gains(p: ServoParams, period_s: float) -> tuple[float, float, int]:
    """(kp V/count, kv V per count/s, speed window m periods) for a sampling period.

    The speed error is the count difference over a window W = m T; one count entering or
    leaving the window moves the speed term by kv / W volts, so kv <= SPEED_NOISE_V * W
    (quantisation of a 600 counts/inch strip; a larger kv chops the current into the 2 A
    cut).  Fast loops (T <= 4 ms): W = 4 ms and kp for a damping ratio of 0.55 of the
    continuous loop  tau s^2 + (1 + K kv) s + K kp  (K = counts/s per volt, tau = J R/Ke Kt).
    Slow loops: the discrete closed loop (ZOH plant incl. the armature inductance, one-period
    speed window) is searched for the stiffest kp whose poles are all inside the unit circle
    with a damping ratio >= 0.5.  docs/motion.md, "Gains"."""
    K = p.counts_per_rad / p.ke
    tau = p.tau_mech_s
    if period_s <= FAST_PERIOD_S:
        m = max(1, int(round(SPEED_WINDOW_S / period_s)))
        kv = SPEED_NOISE_V * m * period_s
        kp = (1 + K * kv) ** 2 / (4 * DAMPING ** 2 * tau * K)
        return kp, kv, m
    kp, kv = _discrete_design(p.ke, p.kt, p.r_ohm, p.l_h, p.j_kg_m2, p.counts_per_rad,
                              p.ti_s, float(period_s))
    return kp, kv, 1


def _expm(a: np.ndarray) -> np.ndarray:
    norm = float(np.abs(a).sum(axis=0).max())
    s = max(0, int(math.ceil(math.log2(norm))) + 1) if norm > 0 else 0
    b = a / 2 ** s
    out = np.eye(a.shape[0])
    term = np.eye(a.shape[0])
    for k in range(1, 30):
        term = term @ b / k
        out = out + term
    for _ in range(s):
        out = out @ out
    return out


def _zoh_plant(ke, kt, r, l, j, cpr, T):
    """Exact ZOH discretisation of the (x counts, v counts/s, i A) plant for one period."""
    a = np.array([[0, 1, 0], [0, 0, cpr * kt / j], [0, -ke / cpr / l, -r / l]], dtype=float)
    b = np.array([0, 0, 1 / l], dtype=float)
    m = np.zeros((4, 4))
    m[:3, :3] = a * T
    m[:3, 3] = b * T
    e = _expm(m)
    return e[:3, :3], e[:3, 3]


def closed_loop_poles(p: ServoParams, period_s: float | None = None) -> np.ndarray:
    """Poles (z-plane) of the sampled loop with p's gains (no quantisation, no saturation)."""
    T = float(period_s or p.period_s)
    return _poles(p.ke, p.kt, p.r_ohm, p.l_h, p.j_kg_m2, p.counts_per_rad, T, p.kp,
                  p.kp * T / p.ti_s if p.ti_s > 0 else 0.0, p.kv / (p.speed_window * T),
                  int(p.speed_window))


def _poles(ke, kt, r, l, j, cpr, T, kp, ki, kdw, m):
    ad, bd = _zoh_plant(ke, kt, r, l, j, cpr, T)
    # state: x, v, i, sum(e), e[k-1] .. e[k-m]; reference 0 so e[k] = -x[k]
    n = 4 + m
    a = np.zeros((n, n))
    u = np.zeros(n)                      # u[k] = kp e + ki (S + e) + kdw (e - e[k-m])
    u[0] = -(kp + ki + kdw)
    u[3] = ki
    u[3 + m] = -kdw
    a[:3, :3] = ad
    a[:3, :] += np.outer(bd, u)
    a[3, 3] = 1.0
    a[3, 0] = -1.0
    a[4, 0] = -1.0
    for q in range(5, 4 + m):
        a[q, q - 1] = 1.0
    return np.linalg.eigvals(a)


@lru_cache(maxsize=64)
def _discrete_design(ke, kt, r, l, j, cpr, ti, T) -> tuple[float, float]:
    best = (0.0, 0.0)
    for kv in np.geomspace(1e-5, SPEED_NOISE_V * T, 40):
        for kp in np.geomspace(1e-5, 1.0, 60):
            if kp <= best[0]:
                continue
            z = _poles(ke, kt, r, l, j, cpr, T, kp, kp * T / ti, kv / T, 1)
            if np.max(np.abs(z)) >= 1.0:
                break                               # stiffer kp only gets worse
            z = z[np.abs(z) > 0.5]
            s = np.log(z.astype(complex)) / T
            zeta = np.min(-s.real / np.maximum(np.abs(s), 1e-300))
            if zeta >= 0.5:
                best = (float(kp), float(kv))
    return best


# -- the kernel ------------------------------------------------------------------------------
@kernel()
def _servo_kernel(ff, xref, n_sub, dt, x0, kp, ki, kdw, m, vmax, ke, kt, r, l, j, tf, ilim, cpr,
                  out_x, out_v, out_i, out_u):
    """Run len(ff) controller periods of n_sub plant steps each.  ff[k] is the feed-forward
    voltage for period k, xref[k] the reference at its start.  Records the state after every
    plant step (index 0 = initial).  Returns (tripped, samples written).

    Controller (velocity form, seed eq. 3-10) on the position error e = xref - count:
        du = kp (e[k] - e[k-1]) + ki e[k] + kdw ((e[k] - e[k-m]) - (e[k-1] - e[k-1-m]))
    i.e. u = kp e + ki sum(e) + kdw (e[k] - e[k-m]): the last term is the speed error
    measured over a window of m periods."""
    x = x0
    v = 0.0          # counts/s
    i = 0.0
    u = 0.0          # the velocity-form accumulator
    hist = np.zeros(m + 2)     # e[k-1] .. e[k-1-m] in a ring
    tripped = False
    out_x[0] = x
    out_v[0] = 0.0
    out_i[0] = 0.0
    out_u[0] = 0.0
    ea = math.exp(-dt * r / l)
    mean_f = (l / (r * dt)) * (1.0 - ea)      # mean of the exponential over the step
    n = 0
    h = m + 2
    for k in range(ff.shape[0]):
        cnt = math.floor(x + 1e-9)             # QEP count: edges at integer positions
        e = xref[k] - cnt
        if k == 0:
            for q in range(h):
                hist[q] = e
        e1 = hist[(k - 1) % h]
        em = hist[(k - m) % h]
        em1 = hist[(k - 1 - m) % h]
        du = kp * (e - e1) + ki * e + kdw * ((e - em) - (e1 - em1))
        hist[k % h] = e
        u += du
        volts = u + ff[k]
        # anti-windup: the accumulator never asks beyond the bridge
        if volts > vmax:
            u -= volts - vmax
            volts = vmax
        elif volts < -vmax:
            u -= volts + vmax
            volts = -vmax
        for s in range(n_sub):
            w = v / cpr
            iss = (volts - ke * w) / r
            i_new = iss + (i - iss) * ea
            i_avg = iss + (i - iss) * mean_f
            # LM393 over-current cut: the bridge turns off until the current falls below the
            # limit; at PWM rates this chops the current at the limit (ideal clamp)
            if i_new > ilim:
                i_new = ilim
                tripped = True
            elif i_new < -ilim:
                i_new = -ilim
                tripped = True
            if i_avg > ilim:
                i_avg = ilim
            elif i_avg < -ilim:
                i_avg = -ilim
            torque = kt * i_avg
            if w > 0.0:
                w_new = w + dt * (torque - tf) / j
                if w_new < 0.0:
                    w_new = 0.0
            elif w < 0.0:
                w_new = w + dt * (torque + tf) / j
                if w_new > 0.0:
                    w_new = 0.0
            else:
                if torque > tf:
                    w_new = dt * (torque - tf) / j
                elif torque < -tf:
                    w_new = dt * (torque + tf) / j
                else:
                    w_new = 0.0
            v_new = w_new * cpr
            x += 0.5 * (v + v_new) * dt
            v = v_new
            i = i_new
            n += 1
            out_x[n] = x
            out_v[n] = v
            out_i[n] = i
            out_u[n] = volts
    return tripped, n + 1


# -- reference ---------------------------------------------------------------------------------
@kernel()
def _trapezoid_kernel(t, start, s, distance, vp, a, tr, T, d_ramp, x, v, acc):  # pragma: no cover - compiled
    """One pass of the trapezoid's three phases; the same operations in the same order as
    numpy's would be (bit for bit: the servo's reference and the fire times depend on it)."""
    half_a = 0.5 * a
    t_down = T - tr
    for k in range(t.shape[0]):
        tk = max(t[k], 0.0)
        if tk >= t_down:                      # the ramp down wins where the ramps meet
            rem = max(T - tk, 0.0)
            d = distance - half_a * (rem * rem)
            vk = a * rem
            ak = -a if tk < T else 0.0
        elif tk <= tr:
            d = half_a * (tk * tk)
            vk = a * tk
            ak = a
        else:
            d = d_ramp + vp * (tk - tr)
            vk = vp
            ak = 0.0
        x[k] = start + s * d
        v[k] = s * vk
        acc[k] = s * ak


def trapezoid_reference(move: Trapezoid, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, speed and acceleration of the ideal trapezoid at times t (compiled: the
    servo's fine grid is ~270,000 samples a full-width line)."""
    t = np.asarray(t, dtype=np.float64)
    if move.distance == 0:
        return np.full_like(t, move.start), np.zeros_like(t), np.zeros_like(t)
    flat = np.ascontiguousarray(t).reshape(-1)
    x, v, acc = np.empty_like(flat), np.empty_like(flat), np.empty_like(flat)
    _trapezoid_kernel(flat, float(move.start), float(move.sign), float(move.distance),
                      float(move.v_peak), float(move.a), float(move.t_ramp), float(move.duration),
                      float(move.d_ramp), x, v, acc)
    return x.reshape(t.shape), v.reshape(t.shape), acc.reshape(t.shape)


@dataclass
class Trajectory:
    t: np.ndarray                 # sample times (s), from 0
    x: np.ndarray                 # position in counts (float)
    v: np.ndarray                 # counts/s
    i: np.ndarray                 # motor current (A)
    tripped: bool                 # over-current cut tripped
    max_following_error: float    # counts, max |reference - x| over the whole run
    start: float = 0.0
    target: float = 0.0
    move_duration: float = 0.0    # the reference's duration (s)
    period_s: float = 0.0
    u: np.ndarray = field(default=None, repr=False)       # bridge average voltage (V)
    x_ref: np.ndarray = field(default=None, repr=False)   # the DSP's reference at t

    @property
    def forward(self) -> bool:
        return self.target >= self.start

    @property
    def final_position(self) -> float:
        return float(self.x[-1])

    @property
    def final_count(self) -> int:
        """The QEP counter at the end."""
        return int(math.floor(self.x[-1] + 1e-9))

    @property
    def final_error(self) -> float:
        """Counter at the end minus the target (counts)."""
        return self.final_count - self.target

    @property
    def following_error(self) -> np.ndarray:
        return self.x_ref - self.x

    def max_following_error_during(self, t0: float = 0.0, t1: float | None = None) -> float:
        t1 = self.move_duration if t1 is None else t1
        m = (self.t >= t0) & (self.t <= t1)
        return float(np.max(np.abs(self.following_error[m]))) if m.any() else 0.0

    @property
    def peak_current(self) -> float:
        return float(np.max(np.abs(self.i)))

    def stop_time(self, tol_counts: float = 1.0, v_tol: float | None = None) -> float:
        """First time after which the carriage stays within tol_counts of the target (and,
        if v_tol is given, slower than v_tol counts/s) to the end of the run; np.nan if it
        never settles within the run.  At rest the loop may hunt across one encoder edge
        (a fraction of a count at a few counts/s): that counts as settled."""
        bad = np.abs(self.x - self.target) > tol_counts
        if v_tol is not None:
            bad |= np.abs(self.v) > v_tol
        idx = np.flatnonzero(bad)
        if idx.size == 0:
            return float(self.t[0])
        if idx[-1] == self.t.size - 1:
            return math.nan
        return float(self.t[idx[-1] + 1])

    @property
    def settle_time(self) -> float:
        """stop_time() minus the reference's duration (s; negative: settled before the
        reference ended)."""
        return self.stop_time() - self.move_duration

    def crossing_times(self, positions: np.ndarray, forward: bool | None = None) -> np.ndarray:
        """Time at which the encoder first reaches each position moving in the line's direction
        (np.nan if never). Vectorised: running max (forward) / running min (reverse) of x, then
        searchsorted + linear interpolation. Positions are encoder edges; the FPGA fires on
        the first crossing only, so servo jitter never fires twice."""
        forward = self.forward if forward is None else forward
        p = np.asarray(positions, dtype=np.float64)
        x = self.x if forward else -self.x
        q = p if forward else -p
        m = np.maximum.accumulate(x)
        idx = np.searchsorted(m, q, side="left")        # first sample with running max >= q
        out = np.full(q.shape, np.nan)
        at0 = idx == 0
        out[at0] = self.t[0]
        ok = (idx > 0) & (idx < x.size)
        k = idx[ok]
        x0, x1 = x[k - 1], x[k]                          # x0 <= m[k-1] < q <= x1 = m[k]
        frac = (q[ok] - x0) / (x1 - x0)
        out[ok] = self.t[k - 1] + frac * (self.t[k] - self.t[k - 1])
        return out


def simulate_move(params: ServoParams, start_counts: float, end_counts: float, v_counts_s: float,
                  a_counts_s2: float, settle_s: float = 0.2) -> Trajectory:
    """Run one carriage move through the DSP loop and the plant; the run lasts the reference's
    duration plus settle_s."""
    p = params
    if start_counts != end_counts and (v_counts_s <= 0 or a_counts_s2 <= 0):
        raise ValueError("a move needs a positive speed and acceleration")
    move = Trapezoid(float(start_counts), float(end_counts), float(v_counts_s), float(a_counts_s2))
    T = float(p.period_s)
    n_sub = max(1, int(math.ceil(T / p.max_dt_s - 1e-9)))
    dt = T / n_sub
    total = move.duration + max(settle_s, 0.0)
    n_ctrl = max(1, int(math.ceil(total / T - 1e-9)))
    tk = np.arange(n_ctrl + 1) * T
    xr, vr, _ = trapezoid_reference(move, tk)
    # feed-forward per period from the reference's mean speed and acceleration over it
    ff = p.kff_v * np.diff(xr) / T + p.kff_a * np.diff(vr) / T
    n = n_ctrl * n_sub + 1
    out_x = np.empty(n)
    out_v = np.empty(n)
    out_i = np.empty(n)
    out_u = np.empty(n)
    tripped, _ = _servo_kernel(ff, xr[:-1].copy(), n_sub, dt, float(start_counts), p.kp, p.ki,
                               p.kv / (p.speed_window * T), int(p.speed_window), p.supply_v, p.ke, p.kt, p.r_ohm, p.l_h, p.j_kg_m2,
                               p.friction_nm, p.current_limit_a, p.counts_per_rad,
                               out_x, out_v, out_i, out_u)
    t = np.arange(n) * dt
    x_ref = trapezoid_reference(move, t)[0]
    fe = float(np.max(np.abs(x_ref - out_x)))
    return Trajectory(t=t, x=out_x, v=out_v, i=out_i, tripped=bool(tripped),
                      max_following_error=fe, start=float(start_counts),
                      target=float(end_counts), move_duration=move.duration, period_s=T,
                      u=out_u, x_ref=x_ref)


class ServoMove:
    """A carriage move as the DSP's servo actually runs it (simulate_move): the same
    interface as motion.Trapezoid, but times and positions come from the simulated motor, so fire
    times carry the servo's real speed ripple and the move ends where the motor stopped."""

    def __init__(self, params, start: float, end: float, v: float, a: float):
        self.start, self.end, self.v, self.a = float(start), float(end), v, a
        self.traj = simulate_move(params, start, end, v, a)
        self.sign = 1 if end >= start else -1
        self.duration = float(self.traj.stop_time())
        self.final = float(self.traj.final_position)

    def time_at(self, positions: np.ndarray) -> np.ndarray:
        t = self.traj.crossing_times(np.asarray(positions, dtype=np.float64), self.sign > 0)
        if np.isnan(t).any():
            raise ValueError("the servo never reached a fire position")
        return t

    def position_at(self, t: float) -> float:
        return float(np.interp(t, self.traj.t, self.traj.x))

    def speed_at(self, t: float) -> float:
        return float(np.interp(t, self.traj.t, self.traj.v))

    def speeds_at(self, t: np.ndarray) -> np.ndarray:
        """Signed carriage speed (counts/s) at these times (the physical model's drops)."""
        return np.interp(t, self.traj.t, self.traj.v)
